import dataclasses
import re

import pytest
import torch

import data_synth
from gesturelib.checkpoints import load_model, read_checkpoint
from gesturelib.configs import config_from_dict, config_to_dict
from gesturelib.data import WindowConfig, make_datasets
from gesturelib.models import (
    CVAE,
    Aud2Pose,
    Aud2PoseConfig,
    Aud2Repr2Pose,
    Aud2Repr2PoseConfig,
    CVAEConfig,
    MotionDAEConfig,
    MotionDenoisingAutoencoder,
    PoseAutoencoder,
    PoseAutoencoderConfig,
    PoseVAE,
    PoseVAEConfig,
    gaussian_kl,
    reparameterise,
)
from gesturelib.train import TrainConfig, train

# Small windows keep every test fast: 2 past + 1 + 3 future = 6 speech frames, 2 past poses.
WINDOW = WindowConfig(past_poses=2, speech_past=2, speech_future=3)
W = WINDOW.speech_window
SMALL_WINDOW = {"speech_past": WINDOW.speech_past, "speech_future": WINDOW.speech_future}


pytestmark = pytest.mark.usefixtures("one_thread")


def make_batch(batch_size=4, length=5, seed=0, tau=WINDOW.past_poses, window=W):
    """Random parts of the documented shapes; the poses lie near a 2-D plane, as poses lie near
    a low-dimensional manifold, so that a 2-D latent can learn them."""
    generator = torch.Generator().manual_seed(seed)
    activity = torch.nn.functional.one_hot(
        torch.randint(0, 4, (batch_size, length, window), generator=generator), 4
    ).float()
    plane = torch.randn(2, 54, generator=generator)
    coordinates = torch.randn(batch_size, length, 2, generator=generator)
    noise = 0.05 * torch.randn(batch_size, length, 54, generator=generator)
    return {
        "pose": coordinates @ plane + noise,
        "past_pose": torch.randn(batch_size, length, tau, 54, generator=generator),
        "speech": torch.randn(batch_size, length, window, 27, generator=generator),
        "activity": activity,
    }


def build(name: str, seed: int = 0, **changes) -> torch.nn.Module:
    """A small model of each kind; ``changes`` go to its config."""
    torch.manual_seed(seed)
    if name == "autoencoder":
        return PoseAutoencoder(PoseAutoencoderConfig.quick(**changes))
    if name == "vae":
        return PoseVAE(PoseVAEConfig.quick(**changes))
    if name == "cvae":
        return CVAE(CVAEConfig.quick(**SMALL_WINDOW, **changes))
    if name == "aud2pose":
        return Aud2Pose(Aud2PoseConfig.quick(**SMALL_WINDOW, **changes))
    if name == "dae":
        return MotionDenoisingAutoencoder(MotionDAEConfig.quick(**changes))
    if name == "aud2repr2pose":
        autoencoder = MotionDenoisingAutoencoder(MotionDAEConfig.quick())
        config = Aud2Repr2PoseConfig.quick(**SMALL_WINDOW, **changes)
        return Aud2Repr2Pose.from_autoencoder(autoencoder, config)
    raise ValueError(name)


MODELS = ["autoencoder", "vae", "cvae", "aud2pose", "dae", "aud2repr2pose"]
LOGGED = {
    "autoencoder": {"loss", "mse"},
    "vae": {"loss", "mse", "kl"},
    "cvae": {"loss", "mse", "kl"},
    "aud2pose": {"loss", "mse", "velocity_mse"},
    "dae": {"loss", "mse"},
    "aud2repr2pose": {"loss", "mse"},
}


# ---------------------------------------------------------------------------------------------
# The loss of every model
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", MODELS)
def test_loss_returns_the_documented_finite_scalars(name):
    terms = build(name).loss(make_batch())
    assert set(terms) == LOGGED[name]
    for value in terms.values():
        assert value.shape == () and torch.isfinite(value)
    assert terms["loss"].requires_grad


@pytest.mark.parametrize("name", MODELS)
def test_loss_decreases_on_a_fixed_batch(name):
    no_dropout = {"dropout": 0.0} if name in ("cvae", "aud2pose", "aud2repr2pose") else {}
    model = build(name, **no_dropout)
    batch = make_batch(batch_size=8, length=6, seed=1)

    def evaluated_loss():
        torch.manual_seed(123)  # the same noise for the VAEs' and the DAE's draws
        with torch.no_grad():
            return float(model.loss(batch)["loss"])

    before = evaluated_loss()
    optimiser = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=1e-2)
    for _ in range(40):
        optimiser.zero_grad()
        model.loss(batch)["loss"].backward()
        optimiser.step()
    assert evaluated_loss() < 0.6 * before


