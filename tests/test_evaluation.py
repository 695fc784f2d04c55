"""gesturelib.evaluation on motions with a known answer."""

import numpy as np
import pytest

from gesturelib.conventions import FPS, Activity
from gesturelib.evaluation import (
    WRIST_SPEED_BINS,
    hand_sharing,
    pause_speed_profile,
    pause_wrist_speed,
    speaking_listening_ratio,
    speaking_wrist_speeds,
    stroke_lead,
    wrist_speed_hellinger,
    wrist_speed_histogram,
)
from gesturelib.skeleton import JOINT_INDEX, t_pose

WRISTS = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]


def moving(speed_cm_s: float, frames: int = 100) -> np.ndarray:
    """Both wrists moving sideways at a constant speed."""
    motion = np.repeat(t_pose()[None], frames, axis=0)
    motion[:, WRISTS, 0] += speed_cm_s / 25 * np.arange(frames)[:, None]
    return motion


def test_the_histogram_has_4_cm_s_bins_to_400_and_keeps_faster_speeds():
    assert WRIST_SPEED_BINS[1] == 4 and WRIST_SPEED_BINS[-1] == 400
    histogram = wrist_speed_histogram([moving(10.0), moving(1000.0)])
    assert histogram.sum() == pytest.approx(1.0)
    assert histogram[2] == pytest.approx(0.5) and histogram[-1] == pytest.approx(0.5)


def test_hellinger_is_zero_for_the_same_speeds_and_one_for_disjoint_ones():
    assert wrist_speed_hellinger([moving(10.0)], [moving(10.0, frames=50)]) == pytest.approx(0.0)
    assert wrist_speed_hellinger([moving(10.0)], [moving(50.0)]) == pytest.approx(1.0)
    halves = wrist_speed_hellinger([moving(10.0), moving(50.0)], [moving(10.0)])
    assert halves == pytest.approx(np.sqrt(1 - np.sqrt(0.5)))  # overlap of half the mass


def test_the_speaking_listening_ratio_compares_mean_wrist_speeds():
    motion = np.repeat(t_pose()[None], 101, axis=0)
    step = np.where(np.arange(101) < 51, 3.0, 1.0) / 25  # 3 cm/s for 50 speeds, then 1 cm/s
    motion[:, WRISTS, 1] += np.cumsum(step)[:, None]
    activity = np.where(np.arange(101) <= 50, Activity.A_SPEAKS, Activity.B_SPEAKS)
    assert speaking_listening_ratio(motion, activity) == pytest.approx(3.0)
    with pytest.raises(ValueError, match="both speak and listen"):
        speaking_listening_ratio(motion, np.full(101, Activity.A_SPEAKS))


def test_hand_sharing_tells_hands_that_take_turns_from_hands_that_move_together():
    turns = np.array([[30.0, 1.0], [2.0, 20.0]] * 50)  # one hand strokes while the other rests
    assert hand_sharing(turns) == pytest.approx(
        {"still": 0.5, "one_hand": 1.0, "correlation": -1.0}
    )
    together = np.array([[30.0, 25.0], [2.0, 3.0], [10.0, 12.0]] * 20)
    shared = hand_sharing(together)
    assert shared["one_hand"] == 0.0 and shared["still"] == pytest.approx(1 / 3)
    assert shared["correlation"] > 0.99
    assert np.isnan(hand_sharing(np.ones((10, 2)))["correlation"])  # no variation: undefined
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        hand_sharing(np.ones((10, 9)))


def test_speaking_wrist_speeds_keep_the_frames_where_the_agent_speaks():
    from types import SimpleNamespace

    motion = np.repeat(t_pose()[None], 101, axis=0)
    motion[:, WRISTS[0], 0] += 0.4 * np.arange(101)  # the left wrist at 10 cm/s, the right still
    activity = np.where(np.arange(101) < 41, Activity.A_SPEAKS, Activity.B_SPEAKS)
    speeds = speaking_wrist_speeds([motion], [SimpleNamespace(activity=activity)])
    assert speeds.shape == (40, 2)  # the speeds into frames 1-40
    np.testing.assert_allclose(speeds, [[10.0, 0.0]] * 40, atol=1e-9)


def test_pause_wrist_speed_averages_the_wrists_over_short_pauses_only():
    from types import SimpleNamespace

    # Speaks 2 s, silent 1 s, speaks 2 s, silent 6 s (a pause too long to count), speaks 1 s.
    codes = [Activity.A_SPEAKS] * 50 + [Activity.B_SPEAKS] * 25 + [Activity.BOTH] * 50
    codes += [Activity.NONE] * 150 + [Activity.A_SPEAKS] * 25
    activity = np.array(codes)
    speeds = np.where(activity == Activity.B_SPEAKS, 10.0, 30.0)  # cm/s into each frame
    track = np.cumsum(np.r_[0.0, speeds[1:] / FPS])
    motion = np.repeat(t_pose()[None], len(codes), axis=0)
    motion[:, :, 0] += track[:, None]
    conversation = SimpleNamespace(activity=activity)
    assert pause_wrist_speed([motion], [conversation]) == pytest.approx(10.0)
    assert pause_wrist_speed([motion], [conversation], longest_s=7.0) == pytest.approx(
        (25 * 10.0 + 150 * 30.0) / 175
    )
    speaking = SimpleNamespace(activity=np.full(len(codes), Activity.A_SPEAKS))
    assert np.isnan(pause_wrist_speed([motion], [speaking]))


