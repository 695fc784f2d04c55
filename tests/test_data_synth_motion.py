"""Tests of the agent's motion: determinism, plausibility and the rules, measured from the data."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from data_synth import (
    ConversationConfig,
    MotionConfig,
    StyleRanges,
    TurnConfig,
    generate_conversation,
    measure_stroke_lead,
    resample_motion,
)
from gesturelib.conventions import Activity
from gesturelib.metrics import (
    JOINT_GROUPS,
    acceleration,
    distance_from_mean_pose,
    speed,
    split_by_activity,
)
from gesturelib.skeleton import BONE_LENGTHS, JOINT_INDEX, bone_lengths, forward_kinematics

WRISTS = list(JOINT_GROUPS["wrists"])


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(60.0, seed=3)


@pytest.fixture(scope="module")
def short():
    return generate_conversation(20.0, seed=7)


def frame_times(conversation) -> np.ndarray:
    return (np.arange(conversation.num_frames) + 0.5) / conversation.fps


# --------------------------------------------------------------------------- seeds


def test_same_seeds_give_identical_conversations(short):
    again = generate_conversation(20.0, seed=7)
    for name in ("audio", "activity", "rotations", "positions"):
        np.testing.assert_array_equal(getattr(again, name), getattr(short, name))
    assert again.events == short.events and again.style == short.style


def test_another_motion_seed_changes_the_motion_but_not_the_conversation(short):
    redrawn = resample_motion(short, 99)
    assert redrawn.motion_seed == 99 and short.motion_seed == 7  # the input is untouched
    np.testing.assert_array_equal(redrawn.audio, short.audio)
    np.testing.assert_array_equal(redrawn.activity, short.activity)
    assert redrawn.style == short.style
    for kind in ("phrases", "syllables", "accents"):
        assert getattr(redrawn.events, kind) == getattr(short.events, kind)
    difference = np.linalg.norm(redrawn.positions - short.positions, axis=-1)
    assert difference[:, WRISTS].mean() > 1.0  # cm: a different motion
    # The same as asking for that motion seed at generation time.
    direct = generate_conversation(20.0, seed=7, motion_seed=99)
    np.testing.assert_array_equal(direct.positions, redrawn.positions)
    np.testing.assert_array_equal(direct.audio, short.audio)


def test_another_conversation_seed_changes_everything(short):
    other = generate_conversation(20.0, seed=8)
    assert not np.array_equal(other.audio, short.audio)
    assert other.style != short.style


# --------------------------------------------------------------------------- plausibility


def test_positions_are_the_forward_kinematics_of_the_rotations(conversation):
    assert conversation.rotations.dtype == np.float32
    assert conversation.positions.dtype == np.float32
    assert np.all(np.isfinite(conversation.rotations))
    recomputed = forward_kinematics(conversation.rotations.astype(np.float64))
    np.testing.assert_allclose(recomputed, conversation.positions, atol=1e-4)
    lengths = bone_lengths(conversation.positions.astype(np.float64))
    np.testing.assert_allclose(lengths, np.broadcast_to(BONE_LENGTHS, lengths.shape), atol=1e-3)


def test_motion_is_smooth_and_as_fast_as_a_real_speaker(conversation):
    positions, fps = conversation.positions.astype(np.float64), conversation.fps
    speeds = speed(positions, fps)
    assert speeds.max() < 250.0  # cm/s: no joint moves faster than a fast human hand
    assert np.abs(np.diff(positions, axis=0)).max() < 8.0  # cm per frame: no jumps
    assert acceleration(positions, fps).max() < 5000.0  # cm/s^2
    # Beat strokes peak at 40-200 cm/s; at rest the wrists drift at a few cm/s.
    stroke_rows = [round(s.time * fps - 1) for s in conversation.events.strokes]
    peaks = [speeds[max(r - 1, 0): r + 2, WRISTS].max() for r in stroke_rows]
    assert 40.0 < np.median(peaks) < 200.0
    listening = split_by_activity(speeds[:, WRISTS], conversation.activity)[Activity.B_SPEAKS]
    assert 0.3 < np.median(listening) < 5.0


def test_elbows_bend_the_natural_way(conversation):
    positions = conversation.positions.astype(np.float64)
    for side, hand in ((1.0, "left"), (-1.0, "right")):
        shoulder, elbow, wrist = (positions[:, JOINT_INDEX[f"{hand}_{j}"]]
                                  for j in ("shoulder", "elbow", "wrist"))
        assert np.all(elbow[:, 1] < shoulder[:, 1])  # never raised above the shoulder
        line = (wrist - shoulder) / np.linalg.norm(wrist - shoulder, axis=1, keepdims=True)
        bend = (elbow - shoulder) - np.sum((elbow - shoulder) * line, axis=1)[:, None] * line
        assert np.all(bend[:, 1] < 0)  # the elbow points down ...
        assert np.all(side * bend[:, 0] > 0)  # ... and outwards, never across the body
        upper, fore = shoulder - elbow, wrist - elbow
        inner = np.degrees(np.arccos(np.sum(upper * fore, axis=1)
                                     / np.linalg.norm(upper, axis=1)
                                     / np.linalg.norm(fore, axis=1)))
        assert inner.min() > 30 and inner.max() < 175  # neither folded flat nor locked straight
        assert np.all(wrist[:, 2] > 10)  # the hands stay in front of the body


def test_style_is_drawn_within_its_ranges(conversation):
    ranges = StyleRanges()
    for field in dataclasses.fields(ranges):
        low, high = getattr(ranges, field.name)
        assert low <= getattr(conversation.style, field.name) <= high


def test_style_shows_in_the_motion():
    def pinned(**values):
        return ConversationConfig(style=StyleRanges(**{k: (v, v) for k, v in values.items()}))

    calm = pinned(gesture_radius_cm=6.0, hand_height_cm=2.0, speed=0.8, symmetry=0.0,
                  handedness=1.0, beat_amplitude_cm=7.0)
    lively = pinned(gesture_radius_cm=16.0, hand_height_cm=8.0, speed=1.25, symmetry=1.0,
                    handedness=1.0, beat_amplitude_cm=13.0)
    measured = {}
    for name, config in (("calm", calm), ("lively", lively)):
        conv = generate_conversation(30.0, seed=2, config=config)
        speaking = conv.activity == Activity.A_SPEAKS
        wrist_speed = split_by_activity(speed(conv.positions, conv.fps)[:, WRISTS],
                                        conv.activity)[Activity.A_SPEAKS]
        measured[name] = {
            "height": conv.positions[speaking, JOINT_INDEX["right_wrist"], 1].mean(),
            "fast": np.percentile(wrist_speed, 95),
            "symmetry": np.corrcoef(wrist_speed.T)[0, 1],
            "both_hands": np.mean([p.hands == "both" for p in conv.events.gesture_phrases]),
        }
    assert measured["lively"]["height"] > measured["calm"]["height"] + 2.0  # cm
    assert measured["lively"]["fast"] > 2 * measured["calm"]["fast"]
    assert measured["lively"]["symmetry"] > 0.9 > 0.3 > measured["calm"]["symmetry"]
    assert measured["lively"]["both_hands"] == 1.0 and measured["calm"]["both_hands"] == 0.0


# --------------------------------------------------------------------------- the rules


def test_listening_is_less_active_than_speaking(conversation):
    positions, fps = conversation.positions.astype(np.float64), conversation.fps
    wrist_speed = split_by_activity(speed(positions, fps)[:, WRISTS], conversation.activity)
    distance = split_by_activity(distance_from_mean_pose(positions), conversation.activity)
    speaking, listening = Activity.A_SPEAKS, Activity.B_SPEAKS
    assert wrist_speed[listening].mean() < 0.5 * wrist_speed[speaking].mean()
    assert distance[listening][:, WRISTS].mean() < 0.85 * distance[speaking][:, WRISTS].mean()
    assert distance[listening].mean() < distance[speaking].mean()  # over all joints too


@pytest.mark.parametrize("lead_s", [0.12, 0.32])
def test_wrist_speed_leads_the_audio_emphasis_by_the_configured_time(lead_s):
    config = ConversationConfig(motion=MotionConfig(stroke_lead_s=lead_s))
    conv = generate_conversation(40.0, seed=21, config=config)
    measured = measure_stroke_lead(conv.audio, conv.sample_rate, conv.activity, conv.positions,
                                   conv.fps)
    assert measured == pytest.approx(lead_s, abs=1.0 / conv.fps)


def test_every_accent_of_the_agent_gets_a_beat(conversation):
    accents = conversation.events.accents_of("A")
    phrases = conversation.events.phrases_of("A")
    in_phrases = [a for a in accents if any(p.start <= a.time < p.end for p in phrases)]
    strokes = conversation.events.strokes
    assert len(strokes) >= 0.9 * len(in_phrases) > 20
    leads = np.array([s.accent_time - s.time for s in strokes])
    assert np.mean(leads) == pytest.approx(MotionConfig().stroke_lead_s, abs=0.01)


def test_the_agent_nods_after_the_partners_phrases_while_listening():
    # A talkative partner gives many phrase ends to answer; every one is answered with a nod.
    config = ConversationConfig(
        turns=TurnConfig(b_phrases_per_turn=3.0, a_phrases_per_turn=1.5),
        motion=MotionConfig(listening_nod_probability=1.0))
    conv = generate_conversation(50.0, seed=4, config=config)
    positions, fps, times = conv.positions.astype(np.float64), conv.fps, frame_times(conv)
    head_to_nose = positions[:, JOINT_INDEX["nose"]] - positions[:, JOINT_INDEX["head"]]
    pitch = np.degrees(np.arctan2(-head_to_nose[:, 1], head_to_nose[:, 2]))  # + looking down
    pitch_speed = np.abs(np.diff(pitch)) * fps  # row t between frames t and t + 1

    def peak_pitch_speed(start, end):
        rows = np.flatnonzero((times[:-1] >= start) & (times[:-1] < end))
        return pitch_speed[rows].max()

    agent = conv.events.phrases_of("A")
    after, before = [], []
    for phrase in conv.events.phrases_of("B"):
        end = phrase.end
        listening = not any(u.start < end + 1.0 and u.end > end - 0.8 for u in agent)
        if listening and end + 1.0 < conv.duration_s:
            after.append(peak_pitch_speed(end, end + 1.0))
            before.append(peak_pitch_speed(end - 0.8, end))
    assert len(after) >= 8
    nodding = 15.0  # deg/s: a nod of 4-9 degrees over 0.45 s peaks at 30-60 deg/s
    assert np.mean(np.array(after) > nodding) > 0.8
    assert np.mean(np.array(before) > nodding) < 0.3
