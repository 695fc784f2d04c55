"""Motion statistics and distribution distances: how the field measures generated gestures.

A generative model of gesture is not meant to reproduce *the* recorded motion, only a plausible
one, so most measures compare *distributions* (Kucherenko et al. 2021; Taylor et al. 2021):

* **Kinematics** (Kucherenko et al.): :func:`speed`, :func:`acceleration` and :func:`jerk` are
  the magnitudes of finite differences of joint positions; :func:`motion_statistics` averages
  them per joint. Jerk measures smoothness: jittery motion has high jerk.
* **Speed distributions** (Kucherenko et al.): :func:`speed_histogram` and
  :func:`hellinger_distance`, combined in :func:`speed_hellinger` per joint group.
* **Activity** (Taylor et al., Figures 6-8): :func:`distance_from_mean_pose`, and
  :func:`speaking_listening_statistics`, which splits it and its first derivative into the frames
  where the agent speaks and those where it listens (:func:`split_by_activity`).
* **Timing**: :func:`lag_correlation`, the normalised cross-correlation of two series at every
  lag, and :func:`lead_lag`, the lag that best aligns them (e.g. wrist speed against audio
  emphasis).
* **Order**: :func:`rank_correlation` (Spearman's), e.g. of a requested style against the one
  realised.
* **Accuracy and features**: :func:`average_position_error` (APE) and :func:`frechet_distance`
  (the distance behind FID and FGD, Ye et al. 2022).

Conventions: positions are ``(T, J, 3)`` or batched ``(B, T, J, 3)`` in cm, for any number of
joints ``J``. The frame rate ``fps`` is always an explicit argument, never assumed. Inputs may be
numpy arrays or torch tensors (detached and copied to the CPU); results are numpy arrays or
floats, in float64. Bad input (wrong shape, too few frames, NaN, ``fps <= 0``) raises
``ValueError`` naming the argument and what was expected.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import torch

from gesturelib.conventions import Activity
from gesturelib.skeleton import JOINT_INDEX, NUM_JOINTS

#: Default width in cm/s of the speed-histogram bins of :func:`speed_hellinger`. Kucherenko
#: et al. use equal-width bins without stating the width; 1 cm/s resolves the slow idle motion
#: (breathing, sway: a few cm/s) as well as the fast tail of beat strokes.
DEFAULT_SPEED_BIN_WIDTH = 1.0

#: Joint groups of the 9-keypoint skeleton, as compared by Kucherenko et al. (Table 2).
JOINT_GROUPS: dict[str, tuple[int, ...]] = {
    "all": tuple(range(NUM_JOINTS)),
    "elbows": (JOINT_INDEX["left_elbow"], JOINT_INDEX["right_elbow"]),
    "wrists": (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]),
}


# --------------------------------------------------------------------------- validation


def _as_array(x, name: str) -> np.ndarray:
    """``x`` as a finite float64 numpy array; torch tensors are detached and moved to the CPU."""
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    array = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return array


def _positions(x, name: str, min_frames: int = 1) -> np.ndarray:
    """Validate positions ``(T, J, 3)`` or ``(B, T, J, 3)`` with at least ``min_frames`` frames."""
    array = _as_array(x, name)
    if array.ndim not in (3, 4) or array.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (T, J, 3) or (B, T, J, 3), got {array.shape}")
    if array.shape[-3] < min_frames:
        raise ValueError(
            f"{name} needs at least {min_frames} frames (axis -3), got {array.shape[-3]}"
        )
    return array


def _check_fps(fps) -> float:
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise ValueError(f"fps must be a positive number of frames per second, got {fps!r}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive number of frames per second, got {fps!r}")
    return float(fps)


# --------------------------------------------------------------------------- kinematics


def _difference_magnitude(positions, fps, order: int, name: str) -> np.ndarray:
    positions = _positions(positions, name, min_frames=order + 1)
    derivative = np.diff(positions, n=order, axis=-3) * _check_fps(fps) ** order
    return np.linalg.norm(derivative, axis=-1)


def speed(positions, fps) -> np.ndarray:
    """Joint speeds in cm/s from positions ``(T, J, 3)`` or ``(B, T, J, 3)`` in cm.

    Finite differences of order k (here k = 1; 2 for :func:`acceleration`, 3 for :func:`jerk`)
    are ``numpy.diff(positions, n=k)`` along time, times ``fps ** k``: row ``i`` of the result
    uses frames ``i .. i + k``. It is exact for polynomials of degree k and, read as a derivative,
    it belongs at time ``(i + k / 2) / fps`` (row i of the speed is the mean velocity between
    frames i and i + 1, the backward difference at frame i + 1 of Kucherenko et al.).

    Returns:
        ``(T - 1, J)`` or ``(B, T - 1, J)``: the magnitude of the velocity.
    """
    return _difference_magnitude(positions, fps, 1, "positions")


def acceleration(positions, fps) -> np.ndarray:
    """Magnitude of the second difference in cm/s^2: ``(T - 2, J)`` or ``(B, T - 2, J)``.

    Row ``i`` uses frames ``i, i + 1, i + 2`` and is centred on frame ``i + 1`` (see :func:`speed`).
    """
    return _difference_magnitude(positions, fps, 2, "positions")


def jerk(positions, fps) -> np.ndarray:
    """Magnitude of the third difference in cm/s^3: ``(T - 3, J)`` or ``(B, T - 3, J)``.

    Row ``i`` uses frames ``i .. i + 3`` and is centred between frames ``i + 1`` and ``i + 2``.
    """
    return _difference_magnitude(positions, fps, 3, "positions")


def motion_statistics(positions, fps) -> dict[str, np.ndarray]:
    """Mean speed (cm/s), acceleration (cm/s^2) and jerk (cm/s^3) of each joint.

    Args:
        positions: ``(T, J, 3)`` or ``(B, T, J, 3)`` in cm, at least 4 frames.
        fps: frames per second of ``positions``.
    Returns:
        ``{"speed": (J,), "acceleration": (J,), "jerk": (J,)}``, each averaged over frames (and
        sequences). Averaging the ``(J,)`` vector over joints gives the single numbers of
        Kucherenko et al.'s Table 1.
    """
    positions = _positions(positions, "positions", min_frames=4)
    frame_axes = tuple(range(positions.ndim - 2))  # every axis of the result but the joints
    return {
        "speed": speed(positions, fps).mean(axis=frame_axes),
        "acceleration": acceleration(positions, fps).mean(axis=frame_axes),
        "jerk": jerk(positions, fps).mean(axis=frame_axes),
    }


def distance_from_mean_pose(positions, mean_pose=None) -> np.ndarray:
    """Euclidean distance in cm of each joint from its position in the mean pose.

    Args:
        positions: ``(T, J, 3)`` or ``(B, T, J, 3)`` in cm.
        mean_pose: ``(J, 3)``; defaults to the mean of ``positions`` over every frame (and every
            sequence of a batch). Pass the ground truth's mean pose to compare a model's output
            with the ground truth on one scale, as in Taylor et al.'s Figure 6.
    Returns:
        ``(T, J)`` or ``(B, T, J)``.
    """
    positions = _positions(positions, "positions")
    if mean_pose is None:
        mean_pose = positions.reshape(-1, *positions.shape[-2:]).mean(axis=0)
    else:
        mean_pose = _as_array(mean_pose, "mean_pose")
        if mean_pose.shape != positions.shape[-2:]:
            raise ValueError(
                f"mean_pose must have shape (J, 3) = {positions.shape[-2:]} to match positions, "
                f"got {mean_pose.shape}"
            )
    return np.linalg.norm(positions - mean_pose, axis=-1)


# --------------------------------------------------------------------------- distributions


def speed_bin_edges(max_speed: float, bin_width: float = DEFAULT_SPEED_BIN_WIDTH) -> np.ndarray:
    """Edges ``(n_bins + 1,)`` of equal-width bins from 0 cm/s to at least ``max_speed``."""
    if not bin_width > 0:
        raise ValueError(f"bin_width must be a positive speed in cm/s, got {bin_width!r}")
    if not (np.isfinite(max_speed) and max_speed >= 0):
        raise ValueError(f"max_speed must be a finite speed >= 0 in cm/s, got {max_speed!r}")
    n_bins = max(1, int(np.ceil(max_speed / bin_width)))
    return np.arange(n_bins + 1) * bin_width


def speed_histogram(speeds, bins) -> np.ndarray:
    """Relative frequency of speeds in each bin: a histogram that sums to 1.

    Args:
        speeds: any shape, e.g. ``(T - 1, J)`` from :func:`speed`; every value is counted.
        bins: ``(n_bins + 1,)`` increasing bin edges (see :func:`speed_bin_edges`). Use the same
            edges for every histogram you compare.
    Returns:
        ``(n_bins,)``. Values beyond the last edge are counted in the last bin and values below
        the first edge in the first bin, so no frame is silently dropped.
    """
    speeds = _as_array(speeds, "speeds").ravel()
    if speeds.size == 0:
        raise ValueError("speeds is empty: a histogram needs at least one value")
    edges = _as_array(bins, "bins")
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(
            "bins must be strictly increasing edges of shape (n_bins + 1,) with n_bins >= 1, "
            f"got shape {edges.shape}; see speed_bin_edges"
        )
    counts, _ = np.histogram(np.clip(speeds, edges[0], edges[-1]), bins=edges)
    return counts / counts.sum()


def hellinger_distance(p, q) -> float:
    """Hellinger distance ``sqrt(1 - sum_i sqrt(p_i q_i))`` between two discrete distributions.

    Kucherenko et al.'s equation 2. 0 for equal distributions, 1 for disjoint supports.

    Args:
        p, q: ``(n,)`` non-negative weights (e.g. histograms); each is normalised to sum to 1.
    """
    p, q = _as_array(p, "p"), _as_array(q, "q")
    if p.ndim != 1 or p.shape != q.shape:
        raise ValueError(f"p and q must both have shape (n,), got {p.shape} and {q.shape}")
    for name, weights in (("p", p), ("q", q)):
        if np.any(weights < 0) or not weights.sum() > 0:
            raise ValueError(f"{name} must be non-negative with a positive sum")
    bhattacharyya = np.sum(np.sqrt(p / p.sum() * q / q.sum()))
    # Rounding can push the coefficient of identical distributions a hair above 1.
    return float(np.sqrt(max(0.0, 1.0 - bhattacharyya)))


def speed_hellinger(
    positions_a,
    positions_b,
    fps,
    joints: Sequence[int] | None = None,
    bins=None,
    bin_width: float = DEFAULT_SPEED_BIN_WIDTH,
) -> float:
    """Hellinger distance between the speed histograms of two motions (Kucherenko et al.).

    The speeds of the chosen joints over all frames are pooled into one histogram per motion
    (equal to the average of the per-joint histograms), as in their Figures 5-6 and Table 2.

    Args:
        positions_a, positions_b: ``(T_a, J, 3)`` and ``(T_b, J, 3)`` (or batched), in cm, at the
            same ``fps``; their lengths may differ.
        fps: frames per second of both.
        joints: joint indices to pool, e.g. ``JOINT_GROUPS["wrists"]``; ``None`` for all joints.
        bins: explicit bin edges ``(n_bins + 1,)``; by default, bins of ``bin_width`` cm/s from
            0 to the highest speed of either motion.
        bin_width: width in cm/s of the default bins (:data:`DEFAULT_SPEED_BIN_WIDTH`).
    Returns:
        The distance in [0, 1]. Two finite samples of the *same* motion process do not give 0:
        compare against the distance between two draws of the ground truth.
    """
    speeds_a = speed(positions_a, fps)
    speeds_b = speed(positions_b, fps)
    n_joints = speeds_a.shape[-1]
    if speeds_b.shape[-1] != n_joints:
        raise ValueError(
            f"positions_a and positions_b must have the same number of joints J, "
            f"got {n_joints} and {speeds_b.shape[-1]}"
        )
    if joints is not None:
        joints = list(joints)
        if not joints or not all(-n_joints <= int(j) < n_joints for j in joints):
            raise ValueError(
                f"joints must be a non-empty list of indices below {n_joints}, got {joints}"
            )
        speeds_a, speeds_b = speeds_a[..., joints], speeds_b[..., joints]
    if bins is None:
        bins = speed_bin_edges(max(speeds_a.max(), speeds_b.max()), bin_width)
    return hellinger_distance(speed_histogram(speeds_a, bins), speed_histogram(speeds_b, bins))


# --------------------------------------------------------------------------- speaking vs listening


def split_by_activity(values, activity) -> dict[Activity, np.ndarray]:
    """Select the frames of each speech-activity class.

    Args:
        values: ``(N, ...)`` per-frame values, either one per frame (``N = T``) or from a finite
            difference of order ``k = T - N`` (1 for speeds, up to 3 for jerk), whose row ``i``
            uses frames ``i .. i + k`` (see :func:`speed`).
        activity: ``(T,)`` integer codes of :class:`gesturelib.conventions.Activity`.
    Returns:
        ``{activity_class: values[rows of that class]}`` for every class, each ``(n_c, ...)``
        (``n_c`` may be 0). A difference row belongs to a class only if *all* the frames it
        uses do; rows that span a change of activity are left out, so a turn change never
        contaminates either side.
    """
    values = _as_array(values, "values")
    activity = _as_array(activity, "activity")
    if activity.ndim != 1 or np.any(activity != np.round(activity)):
        raise ValueError(
            f"activity must be integer codes of shape (T,), got shape {activity.shape}"
        )
    valid_codes = [int(a) for a in Activity]
    if not np.all(np.isin(activity, valid_codes)):
        raise ValueError(f"activity codes must be in {valid_codes}, got {np.unique(activity)}")
    n_frames = activity.shape[0]
    order = n_frames - values.shape[0] if values.ndim > 0 else -1  # the k of the difference
    if not 0 <= order <= min(3, n_frames - 1):
        raise ValueError(
            f"values must have shape (T - k, ...) with T = {n_frames} frames of activity and "
            f"k in 0..3, got {values.shape}"
        )
    windows = np.lib.stride_tricks.sliding_window_view(activity, order + 1)  # (N, k + 1)
    uniform = np.all(windows == windows[:, :1], axis=1)
    return {a: values[uniform & (windows[:, 0] == a)] for a in Activity}


def speaking_listening_statistics(
    positions, activity, fps, mean_pose=None
) -> dict[str, dict[str, np.ndarray]]:
    """Distance from the mean pose and its rate of change while the agent speaks vs listens.

    What Taylor et al. plot in their Figures 7-8: the agent (speaker A) "speaks" in the frames
    labelled ``A_SPEAKS`` and "listens" in those labelled ``B_SPEAKS`` (cross-talk and silence
    are left out). The rate is signed: negative while a joint returns towards the mean pose,
    which is what a listener does.

    Args:
        positions: ``(T, J, 3)`` in cm.
        activity: ``(T,)`` :class:`Activity` codes.
        fps: frames per second.
        mean_pose: ``(J, 3)``; defaults to the mean over *all* frames of ``positions`` (not of
            each mode separately, so that both modes are measured from the same pose).
    Returns:
        ``{"speaking": {...}, "listening": {...}}``, each with ``"distance"`` ``(n, J)`` in cm and
        ``"distance_rate"`` ``(m, J)`` in cm/s (the first difference times ``fps``, kept only
        where both of its frames are in the mode, see :func:`split_by_activity`).
    """
    positions = _positions(positions, "positions", min_frames=2)
    if positions.ndim != 3:
        raise ValueError(f"positions must have shape (T, J, 3), got {positions.shape}")
    if tuple(np.shape(activity)) != (positions.shape[0],):
        raise ValueError(
            f"activity must have shape (T,) = ({positions.shape[0]},) to match positions, "
            f"got {tuple(np.shape(activity))}"
        )
    distance = distance_from_mean_pose(positions, mean_pose)
    rate = np.diff(distance, axis=0) * _check_fps(fps)
    distance_by_mode = split_by_activity(distance, activity)
    rate_by_mode = split_by_activity(rate, activity)
    modes = {"speaking": Activity.A_SPEAKS, "listening": Activity.B_SPEAKS}
    return {
        mode: {"distance": distance_by_mode[code], "distance_rate": rate_by_mode[code]}
        for mode, code in modes.items()
    }


# --------------------------------------------------------------------------- timing


def lag_correlation(reference, signal, fps, max_lag_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The normalised cross-correlation of two series at every lag up to ``max_lag_s``.

    For each lag ``k`` frames in ``[-K, K]`` (``K = round(max_lag_s * fps)``): the Pearson
    correlation of ``signal[t]`` with ``reference[t + k]`` over the frames where both exist.
    Positive lags are those where ``signal`` LEADS (see :func:`lead_lag`).

    Args:
        reference, signal: ``(T,)`` series on the same frames (align them first), not constant.
        fps: frames per second.
        max_lag_s: largest lag, in seconds; at least one frame and less than ``T - 2``.
    Returns:
        ``(lags (2K + 1,) in seconds, correlations (2K + 1,))``.
    """
    fps = _check_fps(fps)
    reference, signal = _as_array(reference, "reference"), _as_array(signal, "signal")
    if reference.ndim != 1 or signal.shape != reference.shape:
        raise ValueError(
            "reference and signal must both have shape (T,), "
            f"got {reference.shape} and {signal.shape}"
        )
    n_frames = reference.shape[0]
    max_lag = round(float(max_lag_s) * fps) if np.isfinite(float(max_lag_s)) else 0
    if not 1 <= max_lag < n_frames - 2:
        raise ValueError(
            f"max_lag_s * fps must round to between 1 and T - 3 = {n_frames - 3} frames, "
            f"got max_lag_s={max_lag_s!r} at fps={fps} with T={n_frames}"
        )
    for name, series in (("reference", reference), ("signal", signal)):
        if np.ptp(series) == 0:
            raise ValueError(f"{name} is constant: its correlation with anything is undefined")
    lags = np.arange(-max_lag, max_lag + 1)
    return lags / fps, np.array([_pearson(signal, reference, lag) for lag in lags])


