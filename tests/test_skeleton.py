import numpy as np
import pytest
import torch

from gesturelib.rotations import RotationError
from gesturelib.skeleton import (
    BONE_LENGTHS,
    JOINT_INDEX,
    KEYPOINTS,
    MIRROR_INDEX,
    NUM_JOINTS,
    PARENTS,
    T_POSE_OFFSETS,
    bone_lengths,
    forward_kinematics,
    identity_rot6d,
    mirror_positions,
    mirror_rotations,
    rotations_from_positions,
    t_pose,
)


@pytest.fixture(scope="module")
def random_rot6d():
    return np.random.default_rng(0).normal(size=(200, NUM_JOINTS, 6))


def test_the_nine_keypoints_of_the_flow_vae_paper():
    assert NUM_JOINTS == 9
    assert set(KEYPOINTS) == {
        "sternum",
        "nose",
        "head",
        "left_shoulder",
        "left_elbow",
        "left_wrist",
        "right_shoulder",
        "right_elbow",
        "right_wrist",
    }
    assert all(parent < child for child, parent in enumerate(PARENTS)), "parents first"


def test_t_pose_is_symmetric_and_adult_sized():
    positions = t_pose()
    np.testing.assert_allclose(positions, mirror_positions(positions), atol=1e-12)
    wingspan = positions[JOINT_INDEX["left_wrist"], 0] - positions[JOINT_INDEX["right_wrist"], 0]
    assert 130 < wingspan < 170, "wrist-to-wrist span of an adult in a T-pose, cm"
    assert positions[:, 1].min() > 0, "everything above the spine base"


def test_identity_rotations_give_the_t_pose():
    rot6d = np.tile(identity_rot6d(), (NUM_JOINTS, 1))
    np.testing.assert_allclose(forward_kinematics(rot6d), t_pose(), atol=1e-12)


def test_forward_kinematics_preserves_bone_lengths(random_rot6d):
    lengths = bone_lengths(forward_kinematics(random_rot6d))
    np.testing.assert_allclose(lengths, np.broadcast_to(BONE_LENGTHS, lengths.shape), rtol=1e-12)


def test_rotations_from_positions_inverts_forward_kinematics(random_rot6d):
    positions = forward_kinematics(random_rot6d)
    np.testing.assert_allclose(
        forward_kinematics(rotations_from_positions(positions)), positions, atol=1e-9
    )


def test_rotations_from_positions_keeps_directions_of_wrong_length_limbs():
    positions = t_pose() * 1.3  # a bigger person: same directions, longer limbs
    np.testing.assert_allclose(
        forward_kinematics(rotations_from_positions(positions)), t_pose(), atol=1e-9
    )


def test_forward_kinematics_with_custom_offsets():
    offsets = T_POSE_OFFSETS * 0.5
    rot6d = np.tile(identity_rot6d(), (NUM_JOINTS, 1))
    np.testing.assert_allclose(forward_kinematics(rot6d, offsets), 0.5 * t_pose(), atol=1e-12)


def test_forward_kinematics_batches_and_torch(random_rot6d):
    batch = torch.from_numpy(random_rot6d.reshape(4, 50, NUM_JOINTS, 6)).float()
    positions = forward_kinematics(batch)
    assert positions.shape == (4, 50, NUM_JOINTS, 3) and positions.dtype == torch.float32
    np.testing.assert_allclose(
        positions.reshape(200, NUM_JOINTS, 3).numpy(), forward_kinematics(random_rot6d), atol=1e-4
    )


def test_mirroring_twice_is_the_identity(random_rot6d):
    positions = forward_kinematics(random_rot6d)
    np.testing.assert_allclose(mirror_positions(mirror_positions(positions)), positions)
    np.testing.assert_allclose(mirror_rotations(mirror_rotations(random_rot6d)), random_rot6d)


def test_mirrored_rotations_give_mirrored_positions(random_rot6d):
    np.testing.assert_allclose(
        forward_kinematics(mirror_rotations(random_rot6d)),
        mirror_positions(forward_kinematics(random_rot6d)),
        atol=1e-9,
    )


