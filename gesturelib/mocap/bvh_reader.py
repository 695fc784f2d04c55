"""Reading a BVH file: its joint hierarchy, its channels and, per frame, each joint in the world.

A BVH file is a ``HIERARCHY`` (each joint's offset from its parent in the rest pose and its
channels) and a ``MOTION`` block, one line of channel values per frame. A joint's rotation
channels, read in their file order ``(A1, A2, A3)``, give its rotation relative to its parent
as ``R = R_A1(a1) @ R_A2(a2) @ R_A3(a3)`` (angles in degrees); every joint names its own order.
Position channels, where a joint has them (always the root), replace its offset for that frame.
With every channel at zero the skeleton stands in its rest pose, each joint's world rotation the
identity. Units are whatever the file's author used (centimetres, metres, millimetres).
"""

from __future__ import annotations

import io
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

AXES = "XYZ"


class BvhError(ValueError):
    """A BVH file that cannot be read; the message names the file and what is wrong in it."""


@dataclass(frozen=True)
class BvhTake:
    """One BVH file read whole.

    Attributes:
        names: ``(J,)`` joint names in file order (parents before their children).
        parents: ``(J,)`` the index of each joint's parent, -1 for the root.
        offsets: ``(J, 3)`` each joint's rest offset from its parent, in the file's units.
        channels: for each joint its channel names in file order, e.g.
            ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``.
        frame_time: seconds per frame.
        values: ``(F, C)`` channel values per frame, joints' channels in file order.
        path: the file it was read from.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    frame_time: float
    values: np.ndarray
    path: Path

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def num_frames(self) -> int:
        return len(self.values)

    def index(self, name: str) -> int:
        """The index of joint ``name`` (KeyError if the file has none)."""
        return self.names.index(name)

    def world(self, joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Where ``joints`` are in the world, every frame: positions ``(F, len(joints), 3)`` in the
        file's units and rotations ``(F, len(joints), 3, 3)``. Only the joints asked for and
        their ancestors are computed (a rig of hundreds of finger and face joints costs
        nothing more)."""
        wanted = [self.index(name) for name in joints]
        needed = set()
        for joint in wanted:
            while joint >= 0 and joint not in needed:
                needed.add(joint)
                joint = self.parents[joint]
        starts = np.cumsum([0, *(len(c) for c in self.channels)])
        positions, rotations = {}, {}
        for joint in sorted(needed):  # parents come first
            local_rotation, local_offset = self._local(joint, starts[joint])
            parent = self.parents[joint]
            if parent < 0:
                positions[joint], rotations[joint] = local_offset, local_rotation
            else:
                rotations[joint] = rotations[parent] @ local_rotation
                positions[joint] = positions[parent] + np.einsum(
                    "fij,fj->fi", rotations[parent], local_offset
                )
        return (
            np.stack([positions[j] for j in wanted], axis=1),
            np.stack([rotations[j] for j in wanted], axis=1),
        )

    def _local(self, joint: int, start: int) -> tuple[np.ndarray, np.ndarray]:
        """A joint's rotation ``(F, 3, 3)`` and translation ``(F, 3)`` relative to its parent."""
        frames = self.num_frames
        offset = np.tile(self.offsets[joint], (frames, 1))
        order, angles = "", []
        for k, channel in enumerate(self.channels[joint]):
            column = self.values[:, start + k]
            if channel.endswith("position"):
                offset[:, AXES.index(channel[0].upper())] = column
            else:
                order += channel[0].upper()
                angles.append(column)
        if not order:
            return np.tile(np.eye(3), (frames, 1, 1)), offset
        with warnings.catch_warnings():  # gimbal lock is exact going from angles to a matrix
            warnings.simplefilter("ignore", UserWarning)
            rotation = Rotation.from_euler(order, np.stack(angles, axis=1), degrees=True)
        return rotation.as_matrix(), offset


_CHANNEL_NAMES = {f"{axis}{kind}" for axis in AXES for kind in ("position", "rotation")}


def read_bvh(path: str | os.PathLike) -> BvhTake:
    """Read a BVH file.

    Raises:
        FileNotFoundError: if ``path`` does not exist.
        BvhError: naming the file and the line, for anything but a well-formed BVH file: no
            hierarchy or motion, unknown channels, braces that do not match, more than one root,
            fewer frames than the header promises, non-numbers, NaN or infinite values, or a frame
            time that is not a positive number.
    """
    path = Path(path)
    if not path.is_file():
        if path.is_dir():
            raise BvhError(f"{path} is a folder, not a BVH file")
        raise FileNotFoundError(f"{path} does not exist")
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as stream:  # a BOM is read past
            return _read(stream, path)
    except UnicodeError as error:  # pragma: no cover - errors="replace" reads any bytes
        raise BvhError(f"{path} is not a text file ({error})") from None


