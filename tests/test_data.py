import dataclasses
import json
from dataclasses import dataclass

import numpy as np
import pytest
import torch

from gesturelib.conventions import FPS, SAMPLE_RATE
from gesturelib.data import (
    ConversationFeatures,
    Normaliser,
    WindowConfig,
    WindowDataset,
    control_dims,
    make_datasets,
)
from gesturelib.features import activity_one_hot
from gesturelib.skeleton import (
    POSE_DIM,
    forward_kinematics,
    mirror_rotations,
    rotations_from_positions,
)
from gesturelib.style import STYLE_FEATURES


@dataclass
class FakeConversation:
    audio: np.ndarray
    rotations: np.ndarray
    activity: np.ndarray
    sample_rate: int = SAMPLE_RATE
    fps: int = FPS


def fake_conversation(n_frames: int, seed: int) -> FakeConversation:
    """Random poses (valid limb rotations), noise for audio, random activity codes."""
    rng = np.random.default_rng(seed)
    positions = forward_kinematics(rng.standard_normal((n_frames, 9, 6)))
    return FakeConversation(
        audio=(0.1 * rng.standard_normal(n_frames * SAMPLE_RATE // FPS)).astype(np.float32),
        rotations=rotations_from_positions(positions).astype(np.float32),
        activity=rng.integers(0, 4, n_frames),
    )


def indexed_features(n_frames: int, seed: int = 0) -> ConversationFeatures:
    """Features whose pose and style numbers encode their frame index: frame t has pose values
    t + 0.01 * d and style values t + 0.1 * i (not rotations: for checking windows only)."""
    rng = np.random.default_rng(seed)
    frames = np.arange(n_frames, dtype=np.float32)[:, None]
    return ConversationFeatures(
        pose=frames + 0.01 * np.arange(POSE_DIM, dtype=np.float32),
        speech=rng.standard_normal((n_frames, 27)).astype(np.float32),
        activity=activity_one_hot(rng.integers(0, 4, n_frames)),
        style=frames + 0.1 * np.arange(len(STYLE_FEATURES), dtype=np.float32),
    )


IDENTITY = Normaliser(
    pose_mean=np.zeros(POSE_DIM, np.float32),
    pose_std=np.ones(POSE_DIM, np.float32),
    speech_mean=np.zeros(27, np.float32),
    speech_std=np.ones(27, np.float32),
    style_mean=np.zeros(4, np.float32),
    style_std=np.ones(4, np.float32),
    style_percentiles=np.tile(np.linspace(-2.0, 2.0, 101)[:, None], (1, 4)),
)


@pytest.fixture(scope="module")
def features():
    return indexed_features(100)


def test_features_have_one_row_per_frame():
    features = ConversationFeatures.from_conversation(fake_conversation(100, seed=0))
    assert features.pose.shape == (100, POSE_DIM)
    assert features.speech.shape == (100, 27)
    assert features.activity.shape == (100, 4)
    assert features.style.shape == (100, len(STYLE_FEATURES))


@pytest.mark.parametrize("length", [1, 8])
def test_window_shapes_and_count(features, length):
    config = WindowConfig(past_poses=5, speech_past=5, speech_future=25, sequence_length=length)
    dataset = WindowDataset([features], config, IDENTITY)
    assert len(dataset) == 100 - 25 - length - 5 + 1  # every window whose context fits
    item = dataset[0]
    assert item["pose"].shape == (length, POSE_DIM)
    assert item["past_pose"].shape == (length, 5, POSE_DIM)
    assert item["speech"].shape == (length, 31, 27)
    assert item["activity"].shape == (length, 31, 4)
    assert item["style"].shape == (length, 4)
    assert all(value.dtype == torch.float32 for value in item.values())
    assert sum(control_dims(config).values()) == 5 * POSE_DIM + 31 * (27 + 4) + 4


def test_windows_hold_the_right_frames(features):
    config = WindowConfig(past_poses=3, speech_past=2, speech_future=4, sequence_length=6, stride=5)
    dataset = WindowDataset([features], config, IDENTITY)
    for item_number in (0, 3, len(dataset) - 1):
        item = dataset[item_number]
        first = 3 + 5 * item_number  # max(past_poses, speech_past) + stride * n
        frames = item["pose"][:, 0].round().long()
        assert frames.tolist() == list(range(first, first + 6))
        for k, t in enumerate(frames.tolist()):
            assert item["past_pose"][k, :, 0].round().long().tolist() == [t - 3, t - 2, t - 1]
            np.testing.assert_allclose(item["speech"][k], features.speech[t - 2 : t + 5])
            np.testing.assert_allclose(item["activity"][k], features.activity[t - 2 : t + 5])
            assert item["style"][k, 0].round().long().item() == t
    last = dataset[len(dataset) - 1]["pose"][-1, 0].round().long().item()
    assert last + config.speech_future <= 99, "the future context stays inside the conversation"


def test_no_past_poses(features):
    dataset = WindowDataset([features], WindowConfig(past_poses=0, sequence_length=2), IDENTITY)
    assert dataset[0]["past_pose"].shape == (2, 0, POSE_DIM)


def test_normaliser_standardises_and_inverts():
    train = [ConversationFeatures.from_conversation(fake_conversation(80, seed)) for seed in (1, 2)]
    normaliser = Normaliser.fit(train)
    pose = np.concatenate([f.pose for f in train])
    normalised = normaliser.normalise_pose(pose)
    np.testing.assert_allclose(normalised.mean(0), 0.0, atol=1e-4)
    np.testing.assert_allclose(normalised.std(0), 1.0, atol=1e-4)
    np.testing.assert_allclose(normaliser.denormalise_pose(normalised), pose, rtol=1e-5, atol=1e-4)
    tensor = torch.from_numpy(pose)
    torch.testing.assert_close(
        normaliser.denormalise_pose(normaliser.normalise_pose(tensor)), tensor
    )
    restored = Normaliser.from_dict(normaliser.to_dict())
    np.testing.assert_array_equal(restored.pose_std, normaliser.pose_std)


def test_constant_feature_is_centred_not_blown_up():
    features = ConversationFeatures.from_conversation(fake_conversation(60, seed=3))
    constant = ConversationFeatures(
        np.ones_like(features.pose), features.speech, features.activity, features.style
    )
    normalised = Normaliser.fit([constant]).normalise_pose(constant.pose)
    assert np.isfinite(normalised).all() and np.abs(normalised).max() < 1e-3


def test_make_datasets_fits_on_train_and_mirrors_train_only():
    splits = {
        "train": [fake_conversation(70, 4), fake_conversation(70, 5)],
        "val": [fake_conversation(70, 6)],
    }
    config = WindowConfig()
    datasets, normaliser = make_datasets(splits, config, mirror_train=True)
    per_conversation = 70 - 25 - 1 - 5 + 1
    assert len(datasets["train"]) == 4 * per_conversation  # two conversations and their mirrors
    assert len(datasets["val"]) == per_conversation
    train = [ConversationFeatures.from_conversation(c) for c in splits["train"]]
    expected = Normaliser.fit([*train, *(f.mirrored() for f in train)])
    np.testing.assert_allclose(normaliser.pose_mean, expected.pose_mean, rtol=1e-6)
    # The second half of the training items are the mirror images of the first half.
    mirrored_item = datasets["train"][2 * per_conversation]["pose"][0]
    raw = normaliser.denormalise_pose(mirrored_item).numpy().reshape(9, 6)
    original_frame = train[0].pose[5].reshape(9, 6)
    np.testing.assert_allclose(raw, mirror_rotations(original_frame), atol=1e-4)


def test_bad_configs_and_inputs_are_rejected(tmp_path, features):
    with pytest.raises(ValueError, match="sequence_length must be an integer >= 1"):
        WindowConfig(sequence_length=0)
    with pytest.raises(ValueError, match="past_poses must be an integer >= 0"):
        WindowConfig(past_poses=-1)
    with pytest.raises(ValueError, match=r"at least 130 frames \(5.2 s\)"):
        WindowDataset([features], WindowConfig(sequence_length=100), IDENTITY)
    short_motion = fake_conversation(50, 7)
    short_motion.rotations = short_motion.rotations[:40]
    with pytest.raises(ValueError, match="40 pose frames, 50 speech frames, 50 activity frames"):
        ConversationFeatures.from_conversation(short_motion)
    with pytest.raises(ValueError, match=r"must include 'train'"):
        make_datasets({"val": [fake_conversation(70, 8)]}, WindowConfig())
    corrupt = tmp_path / "normaliser.json"
    corrupt.write_text("{not json")
    with pytest.raises(
        ValueError, match="cannot read normalisation statistics from .*normaliser.json"
    ):
        Normaliser.load(corrupt)


# --------------------------------------------------------------------------- bad input


def test_features_of_different_lengths_or_shapes_are_refused(features):
    pose, speech, activity, style = (
        features.pose,
        features.speech,
        features.activity,
        features.style,
    )
    with pytest.raises(ValueError, match="100 pose frames, 99 speech frames, 100 activity"):
        ConversationFeatures(pose, speech[:-1], activity, style)
    with pytest.raises(
        ValueError, match=r"pose must be .* \(T, 54\), got float32 of shape \(100, 9, 6\)"
    ):
        ConversationFeatures(pose.reshape(100, 9, 6), speech, activity, style)
    with pytest.raises(
        ValueError, match=r"activity must be .* \(T, 4\), got int64 of shape \(100,\)"
    ):
        ConversationFeatures(pose, speech, np.zeros(100, dtype=np.int64), style)
    with pytest.raises(ValueError, match=r"style must be .* \(T, 4\)"):
        ConversationFeatures(pose, speech, activity, style[:, :3])


def test_nan_poses_are_refused_before_they_reach_the_normaliser(features):
    pose = features.pose.copy()
    pose[10, 3] = np.nan
    with pytest.raises(ValueError, match="pose holds NaN or infinite values at frame 10"):
        ConversationFeatures(pose, features.speech, features.activity, features.style)
    conversation = fake_conversation(60, seed=9)
    conversation.rotations[12, 0, 0] = np.inf
    with pytest.raises(ValueError, match="at index 12: .* NaN or infinite"):
        make_datasets({"train": [conversation]}, WindowConfig())


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"pose_std": [0.0] * POSE_DIM}, r"pose_std\[0\] is 0.0, but it must be positive"),
        ({"speech_mean": [float("nan")] * 27}, r"speech_mean\[0\] is nan, but it must be finite"),
        ({"speech_std": [1.0] * 20}, r"speech_std must have shape \(27,\), got \(20,\)"),
        ({"pose_mean": ["a"] * POSE_DIM}, "pose_mean must be a list of numbers"),
    ],
)
def test_normaliser_refuses_unusable_statistics(tmp_path, change, message):
    with pytest.raises(ValueError, match=message):
        Normaliser.from_dict({**IDENTITY.to_dict(), **change})
    path = tmp_path / "normaliser.json"
    path.write_text(json.dumps({**IDENTITY.to_dict(), **change}))
    with pytest.raises(ValueError, match=f"normaliser.json: .*{message}"):
        Normaliser.load(path)


