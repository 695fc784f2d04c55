"""Style measured from the motion itself: MoGlow's four style controls (Alexanderson et al. 2020).

MoGlow controls the style of its gestures with a few numbers per frame, computed from the wrist
positions of the training motion without any annotation (its §4.2), each averaged over a centred
4 s window:

* ``hand_height``: the height of the right wrist (cm);
* ``hand_speed``: the speed of the left wrist plus that of the right (cm/s);
* ``gesture_radius``: the distance of the left wrist from the vertical axis through the root plus
  that of the right (cm);
* ``symmetry``: the correlation of the right wrist's velocity with the left wrist's mirrored one
  (x negated), over the window: 1 when the hands move as mirror images, 0 when unrelated.

The right hand alone defines the height, as in the paper, so mirroring the motion changes it:
compute the style of mirrored data from the mirrored motion (``ConversationFeatures.mirrored``
does). At generation a model is given constant values, usually percentiles of the training values,
and the style realised in its samples is measured back with the same function.
"""

from __future__ import annotations

import numpy as np

from gesturelib.conventions import FPS
from gesturelib.skeleton import JOINT_INDEX

#: The style features, in the order of the columns of :func:`style_features`.
STYLE_FEATURES = ("hand_height", "hand_speed", "gesture_radius", "symmetry")
#: Length of the centred averaging window, in seconds (the paper's).
WINDOW_S = 4.0

_LEFT, _RIGHT = JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]


def style_features(positions: np.ndarray, fps: int = FPS, window_s: float = WINDOW_S) -> np.ndarray:
    """The four style features of every frame, ``(T, 4)``, from keypoint positions ``(T, 9, 3)``.

    Each is averaged over a window of ``window_s`` seconds centred on the frame, shortened at the
    ends of the motion (so the first and last two seconds average fewer frames).
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[1:] != (9, 3) or len(positions) < 2:
        raise ValueError(f"positions must have shape (T, 9, 3) with T >= 2, got {positions.shape}")
    left, right = positions[:, _LEFT], positions[:, _RIGHT]
    # Velocities at frame t from the centred difference (one-sided at the ends): (T, 3) each.
    left_velocity = np.gradient(left, axis=0) * fps
    right_velocity = np.gradient(right, axis=0) * fps
    speed = np.linalg.norm(left_velocity, axis=1) + np.linalg.norm(right_velocity, axis=1)
    radius = np.linalg.norm(left[:, [0, 2]], axis=1) + np.linalg.norm(right[:, [0, 2]], axis=1)
    mirrored_left = left_velocity * np.array([-1.0, 1.0, 1.0])
    width = max(1, round(window_s * fps))
    averages = [_centred_mean(x, width) for x in (right[:, 1], speed, radius)]
    # Correlation over the window: mean product over the root of the mean squares (uncentred,
    # since a velocity averages to about zero over 4 s anyway).
    product = _centred_mean((right_velocity * mirrored_left).sum(1), width)
    right_power = _centred_mean((right_velocity**2).sum(1), width)
    left_power = _centred_mean((mirrored_left**2).sum(1), width)
    symmetry = product / np.sqrt(right_power * left_power + 1e-9)
    return np.stack([*averages, symmetry], axis=1)


def _centred_mean(values: np.ndarray, width: int) -> np.ndarray:
    """The mean of ``values`` ``(T,)`` over ``width`` frames centred on each frame, ``(T,)``."""
    before, after = width // 2, width - width // 2 - 1
    cumulative = np.concatenate([[0.0], np.cumsum(values)])
    index = np.arange(len(values))
    low = np.clip(index - before, 0, len(values))
    high = np.clip(index + after + 1, 0, len(values))
    return (cumulative[high] - cumulative[low]) / (high - low)