def test_mirror_swaps_left_and_right():
    left, right = JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]
    assert MIRROR_INDEX[left] == right and MIRROR_INDEX[right] == left
    assert MIRROR_INDEX[JOINT_INDEX["nose"]] == JOINT_INDEX["nose"]
    positions = t_pose().copy()
    positions[left] += [0.0, 10.0, 5.0]  # raise the left hand
    mirrored = mirror_positions(positions)
    np.testing.assert_allclose(mirrored[right], [-positions[left, 0], *positions[left, 1:]])


@pytest.mark.parametrize(
    ("function", "shape", "message"),
    [
        (
            forward_kinematics,
            (10, 8, 6),
            r"rot6d must have shape \(\.\.\., 9, 6\), got \(10, 8, 6\)",
        ),
        (forward_kinematics, (10, 9, 5), r"\(\.\.\., 9, 6\), got \(10, 9, 5\)"),
        (rotations_from_positions, (9, 2), r"positions must have shape \(\.\.\., 9, 3\)"),
        (mirror_positions, (8, 3), r"\(\.\.\., 9, 3\), got \(8, 3\)"),
        (mirror_rotations, (9, 9), r"\(\.\.\., 9, 6\), got \(9, 9\)"),
    ],
)
def test_wrong_shapes_are_rejected(function, shape, message):
    with pytest.raises(ValueError, match=message):
        function(np.zeros(shape))


def test_wrong_offsets_are_rejected():
    with pytest.raises(ValueError, match=r"offsets must have shape \(9, 3\)"):
        forward_kinematics(np.zeros((9, 6)), np.zeros((8, 3)))


def test_a_limb_without_a_rotation_is_named_with_its_frame():
    rot6d = np.tile(identity_rot6d(), (4, NUM_JOINTS, 1))
    rot6d[2, JOINT_INDEX["right_elbow"]] = [1.0, 0.0, 0.0, 2.0, 0.0, 0.0]  # parallel halves
    with pytest.raises(RotationError, match="limb 'right_elbow' at index 2: .* zero or parallel"):
        forward_kinematics(rot6d)
    with pytest.raises(RotationError, match="limb 'sternum': "):
        forward_kinematics(np.zeros((NUM_JOINTS, 6)))  # all keypoints at the origin before


def test_a_zero_length_limb_has_no_rotation():
    positions = np.stack([t_pose()] * 3)
    positions[1, JOINT_INDEX["left_wrist"]] = positions[1, JOINT_INDEX["left_elbow"]]
    with pytest.raises(RotationError, match="limb 'left_wrist' at index 1: .* zero vector"):
        rotations_from_positions(positions)


def test_lists_and_integers_give_floats_like_arrays(random_rot6d):
    identity = np.tile(identity_rot6d(), (NUM_JOINTS, 1))
    np.testing.assert_array_equal(forward_kinematics(identity.tolist()), t_pose())
    assert forward_kinematics(identity.astype(int)).dtype == np.float64
    np.testing.assert_allclose(rotations_from_positions(t_pose().tolist()), identity, atol=1e-12)
    assert mirror_rotations(identity.astype(int)).dtype == np.float64
    assert mirror_positions(t_pose().round().astype(int)).dtype == np.float64
    np.testing.assert_allclose(bone_lengths(t_pose().tolist()), BONE_LENGTHS)
    from_tensor = forward_kinematics(
        torch.tensor(identity, dtype=torch.float32), T_POSE_OFFSETS.tolist()
    )
    assert isinstance(from_tensor, torch.Tensor) and from_tensor.dtype == torch.float32


def test_offsets_without_a_length_are_refused():
    offsets = T_POSE_OFFSETS.copy()
    offsets[JOINT_INDEX["nose"]] = 0.0
    offsets[JOINT_INDEX["head"], 1] = np.nan
    with pytest.raises(
        ValueError, match=r"offsets of \['head', 'nose'\] are zero, NaN or infinite"
    ):
        t_pose(offsets)
