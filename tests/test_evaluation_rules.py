"""gesturelib.evaluation.rules: events detected in motion, checked against the generator's rules,
on signals whose answer is known by construction."""

from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from data_synth.config import MotionConfig
from data_synth.events import Accent, Events, Phrase
from gesturelib.evaluation.figures import plot_head_drops
from gesturelib.evaluation.rules import (
    BEAT_SIGMA_S,
    accent_leads,
    answered_phrase_ends,
    beat_alignment_score,
    head_drops_after_phrase_ends,
    head_pitch,
    kinematic_beats,
    nod_times,
    on_rule_nods,
    on_rule_strokes,
    partner_nods,
    rule_measures,
    stroke_times,
)
from gesturelib.skeleton import JOINT_INDEX, T_POSE_OFFSETS, forward_kinematics

FPS = 25


def still_pose(frames: int) -> np.ndarray:
    """The T-pose's keypoints, ``(frames, 9, 3)``."""
    rotations = np.tile(np.array([1.0, 0, 0, 0, 1, 0]), (frames, 9, 1))
    return forward_kinematics(rotations).astype(np.float64)


def with_strokes(times: list[float], frames: int, travel: float = 20.0) -> np.ndarray:
    """Still keypoints whose right wrist makes a smooth step of ``travel`` cm down at each time:
    the speed between frames t - 1 and t (time t / fps) peaks there."""
    positions = still_pose(frames)
    edges = np.arange(frames) + 0.5  # frame t is sampled at (t + 0.5) / fps
    for time in times:
        positions[:, JOINT_INDEX["right_wrist"], 1] -= travel / (
            1 + np.exp(-(edges - time * FPS) / 1.2)
        )
    return positions


def with_nods(times: list[float], frames: int, degrees: float = 8.0) -> np.ndarray:
    """Still keypoints whose nose pitches down and back (a cosine cycle of 0.45 s) so that its
    downward speed peaks at each time."""
    positions = still_pose(frames)
    cycle = 0.45
    pitch = np.zeros(frames)
    centres = (np.arange(frames) + 0.5) / FPS
    for time in times:
        tau = centres - (time - cycle / 4) + 0.5 / FPS
        inside = (tau >= 0) & (tau <= cycle)
        pitch[inside] += np.radians(degrees) * (1 - np.cos(2 * np.pi * tau[inside] / cycle)) / 2
    nose = T_POSE_OFFSETS[JOINT_INDEX["nose"]]
    length, rest = np.hypot(nose[1], nose[2]), np.arctan2(-nose[1], nose[2])
    head = positions[:, JOINT_INDEX["head"]]
    positions[:, JOINT_INDEX["nose"], 1] = head[:, 1] - length * np.sin(rest + pitch)
    positions[:, JOINT_INDEX["nose"], 2] = head[:, 2] + length * np.cos(rest + pitch)
    return positions


def fake_conversation(accents=(), partner_ends=(), agent_phrases=(), frames=250):
    """The parts of a conversation the rules read: events, motion config, style speed, fps."""
    phrases = [Phrase("B", end - 1.0, end) for end in partner_ends]
    phrases += [Phrase("A", start, end) for start, end in agent_phrases]
    return SimpleNamespace(
        fps=FPS,
        config=SimpleNamespace(motion=MotionConfig()),
        style=SimpleNamespace(speed=1.0),
        events=Events(phrases=phrases, accents=[Accent("A", t, 0.8) for t in accents]),
        positions=still_pose(frames),
        audio=np.zeros(frames * 640, dtype=np.float32),  # silence: no onsets, no beats to align
        sample_rate=16000,
        activity=np.zeros(frames, dtype=np.int64),
    )


def test_strokes_and_nods_are_found_where_they_were_made():
    strokes = [1.0, 2.4, 3.12, 6.0]
    np.testing.assert_allclose(stroke_times(with_strokes(strokes, 200), FPS), strokes)
    assert stroke_times(still_pose(100), FPS).size == 0
    nods = [1.5, 4.0, 6.2]
    np.testing.assert_allclose(nod_times(with_nods(nods, 200), FPS), nods, atol=1.01 / FPS)
    assert nod_times(with_strokes(strokes, 200), FPS).size == 0  # hands move, the head does not
    pitch = head_pitch(with_nods([2.0], 100, degrees=8.0))
    assert np.degrees(pitch.max() - pitch[0]) == pytest.approx(8.0, abs=0.2)


def test_accent_leads_measure_each_accent_against_the_rule():
    accents = [2.0, 4.0, 6.0, 8.0]
    conversation = fake_conversation(accents)
    # Strokes 0.2 s before the first two accents (the rule), 0.32 s after the third, none near the
    # fourth: leads 0.2, 0.2, -0.32 and none.
    positions = with_strokes([1.8, 3.8, 6.32], 250)
    leads = accent_leads(conversation, positions)
    np.testing.assert_allclose(leads[:3], [0.2, 0.2, -0.32], atol=1e-9)
    assert np.isnan(leads[3])
    conversation.positions = positions
    scores = rule_measures([conversation], [positions])
    assert scores["accent_hits"] == pytest.approx(0.5)
    np.testing.assert_array_equal(on_rule_strokes(conversation, positions), [True, True, False])
    assert scores["stroke_precision"] == pytest.approx(2 / 3)
    assert scores["lead_error"] == pytest.approx(0.0, abs=1e-9)  # median of 0, 0, 0.52
    assert np.isnan(scores["nods"]) and np.isnan(scores["beat_align"])  # nothing to answer


