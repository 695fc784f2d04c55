"""A BVH take on the course's skeleton: 9 keypoints at 25 fps, facing +z, the root at the origin.

Steps, each for a reason:

1. **World positions** of the rig's joints that sit at our keypoints (:mod:`~.rigs`); without
   a nose joint the nose is placed in front of the head joint and turned with it, so that a
   nod (a turn of the head) moves it.
2. **Axes.** The rig's rest pose (every channel at zero) says which way is up (spine base to
   head), left (right shoulder to left shoulder) and forward (their cross product); positions
   are written in those axes as our x (left), y (up), z (forward).
3. **The root at the origin**, each frame, as in our data; and **facing +z**: a person turns
   about on their feet over minutes, so each frame is turned about the vertical by the facing of
   the root joint (its rest forward, turned with it), averaged over :data:`FACING_WINDOW_S`:
   slow turns go, a twist of the torso during a gesture stays.
4. **25 fps**: each output frame averages the source frames of its 40 ms (no aliasing from
   60 or 120 fps), then reads the result at the middle of its interval, as the course's frames
   stand for (``gesturelib.features``), by linear interpolation.
5. **Our skeleton**: each limb's direction becomes its rotation from the T-pose
   (:func:`gesturelib.skeleton.rotations_from_positions`); the keypoints are those rotations on
   our limbs (:func:`~gesturelib.skeleton.forward_kinematics`), so every dataset shares one
   body and only the motion carries over.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gesturelib.conventions import FPS
from gesturelib.mocap.bvh_reader import BvhTake
from gesturelib.mocap.rigs import joint_map
from gesturelib.rotations import RotationError
from gesturelib.skeleton import (
    JOINT_INDEX,
    KEYPOINTS,
    T_POSE_OFFSETS,
    forward_kinematics,
    rotations_from_positions,
)

#: Seconds over which the body's facing is averaged before it is turned to +z.
FACING_WINDOW_S = 2.0
#: The rest pose's spine base to head, in the file's units, for each unit we recognise (ours:
#: 70 cm; people and rigs differ, hence wide ranges).
UNITS = {"m": (0.2, 2.0), "cm": (20.0, 200.0), "mm": (200.0, 2000.0)}


@dataclass(frozen=True)
class Retargeted:
    """A take on our skeleton: ``rotations (T, 9, 6)``, ``positions (T, 9, 3)`` in cm, and what
    was found: the ``rig``, the file's ``units`` (``"unknown"`` when its size fits none), its
    frame rate ``source_fps``."""

    rotations: np.ndarray
    positions: np.ndarray
    rig: str
    units: str
    source_fps: float


def retarget(take: BvhTake, n_frames: int, rig: str | None = None, fps: int = FPS) -> Retargeted:
    """``n_frames`` frames of ``take`` at ``fps`` on our skeleton (the take's last pose held past
    its end: the caller checks that lengths agree).

    Raises:
        RigError: the skeleton fits no rig (or not ``rig``), naming the missing joints.
        RotationError: a limb of zero length in some frame (two mapped joints in one place).
    """
    rig, names = joint_map(take.names, rig)
    ours = ["spine_base", *KEYPOINTS]
    mapped = [name for name in ours if name in names]
    positions, rotations = take.world([names[name] for name in mapped])
    rest = _rest_positions(take, [names[name] for name in mapped])
    where = dict(zip(mapped, range(len(mapped)), strict=True))
    axes = _rest_axes(rest, where)  # (3, 3): columns are our x, y, z in the file's frame
    if "nose" not in names:
        head = where["head"]
        nose_rest = axes @ (
            T_POSE_OFFSETS[JOINT_INDEX["nose"]]
            / np.linalg.norm(T_POSE_OFFSETS[JOINT_INDEX["nose"]])
        )
        scale = np.linalg.norm(rest[where["head"]] - rest[where["sternum"]])
        nose = positions[:, head] + scale * np.einsum("fij,j->fi", rotations[:, head], nose_rest)
        positions = np.concatenate([positions, nose[:, None]], axis=1)
        where["nose"] = len(mapped)
    keypoints = positions[:, [where[name] for name in ours]]
    keypoints = (keypoints - keypoints[:, :1]) @ axes  # root at the origin, in our axes
    forward = np.einsum("fij,j->fi", rotations[:, where["spine_base"]], axes[:, 2]) @ axes
    keypoints = _face_forward(keypoints, forward, take.fps)
    keypoints = resample(keypoints[:, 1:], take.fps, n_frames, fps)
    try:
        limb_rotations = rotations_from_positions(keypoints)
    except RotationError as error:
        raise RotationError(
            f"{take.path}: {error}; two joints of the {rig} map sit in one place"
        ) from None
    return Retargeted(
        limb_rotations.astype(np.float32),
        forward_kinematics(limb_rotations).astype(np.float32),
        rig,
        _units(np.linalg.norm(rest[where["head"]] - rest[where["spine_base"]])),
        take.fps,
    )


def _rest_positions(take: BvhTake, joints: list[str]) -> np.ndarray:
    """``(len(joints), 3)`` where the joints stand in the rest pose: every rotation at zero, every
    joint at its offset (position channels, which some rigs give every joint, set to it)."""
    values = np.zeros((1, take.values.shape[1]))
    column = 0
    for joint, channels in enumerate(take.channels):
        for channel in channels:
            if channel.endswith("position"):
                values[0, column] = take.offsets[joint]["XYZ".index(channel[0])]
            column += 1
    rest = BvhTake(
        take.names, take.parents, take.offsets, take.channels, take.frame_time, values, take.path
    )
    positions, _ = rest.world(joints)
    return positions[0]


def _rest_axes(rest: np.ndarray, where: dict[str, int]) -> np.ndarray:
    """Our x (left), y (up), z (forward) as columns, in the file's frame, from the rest pose."""
    up = rest[where["head"]] - rest[where["spine_base"]]
    left = rest[where["left_shoulder"]] - rest[where["right_shoulder"]]
    if np.linalg.norm(up) < 1e-9:
        raise RotationError("the rest pose's head sits on the spine's base")
    up /= np.linalg.norm(up)
    left = left - (left @ up) * up
    if np.linalg.norm(left) < 1e-9:
        raise RotationError("the rest pose's shoulders do not lie left and right of the spine")
    left /= np.linalg.norm(left)
    return np.stack([left, up, np.cross(left, up)], axis=1)