def test_vae_loss_is_summed_squared_error_plus_beta_kl():
    """The documented ELBO: squared error summed over the 54 numbers + beta * KL, per frame."""
    model = build("vae", beta=0.3)
    pose = make_batch()["pose"]
    mean, log_var = model.encode(pose)
    torch.manual_seed(5)
    reconstruction = model.decode(reparameterise(mean, log_var))
    expected_error = (reconstruction - pose).pow(2)
    expected_kl = gaussian_kl(mean, log_var).mean()
    torch.manual_seed(5)
    terms = model.loss({"pose": pose})
    torch.testing.assert_close(terms["loss"], expected_error.sum(-1).mean() + 0.3 * expected_kl)
    torch.testing.assert_close(terms["mse"], expected_error.mean())
    torch.testing.assert_close(terms["kl"], expected_kl)


def test_aud2pose_velocity_target_is_the_difference_to_the_previous_pose():
    model = build("aud2pose", dropout=0.0).eval()
    batch = make_batch()
    _, predicted_velocity = model(batch)
    velocity = batch["pose"] - batch["past_pose"][:, :, -1]
    expected = (predicted_velocity - velocity).pow(2).mean()
    torch.testing.assert_close(model.loss(batch)["velocity_mse"], expected)
    # the velocity target alone changes the logged velocity error
    shifted = dict(batch, past_pose=batch["past_pose"] + 1.0)
    assert model.loss(shifted)["velocity_mse"] > model.loss(batch)["velocity_mse"]


def test_aud2pose_without_velocity_needs_no_past_pose():
    model = build("aud2pose", velocity_weight=0.0)
    batch = make_batch()
    del batch["past_pose"]
    assert set(model.loss(batch)) == {"loss", "mse"}


# ---------------------------------------------------------------------------------------------
# KL and reparameterisation
# ---------------------------------------------------------------------------------------------


def test_gaussian_kl_matches_torch_distributions_and_is_non_negative():
    generator = torch.Generator().manual_seed(0)
    mean = torch.randn(100, 5, generator=generator)
    log_var = 2 * torch.randn(100, 5, generator=generator)
    kl = gaussian_kl(mean, log_var)
    posterior = torch.distributions.Normal(mean, (0.5 * log_var).exp())
    prior = torch.distributions.Normal(0.0, 1.0)
    torch.testing.assert_close(kl, torch.distributions.kl_divergence(posterior, prior).sum(-1))
    assert kl.shape == (100,) and (kl >= 0).all()
    assert torch.equal(gaussian_kl(torch.zeros(3, 5), torch.zeros(3, 5)), torch.zeros(3))


def test_kl_is_zero_when_the_posterior_is_the_prior():
    model = build("vae")
    last = model.encoder[-1]  # outputs [mean, log_var]: zero weights give mean 0, variance 1
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)
    assert float(model.loss(make_batch())["kl"]) == 0.0


def test_reparameterise_draws_from_the_posterior_and_passes_gradients():
    mean = torch.tensor([1.0, -2.0], requires_grad=True)
    log_var = torch.tensor([0.0, 2 * torch.log(torch.tensor(3.0))], requires_grad=True)
    z = reparameterise(
        mean.expand(20_000, 2), log_var.expand(20_000, 2), torch.Generator().manual_seed(0)
    )
    torch.testing.assert_close(z.mean(0), mean.detach(), atol=0.06, rtol=0)
    torch.testing.assert_close(z.std(0), torch.tensor([1.0, 3.0]), atol=0.06, rtol=0)
    z.sum().backward()
    assert mean.grad is not None and log_var.grad is not None


def test_cvae_kl_per_dimension_sums_to_the_logged_kl():
    model = build("cvae").eval()
    batch = make_batch()
    per_dimension = model.kl_per_dimension(batch)
    assert per_dimension.shape == (model.config.latent_dim,) and (per_dimension >= 0).all()
    torch.testing.assert_close(per_dimension.sum(), model.loss(batch)["kl"])


