"""Post-processing of generated motion: smoothing filters that any system's output can go through.

Kucherenko et al. (2021) found smoothing as important as the model: once hip-centred and smoothed
(a One Euro filter, then a 5-frame moving average, as Hasegawa et al. 2018 did), model outputs
were rated as natural as the ground truth, and raters could no longer tell the models apart. Both
filters run along time (axis 0) on each channel (one scalar series of an array ``(T, ...)``) with
its own state: a state shared across joints lets one joint's speed open the filter of the others.

* :func:`moving_average`: the mean over a centred window (5 frames in the paper: 200 ms at
  25 fps). It removes jitter and also blunts the peaks of fast strokes.
* :func:`one_euro` (Casiez, Roussel and Vogel 2012): exponential smoothing whose cutoff
  frequency rises with speed, so it smooths hard while a limb holds still, where jitter shows,
  and follows fast strokes with little lag. It is causal: it could run live.

:func:`smooth_rotations` filters limb rotations ``(T, 9, 6)``. Filtering the 6 numbers averages
entries of rotation matrices, which leaves the rotations (a mean of rotations is shrunk), so the
result is orthonormalised again and forward kinematics keeps every bone length.

Inputs are anything NumPy reads as a finite real array; results are float64 arrays of the input's
shape. Bad input raises ``ValueError`` saying what was wrong and what to do.
"""

from __future__ import annotations

import numpy as np

from gesturelib.rotations import normalize_rot6d
from gesturelib.skeleton import NUM_JOINTS

#: Default lowest cutoff in Hz of :func:`one_euro`: the smoothing of a still signal. At 25 fps it
#: gives ``alpha = 0.2`` (a time constant of 4 frames), which removes frame-to-frame jitter while
#: holds and slow sway (below 1 Hz) pass. Casiez et al. suggest starting from 1 Hz.
ONE_EURO_MIN_CUTOFF = 1.0
#: Default rise of the cutoff in Hz per unit/s of speed, for 6D rotations (numbers in [-1, 1]):
#: their speed is below 0.25 /s in 90% of the frames of synthetic motion and about 2 /s in fast
#: strokes, where the cutoff reaches 3 Hz. With jitter of 0.03 added, these defaults cut its jerk
#: 7-fold, as a 5-frame average does. Positions in cm move about 20 times faster: divide by 20.
ONE_EURO_BETA = 1.0


def _signal(values, name: str) -> np.ndarray:
    """``values`` as a finite float64 array ``(T, ...)`` with at least one frame."""
    array = np.asarray(values, dtype=np.float64)
    if array.ndim < 1 or array.shape[0] < 1:
        raise ValueError(f"{name} must have shape (T, ...), time first, T >= 1, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite values: fill or cut the gaps first")
    return array


def _number(value, name: str, what: str, zero_allowed: bool = False) -> float:
    """``value`` as a float if it is a finite number > 0 (>= 0 if ``zero_allowed``)."""
    real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not (real and np.isfinite(value) and (value >= 0 if zero_allowed else value > 0)):
        bound = ">= 0" if zero_allowed else "> 0"
        raise ValueError(f"{name} must be a finite number {bound} ({what}), got {value!r}")
    return float(value)