def _read(stream, path: Path) -> BvhTake:
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []  # the open joints; -2 marks an End Site
    line_number = 0

    def fail(what: str) -> BvhError:
        return BvhError(f"{path}, line {line_number}: {what}; is it a BVH file, and whole?")

    first = stream.readline()
    line_number = 1
    if first.strip().upper() != "HIERARCHY":
        raise fail(f"a BVH file starts with HIERARCHY, this one with {first.strip()[:40]!r}")
    for line in stream:
        line_number += 1
        words = line.split()
        if not words:
            continue
        keyword = words[0].upper()
        if keyword in ("ROOT", "JOINT"):
            if (keyword == "ROOT") != (not stack):
                raise fail("a ROOT inside a joint, a JOINT outside one, or a second ROOT")
            if len(words) < 2:
                raise fail(f"{keyword} without a name")
            names.append(" ".join(words[1:]))
            parents.append(stack[-1] if stack else -1)
            offsets.append(None)
            channels.append(())
            stack.append(len(names) - 1)
        elif keyword == "END":
            stack.append(-2)
        elif keyword == "OFFSET":
            if not stack:
                raise fail("OFFSET outside a joint")
            offset = _numbers(words[1:], 3, fail, "OFFSET")
            if stack[-1] >= 0:
                offsets[stack[-1]] = offset
        elif keyword == "CHANNELS":
            if not stack or stack[-1] < 0:
                raise fail("CHANNELS outside a joint")
            joint_channels = tuple(words[2:])
            if not words[1].isdigit() or int(words[1]) != len(joint_channels):
                raise fail(f"CHANNELS {words[1]} followed by {len(joint_channels)} names")
            unknown = [c for c in joint_channels if c.capitalize() not in _CHANNEL_NAMES]
            if unknown or len({c.lower() for c in joint_channels}) < len(joint_channels):
                raise fail(
                    f"channels {' '.join(joint_channels)} (each of Xposition .. Zrotation once)"
                )
            channels[stack[-1]] = tuple(c[0].upper() + c[1:].lower() for c in joint_channels)
        elif keyword == "{":
            continue
        elif keyword == "}":
            if not stack:
                raise fail("a closing brace without an open joint")
            stack.pop()
        elif keyword == "MOTION":
            break
        else:
            raise fail(f"{words[0][:40]!r} is not a BVH keyword")
    else:
        raise fail("no MOTION section")
    if stack:
        raise fail("the hierarchy's braces do not close")
    if not names:
        raise fail("no joints")
    missing = [names[j] for j, offset in enumerate(offsets) if offset is None]
    if missing:
        raise fail(f"joints without an OFFSET: {', '.join(missing[:5])}")

    frames_line, time_line = stream.readline(), stream.readline()
    line_number += 2
    try:
        frames = int(frames_line.split(":")[1])
        frame_time = float(time_line.split(":")[1])
    except (IndexError, ValueError):
        raise fail("MOTION must be followed by 'Frames: N' and 'Frame Time: SECONDS'") from None
    if frames < 1 or not (np.isfinite(frame_time) and frame_time > 0):
        raise fail(f"{frames} frames of {frame_time} s each (at least 1 frame, a positive time)")
    n_channels = sum(len(c) for c in channels)
    text = stream.read()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an empty motion block, refused below
            values = np.loadtxt(io.StringIO(text), dtype=np.float64, ndmin=2, max_rows=frames)
    except ValueError:
        line_number, what = _first_bad_frame(text, n_channels, line_number)
        raise fail(what) from None
    if values.size and values.shape[1] != n_channels:
        raise fail(
            f"the frames hold {values.shape[1]} values, the joints have {n_channels} channels"
        )
    if len(values) < frames:
        raise fail(f"the header promises {frames} frames, the file holds {len(values)}")
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise fail(f"frame {bad} holds NaN or infinite values")
    return BvhTake(
        tuple(names),
        tuple(parents),
        np.array(offsets, dtype=np.float64),
        tuple(channels),
        frame_time,
        values,
        path,
    )


def _numbers(words: list[str], count: int, fail, what: str) -> np.ndarray:
    try:
        numbers = np.array([float(w) for w in words[:count]])
    except ValueError:
        numbers = np.array([])
    if len(numbers) != count or not np.isfinite(numbers).all():
        raise fail(f"{what} needs {count} finite numbers, got {' '.join(words)[:60]!r}")
    return numbers


def _first_bad_frame(text: str, n_channels: int, line_number: int) -> tuple[int, str]:
    """The line of the first frame that is not ``n_channels`` numbers, and what is wrong."""
    for number, line in enumerate(text.splitlines(), start=line_number + 1):
        words = line.split()
        if not words:
            continue
        try:
            [float(word) for word in words]
        except ValueError:
            return number, "a frame holds something that is not a number"
        if len(words) != n_channels:
            return (
                number,
                f"a frame holds {len(words)} values, the joints have {n_channels} channels",
            )
    return line_number, "the motion cannot be read"  # pragma: no cover - loadtxt found a problem