def lead_lag(reference, signal, fps, max_lag_s: float) -> float:
    """How many seconds ``signal`` leads ``reference``: the peak of :func:`lag_correlation`.

    The best lag is refined to a fraction of a frame by fitting a parabola through the
    correlation peak and its two neighbours (vertex at ``(c[k-1] - c[k+1]) / (2 (c[k-1] - 2 c[k]
    + c[k+1]))`` frames from ``k``). For a shift of smooth peaks 1-5 frames wide, the error of
    this refinement is a few hundredths of a frame.

    Sign: POSITIVE when ``signal`` LEADS. Example at 25 fps: if audio emphasis (``reference``)
    peaks at frame 50 and wrist speed (``signal``) at frame 48, the wrist leads by 2 frames and
    the result is ``+0.08`` s; ``signal[t] == reference[t + 2]``.

    Args:
        reference, signal, fps, max_lag_s: as :func:`lag_correlation`.
    Returns:
        The lag in seconds. If the peak lies at the edge of the search range a warning says the
        true lag may lie beyond it.

    Choose ``max_lag_s`` well beyond the lag you expect: for rhythmic signals (accents every few
    syllables) the correlation has side peaks, so a true lag outside the range shows up as one of
    those side peaks *inside* it, and no warning can tell.
    """
    lags, correlation = lag_correlation(reference, signal, fps, max_lag_s)
    best = int(np.argmax(correlation))
    if best in (0, len(lags) - 1):
        warnings.warn(
            f"the correlation peaks at the edge of the search range (+-{max_lag_s} s); "
            "the true lag may be larger: increase max_lag_s",
            stacklevel=2,
        )
        return float(lags[best])
    before, peak, after = correlation[best - 1 : best + 2]
    curvature = before - 2.0 * peak + after
    offset = 0.5 * (before - after) / curvature if curvature < 0 else 0.0
    return float(lags[best] + offset * (lags[1] - lags[0]))


