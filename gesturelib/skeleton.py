"""The upper-body skeleton of the Flow-VAE paper: 9 keypoints, one rotation per limb.

Coordinates are in centimetres with y up; the agent faces +z, so its *left* is +x. The root is
the base of the spine, fixed at the origin; it is not one of the 9 keypoints.

Each keypoint ``j`` ends one limb (bone) that starts at its parent. A pose is one rotation per
limb, relative to the T-pose, as in Taylor et al. (2021): the limb's direction in the pose is
``R_j @ (direction of the limb in the T-pose)``. The rotations are *global* (each limb's rotation
is measured in the world frame, not relative to its parent), and :func:`rotations_from_positions`
returns the shortest-arc rotation, so a pose has no twist about its limbs and the map between
positions and rotations is one-to-one for a fixed set of bone lengths.

Shapes: rotations ``(..., 9, 6)`` in the 6D representation (see :mod:`gesturelib.rotations`),
positions ``(..., 9, 3)`` in cm; ``...`` is any batch shape, e.g. ``(T,)`` or ``(B, T)``.
Inputs follow :mod:`gesturelib.rotations`: NumPy arrays, tensors or lists; integers become
floats; the result is of the input's kind (a NumPy array for a list). A limb without a rotation
(zero or parallel 6D vectors, a zero-length limb) raises
:class:`~gesturelib.rotations.RotationError` naming the limb and the frame.
"""

from __future__ import annotations

import numpy as np
import torch

from gesturelib.rotations import (
    RotationError,
    as_real_array,
    check_trailing_shape,
    rot6d_to_matrix,
    shortest_arc,
)

ROOT = "spine_base"

#: The 9 keypoints in their fixed order. Parents come before their children.
KEYPOINTS: tuple[str, ...] = (
    "sternum",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "head",
    "nose",
)
NUM_JOINTS = len(KEYPOINTS)
#: Numbers per frame in the 6D pose representation: 9 joints x 6 = 54.
POSE_DIM = NUM_JOINTS * 6
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(KEYPOINTS)}

#: Parent of each keypoint, as an index into KEYPOINTS; -1 is the root (spine base at the origin).
#: The head keypoint is the centre of the head, the nose sits in front of it: a nod turns the
#: head->nose limb, a lean of the neck turns the sternum->head limb.
PARENTS: tuple[int, ...] = (
    -1,  # sternum        <- spine base
    0,  # left_shoulder   <- sternum
    1,  # left_elbow      <- left_shoulder
    2,  # left_wrist      <- left_elbow
    0,  # right_shoulder  <- sternum
    4,  # right_elbow     <- right_shoulder
    5,  # right_wrist     <- right_elbow
    0,  # head            <- sternum
    7,  # nose            <- head
)

#: Limb vectors (child minus parent) of the reference T-pose, in cm: plausible adult proportions
#: (spine base to sternum 50, shoulder half-width 18, upper arm 30, forearm 25, neck to head
#: centre 20, head centre to nose about 10.4).
T_POSE_OFFSETS = np.array(
    [
        [0.0, 50.0, 0.0],  # sternum
        [18.0, 0.0, 0.0],  # left_shoulder
        [30.0, 0.0, 0.0],  # left_elbow
        [25.0, 0.0, 0.0],  # left_wrist
        [-18.0, 0.0, 0.0],  # right_shoulder
        [-30.0, 0.0, 0.0],  # right_elbow
        [-25.0, 0.0, 0.0],  # right_wrist
        [0.0, 20.0, 0.0],  # head
        [0.0, -3.0, 10.0],  # nose
    ]
)
BONE_LENGTHS = np.linalg.norm(T_POSE_OFFSETS, axis=-1)


def _mirror_name(name: str) -> str:
    """``left_x`` <-> ``right_x``; keypoints on the midline are their own mirror image."""
    for side, other in (("left_", "right_"), ("right_", "left_")):
        if name.startswith(side):
            return other + name.removeprefix(side)
    return name


#: Index of each keypoint's mirror image (left <-> right); an involution.
MIRROR_INDEX: tuple[int, ...] = tuple(JOINT_INDEX[_mirror_name(name)] for name in KEYPOINTS)

#: Lines to draw for a stick figure: (start, end) indices, -1 for the root at the origin.
BONES: tuple[tuple[int, int], ...] = tuple((parent, child) for child, parent in enumerate(PARENTS))

# Reflection across the body's plane of symmetry (x = 0).
_MIRROR = np.diag([-1.0, 1.0, 1.0])


def _as_like(array: np.ndarray, like):
    """``array`` as the same kind (numpy or torch), dtype and device as ``like``."""
    if isinstance(like, torch.Tensor):
        return torch.as_tensor(array, dtype=like.dtype, device=like.device)
    return np.asarray(array, dtype=like.dtype)


def _validated_offsets(offsets, like):
    """Offsets ``(9, 3)`` (the T-pose's by default) of the kind, dtype and device of ``like``."""
    if offsets is None:
        return _as_like(T_POSE_OFFSETS, like)
    offsets = as_real_array(offsets, "offsets")
    if tuple(offsets.shape) != (NUM_JOINTS, 3):
        raise ValueError(f"offsets must have shape ({NUM_JOINTS}, 3), got {tuple(offsets.shape)}")
    lengths = np.linalg.norm(np.array(offsets.tolist()), axis=-1)
    bad = [name for name, length in zip(KEYPOINTS, lengths, strict=True) if not 0 < length < np.inf]
    if bad:
        raise ValueError(f"offsets of {bad} are zero, NaN or infinite: every limb needs a length")
    return _as_like(offsets, like)