def moving_average(values, window: int = 5) -> np.ndarray:
    """Centred moving average of ``window`` frames along time, per channel.

    Frame ``t`` becomes the mean of frames ``t - h .. t + h`` with ``h = window // 2``. Near the
    ends the window shrinks symmetrically to what fits (``h = min(h, t, T - 1 - t)``), so the
    first and last frames are kept as they are and smoothing grows over the first ``h`` frames.
    A symmetric window keeps constants and straight lines (ramps) exact at every frame.

    Args:
        values: ``(T, ...)``, any trailing shape.
        window: odd number of frames >= 1; 1 returns the input (as float64).
    Returns:
        ``(T, ...)``.
    """
    array = _signal(values, "values")
    integer = isinstance(window, (int, np.integer)) and not isinstance(window, bool)
    if not (integer and window >= 1 and window % 2 == 1):
        raise ValueError(f"window must be an odd number of frames >= 1 (centred), got {window!r}")
    frames = np.arange(len(array))
    half = np.minimum(window // 2, np.minimum(frames, len(array) - 1 - frames))  # (T,)
    total = array.copy()
    for offset in range(1, window // 2 + 1):
        inside = frames[half >= offset]
        total[inside] += array[inside - offset] + array[inside + offset]
    return total / (2 * half + 1).reshape(-1, *[1] * (array.ndim - 1))


def one_euro(
    values,
    fps,
    min_cutoff: float = ONE_EURO_MIN_CUTOFF,
    beta: float = ONE_EURO_BETA,
    d_cutoff: float = 1.0,
) -> np.ndarray:
    """The One Euro filter (Casiez et al. 2012) along time, per channel.

    An exponential smoother ``y_t = alpha_t x_t + (1 - alpha_t) y_{t-1}`` (``y_0 = x_0``) with
    ``alpha = 1 / (1 + tau fps)`` and ``tau = 1 / (2 pi cutoff)``, whose cutoff rises with speed:
    ``cutoff_t = min_cutoff + beta |s_t|``, where ``s_t`` is the speed ``(x_t - x_{t-1}) fps``
    smoothed the same way with the fixed cutoff ``d_cutoff`` (``s_0 = 0``), as in the authors'
    reference code. With ``beta = 0`` it is plain exponential smoothing, which lags a ramp by
    ``tau fps`` frames; a speed-dependent cutoff shrinks that lag during fast motion.

    Args:
        values: ``(T, ...)``, any trailing shape; every scalar series is filtered on its own.
        fps: frames per second of ``values``.
        min_cutoff: cutoff in Hz at rest (:data:`ONE_EURO_MIN_CUTOFF`); lower smooths more.
        beta: Hz of cutoff added per unit/s of speed, >= 0 (:data:`ONE_EURO_BETA`, for 6D
            rotations; its scale depends on the units of ``values``). Higher lags less.
        d_cutoff: cutoff in Hz of the speed estimate.
    Returns:
        ``(T, ...)``.
    """
    array = _signal(values, "values")
    fps = _number(fps, "fps", "frames per second")
    min_cutoff = _number(min_cutoff, "min_cutoff", "Hz")
    beta = _number(beta, "beta", "Hz per unit/s of speed", zero_allowed=True)
    d_cutoff = _number(d_cutoff, "d_cutoff", "Hz")

    def alpha(cutoff):
        return 1.0 / (1.0 + fps / (2.0 * np.pi * cutoff))

    speed_weight = alpha(d_cutoff)
    filtered = np.empty_like(array)
    filtered[0] = array[0]
    speed = np.zeros_like(array[0])
    for t in range(1, len(array)):
        raw_speed = (array[t] - array[t - 1]) * fps
        speed = speed_weight * raw_speed + (1.0 - speed_weight) * speed
        weight = alpha(min_cutoff + beta * np.abs(speed))
        filtered[t] = weight * array[t] + (1.0 - weight) * filtered[t - 1]
    return filtered


#: The filters :func:`smooth_rotations` can apply, by name.
SMOOTHERS = {"moving_average": moving_average, "one_euro": one_euro}


def smooth_rotations(rotations, method: str = "moving_average", **options) -> np.ndarray:
    """Smooth limb rotations ``(T, 9, 6)`` with a filter and make them rotations again.

    Args:
        rotations: ``(T, 9, 6)`` 6D limb rotations, e.g. a model's samples.
        method: a key of :data:`SMOOTHERS`; the default is the paper's 5-frame moving average.
        **options: passed to the filter, e.g. ``window=5``, or ``fps=25`` (required) for
            ``"one_euro"``.
    Returns:
        ``(T, 9, 6)`` float64 valid 6D rotations (orthonormal rows): forward kinematics of them
        keeps every bone length.
    Raises:
        ValueError: for a bad shape, method or option; :class:`~gesturelib.rotations.RotationError`
            if smoothing leaves a limb no rotation (frames of one window about 180 deg apart).
    """
    if method not in SMOOTHERS:
        raise ValueError(f"method must be one of {sorted(SMOOTHERS)}, got {method!r}")
    rotations = _signal(rotations, "rotations")
    if rotations.shape[1:] != (NUM_JOINTS, 6):
        raise ValueError(f"rotations must have shape (T, {NUM_JOINTS}, 6), got {rotations.shape}")
    return normalize_rot6d(SMOOTHERS[method](rotations, **options))