def _pearson(signal: np.ndarray, reference: np.ndarray, lag: int) -> float:
    """Correlation of ``signal[t]`` with ``reference[t + lag]`` over the frames where both exist."""
    if lag >= 0:
        a, b = signal[: len(signal) - lag], reference[lag:]
    else:
        a, b = signal[-lag:], reference[: len(reference) + lag]
    a, b = a - a.mean(), b - b.mean()
    norm = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / norm) if norm > 0 else 0.0


def rank_correlation(a, b) -> float:
    """Spearman's rank correlation of two series ``(n,)``: the Pearson correlation of their
    ranks, tied values sharing their mean rank. 1 when ``b`` rises with ``a``, -1 when it falls.

    Raises:
        ValueError: for series of different lengths, fewer than 2 values, or a constant one.
    """
    a, b = _as_array(a, "a"), _as_array(b, "b")
    if a.ndim != 1 or a.shape != b.shape or a.size < 2:
        raise ValueError(
            f"a and b must be series of the same length >= 2, got {a.shape}, {b.shape}"
        )
    ranks = []
    for name, values in (("a", a), ("b", b)):
        if np.ptp(values) == 0:
            raise ValueError(f"{name} is constant: its rank correlation is undefined")
        order = np.argsort(values, kind="stable")
        rank = np.empty(len(values))
        rank[order] = np.arange(len(values), dtype=np.float64)
        for value in np.unique(values):
            rank[values == value] = rank[values == value].mean()  # ties: their mean rank
        ranks.append(rank)
    return float(np.corrcoef(*ranks)[0, 1])