# ---------------------------------------------------------------------------------------------
# Sampling and prediction
# ---------------------------------------------------------------------------------------------


def seeded(seed):
    return torch.Generator().manual_seed(seed)


def test_vae_sampling_shapes_seeds_and_temperature():
    model = build("vae")
    samples = model.sample(6, generator=seeded(0))
    assert samples.shape == (6, 54)
    assert torch.equal(samples, model.sample(6, generator=seeded(0)))
    assert not torch.equal(samples, model.sample(6, generator=seeded(1)))
    mode = model.sample(3, temperature=0.0)
    expected = model.decode(torch.zeros(1, model.config.latent_dim)).detach()
    torch.testing.assert_close(mode, expected.expand(3, -1))
    assert not torch.allclose(model.sample(3, temperature=1.0, generator=seeded(0)), mode)
    # temperature scales z: a draw at 0.5 decodes half the noise of the same draw at 1
    half = model.sample(4, temperature=0.5, generator=seeded(2))
    z = 0.5 * torch.randn(4, model.config.latent_dim, generator=seeded(2))
    torch.testing.assert_close(half, model.decode(z).detach())


def test_cvae_sampling_shapes_seeds_and_temperature():
    model = build("cvae")  # in training mode: sample() must still run without dropout
    control = make_batch(batch_size=3, length=7)
    del control["pose"]
    samples = model.sample(control, generator=seeded(0))
    assert samples.shape == (3, 7, 54)
    assert model.training, "sample() must restore the model's mode"
    assert torch.equal(samples, model.sample(control, generator=seeded(0)))
    assert not torch.equal(samples, model.sample(control, generator=seeded(1)))
    mode = model.sample(control, temperature=0.0)
    expected = model.eval().decode(torch.zeros(3, 7, model.config.latent_dim), control)
    torch.testing.assert_close(mode, expected.detach())
    assert not torch.allclose(model.sample(control, temperature=1.0, generator=seeded(0)), mode)


@pytest.mark.parametrize("temperature", [-0.5, float("nan"), float("inf")])
def test_sampling_rejects_bad_temperatures(temperature):
    with pytest.raises(ValueError, match="temperature"):
        build("vae").sample(2, temperature=temperature)
    with pytest.raises(ValueError, match="temperature"):
        build("cvae").sample(make_batch(), temperature=temperature)


def test_vae_sample_rejects_bad_counts():
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        build("vae").sample(0)


def test_cvae_reconstruct_decodes_the_posterior_mean():
    model = build("cvae")
    batch = make_batch()
    reconstruction = model.reconstruct(batch)
    model.eval()
    mean, _ = model.encode(batch)
    torch.testing.assert_close(reconstruction, model.decode(mean, batch).detach())


@pytest.mark.parametrize("name", ["aud2pose", "aud2repr2pose"])
def test_prediction_is_deterministic_and_frame_by_frame(name):
    model = build(name)  # in training mode, with dropout: predict() must switch it off
    batch = make_batch(batch_size=2, length=4)
    prediction = model.predict(batch)
    assert prediction.shape == (2, 4, 54)
    assert torch.equal(prediction, model.predict(batch)) and model.training
    # each frame depends on its own window only: predicting frame 2 alone gives the same pose
    frame = {key: value[:, 2:3] for key, value in batch.items()}
    torch.testing.assert_close(model.predict(frame)[:, 0], prediction[:, 2])


def test_frame_models_work_on_any_sequence_length():
    for name in ("autoencoder", "vae"):
        model = build(name)
        for length in (1, 3):
            assert set(model.loss(make_batch(length=length))) == LOGGED[name]
    model = build("autoencoder")
    pose = make_batch(length=3)["pose"]
    assert model.latent(pose).shape == (4, 3, 2) and model(pose).shape == (4, 3, 54)
    assert build("vae").latent(pose).shape == (4, 3, 2)


# ---------------------------------------------------------------------------------------------
# Aud2Repr2Pose: the two stages
# ---------------------------------------------------------------------------------------------


