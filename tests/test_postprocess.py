"""Post-processing filters: moving average, One Euro, and smoothing of limb rotations."""

import numpy as np
import pytest

from data_synth import generate_conversation
from gesturelib.metrics import jerk
from gesturelib.postprocess import moving_average, one_euro, smooth_rotations
from gesturelib.skeleton import BONE_LENGTHS, bone_lengths, forward_kinematics

FPS = 25


@pytest.fixture(scope="module")
def rotations():
    """Clean rotations ``(100, 9, 6)`` of 4 s of synthetic motion, and a noisy copy."""
    clean = generate_conversation(4.0, seed=3).rotations.astype(np.float64)
    return clean, clean + np.random.default_rng(0).normal(0.0, 0.03, clean.shape)


def test_both_filters_keep_constants():
    constants = np.broadcast_to(np.array([[7.3, -0.2, 0.0], [1e3, 0.5, -40.0]]), (30, 2, 3))
    for smoothed in [
        *(moving_average(constants, window) for window in (1, 3, 5, 7, 61)),
        one_euro(constants, FPS),
        one_euro(constants, FPS, min_cutoff=0.1, beta=50.0),
    ]:
        np.testing.assert_allclose(smoothed, constants, rtol=1e-14, atol=0)


def test_moving_average_keeps_a_ramp_exact_at_every_frame():
    frames = np.arange(40.0)[:, None]
    ramps = 3.0 + frames * np.array([0.7, -2.5])  # (40, 2), two slopes
    for window in (3, 5, 9):
        np.testing.assert_allclose(moving_average(ramps, window), ramps, rtol=0, atol=1e-12)


def test_moving_average_spreads_an_impulse_and_shrinks_its_window_at_the_ends():
    impulse = np.array([0.0, 0.0, 0.0, 9.0, 0.0, 0.0, 0.0])
    # Frames 0 and 6 keep themselves, 1 and 5 average 3 frames, 2..4 average 5.
    np.testing.assert_allclose(moving_average(impulse, 5), [0, 0, 1.8, 1.8, 1.8, 0, 0])
    np.testing.assert_allclose(moving_average(impulse, 3), [0, 0, 3, 3, 3, 0, 0])


@pytest.mark.parametrize("window", [3, 5, 9])
def test_moving_average_divides_the_variance_of_white_noise_by_the_window(window):
    noise = np.random.default_rng(window).normal(0.0, 2.0, (20_000, 4))
    interior = moving_average(noise, window)[window:-window]
    # 80 000 samples: the relative standard error of the ratio is below 1.5%.
    assert interior.var() / noise.var() == pytest.approx(1.0 / window, rel=0.05)


def test_a_window_of_one_frame_is_the_identity():
    values = np.random.default_rng(1).normal(size=(50, 3, 2)).astype(np.float32)
    smoothed = moving_average(values, 1)
    assert smoothed.dtype == np.float64
    np.testing.assert_array_equal(smoothed, values)


def test_one_euro_without_beta_is_exponential_smoothing_of_a_step():
    step = np.where(np.arange(50) >= 10, 1.0, 0.0)
    tau = 1.0 / (2.0 * np.pi * 1.5)
    alpha = 1.0 / (1.0 + tau * FPS)
    # y_t = alpha x_t + (1 - alpha) y_{t-1} from y = 0: after n frames of the step, 1 - (1 - alpha)^n.
    expected = np.where(step > 0, 1.0 - (1.0 - alpha) ** (np.arange(50) - 9.0), 0.0)
    smoothed = one_euro(step, FPS, min_cutoff=1.5, beta=0.0)
    np.testing.assert_allclose(smoothed, expected, rtol=0, atol=1e-12)