def test_pause_speed_profile_follows_the_pauses_between_phrases_from_either_end():
    from types import SimpleNamespace

    # Silent 0.4 s at the start (not between phrases), speaks 1 s, a pause of 10 frames (its
    # wrists at 3 cm/s per frame into it: 3, 6, ..., 30), speaks 1 s, a pause of 4 frames at
    # 100 cm/s, speaks 1 s, silent 6 s (too long).
    codes = [Activity.NONE] * 10 + [Activity.A_SPEAKS] * 25 + [Activity.B_SPEAKS] * 10
    codes += [Activity.BOTH] * 25 + [Activity.NONE] * 4 + [Activity.A_SPEAKS] * 25
    codes += [Activity.NONE] * 150
    activity = np.array(codes)
    speeds = np.full(len(codes), 50.0)  # cm/s into each frame
    speeds[35:45] = 3.0 * np.arange(1, 11)
    speeds[70:74] = 100.0
    track = np.cumsum(np.r_[0.0, speeds[1:] / FPS])
    motion = np.repeat(t_pose()[None], len(codes), axis=0)
    motion[:, :, 0] += track[:, None]
    conversation = SimpleNamespace(activity=activity)
    after_end, before_start = pause_speed_profile([motion], [conversation], seconds=0.4)
    assert after_end.shape == before_start.shape == (10,)
    np.testing.assert_allclose(after_end[:4], (3.0 * np.arange(1, 5) + 100.0) / 2)
    np.testing.assert_allclose(after_end[4:], 3.0 * np.arange(5, 11))
    np.testing.assert_allclose(before_start[:4], (3.0 * np.arange(10, 6, -1) + 100.0) / 2)
    np.testing.assert_allclose(before_start[4:], 3.0 * np.arange(6, 0, -1))
    after_end, _ = pause_speed_profile([motion], [conversation], seconds=0.8)
    assert np.isnan(after_end[10:]).all()


def test_the_stroke_lead_of_the_generators_motion_is_its_rule():
    from data_synth import generate_conversation

    conversation = generate_conversation(30.0, seed=4)
    lead = stroke_lead(
        conversation.audio, conversation.sample_rate, conversation.activity, conversation.positions
    )
    assert 0.1 <= lead <= 0.3  # the rule: 0.2 s


def test_the_references_rank_as_they_must_on_the_headline_measures():
    from data_synth import generate_conversation
    from gesturelib.evaluation import headline_measures, reference_motions

    conversations = [generate_conversation(30.0, seed=seed) for seed in (4, 5)]
    mean_pose = np.mean([c.positions.mean(0) for c in conversations], axis=0)
    references = reference_motions(conversations, mean_pose, seed=7)
    assert all(len(r) == 2 for r in references.values())
    assert not np.allclose(references["floor"][0], conversations[0].positions)
    np.testing.assert_array_equal(references["mismatched"][0], conversations[1].positions)
    scores = {name: headline_measures(conversations, m) for name, m in references.items()}
    truth = headline_measures(conversations, [c.positions for c in conversations])
    assert truth["hellinger"] == 0.0
    assert scores["floor"]["hellinger"] < 0.2 < scores["mean_pose"]["hellinger"]
    assert abs(scores["floor"]["lead"] - 0.2) < 0.1  # the floor keeps the rule
    assert np.isnan(scores["mean_pose"]["ratio"]) and np.isnan(scores["mean_pose"]["lead"])
    with pytest.raises(ValueError, match="at least 2"):
        reference_motions(conversations[:1], mean_pose)
    alone = reference_motions(conversations[:1], mean_pose, others=conversations[1:])
    np.testing.assert_array_equal(alone["mismatched"][0], conversations[1].positions)


def test_drift_measures_an_error_that_grows_by_a_known_amount():
    """Every limb turned away from the truth by 2 + 0.1 t degrees (t in seconds): the error per
    10 s is the mean of that line over each chunk, and the drift their last over their first."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from gesturelib.evaluation.headline import drift, error_over_time
    from gesturelib.rotations import matrix_to_rot6d
    from gesturelib.skeleton import T_POSE_OFFSETS

    frames = 60 * FPS
    seconds = np.arange(frames) / FPS
    angle = 2.0 + 0.1 * seconds
    truth = np.tile(np.array([1.0, 0, 0, 0, 1, 0]), (frames, 9, 1))  # the T-pose
    turned = np.empty_like(truth)
    for limb, offset in enumerate(T_POSE_OFFSETS):
        axis = np.cross(offset, [0.0, 0.0, 1.0])
        axis = axis if np.linalg.norm(axis) > 1e-6 else np.cross(offset, [1.0, 0.0, 0.0])
        axis /= np.linalg.norm(axis)
        matrices = Rotation.from_rotvec(np.radians(angle)[:, None] * axis).as_matrix()
        turned[:, limb] = matrix_to_rot6d(matrices)
    conversation = SimpleNamespace(rotations=truth)
    expected = 2.0 + 0.1 * (np.arange(6) * 10 + (10 - 1 / FPS) / 2)  # each chunk's mean angle
    np.testing.assert_allclose(error_over_time([turned], [conversation]), expected, atol=1e-3)
    assert drift([[turned], [turned]], [conversation]) == pytest.approx(expected[-1] / expected[0])