def test_normaliser_from_something_else_than_a_dictionary(tmp_path):
    with pytest.raises(ValueError, match="must be a dictionary, got int"):
        Normaliser.from_dict(5)
    (tmp_path / "five.json").write_text("5")
    with pytest.raises(ValueError, match="five.json: .*must be a dictionary"):
        Normaliser.load(tmp_path / "five.json")


def test_normaliser_save_keeps_an_existing_file_unless_asked(tmp_path):
    path = tmp_path / "normaliser.json"
    path.write_text("precious")
    with pytest.raises(
        FileExistsError, match="normaliser.json already exists; pass overwrite=True"
    ):
        IDENTITY.save(path)
    assert path.read_text() == "precious"
    IDENTITY.save(path, overwrite=True)
    np.testing.assert_array_equal(Normaliser.load(path).pose_std, IDENTITY.pose_std)
    with pytest.raises(IsADirectoryError, match="is a folder"):
        IDENTITY.save(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["normaliser.json"]  # no partial file left


def test_normalising_a_pose_of_the_wrong_shape_says_how_to_flatten_it(features):
    with pytest.raises(ValueError, match=r"got \(100, 9, 6\); flatten the joints"):
        IDENTITY.normalise_pose(features.pose.reshape(100, 9, 6))
    with pytest.raises(ValueError, match=r"speech must have shape \(\.\.\., 27\)"):
        IDENTITY.normalise_speech(torch.zeros(3, 20))


def test_datasets_refuse_what_is_not_a_list_of_features(features):
    config = WindowConfig()
    with pytest.raises(TypeError, match="list of ConversationFeatures .* got ConversationFeatures"):
        WindowDataset(features, config, IDENTITY)
    with pytest.raises(TypeError, match=r"features\[0\] is a FakeConversation.*from_conversation"):
        WindowDataset([fake_conversation(50, 10)], config, IDENTITY)
    with pytest.raises(ValueError, match="features is empty"):
        WindowDataset([], config, IDENTITY)
    twenty_bands = dataclasses.replace(
        IDENTITY, speech_mean=np.zeros(20, np.float32), speech_std=np.ones(20, np.float32)
    )
    with pytest.raises(ValueError, match="27 mel bands but the normaliser was fitted on 20"):
        WindowDataset([features], config, twenty_bands)
    with pytest.raises(ValueError, match=r"mix speech of \[20, 27\] mel bands"):
        Normaliser.fit(
            [
                features,
                ConversationFeatures(
                    features.pose, features.speech[:, :20], features.activity, features.style
                ),
            ]
        )
    with pytest.raises(ValueError, match="split 'val' has no conversations"):
        make_datasets({"train": [fake_conversation(60, 11)], "val": []}, config)
    with pytest.raises(TypeError, match="lacks"):
        ConversationFeatures.from_conversation({"audio": np.zeros(16000)})


def test_window_config_takes_any_integer_but_not_a_boolean():
    config = WindowConfig(past_poses=np.int64(3), stride=np.int32(2))
    assert config == WindowConfig(past_poses=3, stride=2) and type(config.past_poses) is int
    with pytest.raises(ValueError, match="stride must be an integer >= 1, got True"):
        WindowConfig(stride=True)