def test_aud2repr2pose_freezes_a_copy_of_the_trained_autoencoder():
    torch.manual_seed(0)
    autoencoder = MotionDenoisingAutoencoder(MotionDAEConfig.quick())
    model = Aud2Repr2Pose.from_autoencoder(autoencoder, Aud2Repr2PoseConfig.quick(**SMALL_WINDOW))
    assert model.config.autoencoder == autoencoder.config
    frozen = {k: v.clone() for k, v in model.autoencoder.state_dict().items()}
    for key, value in autoencoder.state_dict().items():
        assert torch.equal(frozen[key], value)
    assert not any(p.requires_grad for p in model.autoencoder.parameters())
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-2)
    batch = make_batch()
    for _ in range(3):
        optimiser.zero_grad()
        model.loss(batch)["loss"].backward()
        optimiser.step()
    for key, value in model.autoencoder.state_dict().items():
        assert torch.equal(frozen[key], value)
    # the prediction is MotionD of SpeechE's output
    model.eval()
    expected = autoencoder.decode(model(batch)).detach()
    torch.testing.assert_close(model.predict(batch), expected)


def test_aud2repr2pose_refuses_to_train_without_a_trained_autoencoder():
    model = Aud2Repr2Pose(Aud2Repr2PoseConfig.quick(**SMALL_WINDOW))
    with pytest.raises(RuntimeError, match="from_autoencoder"):
        model.loss(make_batch())


def test_aud2repr2pose_config_round_trips_through_a_dict():
    config = Aud2Repr2PoseConfig.quick(autoencoder=MotionDAEConfig(hidden_sizes=(16, 12)))
    assert config_from_dict(Aud2Repr2PoseConfig, config_to_dict(config)) == config
    with pytest.raises(ValueError, match="representation_dim"):
        config_from_dict(Aud2Repr2PoseConfig, {"autoencoder": {"representation_dim": 0}})


# ---------------------------------------------------------------------------------------------
# The training protocol: train() on real windows, checkpoints, load_model()
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_datasets():
    """Windows of two short generated conversations: a training and a validation split."""
    splits = {
        "train": [data_synth.generate_conversation(4.0, seed=1)],
        "val": [data_synth.generate_conversation(3.0, seed=2)],
    }
    frames, _ = make_datasets(splits, dataclasses.replace(WINDOW, stride=8))
    sequences, _ = make_datasets(
        splits, dataclasses.replace(WINDOW, sequence_length=10, stride=20), mirror_train=False
    )
    return {"frames": frames, "sequences": sequences}


@pytest.mark.parametrize("name", MODELS)
def test_models_train_with_the_training_loop_and_reload(name, tiny_datasets, tmp_path):
    datasets = tiny_datasets["sequences" if name == "cvae" else "frames"]
    model = build(name)
    config = TrainConfig(epochs=2, batch_size=8, warmup_steps=2, patience=None)
    history = train(model, datasets["train"], datasets["val"], config, tmp_path, progress=False)
    assert history.epochs == 2 and set(history.train) == LOGGED[name] == set(history.val)
    assert read_checkpoint(tmp_path / "best.pt")["model_class"] == type(model).__name__
    loaded = load_model(tmp_path / "best.pt", type(model))
    assert loaded.config == model.config
    for key, value in model.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value), key
    batch = next(iter(torch.utils.data.DataLoader(datasets["val"], batch_size=4)))
    if name == "cvae":
        torch.testing.assert_close(
            loaded.sample(batch, generator=seeded(0)), model.sample(batch, generator=seeded(0))
        )
    elif name in ("aud2pose", "aud2repr2pose"):
        torch.testing.assert_close(loaded.predict(batch), model.predict(batch))


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", MODELS)
def test_a_missing_part_is_named_with_its_shape(name):
    model = build(name)
    needed = "pose" if name in ("autoencoder", "vae", "dae") else "speech"
    batch = make_batch()
    del batch[needed]
    expected = "(B, L, 54)" if needed == "pose" else f"(B, L, {W}, 27)"
    with pytest.raises(ValueError, match=re.escape(f"batch['{needed}'] with shape {expected}")):
        model.loss(batch)


@pytest.mark.parametrize(
    ("name", "part", "shape", "expected"),
    [
        ("autoencoder", "pose", (4, 5, 53), "(B, L, 54)"),
        ("vae", "pose", (4, 54), "(B, L, 54)"),
        ("cvae", "speech", (4, 5, W + 1, 27), f"(B, L, {W}, 27)"),
        ("cvae", "activity", (4, 5, W, 3), f"(B, L, {W}, 4)"),
        ("aud2pose", "speech", (4, 5, W, 26), f"(B, L, {W}, 27)"),
        ("aud2pose", "past_pose", (4, 5, 2, 50), "(B, L, tau, 54)"),
        ("dae", "pose", (4, 5, 1, 54), "(B, L, 54)"),
        ("aud2repr2pose", "activity", (4, 5, W), f"(B, L, {W}, 4)"),
    ],
)
def test_a_misshapen_part_is_named_with_expected_and_actual_shape(name, part, shape, expected):
    batch = make_batch()
    batch[part] = torch.zeros(shape)
    with pytest.raises(ValueError) as error:
        build(name).loss(batch)
    message = str(error.value)
    assert f"batch['{part}'] must have shape {expected}" in message
    assert f"got {shape}" in message


