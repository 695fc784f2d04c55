"""Motion building blocks: smooth trajectories, two-bone inverse kinematics, rotations, noise.

* :func:`minimum_jerk_path`: through keyframes, each segment the minimum-jerk movement of Flash
  and Hogan (1985), ``x(s) = x0 + (x1 - x0) (10 s^3 - 15 s^4 + 6 s^5)``: it starts and ends at
  rest (zero velocity and acceleration), and its speed is a symmetric bell that peaks at the
  middle of the segment at ``1.875 |x1 - x0| / duration``. Human reaching follows it closely.
* :func:`two_bone_ik`: where the elbow goes, given the shoulder, the wrist target and a *pole*
  direction the elbow should point to (analytic, vectorised over frames).
* :func:`euler_matrix`: rotations from pitch (about x), yaw (about y) and roll (about z).
* :func:`smooth_noise`: Gaussian-filtered white noise of unit standard deviation, for sway.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

#: Targets are kept this far inside the arm's full reach, so the elbow never locks straight.
REACH_MARGIN = 0.98


def minimum_jerk_path(
    key_times: np.ndarray, key_values: np.ndarray, times: np.ndarray
) -> np.ndarray:
    """Evaluate a chain of minimum-jerk movements through keyframes.

    Args:
        key_times: ``(K,)`` strictly increasing times in seconds.
        key_values: ``(K, D)`` values at those times (e.g. wrist positions, ``D = 3``).
        times: ``(T,)`` where to evaluate.
    Returns:
        ``(T, D)``: the value, held constant before the first and after the last keyframe.
        Velocity and acceleration are zero at every keyframe, so the path is smooth (C2).
    """
    key_times = np.asarray(key_times, dtype=float)
    key_values = np.asarray(key_values, dtype=float)
    if key_times.ndim != 1 or key_values.shape[0] != key_times.size or key_values.ndim != 2:
        raise ValueError(
            f"key_times must be (K,) and key_values (K, D), got {key_times.shape} and "
            f"{key_values.shape}"
        )
    if key_times.size > 1 and np.any(np.diff(key_times) <= 0):
        raise ValueError("key_times must be strictly increasing")
    if key_times.size == 1:
        return np.repeat(key_values, len(times), axis=0)
    segment = np.clip(np.searchsorted(key_times, times, side="right") - 1, 0, key_times.size - 2)
    t0, t1 = key_times[segment], key_times[segment + 1]
    s = np.clip((times - t0) / (t1 - t0), 0.0, 1.0)[:, None]
    blend = s**3 * (10.0 - 15.0 * s + 6.0 * s * s)
    return key_values[segment] + blend * (key_values[segment + 1] - key_values[segment])


def two_bone_ik(
    root: np.ndarray, target: np.ndarray, pole: np.ndarray, upper_length: float, lower_length: float
) -> tuple[np.ndarray, np.ndarray]:
    """Place the middle joint of a two-bone chain (shoulder-elbow-wrist) analytically.

    The end joint reaches ``target`` (pulled in to ``REACH_MARGIN`` of full reach, or pushed out
    so the chain never folds completely); the middle joint lies in the plane of the root-target
    line and ``pole``, on the pole's side, so the elbow always bends the same, natural way.

    Args:
        root: ``(T, 3)`` root (shoulder) positions.
        target: ``(T, 3)`` wanted end (wrist) positions.
        pole: ``(T, 3)`` or ``(3,)`` direction the middle joint points to, away from the line;
            it must not be parallel to the root-target line.
        upper_length, lower_length: bone lengths.
    Returns:
        ``(middle, end)``, each ``(T, 3)``, with exact bone lengths.
    """
    offset = target - root
    distance = np.linalg.norm(offset, axis=-1, keepdims=True)
    direction = offset / np.maximum(distance, 1e-9)
    shortest = abs(upper_length - lower_length) + 1e-3
    distance = np.clip(distance, shortest, REACH_MARGIN * (upper_length + lower_length))
    # Law of cosines: how far along the root-target line the middle joint's foot lies.
    along = (upper_length**2 - lower_length**2 + distance**2) / (2.0 * distance)
    height = np.sqrt(np.maximum(upper_length**2 - along**2, 0.0))
    side = np.broadcast_to(pole, offset.shape)
    side = side - np.sum(side * direction, axis=-1, keepdims=True) * direction
    side_norm = np.linalg.norm(side, axis=-1, keepdims=True)
    if np.any(side_norm < 1e-6):
        raise ValueError("the pole is parallel to the root-target line: the bend is undefined")
    middle = root + along * direction + height * side / side_norm
    end = root + distance * direction
    return middle, end


def euler_matrix(pitch: np.ndarray, yaw: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(T, 3, 3)`` ``R = R_y(yaw) R_x(pitch) R_z(roll)``, angles ``(T,)`` in
    radians.

    With y up and the agent facing +z: positive pitch tips the top forwards (a nod down),
    positive yaw turns the front to the agent's left (+x), positive roll tilts the top to the
    agent's right (-x).
    """
    zero, one = np.zeros_like(pitch), np.ones_like(pitch)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    cr, sr = np.cos(roll), np.sin(roll)
    r_x = np.stack([one, zero, zero, zero, cp, -sp, zero, sp, cp], -1).reshape(-1, 3, 3)
    r_y = np.stack([cy, zero, sy, zero, one, zero, -sy, zero, cy], -1).reshape(-1, 3, 3)
    r_z = np.stack([cr, -sr, zero, sr, cr, zero, zero, zero, one], -1).reshape(-1, 3, 3)
    return r_y @ r_x @ r_z


def smooth_noise(rng: np.random.Generator, n: int, sigma: float, dims: int = 1) -> np.ndarray:
    """Gaussian-filtered white noise ``(n, dims)`` with unit standard deviation (in expectation).

    ``sigma`` (>= 1) is the filter's standard deviation in samples: the noise varies on that time
    scale. Filtering unit white noise with a normalised Gaussian leaves a variance of
    ``1 / (2 sqrt(pi) sigma)``, which is divided out.
    """
    margin = int(4 * sigma)
    noise = gaussian_filter1d(rng.standard_normal((n + 2 * margin, dims)), sigma, axis=0)
    return noise[margin : margin + n] * np.sqrt(2.0 * np.sqrt(np.pi) * sigma)