def test_listening_nods_count_only_in_the_rules_window():
    config = MotionConfig()
    quarter = config.nod_duration_s / 4
    ends = [2.0, 5.0, 8.0]
    # The agent speaks right after the third end: no nod is due there.
    conversation = fake_conversation(partner_ends=ends, agent_phrases=[(8.2, 9.0)])
    np.testing.assert_allclose(answered_phrase_ends(conversation), [2.0, 5.0])
    on_time = 2.0 + config.nod_delay_s[0] + quarter + 0.05
    late = 5.0 + config.nod_delay_s[1] + quarter + 0.5
    answered = partner_nods(conversation, with_nods([on_time, late], 250))
    np.testing.assert_array_equal(answered, [True, False])
    assert not partner_nods(conversation, still_pose(250)).any()
    # The nod on time is in a rule's window, the late one in none (no accents, no "mm-hm").
    np.testing.assert_array_equal(
        on_rule_nods(conversation, with_nods([on_time, late], 250)), [True, False]
    )


def test_head_drops_are_the_downward_pitch_speed_after_each_answered_phrase_end():
    ends = [2.0, 5.0, 8.0, 9.8]  # the agent answers the third; the fourth's window runs past
    conversation = fake_conversation(partner_ends=ends, agent_phrases=[(8.2, 9.0)])
    motion = with_nods([2.3], 250)
    pitch = np.degrees(head_pitch(motion))
    drops = head_drops_after_phrase_ends(conversation, motion[1:], motion[:-1], first=1)
    assert drops.shape == (2, 15)  # the ends at 2 and 5 s, 0.6 s (15 frames) each
    np.testing.assert_allclose(drops[0], np.diff(pitch)[49:64] * FPS)  # frames 50 to 64
    np.testing.assert_allclose(drops[1], 0.0, atol=1e-9)  # no nod after the second end
    assert drops[0].argmax() == round(2.3 * FPS) - 50 and drops[0].max() > 50
    # Drawn frames move from the frames given as `previous`, and `first` places them in time:
    # the same frames, starting later, leave out the first end.
    shifted = head_drops_after_phrase_ends(conversation, motion[60:], motion[59:-1], first=60)
    np.testing.assert_allclose(shifted, drops[1:])
    with pytest.raises(ValueError, match="one previous frame per frame"):
        head_drops_after_phrase_ends(conversation, motion[1:], motion, first=1)
    figure = plot_head_drops({"nodding": drops[0], "still": drops[1]})
    lines = figure.axes[0].get_lines()
    assert [line.get_label() for line in lines] == ["nodding", "still"]
    np.testing.assert_allclose(lines[0].get_xdata(), np.arange(15) * 40.0)  # ms after the end
    np.testing.assert_allclose(lines[0].get_ydata(), drops[0])
    plt.close(figure)


def test_beat_alignment_follows_bailandos_formula():
    beats = np.array([1.0, 2.0, 3.5])
    assert beat_alignment_score(beats, beats) == pytest.approx(1.0)
    assert beat_alignment_score(beats, beats + BEAT_SIGMA_S) == pytest.approx(np.exp(-0.5))
    assert beat_alignment_score(beats, np.array([])) == 0.0
    assert np.isnan(beat_alignment_score(np.array([]), beats))
    # Kinematic beats are where the joints stop: between two strokes the wrist rests.
    positions = with_strokes([1.0, 2.0], 100, travel=30.0)
    found = kinematic_beats(positions, FPS)
    assert np.any(np.abs(found - 1.5) <= 1 / FPS)
    assert not np.any(np.abs(found - 1.0) < 0.12)  # never on a stroke's peak


def test_the_references_rank_as_they_must_on_the_rules():
    """The floor keeps every rule; motion of another conversation breaks them; the mean pose
    makes no strokes and no nods."""
    from data_synth import generate_conversation, resample_motion

    conversations = [generate_conversation(40.0, seed=seed) for seed in (3, 8)]
    truth = rule_measures(conversations, [c.positions for c in conversations])
    floor = rule_measures(conversations, [resample_motion(c, 11).positions for c in conversations])
    mismatched = rule_measures(conversations, [c.positions for c in conversations[::-1]])
    mean_pose = rule_measures(
        conversations,
        [np.repeat(c.positions.mean(0)[None], len(c.positions), 0) for c in conversations],
    )
    assert truth["accent_hits"] > 0.9 and truth["lead_error"] < 0.04
    assert floor["accent_hits"] > 0.9 and floor["lead_error"] < 0.04
    assert mismatched["accent_hits"] < 0.5 and mismatched["lead_error"] > 0.06
    assert mean_pose["accent_hits"] == 0.0 and np.isnan(mean_pose["lead_error"])
    assert floor["nods"] > mismatched["nods"] and mean_pose["nods"] == 0.0
    assert floor["beat_align"] > mean_pose["beat_align"] == 0.0
    # Jitter strikes and nods everywhere: it hits accents by chance, but its precision gives it away.
    rng = np.random.default_rng(0)
    jitter = rule_measures(
        conversations,
        [c.positions.mean(0) + rng.normal(0, 0.5, c.positions.shape) for c in conversations],
    )
    assert jitter["stroke_precision"] < floor["stroke_precision"] / 2
    assert jitter["nod_precision"] < floor["nod_precision"] / 2
    events_unknown = [SimpleNamespace(**{**vars(c), "events": None}) for c in conversations]
    unknown = rule_measures(events_unknown, [c.positions for c in conversations])
    assert np.isnan(unknown["accent_hits"]) and np.isnan(unknown["nods"])
    assert unknown["beat_align"] == truth["beat_align"]  # the proxy needs no events
