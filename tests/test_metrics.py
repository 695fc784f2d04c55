"""Tests of gesturelib.metrics on signals whose answers are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import torch

from gesturelib.conventions import Activity
from gesturelib.metrics import (
    JOINT_GROUPS,
    acceleration,
    average_position_error,
    distance_from_mean_pose,
    frechet_distance,
    hellinger_distance,
    jerk,
    lag_correlation,
    lead_lag,
    motion_statistics,
    speaking_listening_statistics,
    speed,
    speed_bin_edges,
    speed_hellinger,
    speed_histogram,
    split_by_activity,
)
from gesturelib.skeleton import NUM_JOINTS


def frame_times(n_frames: int, fps: float) -> np.ndarray:
    return np.arange(n_frames) / fps


# --------------------------------------------------------------------------- kinematics


def test_constant_velocity_has_that_speed_and_no_acceleration_or_jerk():
    fps, n_frames = 25, 20
    velocities = np.array([[3.0, 4.0, 0.0], [0.0, -2.0, 0.0]])  # cm/s: speeds 5 and 2
    start = np.array([[1.0, 2.0, 3.0], [-5.0, 0.0, 7.0]])
    positions = start + frame_times(n_frames, fps)[:, None, None] * velocities  # (T, 2, 3)

    assert speed(positions, fps).shape == (n_frames - 1, 2)
    assert acceleration(positions, fps).shape == (n_frames - 2, 2)
    assert jerk(positions, fps).shape == (n_frames - 3, 2)
    np.testing.assert_allclose(
        speed(positions, fps), np.broadcast_to([5.0, 2.0], (n_frames - 1, 2))
    )
    np.testing.assert_allclose(acceleration(positions, fps), 0.0, atol=1e-9)
    np.testing.assert_allclose(jerk(positions, fps), 0.0, atol=1e-6)


def test_circular_motion_speed_and_centripetal_acceleration():
    fps, radius, omega = 100.0, 10.0, 2 * np.pi * 0.5  # 10 cm circle, half a turn a second
    angle = omega * frame_times(201, fps)
    positions = radius * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], -1)[:, None]

    # The finite differences are exact for chords: |chord| = 2 r sin(omega dt / 2).
    half_step = omega / fps / 2
    np.testing.assert_allclose(speed(positions, fps), 2 * radius * np.sin(half_step) * fps)
    np.testing.assert_allclose(
        acceleration(positions, fps), 4 * radius * np.sin(half_step) ** 2 * fps**2
    )
    # ... and approach the continuous answers v = r omega and v^2 / r.
    tangential_speed = radius * omega
    np.testing.assert_allclose(speed(positions, fps), tangential_speed, rtol=1e-3)
    np.testing.assert_allclose(
        acceleration(positions, fps), tangential_speed**2 / radius, rtol=1e-3
    )


def test_cubic_trajectory_has_constant_jerk():
    fps = 25
    t = frame_times(50, fps)
    direction = np.array([2.0, -1.0, 2.0]) / 3.0  # unit vector
    cubic = 5.0  # cm/s^3 coefficient: jerk = 6 * 5 = 30 cm/s^3
    # Lower-order terms change speed and acceleration but not the third derivative.
    trajectory = (cubic * t**3 - 4.0 * t**2 + 7.0 * t + 1.0)[:, None] * direction
    positions = trajectory[:, None, :]
    np.testing.assert_allclose(jerk(positions, fps), 6 * cubic, rtol=1e-6)


def test_derivatives_scale_with_fps_and_accept_batches_and_tensors():
    rng = np.random.default_rng(0)
    positions = rng.normal(size=(2, 12, 5, 3))  # (B, T, J, 3): any number of joints
    np.testing.assert_allclose(speed(positions, 50), 2 * speed(positions, 25))
    np.testing.assert_allclose(acceleration(positions, 50), 4 * acceleration(positions, 25))
    np.testing.assert_allclose(jerk(positions, 50), 8 * jerk(positions, 25))
    assert speed(positions, 25).shape == (2, 11, 5)
    np.testing.assert_allclose(speed(positions, 25)[1], speed(positions[1], 25))
    np.testing.assert_allclose(speed(torch.from_numpy(positions), 25), speed(positions, 25))


def test_motion_statistics_are_per_joint_means():
    fps = 30
    velocities = np.array([[0.0, 6.0, 8.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    positions = frame_times(10, fps)[:, None, None] * velocities
    stats = motion_statistics(np.stack([positions, positions + 1.0]), fps)  # (B=2, T, J, 3)
    assert set(stats) == {"speed", "acceleration", "jerk"}
    np.testing.assert_allclose(stats["speed"], [10.0, 1.0, 0.0])
    np.testing.assert_allclose(stats["acceleration"], 0.0, atol=1e-9)
    np.testing.assert_allclose(stats["jerk"], 0.0, atol=1e-6)

    rng = np.random.default_rng(1)
    noisy = rng.normal(size=(15, 4, 3))
    stats = motion_statistics(noisy, fps)
    np.testing.assert_allclose(stats["jerk"], jerk(noisy, fps).mean(axis=0))


def test_distance_from_mean_pose_of_a_joint_oscillating_between_two_points():
    a, b = np.array([0.0, 10.0, 0.0]), np.array([6.0, 10.0, 8.0])  # |a - b| = 10 cm
    oscillating = np.where((np.arange(8) % 2 == 0)[:, None], a, b)  # a, b, a, b, ...
    still = np.tile([1.0, 2.0, 3.0], (8, 1))
    positions = np.stack([oscillating, still], axis=1)  # (8, 2, 3)

    distance = distance_from_mean_pose(positions)
    assert distance.shape == (8, 2)
    np.testing.assert_allclose(distance[:, 0], 5.0)  # the mean pose is the midpoint
    np.testing.assert_allclose(distance[:, 1], 0.0)

    given_mean = np.stack([a, [1.0, 2.0, 0.0]])
    distance = distance_from_mean_pose(positions, mean_pose=given_mean)
    np.testing.assert_allclose(distance[:, 0], np.tile([0.0, 10.0], 4))
    np.testing.assert_allclose(distance[:, 1], 3.0)


# --------------------------------------------------------------------------- distributions


def test_hellinger_known_values():
    p = np.array([0.2, 0.3, 0.5, 0.0])
    assert hellinger_distance(p, p) == pytest.approx(0.0, abs=1e-7)
    assert hellinger_distance([1.0, 0.0, 0.0], [0.0, 0.4, 0.6]) == pytest.approx(1.0)
    # By hand: [1, 3] normalises to [1/4, 3/4]; the coefficient is sqrt(1/8) + sqrt(3/8).
    expected = np.sqrt(1.0 - (np.sqrt(1 / 8) + np.sqrt(3 / 8)))
    assert hellinger_distance([1.0, 3.0], [0.5, 0.5]) == pytest.approx(expected)
    assert hellinger_distance([0.5, 0.5], [1.0, 3.0]) == pytest.approx(expected)
    assert expected == pytest.approx(0.18459, abs=1e-5)


def test_speed_histogram_counts_every_value_and_sums_to_one():
    edges = speed_bin_edges(2.5, bin_width=1.0)
    np.testing.assert_allclose(edges, [0.0, 1.0, 2.0, 3.0])
    speeds = np.array([[0.5, 1.5], [1.7, 10.0]])  # 10 lies beyond the last edge
    np.testing.assert_allclose(speed_histogram(speeds, edges), [0.25, 0.5, 0.25])
    histogram = speed_histogram(np.random.default_rng(2).gamma(2.0, 5.0, size=500), edges)
    assert histogram.sum() == pytest.approx(1.0)


def test_speed_hellinger_per_joint_group():
    fps, n_frames = 25, 40
    t = frame_times(n_frames, fps)[:, None, None]
    rng = np.random.default_rng(3)
    base = rng.normal(scale=0.1, size=(n_frames, NUM_JOINTS, 3))  # speeds of a few cm/s
    faster_elbows = base.copy()
    elbows = list(JOINT_GROUPS["elbows"])
    faster_elbows[:, elbows] += t * np.array([100.0, 0.0, 0.0])  # elbows 100 cm/s faster

    assert speed_hellinger(base, base, fps) == pytest.approx(0.0, abs=1e-7)
    assert speed_hellinger(
        base, faster_elbows, fps, joints=JOINT_GROUPS["wrists"]
    ) == pytest.approx(0.0, abs=1e-7)
    # 2 of 9 joints leave the slow bins, so by Cauchy-Schwarz the Bhattacharyya coefficient is
    # at most sqrt(7 / 9).
    assert speed_hellinger(base, faster_elbows, fps) >= np.sqrt(1 - np.sqrt(7 / 9))
    # Joints moving at 5 cm/s against 50 cm/s: disjoint speed histograms.
    slow = t * np.array([5.0, 0.0, 0.0]) + np.zeros((1, 3, 3))
    assert speed_hellinger(slow, 10 * slow, fps) == pytest.approx(1.0)
    # Explicit edges are used as given: one bin holds everything, so the histograms agree.
    assert speed_hellinger(slow, 10 * slow, fps, bins=[0.0, 1.0]) == pytest.approx(0.0, abs=1e-7)


# --------------------------------------------------------------------------- activity


def test_split_by_activity_selects_frames_and_drops_differences_across_a_turn_change():
    activity = np.array([0, 0, 1, 1, 1, 2, 3, 3, 0])
    per_frame = split_by_activity(np.arange(9.0), activity)
    assert set(per_frame) == set(Activity)
    np.testing.assert_array_equal(per_frame[Activity.A_SPEAKS], [0, 1, 8])
    np.testing.assert_array_equal(per_frame[Activity.B_SPEAKS], [2, 3, 4])
    np.testing.assert_array_equal(per_frame[Activity.BOTH], [5])
    np.testing.assert_array_equal(per_frame[Activity.NONE], [6, 7])

    # Row i of a first difference uses frames i and i + 1.
    per_step = split_by_activity(np.arange(8.0)[:, None] * [1.0, -1.0], activity)  # (T-1, 2)
    np.testing.assert_array_equal(per_step[Activity.A_SPEAKS][:, 0], [0])
    np.testing.assert_array_equal(per_step[Activity.B_SPEAKS][:, 0], [2, 3])
    assert per_step[Activity.BOTH].shape == (0, 2)
    np.testing.assert_array_equal(per_step[Activity.NONE][:, 1], [-6])
    # A third difference (jerk) uses four frames, and no four consecutive frames share a class.
    assert all(len(rows) == 0 for rows in split_by_activity(np.arange(6.0), activity).values())


def test_speaking_listening_statistics_known_rates():
    fps = 25
    # One joint moves away from the origin by 2 cm a frame while A speaks (frames 0-9) and
    # back by 2 cm a frame while B speaks (frames 10-19); then both talk (frames 20-24).
    x = np.concatenate([2.0 * np.arange(10), 20.0 - 2.0 * np.arange(1, 11), np.zeros(5)])
    positions = np.stack([x, np.zeros_like(x), np.zeros_like(x)], -1)[:, None, :]  # (25, 1, 3)
    activity = np.array([0] * 10 + [1] * 10 + [2] * 5)

    stats = speaking_listening_statistics(positions, activity, fps, mean_pose=np.zeros((1, 3)))
    assert set(stats) == {"speaking", "listening"}
    np.testing.assert_allclose(stats["speaking"]["distance"][:, 0], 2.0 * np.arange(10))
    np.testing.assert_allclose(stats["speaking"]["distance_rate"], 2.0 * fps)
    np.testing.assert_allclose(stats["listening"]["distance_rate"], -2.0 * fps)
    assert stats["speaking"]["distance_rate"].shape == (9, 1)  # the turn-change step is left out
    assert stats["listening"]["distance"].shape == (10, 1)

    # By default, distances are measured from the mean over *all* frames.
    default = speaking_listening_statistics(positions, activity, fps)
    np.testing.assert_allclose(default["listening"]["distance"][:, 0], np.abs(x[10:20] - x.mean()))


# --------------------------------------------------------------------------- timing


def test_lead_lag_sign_convention_example():
    reference, signal = np.zeros(100), np.zeros(100)
    reference[50], signal[48] = 1.0, 1.0  # the signal's event happens 2 frames earlier
    # The parabola through the peak's neighbours moves it by far less than 0.01 frame.
    assert lead_lag(reference, signal, fps=25, max_lag_s=0.4) == pytest.approx(0.08, abs=0.01 / 25)
    assert lead_lag(signal, reference, fps=25, max_lag_s=0.4) == pytest.approx(-0.08, abs=0.01 / 25)


@pytest.mark.parametrize("shift_frames", [3, -4])
def test_lead_lag_recovers_integer_shift_of_a_spike_train(shift_frames):
    rng = np.random.default_rng(4)
    reference = (rng.random(400) < 0.05).astype(float)
    signal = np.zeros_like(reference)  # signal[t] = reference[t + shift]: leads by `shift`
    if shift_frames >= 0:
        signal[: len(signal) - shift_frames] = reference[shift_frames:]
    else:
        signal[-shift_frames:] = reference[:shift_frames]
    fps = 25
    measured_frames = lead_lag(reference, signal, fps, max_lag_s=0.5) * fps
    assert measured_frames == pytest.approx(shift_frames, abs=0.01)


def test_lag_correlation_is_one_at_the_shift_of_a_spike_train_and_small_elsewhere():
    rng = np.random.default_rng(4)
    reference = (rng.random(400) < 0.05).astype(float)
    signal = np.zeros_like(reference)
    signal[:-3] = reference[3:]  # leads by 3 frames
    lags, correlation = lag_correlation(reference, signal, fps=25, max_lag_s=0.4)
    np.testing.assert_allclose(lags, np.arange(-10, 11) / 25)
    assert correlation[lags.tolist().index(3 / 25)] == pytest.approx(1.0, abs=0.01)
    assert np.delete(correlation, lags.tolist().index(3 / 25)).max() < 0.3


@pytest.mark.parametrize("lead_frames", [2.4, -1.7, 0.5])
def test_lead_lag_recovers_fractional_shift_of_a_smoothed_pulse_train(lead_frames):
    rng = np.random.default_rng(5)
    n_frames, width = 500, 2.5
    event_frames = np.sort(rng.uniform(20, n_frames - 20, size=25))
    frames = np.arange(n_frames)[:, None]

    def pulses(at):
        return np.exp(-0.5 * ((frames - at) / width) ** 2).sum(axis=1)

    reference, signal = pulses(event_frames), pulses(event_frames - lead_frames)
    fps = 50
    measured_frames = lead_lag(reference, signal, fps, max_lag_s=0.2) * fps
    assert measured_frames == pytest.approx(lead_frames, abs=0.02)


def test_lead_lag_warns_when_the_peak_is_at_the_edge_of_the_search():
    frames = np.arange(100)
    reference = np.exp(-0.5 * ((frames - 60) / 5.0) ** 2)
    signal = np.exp(-0.5 * ((frames - 40) / 5.0) ** 2)  # 20 frames earlier, only 5 searched
    with pytest.warns(UserWarning, match="edge of the search range"):
        lead_lag(reference, signal, fps=25, max_lag_s=0.2)


# --------------------------------------------------------------------------- accuracy, features


def test_average_position_error_of_a_constant_offset():
    positions = np.random.default_rng(6).normal(size=(2, 10, 4, 3))
    assert average_position_error(positions + [3.0, 4.0, 0.0], positions) == pytest.approx(5.0)
    assert average_position_error(positions, positions) == 0.0


def test_frechet_distance_closed_forms():
    rng = np.random.default_rng(7)
    features = rng.normal(size=(200, 4)) @ rng.normal(size=(4, 4))
    shift = np.array([1.0, -2.0, 0.5, 3.0])
    # Same covariance, shifted mean: the squared distance between the means.
    assert frechet_distance(features, features + shift) == pytest.approx(shift @ shift, rel=1e-6)
    # Same mean (zero), covariance C against 4 C: tr(C + 4 C - 2 (4 C^2)^(1/2)) = tr(C).
    centred = features - features.mean(axis=0)
    assert frechet_distance(centred, 2 * centred) == pytest.approx(
        np.trace(np.cov(centred, rowvar=False)), rel=1e-6
    )
    # One dimension: (mu_a - mu_b)^2 + (sigma_a - sigma_b)^2.
    a, b = rng.normal(1.0, 2.0, size=(50, 1)), rng.normal(-1.0, 0.5, size=(80, 1))
    expected = (a.mean() - b.mean()) ** 2 + (a.std(ddof=1) - b.std(ddof=1)) ** 2
    assert frechet_distance(a, b) == pytest.approx(expected)


def test_frechet_distance_of_a_set_to_itself_is_exactly_zero_at_any_scale():
    rng = np.random.default_rng(10)
    for scale in (1e-3, 1.0, 1e4):
        features = scale * (rng.normal(size=(500, 32)) @ rng.normal(size=(32, 32)) + 5.0)
        assert frechet_distance(features, features) == 0.0
        # ... while a shift far smaller than the spread is still seen.
        assert frechet_distance(features, features + 1e-3 * scale) > 0.0


def test_frechet_distance_is_symmetric_and_matches_the_sqrtm_formula():
    rng = np.random.default_rng(8)
    a = rng.normal(size=(300, 5))
    b = rng.normal(size=(250, 5)) @ rng.normal(size=(5, 5)) + 0.3
    cov_a, cov_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    reference = np.sum((a.mean(0) - b.mean(0)) ** 2) + np.trace(
        cov_a + cov_b - 2 * scipy.linalg.sqrtm(cov_a @ cov_b).real
    )
    assert frechet_distance(a, b) == pytest.approx(reference, rel=1e-8)
    assert frechet_distance(b, a) == pytest.approx(frechet_distance(a, b), rel=1e-10)


def test_frechet_distance_with_singular_covariance():
    rng = np.random.default_rng(9)
    few = rng.normal(size=(3, 6))  # 3 samples in 6 dimensions: covariance of rank 2
    assert frechet_distance(few, few) == 0.0
    distance = frechet_distance(few, rng.normal(size=(4, 6)))
    assert np.isfinite(distance) and distance > 0


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: speed(np.zeros((10, 3)), 25), r"positions must have shape \(T, J, 3\)"),
        (lambda: speed(np.zeros((10, 9, 2)), 25), r"positions must have shape \(T, J, 3\)"),
        (lambda: jerk(np.zeros((3, 9, 3)), 25), "positions needs at least 4 frames"),
        (lambda: acceleration(np.zeros((2, 9, 3)), 25), "at least 3 frames"),
        (lambda: speed(np.zeros((10, 9, 3)), 0), "fps must be a positive number"),
        (lambda: speed(np.zeros((10, 9, 3)), -25), "fps must be a positive number"),
        (lambda: speed(np.zeros((10, 9, 3)), float("nan")), "fps must be a positive number"),
        (lambda: speed(np.zeros((10, 9, 3)), "25"), "fps must be a positive number"),
        (lambda: speed(np.full((10, 9, 3), np.nan), 25), "positions contains NaN"),
        (
            lambda: distance_from_mean_pose(np.zeros((5, 9, 3)), np.zeros((8, 3))),
            r"mean_pose must have shape \(J, 3\)",
        ),
        (lambda: hellinger_distance([0.5, -0.5], [0.5, 0.5]), "p must be non-negative"),
        (
            lambda: hellinger_distance([0.5, 0.5], [0.0, 0.0]),
            "q must be non-negative with a positive sum",
        ),
        (lambda: hellinger_distance([0.5, 0.5], [1.0, 0.0, 0.0]), r"shape \(n,\)"),
        (lambda: speed_histogram([1.0, 2.0], [0.0, 2.0, 1.0]), "bins must be strictly increasing"),
        (lambda: speed_histogram([], [0.0, 1.0]), "speeds is empty"),
        (lambda: speed_bin_edges(10.0, bin_width=0.0), "bin_width must be a positive"),
        (
            lambda: speed_hellinger(np.zeros((5, 9, 3)), np.zeros((5, 8, 3)), 25),
            "same number of joints",
        ),
        (
            lambda: speed_hellinger(np.zeros((5, 9, 3)), np.zeros((5, 9, 3)), 25, joints=[9]),
            "joints must be",
        ),
        (lambda: split_by_activity(np.zeros(4), np.zeros(9)), r"values must have shape \(T - k"),
        (lambda: split_by_activity(np.zeros(9), np.full(9, 7)), "activity codes must be in"),
        (lambda: split_by_activity(np.zeros(9), np.full(9, 0.5)), "activity must be integer codes"),
        (
            lambda: speaking_listening_statistics(np.zeros((5, 9, 3)), np.zeros(4), 25),
            r"activity must have shape \(T,\)",
        ),
        (lambda: lead_lag(np.arange(10.0), np.arange(11.0), 25, 0.1), "must both have shape"),
        (lambda: lead_lag(np.arange(10.0), np.arange(10.0), 25, 1.0), "max_lag_s"),
        (lambda: lead_lag(np.arange(10.0), np.ones(10), 25, 0.1), "signal is constant"),
        (lambda: average_position_error(np.zeros((5, 9, 3)), np.zeros((6, 9, 3))), "same shape"),
        (lambda: frechet_distance(np.zeros((5, 3)), np.zeros((5, 4))), "same dimension D"),
        (
            lambda: frechet_distance(np.zeros((1, 3)), np.zeros((5, 3))),
            r"features_a must have shape \(N, D\) with N >= 2",
        ),
    ],
)
def test_bad_input_raises_a_clear_value_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_rank_correlation_sees_order_not_scale_and_shares_ranks_among_ties():
    from gesturelib.metrics import rank_correlation

    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert rank_correlation(x, np.exp(x)) == pytest.approx(1.0)
    assert rank_correlation(x, -(x**3)) == pytest.approx(-1.0)
    # ties share their mean rank: ranks (0.5, 0.5, 2) against (0, 1, 2)
    expected = np.corrcoef([0.5, 0.5, 2.0], [0.0, 1.0, 2.0])[0, 1]
    assert rank_correlation([1.0, 1.0, 2.0], [3.0, 4.0, 5.0]) == pytest.approx(expected)
    with pytest.raises(ValueError, match="constant"):
        rank_correlation([1.0, 1.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="same length"):
        rank_correlation([1.0, 2.0], [1.0, 2.0, 3.0])