def test_parts_that_disagree_in_batch_or_length_are_rejected():
    batch = make_batch()
    batch["activity"] = batch["activity"][:, :4]
    with pytest.raises(ValueError, match=r"\(B, L\) = \(4, 4\).*\(4, 5\)"):
        build("cvae").loss(batch)


def test_non_tensor_parts_and_non_dict_batches_are_rejected():
    batch = make_batch()
    batch["pose"] = batch["pose"].tolist()
    with pytest.raises(TypeError, match=r"batch\['pose'\] must be a float tensor"):
        build("autoencoder").loss(batch)
    batch = make_batch()
    batch["speech"] = batch["speech"].long()
    with pytest.raises(TypeError, match="torch.int64"):
        build("aud2pose").loss(batch)
    with pytest.raises(TypeError, match="a batch must be a dict"):
        build("vae").loss(torch.zeros(4, 5, 54))


def test_cvae_sample_names_a_missing_control_part():
    control = make_batch()
    del control["activity"]
    with pytest.raises(ValueError, match=r"CVAE.sample needs batch\['activity'\]"):
        build("cvae").sample(control)


def test_velocity_without_previous_poses_is_explained():
    with pytest.raises(ValueError, match="past_poses >= 1"):
        build("aud2pose").loss(make_batch(tau=0))


@pytest.mark.parametrize(
    ("factory", "field"),
    [
        (lambda: PoseAutoencoderConfig(latent_dim=0), "PoseAutoencoderConfig.latent_dim"),
        (lambda: PoseAutoencoderConfig(hidden_sizes=(64, -1)), "hidden_sizes"),
        (lambda: PoseAutoencoderConfig(hidden_sizes=[64]), "must be a tuple"),
        (lambda: PoseVAEConfig(beta=-1.0), "PoseVAEConfig.beta"),
        (lambda: CVAEConfig(hidden_size=0), "CVAEConfig.hidden_size"),
        (lambda: CVAEConfig(num_layers=1.5), "CVAEConfig.num_layers"),
        (lambda: CVAEConfig(dropout=1.0), "CVAEConfig.dropout"),
        (lambda: CVAEConfig(speech_future=-1), "CVAEConfig.speech_future"),
        (lambda: Aud2PoseConfig(velocity_weight=float("nan")), "Aud2PoseConfig.velocity_weight"),
        (lambda: Aud2PoseConfig(use_activity="yes"), "Aud2PoseConfig.use_activity"),
        (lambda: MotionDAEConfig(hidden_sizes=(0,)), "MotionDAEConfig.hidden_sizes"),
        (lambda: MotionDAEConfig(noise_std=-0.1), "MotionDAEConfig.noise_std"),
        (lambda: Aud2Repr2PoseConfig(autoencoder={}), "Aud2Repr2PoseConfig.autoencoder"),
    ],
)
def test_bad_config_values_name_the_field(factory, field):
    with pytest.raises(ValueError, match=field):
        factory()


def test_quick_configs_are_smaller_and_take_overrides():
    assert CVAEConfig.quick().hidden_size < CVAEConfig().hidden_size
    assert CVAEConfig.quick(latent_dim=3).latent_dim == 3
    assert Aud2PoseConfig.quick().hidden_size < Aud2PoseConfig().hidden_size
    assert PoseVAEConfig.quick(beta=0.5).beta == 0.5
    assert MotionDAEConfig.quick().representation_dim < MotionDAEConfig().representation_dim
    assert Aud2Repr2PoseConfig.quick().autoencoder == MotionDAEConfig.quick()
    # the defaults match the data's window
    window = WindowConfig()
    for config in (CVAEConfig(), Aud2PoseConfig(), Aud2Repr2PoseConfig()):
        assert config.speech_window == window.speech_window