def test_one_euro_follows_a_fast_ramp_with_less_lag_as_beta_grows():
    speed = 2.0  # units per second
    ramp = np.maximum(np.arange(200) - 20, 0) * speed / FPS
    lags = {}
    for beta in (0.0, 3.0):
        smoothed = one_euro(ramp, FPS, min_cutoff=1.0, beta=beta)
        # On a ramp, exponential smoothing settles at a constant lag of (1 - alpha) / alpha
        # frames = tau * fps, so the cutoff it ran at is fps / (2 pi lag).
        lags[beta] = (ramp[-1] - smoothed[-1]) / (speed / FPS)
        cutoff = FPS / (2.0 * np.pi * lags[beta])
        assert cutoff == pytest.approx(1.0 + beta * speed, rel=1e-6)  # beta is Hz per unit/s
    assert lags[0.0] == pytest.approx(FPS / (2.0 * np.pi), rel=1e-6)  # about 4 frames
    assert lags[3.0] < lags[0.0] / 5


def test_each_channel_is_filtered_on_its_own():
    rng = np.random.default_rng(2)
    values = np.cumsum(rng.normal(size=(60, 3, 2)), axis=0)
    values[30:, 1, 0] += 100.0  # a jump that opens this channel's One Euro filter only
    for smooth in (lambda x: moving_average(x, 5), lambda x: one_euro(x, FPS)):
        stacked = smooth(values)
        for joint in range(3):
            for axis in range(2):
                alone = smooth(values[:, joint, axis])
                np.testing.assert_array_equal(stacked[:, joint, axis], alone)


@pytest.mark.parametrize(
    ("method", "options"), [("moving_average", {}), ("one_euro", {"fps": FPS})]
)
def test_smoothed_rotations_stay_rotations_and_reduce_jerk(rotations, method, options):
    clean, noisy = rotations
    smoothed = smooth_rotations(noisy, method, **options)
    assert smoothed.shape == noisy.shape
    rows = smoothed.reshape(*smoothed.shape[:-1], 2, 3)
    gram = rows @ rows.swapaxes(-1, -2)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(2), gram.shape), atol=1e-12)
    positions = forward_kinematics(smoothed)
    np.testing.assert_allclose(
        bone_lengths(positions), np.broadcast_to(BONE_LENGTHS, (100, 9)), atol=1e-5
    )
    noisy_positions = forward_kinematics(noisy)
    assert jerk(positions, FPS).mean() < jerk(noisy_positions, FPS).mean() / 4
    truth = forward_kinematics(clean)
    error, noisy_error = (np.abs(p - truth).mean() for p in (positions, noisy_positions))
    assert error < 0.75 * noisy_error


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda x: moving_average(x, 4), "window must be an odd number of frames >= 1"),
        (lambda x: moving_average(x, 0), "window must be an odd number of frames >= 1"),
        (lambda x: moving_average(x, 2.5), "window must be an odd number of frames >= 1"),
        (lambda x: moving_average(np.float64(3.0)), r"shape \(T, \.\.\.\)"),
        (lambda x: moving_average(np.zeros((0, 3))), r"T >= 1, got \(0, 3\)"),
        (lambda x: one_euro(np.where(x > 0, np.nan, x), FPS), "NaN or infinite"),
        (lambda x: one_euro(x, 0), "fps must be a finite number > 0"),
        (lambda x: one_euro(x, -25), "fps must be a finite number > 0"),
        (lambda x: one_euro(x, True), "fps must be a finite number > 0"),
        (lambda x: one_euro(x, FPS, min_cutoff=0.0), "min_cutoff must be a finite number > 0"),
        (lambda x: one_euro(x, FPS, d_cutoff=-1.0), "d_cutoff must be a finite number > 0"),
        (lambda x: one_euro(x, FPS, beta=-0.1), "beta must be a finite number >= 0"),
        (lambda x: one_euro(x, FPS, beta=np.inf), "beta must be a finite number >= 0"),
        (lambda x: smooth_rotations(x, "gaussian"), "method must be one of"),
        (lambda x: smooth_rotations(x[..., :3]), r"rotations must have shape \(T, 9, 6\)"),
        (
            lambda x: smooth_rotations(np.where(x > 0, np.inf, x)),
            "rotations contains NaN or infinite",
        ),
    ],
)
def test_bad_input_raises_a_named_error(call, match):
    rotations = np.tile(np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]), (10, 9, 1))
    with pytest.raises(ValueError, match=match):
        call(rotations)
