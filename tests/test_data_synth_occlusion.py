"""Gaps in the motion as a tracker loses keypoints: the mask, the placeholders, the files."""

import numpy as np
import pytest

from data_synth import (
    ConfigError,
    DatasetError,
    generate_conversation,
    load_conversation,
    occlude,
    occlusion_mask,
    save_conversation,
)
from data_synth.occlusion import T_POSE_ROTATION
from gesturelib.data import ConversationFeatures
from gesturelib.skeleton import JOINT_INDEX, forward_kinematics


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(20.0, seed=3)


def test_the_wrists_are_lost_most_often_in_bursts_the_same_for_a_seed():
    visible = occlusion_mask(25 * 600, 25, seed=1)  # ten minutes
    hidden = 1 - visible.mean(axis=0)
    for wrist in ("left_wrist", "right_wrist"):
        assert hidden[JOINT_INDEX[wrist]] > 3 * hidden[JOINT_INDEX["sternum"]]
        assert 0.05 < hidden[JOINT_INDEX[wrist]] < 0.2
    seen = np.concatenate([[1], visible[:, JOINT_INDEX["left_wrist"]].astype(int), [1]])
    gaps = np.flatnonzero(np.diff(seen) == 1) - np.flatnonzero(np.diff(seen) == -1)
    assert gaps.min() >= 3  # 0.1 s at least (gaps that overlap merge into longer ones)
    np.testing.assert_array_equal(visible, occlusion_mask(25 * 600, 25, seed=1))
    assert not np.array_equal(visible, occlusion_mask(25 * 600, 25, seed=2))
    assert occlusion_mask(250, 25, seed=1, rate_scale=0).all()
    with pytest.raises(ConfigError, match="rate_scale"):
        occlusion_mask(250, 25, seed=1, rate_scale=-1)


def test_an_occluded_conversation_holds_the_t_pose_where_it_lost_a_limb(conversation):
    damaged = occlude(conversation, seed=0, rate_scale=3.0)
    visible = damaged.visible
    assert visible.shape == (conversation.num_frames, 9) and not visible.all()
    np.testing.assert_array_equal(damaged.rotations[visible], conversation.rotations[visible])
    np.testing.assert_array_equal(
        damaged.rotations[~visible], np.broadcast_to(T_POSE_ROTATION, (int((~visible).sum()), 6))
    )
    np.testing.assert_allclose(damaged.positions, forward_kinematics(damaged.rotations), atol=1e-4)
    np.testing.assert_array_equal(damaged.audio, conversation.audio)
    assert conversation.visible is None  # the original is untouched


def test_the_mask_travels_with_the_files_and_a_damaged_one_is_named(conversation, tmp_path):
    damaged = occlude(conversation, seed=0)
    save_conversation(damaged, tmp_path / "c")
    loaded = load_conversation(tmp_path / "c")
    np.testing.assert_array_equal(loaded.visible, damaged.visible)
    save_conversation(conversation, tmp_path / "clean")
    assert load_conversation(tmp_path / "clean").visible is None
    with np.load(tmp_path / "c.npz") as arrays:
        parts = dict(arrays)
    np.savez(tmp_path / "c.npz", **{**parts, "visible": parts["visible"][:-1]})
    with pytest.raises(DatasetError, match="visible must be a bool mask"):
        load_conversation(tmp_path / "c")


def test_training_features_refuse_motion_with_gaps(conversation):
    with pytest.raises(ValueError, match="fill the gaps first"):
        ConversationFeatures.from_conversation(occlude(conversation, seed=0, rate_scale=3.0))


def test_occluding_twice_keeps_the_first_gaps_and_bad_arguments_are_named(conversation):
    once = occlude(conversation, seed=0)
    twice = occlude(once, seed=1)
    assert not (twice.visible & ~once.visible).any()  # what was lost stays lost
    assert (~twice.visible).sum() > (~once.visible).sum()
    with pytest.raises(TypeError, match="occlude needs a data_synth.Conversation"):
        occlude({"rotations": conversation.rotations}, seed=0)
    for arguments, name in [
        ((0, 25, 0), "num_frames"),
        ((10, 0, 0), "fps"),
        ((10, 25, -1), "seed"),
    ]:
        with pytest.raises(ConfigError, match=name):
            occlusion_mask(*arguments)
    with pytest.raises(ConfigError, match="rate_scale"):
        occlusion_mask(10, 25, 0, rate_scale=1e8)
