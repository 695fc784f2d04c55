"""The Fréchet Gesture Distance: a tiny feature network trained on a few short conversations."""

import time

import numpy as np
import pytest
import torch

from gesturelib.checkpoints import load_model
from gesturelib.evaluation.fgd import (
    MotionFeatureConfig,
    MotionFeatureNetwork,
    feature_network,
    fgd,
    motion_features,
)

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def conversations():
    """Four 30 s training conversations, one for validation, four of 45 s held out (3 minutes:
    with less, redraws of the same conversations' motion differ by nearly as much as no motion)."""
    from data_synth import generate_conversation

    return {
        "train": [generate_conversation(30.0, seed=seed) for seed in range(100, 104)],
        "val": [generate_conversation(30.0, seed=150)],
        "test": [generate_conversation(45.0, seed=seed) for seed in range(160, 164)],
    }


@pytest.fixture(scope="module")
def trained(conversations, tmp_path_factory):
    """The quick feature network of the training conversations, its cache and its data."""
    cache = tmp_path_factory.mktemp("fgd_cache")
    train = [c.positions for c in conversations["train"]]
    val = [c.positions for c in conversations["val"]]
    network = feature_network(train, val, cache, quick=True, progress=False)
    return network, cache, train, val


def test_network_sizes_and_features():
    network = MotionFeatureNetwork(MotionFeatureConfig())
    parameters = sum(p.numel() for p in network.parameters())
    assert 5_000 < parameters < 100_000
    windows = torch.randn(5, 32, 9, 3) * 10
    assert network.encode(windows).shape == (5, 32)
    assert set(network.state_dict()) >= {"mean", "std"}  # saved with the weights
    with pytest.raises(ValueError, match="window must be a multiple"):
        MotionFeatureConfig(window=30, levels=2)


def test_standardiser_comes_from_the_training_motion(trained):
    network, _, train, _ = trained
    frames = np.concatenate(train).reshape(-1, 27)
    steps = np.concatenate([np.diff(p.reshape(-1, 27), axis=0) for p in train])
    config = network.config
    assert config.velocities
    mean = np.concatenate([frames.mean(axis=0), steps.mean(axis=0)])
    std = np.concatenate(
        [
            np.maximum(frames.std(axis=0), config.min_std),
            np.maximum(steps.std(axis=0), config.min_velocity_std),
        ]
    )
    np.testing.assert_allclose(network.mean.numpy(), mean, atol=1e-3)
    np.testing.assert_allclose(network.std.numpy(), std, rtol=1e-4)


def test_fgd_of_a_set_with_itself_is_zero(trained, conversations):
    network = trained[0]
    truth = [c.positions for c in conversations["test"]]
    assert fgd(network, truth, truth) == pytest.approx(0.0, abs=1e-6)
    assert fgd(network, truth[0], truth[0]) == pytest.approx(0.0, abs=1e-6)


def test_fgd_grows_with_noise(trained, conversations):
    network = trained[0]
    truth = [c.positions for c in conversations["test"]]
    rng = np.random.default_rng(0)
    unit = [rng.standard_normal(p.shape) for p in truth]
    values = [
        fgd(network, [p + s * z for p, z in zip(truth, unit, strict=True)], truth)
        for s in (1, 3, 9)
    ]
    assert values[0] > 1e-3
    assert values[0] < values[1] < values[2]


def test_mean_pose_is_far_worse_than_resampled_motion(trained, conversations):
    from data_synth import resample_motion

    network, _, train, _ = trained
    test = conversations["test"]
    truth = [c.positions for c in test]
    resampled = [resample_motion(c, seed=50 + i).positions for i, c in enumerate(test)]
    mean_pose = np.concatenate(train).mean(axis=0)
    still = [np.broadcast_to(mean_pose, p.shape) for p in truth]
    floor, held_still = fgd(network, resampled, truth), fgd(network, still, truth)
    assert floor > 0
    assert held_still > 3 * floor  # >= 3.8 times in 40 draws (5 data x 8 redraw seeds)


def test_cache_loads_the_same_weights_and_follows_the_motion(trained):
    network, cache, train, val = trained
    started = time.perf_counter()
    again = feature_network(train, val, cache, quick=True, progress=False)
    assert time.perf_counter() - started < 1.0
    assert again is not network
    for name, value in network.state_dict().items():
        assert torch.equal(value, again.state_dict()[name]), name
    (folder,) = cache.iterdir()
    loaded = load_model(folder / "best.pt", MotionFeatureNetwork)  # buffers and weights
    for name, value in network.state_dict().items():
        assert torch.equal(value, loaded.state_dict()[name]), name
    feature_network([train[0]], None, cache, quick=True, progress=False)
    feature_network([train[0] + 1.0], None, cache, quick=True, progress=False)
    assert len(list(cache.iterdir())) == 3  # the key changes with the motion


def test_shape_errors_are_named(trained, conversations):
    network, cache, train, val = trained
    truth = [c.positions for c in conversations["test"]]
    with pytest.raises(ValueError, match=r"motions\[1\] must have shape \(T, 9, 3\)"):
        fgd(network, [truth[0], np.zeros((100, 9, 6))], truth)
    with pytest.raises(ValueError, match=r"reference\[0\] has 20 frames, fewer than"):
        fgd(network, truth, [truth[0][:20]])
    with pytest.raises(ValueError, match="reference gives 1 window"):
        fgd(network, truth, [truth[0][:32]])
    with pytest.raises(ValueError, match=r"motions\[0\] holds NaN"):
        fgd(network, [np.full((64, 9, 3), np.nan)], truth)
    with pytest.raises(ValueError, match="motions is empty"):
        fgd(network, [], truth)
    with pytest.raises(ValueError, match=r"train_positions\[1\] must have shape"):
        feature_network([train[0], train[1][:, :8]], val, cache, quick=True, progress=False)
    with pytest.raises(ValueError, match=r"windows of shape \(N, 32, 9, 3\)"):
        network.encode(torch.zeros(4, 16, 9, 3))
    with pytest.raises(TypeError, match="MotionFeatureNetwork"):
        motion_features(object(), truth)