# --------------------------------------------------------------------------- accuracy, features


def average_position_error(predicted, target) -> float:
    """APE in cm: the mean Euclidean distance between predicted and target joint positions.

    Kucherenko et al.'s equation 1, averaged over joints, frames (and sequences of a batch).

    Args:
        predicted, target: ``(T, J, 3)`` or ``(B, T, J, 3)``, the same shape, in cm.
    """
    predicted = _positions(predicted, "predicted")
    target = _positions(target, "target")
    if predicted.shape != target.shape:
        raise ValueError(
            "predicted and target must have the same shape, "
            f"got {predicted.shape} and {target.shape}"
        )
    return float(np.linalg.norm(predicted - target, axis=-1).mean())


def frechet_distance(features_a, features_b) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets (as in FID and FGD).

    ``|mu_a - mu_b|^2 + tr(C_a + C_b - 2 (C_a C_b)^(1/2))``, with sample means and covariances.

    The trace of the matrix square root is computed as ``sum_i sqrt(lambda_i)`` over the
    eigenvalues of the symmetric matrix ``C_a^(1/2) C_b C_a^(1/2)``, which has the same
    eigenvalues as ``C_a C_b``. Unlike ``scipy.linalg.sqrtm(C_a @ C_b)`` this is always real,
    needs no diagonal offset for singular covariances (fewer samples than dimensions, constant
    features), and only clips rounding-error eigenvalues below zero.

    Args:
        features_a: ``(N, D)`` with ``N >= 2``.
        features_b: ``(M, D)`` with ``M >= 2``.
    Returns:
        The squared-unit distance (>= 0); symmetric in its arguments.
    """
    features_a = _as_array(features_a, "features_a")
    features_b = _as_array(features_b, "features_b")
    for name, features in (("features_a", features_a), ("features_b", features_b)):
        if features.ndim != 2 or features.shape[0] < 2:
            raise ValueError(f"{name} must have shape (N, D) with N >= 2, got {features.shape}")
    if features_a.shape[1] != features_b.shape[1]:
        raise ValueError(
            f"features_a and features_b must have the same dimension D, "
            f"got {features_a.shape[1]} and {features_b.shape[1]}"
        )
    mean_a, mean_b = features_a.mean(axis=0), features_b.mean(axis=0)
    cov_a = np.atleast_2d(np.cov(features_a, rowvar=False))
    cov_b = np.atleast_2d(np.cov(features_b, rowvar=False))
    sqrt_cov_a = _sqrt_psd(cov_a)
    eigenvalues = np.linalg.eigvalsh(sqrt_cov_a @ cov_b @ sqrt_cov_a)
    trace_sqrt = np.sum(np.sqrt(np.clip(eigenvalues, 0.0, None)))
    spread = np.trace(cov_a) + np.trace(cov_b)
    distance = np.sum((mean_a - mean_b) ** 2) + spread - 2.0 * trace_sqrt
    # Below the rounding error of the terms that cancel (identical sets): exactly zero.
    scale = spread + np.sum(mean_a**2) + np.sum(mean_b**2)
    return float(distance) if distance > 1e-9 * scale else 0.0


def _sqrt_psd(matrix: np.ndarray) -> np.ndarray:
    """Symmetric square root of a symmetric positive semi-definite matrix ``(D, D)``."""
    eigenvalues, eigenvectors = np.linalg.eigh(matrix)
    return (eigenvectors * np.sqrt(np.clip(eigenvalues, 0.0, None))) @ eigenvectors.T