def _naming_the_limb(function, *args):
    """Call ``function``; a RotationError at batch index ``(..., joint)`` names the limb."""
    try:
        return function(*args)
    except RotationError as error:
        *frame, joint = error.index
        where = f" at index {frame[0] if len(frame) == 1 else tuple(frame)}" if frame else ""
        raise RotationError(f"limb {KEYPOINTS[joint]!r}{where}: {error}", error.index) from None


def t_pose(offsets=None) -> np.ndarray:
    """Keypoint positions ``(9, 3)`` of the T-pose, in cm (root at the origin)."""
    return forward_kinematics(np.tile(identity_rot6d(), (NUM_JOINTS, 1)), offsets)


def identity_rot6d() -> np.ndarray:
    """The 6D representation ``(6,)`` of the identity rotation: the limb as in the T-pose."""
    return np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0])


def forward_kinematics(rot6d, offsets=None):
    """Keypoint positions from limb rotations.

    Args:
        rot6d: ``(..., 9, 6)`` limb rotations relative to the T-pose (numpy or torch).
        offsets: ``(9, 3)`` T-pose limb vectors in cm; defaults to :data:`T_POSE_OFFSETS`.
    Returns:
        ``(..., 9, 3)`` positions in cm, the root (spine base) at the origin. Same kind and dtype
        as ``rot6d``; differentiable for torch inputs. Any 6 numbers per limb whose two 3-vectors
        are not parallel are accepted (they are orthonormalised), so bone lengths are preserved
        whatever a network outputs.
    Raises:
        RotationError: naming the limb and frame whose two 3-vectors are zero or parallel (or not
            finite): they define no rotation, and no position can be given to that limb.
    """
    rot6d = as_real_array(rot6d, "rot6d")
    check_trailing_shape(rot6d, (NUM_JOINTS, 6), "rot6d")
    offsets = _validated_offsets(offsets, rot6d)
    limbs = (_naming_the_limb(rot6d_to_matrix, rot6d) @ offsets[:, :, None])[..., 0]  # (..., 9, 3)
    positions = []
    for joint, parent in enumerate(PARENTS):
        start = 0.0 if parent < 0 else positions[parent]
        positions.append(start + limbs[..., joint, :])
    stack = torch.stack if isinstance(rot6d, torch.Tensor) else np.stack
    return stack(positions, -2)


def limb_vectors(positions):
    """Limb vectors ``(..., 9, 3)`` (child minus parent) from positions ``(..., 9, 3)``."""
    positions = as_real_array(positions, "positions")
    check_trailing_shape(positions, (NUM_JOINTS, 3), "positions")
    parents = positions[..., [max(p, 0) for p in PARENTS], :]
    root_mask = _as_like(np.array([[p >= 0] for p in PARENTS], dtype=float), positions)
    return positions - parents * root_mask


def bone_lengths(positions):
    """Length in cm ``(..., 9)`` of the limb ending at each keypoint."""
    vectors = limb_vectors(positions)
    if isinstance(vectors, torch.Tensor):
        return vectors.norm(dim=-1)
    return np.linalg.norm(vectors, axis=-1)


def rotations_from_positions(positions, offsets=None):
    """Limb rotations (the inverse of :func:`forward_kinematics`).

    Args:
        positions: ``(..., 9, 3)`` keypoints in cm, root at the origin.
        offsets: ``(9, 3)`` T-pose limb vectors; defaults to :data:`T_POSE_OFFSETS`.
    Returns:
        ``(..., 9, 6)`` the shortest-arc rotation from each T-pose limb to the observed limb.
        ``forward_kinematics(rotations_from_positions(p))`` equals ``p`` whenever ``p`` has the
        skeleton's bone lengths; otherwise the directions are kept and the lengths restored.
    Raises:
        RotationError: naming the limb and frame of a zero-length limb (a keypoint on its
            parent), which has no direction.
    """
    positions = as_real_array(positions, "positions")
    check_trailing_shape(positions, (NUM_JOINTS, 3), "positions")
    offsets = _validated_offsets(offsets, positions)
    matrices = _naming_the_limb(shortest_arc, offsets, limb_vectors(positions))  # (..., 9, 3, 3)
    return matrices[..., :2, :].reshape(*matrices.shape[:-2], 6)  # their 6D: the first two rows


def mirror_positions(positions):
    """Left-right mirror image of positions ``(..., 9, 3)``: x negated, left and right swapped."""
    positions = as_real_array(positions, "positions")
    check_trailing_shape(positions, (NUM_JOINTS, 3), "positions")
    return positions[..., list(MIRROR_INDEX), :] * _as_like(np.diag(_MIRROR), positions)


def mirror_rotations(rot6d):
    """Left-right mirror image of limb rotations ``(..., 9, 6)``.

    Reflecting a pose by ``M = diag(-1, 1, 1)`` turns each limb rotation ``R`` into ``M R M``
    (the T-pose is symmetric, so ``M`` maps each T-pose limb onto its mirror limb) and swaps
    left and right. Applying it twice gives back the input, and
    ``forward_kinematics(mirror_rotations(r)) == mirror_positions(forward_kinematics(r))``.
    """
    rot6d = as_real_array(rot6d, "rot6d")
    check_trailing_shape(rot6d, (NUM_JOINTS, 6), "rot6d")
    swapped = rot6d[..., list(MIRROR_INDEX), :]
    # M R M flips the sign of the entries R[i, k] where exactly one of i, k is the x axis (0).
    # In the 6D layout [R00 R01 R02 R10 R11 R12] those are R01, R02 and R10.
    signs = _as_like(np.array([1.0, -1.0, -1.0, -1.0, 1.0, 1.0]), rot6d)
    return swapped * signs