def _face_forward(keypoints: np.ndarray, forward: np.ndarray, source_fps: float) -> np.ndarray:
    """Turn each frame about y so that the facing, averaged over :data:`FACING_WINDOW_S`,
    points along +z. ``keypoints (F, J, 3)``, ``forward (F, 3)`` in our axes."""
    horizontal = forward[:, [0, 2]]
    horizontal /= np.maximum(np.linalg.norm(horizontal, axis=1, keepdims=True), 1e-9)
    width = 2 * int(round(FACING_WINDOW_S * source_fps / 2)) + 1  # odd: centred
    kernel = np.ones(width) / width
    smooth = np.stack(
        [
            np.convolve(np.pad(c, (width // 2, width // 2), mode="edge"), kernel, "valid")
            for c in horizontal.T
        ],
        axis=1,
    )
    yaw = np.arctan2(smooth[:, 0], smooth[:, 1])  # 0 when facing +z
    cos, sin = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, z = keypoints[..., 0], keypoints[..., 2]
    turned = keypoints.copy()
    turned[..., 0] = x * cos - z * sin
    turned[..., 2] = x * sin + z * cos
    return turned


def resample(positions: np.ndarray, source_fps: float, n_frames: int, fps: int = FPS) -> np.ndarray:
    """``(F, ...)`` at ``source_fps`` -> ``(n_frames, ...)`` at ``fps``: frame ``k`` is the
    average of the source over about ``1/fps`` seconds around the middle of frame ``k``,
    ``(k + 0.5) / fps``, read by linear interpolation (each source frame standing for the middle
    of its own interval, as the course's frames do); past the source's ends its first and last
    frames are held."""
    positions = np.asarray(positions, dtype=np.float64)
    # Average over about one output frame (nothing faster than the output can show), an odd
    # number of source frames so that the average stays centred on its frame.
    width = 2 * int(round((source_fps / fps - 1) / 2)) + 1
    if width > 1:
        kernel = np.ones(width) / width
        padded = np.pad(
            positions, [(width // 2, width // 2)] + [(0, 0)] * (positions.ndim - 1), mode="edge"
        )
        positions = np.apply_along_axis(lambda c: np.convolve(c, kernel, "valid"), 0, padded)
    # A frame stands for the middle of its interval, ours (k + 0.5) / fps as the source's.
    where = np.clip((np.arange(n_frames) + 0.5) * source_fps / fps - 0.5, 0, len(positions) - 1)
    below = np.floor(where).astype(int)
    above = np.minimum(below + 1, len(positions) - 1)
    weight = (where - below).reshape(-1, *([1] * (positions.ndim - 1)))
    return (1 - weight) * positions[below] + weight * positions[above]


def _units(spine_to_head: float) -> str:
    for unit, (low, high) in UNITS.items():
        if low <= spine_to_head <= high:
            return unit
    return "unknown"
