"""Filling gaps in motion: linear interpolation, and the limb angle error of a fill."""

import numpy as np
import pytest
import torch

from data_synth import generate_conversation
from gesturelib.gaps import interpolate_gaps, limb_angle_error
from gesturelib.pose_surface import T_POSE_DIRECTIONS, project
from gesturelib.rotations import shortest_arc
from gesturelib.skeleton import JOINT_INDEX


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(8.0, seed=3)


def test_linear_interpolation_fills_a_gap_between_its_ends_and_keeps_what_was_seen(conversation):
    rotations = conversation.rotations[:100].astype(np.float64)
    still = np.repeat(rotations[:1], 100, axis=0)
    visible = np.ones((100, 9), dtype=bool)
    visible[40:60, JOINT_INDEX["left_wrist"]] = False
    visible[:10, JOINT_INDEX["right_wrist"]] = False  # a gap at the start is held
    np.testing.assert_allclose(interpolate_gaps(still, visible), still, atol=1e-9)
    lost = rotations.copy()
    lost[~visible] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]  # what a tracker holds there: no clue
    filled = interpolate_gaps(lost, visible)
    np.testing.assert_array_equal(filled[visible], rotations[visible])
    wrist = JOINT_INDEX["left_wrist"]
    ends = limb_angle_error(rotations[39], rotations[60])[wrist]
    for frame in range(40, 60):
        to_ends = limb_angle_error(filled[frame], rotations[[39, 60]])[:, wrist]
        assert to_ends.max() <= ends + 1e-6  # between the two ends
    np.testing.assert_allclose(
        limb_angle_error(filled[:10], rotations[[10] * 10])[:, JOINT_INDEX["right_wrist"]],
        0,
        atol=1e-6,
    )


def test_limb_angle_error_on_known_turns():
    source = torch.as_tensor(T_POSE_DIRECTIONS)
    # Turn every limb about an axis at right angles to it, by 0, 30 and 90 degrees.
    other = torch.tensor([0.3, 0.5, 0.8], dtype=torch.float64).expand_as(source)
    axis = torch.nn.functional.normalize(torch.linalg.cross(source, other, dim=-1), dim=-1)
    turned = []
    for angle in np.deg2rad([0.0, 30.0, 90.0]):
        direction = source * np.cos(angle) + torch.linalg.cross(axis, source, dim=-1) * np.sin(
            angle
        )
        turned.append(project(shortest_arc(source, direction)[..., :2, :].flatten(-2)).numpy())
    np.testing.assert_allclose(limb_angle_error(turned[1], turned[0]), 30.0, atol=1e-6)
    np.testing.assert_allclose(limb_angle_error(turned[2], turned[0]), 90.0, atol=1e-6)


def test_the_papers_autoencoder_fills_lost_limbs_better_than_the_mean_pose():
    from data_synth import occlude
    from gesturelib.data import ConversationFeatures, Normaliser, WindowConfig, WindowDataset
    from gesturelib.models import MotionDAEConfig, MotionDenoisingAutoencoder
    from gesturelib.train import TrainConfig, train

    seen = ConversationFeatures.from_conversation(generate_conversation(60.0, seed=1))
    normaliser = Normaliser.fit([seen])
    windows = WindowDataset([seen], WindowConfig(sequence_length=25, stride=2), normaliser)
    torch.manual_seed(0)
    autoencoder = MotionDenoisingAutoencoder(MotionDAEConfig.taylor())
    train(autoencoder, windows, None, TrainConfig.quick(epochs=15, drop_last=True), progress=False)

    truth = generate_conversation(10.0, seed=2)
    damaged = occlude(truth, seed=0, rate_scale=2.0)
    hidden = ~damaged.visible
    pose = torch.as_tensor(normaliser.normalise_pose(damaged.rotations.reshape(-1, 54)))
    filled = autoencoder.fill(pose.float(), torch.as_tensor(damaged.visible))
    by_autoencoder = normaliser.denormalise_pose(filled.numpy()).reshape(-1, 9, 6)
    mean_pose = normaliser.denormalise_pose(np.zeros(54)).reshape(9, 6)
    by_mean = np.where(hidden[..., None], mean_pose, damaged.rotations)
    seen_numbers = torch.as_tensor(damaged.visible).repeat_interleave(6, dim=-1)
    assert torch.equal(filled[seen_numbers], pose.float()[seen_numbers])  # what was seen stays
    errors = {
        name: limb_angle_error(fill, truth.rotations)[hidden].mean()
        for name, fill in (("autoencoder", by_autoencoder), ("mean pose", by_mean))
    }
    assert errors["autoencoder"] < 0.8 * errors["mean pose"], errors


def test_the_autoencoder_fills_each_hidden_limb_from_the_window_centred_on_its_frame():
    from gesturelib.models import MotionDAEConfig, MotionDenoisingAutoencoder

    class FrameNumber(MotionDenoisingAutoencoder):
        """Outputs, for every frame of its window, that frame's sternum value in every number."""

        def forward(self, windows):
            frames = windows.unflatten(-1, (self.config.window, 54))
            return frames[..., :1].expand(frames.shape).flatten(-2)

    autoencoder = FrameNumber(MotionDAEConfig.taylor())
    frames = torch.arange(30, dtype=torch.float32)
    pose = frames[:, None].expand(30, 54).clone()  # every number of frame t is t
    visible = torch.ones(30, 9, dtype=torch.bool)
    visible[10:14, JOINT_INDEX["left_wrist"]] = False
    filled = autoencoder.fill(pose, visible)
    wrist = slice(6 * JOINT_INDEX["left_wrist"], 6 * JOINT_INDEX["left_wrist"] + 6)
    torch.testing.assert_close(filled[10:14, wrist], frames[10:14, None].expand(4, 6))
    assert torch.equal(
        filled[visible.repeat_interleave(6, dim=1)], pose[visible.repeat_interleave(6, dim=1)]
    )
    with pytest.raises(ValueError, match=r"visible must be a bool mask \(T, 9\)"):
        autoencoder.fill(pose, visible.int())
    with pytest.raises(ValueError, match=r"pose must be \(T, 54\)"):
        autoencoder.fill(pose[None], visible)


def test_interpolate_gaps_refuses_a_mask_or_rotations_of_the_wrong_kind():
    rotations = np.zeros((3, 9, 6))
    with pytest.raises(ValueError, match="visible must be a bool mask"):
        interpolate_gaps(rotations, np.ones((3, 9)))
    with pytest.raises(ValueError, match=r"rotations must have shape \(T, 9, 6\)"):
        interpolate_gaps(rotations.reshape(3, 54), np.ones((3, 9), dtype=bool))
