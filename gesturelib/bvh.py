"""Motion as a BVH file, the format Blender, MotionBuilder and most animation tools import.

A BVH file is a joint hierarchy (each joint's offset from its parent in the rest pose) followed
by one line of channel values per frame: the root's position, and for every joint its rotation
as Euler angles, *relative to its parent joint*. A joint's rotation turns every joint below it.

Our poses are one rotation per limb relative to the T-pose, each acting on its own limb
(:func:`gesturelib.skeleton.forward_kinematics`), so :func:`write_bvh` turns them into a chain:
a BVH joint sits at the start of each limb and carries the limb's rotation relative to the
rotation of the limb before it. Three limbs leave the sternum (the neck and both shoulders): each
gets a joint of its own there, at zero offset, so that turning one does not turn the others.

The hierarchy, rooted at the spine base (centimetres, y up, the agent facing +z, 25 fps)::

    spine_base -> sternum -> neck -> head -> nose
                          -> left_clavicle -> left_shoulder -> left_elbow -> left_wrist
                          -> right_clavicle -> right_shoulder -> right_elbow -> right_wrist

Every joint named like a keypoint of :data:`gesturelib.skeleton.KEYPOINTS` sits where that
keypoint is. Angles are written in the channel order Z, X, Y (degrees), the most common one.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gesturelib.conventions import FPS
from gesturelib.rotations import rot6d_to_matrix
from gesturelib.skeleton import JOINT_INDEX, NUM_JOINTS, T_POSE_OFFSETS

#: The BVH joints: ``(name, parent, limb)``: the joint starts the limb that ends at keypoint
#: ``limb`` (its rotation is that limb's), and its offset is the limb before it; ``limb`` None
#: for a joint that only ends a chain (its rotation is its parent's).
JOINTS: tuple[tuple[str, str | None, str | None], ...] = (
    ("spine_base", None, "sternum"),
    ("sternum", "spine_base", None),
    ("neck", "sternum", "head"),
    ("head", "neck", "nose"),
    ("nose", "head", None),
    ("left_clavicle", "sternum", "left_shoulder"),
    ("left_shoulder", "left_clavicle", "left_elbow"),
    ("left_elbow", "left_shoulder", "left_wrist"),
    ("left_wrist", "left_elbow", None),
    ("right_clavicle", "sternum", "right_shoulder"),
    ("right_shoulder", "right_clavicle", "right_elbow"),
    ("right_elbow", "right_shoulder", "right_wrist"),
    ("right_wrist", "right_elbow", None),
)
ORDER = "ZXY"
#: The length of the end bones (nose, wrists) as a share of the limb before them.
END_SITE = 0.3


def _offset(name: str, parent: str | None) -> np.ndarray:
    """The joint's rest offset from its parent: the T-pose limb that ends at it (keypoints), or
    zero (the root and the zero-offset joints of the limbs that leave the sternum)."""
    if parent is None or name not in JOINT_INDEX:
        return np.zeros(3)
    return T_POSE_OFFSETS[JOINT_INDEX[name]]


def global_rotations(rotations: np.ndarray) -> dict[str, np.ndarray]:
    """Each BVH joint's rotation in the world ``(T, 3, 3)``, from limb rotations ``(T, 9, 6)``."""
    limbs = rot6d_to_matrix(np.asarray(rotations, dtype=np.float64))  # (T, 9, 3, 3)
    world = {}
    for name, parent, limb in JOINTS:
        world[name] = limbs[:, JOINT_INDEX[limb]] if limb is not None else world[parent]
    return world


def write_bvh(
    path: str | Path, rotations: np.ndarray, fps: float = FPS, overwrite: bool = False
) -> Path:
    """Write limb rotations ``(T, 9, 6)`` (relative to the T-pose) as a BVH file.

    The file is written whole or not at all (through a temporary file beside it).

    Returns:
        The path written. Its joints' positions are :func:`gesturelib.skeleton.forward_kinematics`
        of ``rotations`` (the root at the origin).
    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
        ValueError: for rotations of another shape, no frames, values that are not finite
            numbers, or a frame rate that is not a finite number of at least 1.
        OSError: naming ``path``, when it cannot be written (a full disk, say).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    try:
        rotations = np.asarray(rotations, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(
            f"rotations must be numbers, shape (T, {NUM_JOINTS}, 6): {error}"
        ) from None
    if rotations.ndim != 3 or rotations.shape[1:] != (NUM_JOINTS, 6) or len(rotations) == 0:
        raise ValueError(
            f"rotations must have shape (T, {NUM_JOINTS}, 6), T >= 1; got {rotations.shape}"
        )
    if not np.isfinite(rotations).all():
        raise ValueError("rotations hold NaN or infinite values; a BVH file cannot show them")
    if (
        isinstance(fps, bool)
        or not isinstance(fps, int | float | np.number)
        or not (np.isfinite(fps) and fps >= 1)
    ):
        raise ValueError(f"fps must be a finite number of at least 1, got {fps!r}")
    world = global_rotations(rotations)
    columns = [np.zeros((len(rotations), 3))]  # the root's position: the origin
    for name, parent, _ in JOINTS:
        local = world[name] if parent is None else np.swapaxes(world[parent], -1, -2) @ world[name]
        with warnings.catch_warnings():  # at gimbal lock the angles are still exact
            warnings.filterwarnings("ignore", "Gimbal lock", UserWarning)
            columns.append(Rotation.from_matrix(local).as_euler(ORDER, degrees=True))
    motion = np.concatenate(columns, axis=1)

    lines = ["HIERARCHY"]
    children = {name: [c for c, p, _ in JOINTS if p == name] for name, _, _ in JOINTS}

    def describe(name: str, parent: str | None, depth: int) -> None:
        pad = "  " * depth
        channels = "6 Xposition Yposition Zposition" if parent is None else "3"
        rotation_channels = " ".join(f"{axis}rotation" for axis in ORDER)
        offset = " ".join(f"{v:.6f}" for v in _offset(name, parent))
        lines.extend(
            [
                f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}",
                f"{pad}{{",
                f"{pad}  OFFSET {offset}",
                f"{pad}  CHANNELS {channels} {rotation_channels}",
            ]
        )
        for child in children[name]:
            describe(child, name, depth + 1)
        if not children[name]:  # a short bone along the last limb, so that tools draw the end
            tip = " ".join(f"{v:.6f}" for v in END_SITE * _offset(name, parent))
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {tip}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    describe(JOINTS[0][0], None, 0)
    lines += ["MOTION", f"Frames: {len(motion)}", f"Frame Time: {1 / fps:.6f}"]
    lines += [" ".join(f"{v:.5f}" for v in frame) for frame in motion]
    descriptor, temporary = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=".tmp", dir=path.parent
    )
    try:
        with os.fdopen(descriptor, "w") as stream:
            stream.write("\n".join(lines) + "\n")
        os.replace(temporary, path)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        raise OSError(error.errno, f"cannot write {path}: {error.strerror or error}") from error
    return path
