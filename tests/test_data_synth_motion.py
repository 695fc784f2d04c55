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
from data_synth.events import Stroke
from data_synth.gestures import (
    HOME_DWELL_S,
    REST_WRIST,
    SETTLE_S,
    gesture_centre,
    home_wrist,
    rest_wrist,
)
from data_synth.motion import ELBOW_POLE_RAISED, ELBOW_POLE_REST, elbow_pole
from data_synth.style import Style
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
ELBOWS = list(JOINT_GROUPS["elbows"])


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(60.0, seed=3)


@pytest.fixture(scope="module")
def short():
    return generate_conversation(20.0, seed=7)


def frame_times(conversation) -> np.ndarray:
    return (np.arange(conversation.num_frames) + 0.5) / conversation.fps


def gesturing(conversation, hand: str) -> np.ndarray:
    """``(T,)`` True in the frames of the agent's phrases whose gestures use ``hand``."""
    times, inside = frame_times(conversation), np.zeros(conversation.num_frames, dtype=bool)
    for phrase in conversation.events.gesture_phrases:
        if phrase.hands in (hand, "both"):
            inside |= (times >= phrase.phrase_start) & (times < phrase.phrase_end)
    return inside


def stroke_travel(conversation) -> list[tuple[Stroke, str, np.ndarray]]:
    """``(stroke, hand, displacement (3,) in cm)`` of each hand's wrist over each beat stroke."""
    positions, times = conversation.positions.astype(np.float64), frame_times(conversation)
    half = conversation.config.motion.stroke_duration_s / conversation.style.speed / 2
    travel = []
    for stroke in conversation.events.strokes:
        first, last = np.searchsorted(times, [stroke.time - half, stroke.time + half])
        last = min(last, conversation.num_frames - 1)
        for hand in ("left", "right") if stroke.hands == "both" else (stroke.hands,):
            wrist = positions[:, JOINT_INDEX[f"{hand}_wrist"]]
            travel.append((stroke, hand, wrist[last] - wrist[first]))
    return travel


def pinned_style(**values) -> ConversationConfig:
    """A configuration whose every conversation has exactly this style."""
    return ConversationConfig(style=StyleRanges(**{k: (v, v) for k, v in values.items()}))


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
    peaks = [speeds[max(r - 1, 0) : r + 2, WRISTS].max() for r in stroke_rows]
    assert 40.0 < np.median(peaks) < 200.0
    listening = split_by_activity(speeds[:, WRISTS], conversation.activity)[Activity.B_SPEAKS]
    assert 0.3 < np.median(listening) < 5.0


def test_elbows_bend_the_natural_way(conversation):
    positions = conversation.positions.astype(np.float64)
    for side, hand in ((1.0, "left"), (-1.0, "right")):
        shoulder, elbow, wrist = (
            positions[:, JOINT_INDEX[f"{hand}_{j}"]] for j in ("shoulder", "elbow", "wrist")
        )
        assert np.all(elbow[:, 1] < shoulder[:, 1])  # never raised above the shoulder
        line = (wrist - shoulder) / np.linalg.norm(wrist - shoulder, axis=1, keepdims=True)
        bend = (elbow - shoulder) - np.sum((elbow - shoulder) * line, axis=1)[:, None] * line
        assert np.all(bend[:, 1] < 0)  # the elbow points down ...
        assert np.all(side * bend[:, 0] > 0)  # ... and outwards, never across the body
        upper, fore = shoulder - elbow, wrist - elbow
        inner = np.degrees(
            np.arccos(
                np.sum(upper * fore, axis=1)
                / np.linalg.norm(upper, axis=1)
                / np.linalg.norm(fore, axis=1)
            )
        )
        assert inner.min() > 30 and inner.max() < 175  # neither folded flat nor locked straight
        assert np.all(wrist[:, 2] > 10)  # the hands stay in front of the body


def test_style_is_drawn_within_its_ranges(conversation):
    ranges = StyleRanges()
    for field in dataclasses.fields(ranges):
        low, high = getattr(ranges, field.name)
        assert low <= getattr(conversation.style, field.name) <= high


def test_style_shows_in_the_motion():
    calm = pinned_style(
        gesture_radius_cm=6.0,
        hand_height_cm=2.0,
        speed=0.8,
        symmetry=0.0,
        handedness=1.0,
        beat_amplitude_cm=7.0,
    )
    lively = pinned_style(
        gesture_radius_cm=16.0,
        hand_height_cm=8.0,
        speed=1.25,
        symmetry=1.0,
        handedness=1.0,
        beat_amplitude_cm=13.0,
    )
    measured = {}
    for name, config in (("calm", calm), ("lively", lively)):
        conv = generate_conversation(30.0, seed=2, config=config)
        speaking = conv.activity == Activity.A_SPEAKS
        wrist_speed = split_by_activity(speed(conv.positions, conv.fps)[:, WRISTS], conv.activity)[
            Activity.A_SPEAKS
        ]
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


# --------------------------------------------------------------------------- where the hands go


def test_places_of_the_hands_are_ordered_from_lap_to_chest():
    style = Style(
        gesture_radius_cm=12.0,
        hand_height_cm=16.0,
        speed=1.0,
        symmetry=0.5,
        handedness=0.5,
        beat_amplitude_cm=15.0,
    )
    rest, home, centre = rest_wrist("left"), home_wrist("left", style), gesture_centre(style)
    assert rest[1] < home[1] < centre[1] == pytest.approx(REST_WRIST[1] + 16.0)
    assert centre[1] < 50.0  # below the sternum
    for hand, side in (("left", 1.0), ("right", -1.0)):  # mirror images, on their own side
        assert side * rest_wrist(hand)[0] > 0 and side * home_wrist(hand, style)[0] > 0
        np.testing.assert_allclose(home_wrist(hand, style) * [side, 1, 1], home)


def test_elbow_pole_turns_from_hanging_to_lifted_as_the_hand_rises():
    n = 200
    shoulder = np.tile([18.0, 50.0, 0.0], (n, 1))
    low = np.tile([11.0, REST_WRIST[1], 28.0], (n, 1))  # inside the shoulder: no extra outward
    high = low + [0.0, 30.0, 4.0]
    np.testing.assert_allclose(elbow_pole(shoulder, low, 1.0, 25), np.tile(ELBOW_POLE_REST, (n, 1)))
    np.testing.assert_allclose(
        elbow_pole(shoulder, high, 1.0, 25), np.tile(ELBOW_POLE_RAISED, (n, 1))
    )
    mirrored = elbow_pole(shoulder * [-1, 1, 1], high * [-1, 1, 1], -1.0, 25)
    np.testing.assert_allclose(mirrored, np.tile(ELBOW_POLE_RAISED * [-1, 1, 1], (n, 1)))
    # A hand out beyond the shoulder takes the elbow further out.
    wide = high + [20.0, 0.0, 0.0]
    assert np.all(elbow_pole(shoulder, wide, 1.0, 25)[:, 0] > ELBOW_POLE_RAISED[0])


def test_hands_rise_into_a_gesture_space_in_front_of_the_chest(conversation):
    positions = conversation.positions.astype(np.float64)
    listening = conversation.activity == Activity.B_SPEAKS
    joints = {part: {} for part in ("wrist", "elbow", "upper_arm_tilt")}
    for hand in ("left", "right"):
        wrist, elbow, shoulder = (
            positions[:, JOINT_INDEX[f"{hand}_{j}"]] for j in ("wrist", "elbow", "shoulder")
        )
        upper_arm = elbow - shoulder
        tilt = np.degrees(np.arccos(-upper_arm[:, 1] / np.linalg.norm(upper_arm, axis=1)))
        for mode, frames in (("up", gesturing(conversation, hand)), ("listening", listening)):
            for part, values in (("wrist", wrist), ("elbow", elbow), ("upper_arm_tilt", tilt)):
                joints[part].setdefault(mode, []).append(values[frames])
    wrist, elbow, tilt = (
        {mode: np.concatenate(v) for mode, v in joints[part].items()}
        for part in ("wrist", "elbow", "upper_arm_tilt")
    )
    assert len(wrist["up"]) > 10 * conversation.fps  # seconds of gesturing, not moments
    height, depth = np.median(wrist["up"][:, 1]), np.median(wrist["up"][:, 2])
    assert 25.0 < height < 40.0 and 20.0 < depth < 35.0  # cm; the sternum is 50 cm up
    assert np.percentile(wrist["up"][:, 1], 25) > REST_WRIST[1] + 8.0  # up, not in the lap
    assert height > np.median(wrist["listening"][:, 1]) + 2.0
    # The upper arm lifts too: the elbow comes forwards and out, away from the body.
    elbow_out = {mode: np.median(np.abs(elbow[mode][:, 0])) for mode in elbow}
    assert elbow_out["up"] > max(20.0, elbow_out["listening"] + 1.5)  # shoulders at x = +-18
    assert np.median(elbow["up"][:, 2]) > 7.0  # cm in front of the shoulders
    assert np.median(tilt["up"]) > max(18.0, np.median(tilt["listening"]) + 1.5)  # degrees


def test_listening_hands_wait_low_with_the_elbows_under_the_shoulders(conversation):
    positions = conversation.positions.astype(np.float64)
    listening = conversation.activity == Activity.B_SPEAKS
    assert np.median(positions[listening][:, WRISTS, 1]) < 32.0  # belly or lap, below the chest
    elbow_x = np.abs(positions[listening][:, ELBOWS, 0])  # the shoulders are at x = +-18
    assert 16.0 < np.median(elbow_x) < 21.0


def test_hands_sink_into_the_lap_only_when_the_agent_is_silent_for_long():
    config = ConversationConfig(
        turns=TurnConfig(long_silence_probability=0.6, long_silence_s=(7.0, 9.0))
    )
    conv = generate_conversation(40.0, seed=6, config=config)
    positions, times = conv.positions.astype(np.float64), frame_times(conv)
    in_lap = np.all(positions[:, WRISTS, 1] < REST_WRIST[1] + 3.0, axis=1)  # both hands
    phrases = conv.events.phrases_of("A")
    long_gaps = 0
    settled_after = 1.0 + HOME_DWELL_S + SETTLE_S  # s: retract (< 1 s), wait at home, settle
    for before, after in zip(phrases, phrases[1:], strict=False):
        if after.start - before.end > settled_after + 2.0:
            long_gaps += 1  # in the lap until it is time to prepare (< 1 s) the next phrase
            assert np.all(in_lap[(times > before.end + settled_after) & (times < after.start - 1)])
    assert long_gaps >= 1
    # ... and never soon after the agent spoke: both hands reach the lap only after they have
    # waited at home.
    last_end = np.array([max([p.end for p in phrases if p.end <= t], default=0.0) for t in times])
    assert np.all(times[in_lap] - last_end[in_lap] > HOME_DWELL_S)


def test_beats_travel_their_amplitude_at_a_speakers_speed(conversation):
    emphasis = {accent.time: accent.emphasis for accent in conversation.events.accents_of("A")}
    rule = np.array(
        [
            stroke.amplitude_cm
            / (conversation.style.beat_amplitude_cm * emphasis[stroke.accent_time])
            for stroke in conversation.events.strokes
        ]
    )
    assert np.all((rule > 0.9 - 1e-9) & (rule < 1.1 + 1e-9))  # amplitude from emphasis, +-10 %
    travel = stroke_travel(conversation)
    distance = np.array([np.linalg.norm(d) for _, _, d in travel])
    ratio = distance / np.array([stroke.amplitude_cm for stroke, _, _ in travel])
    assert 0.85 < np.median(ratio) < 1.15 and np.percentile(ratio, 10) > 0.75
    assert np.median(distance) > 8.0  # cm: beats a viewer can see
    assert np.mean([d[1] < 0 for _, _, d in travel]) > 0.9  # strokes go down
    # The wrist speed peaks as a minimum-jerk stroke does, at 1.875 x amplitude / duration
    # (a little less, measured between frames), like a real speaker's beats: 60-200 cm/s.
    fps = conversation.fps
    speeds = speed(conversation.positions.astype(np.float64), fps)  # row r: frames r to r + 1
    duration = conversation.config.motion.stroke_duration_s / conversation.style.speed
    peaks = np.array(
        [
            speeds[
                max(round(stroke.time * fps) - 2, 0) : round(stroke.time * fps) + 1,
                JOINT_INDEX[f"{hand}_wrist"],
            ].max()
            for stroke, hand, _ in travel
        ]
    )
    predicted = np.array([1.875 * stroke.amplitude_cm / duration for stroke, _, _ in travel])
    assert 0.85 < np.median(peaks / predicted) < 1.05
    assert 60.0 < np.median(peaks) < 200.0 and peaks.max() < 250.0  # cm/s


def test_stroke_forms_and_the_gesturing_hand_follow_the_style():
    compact = pinned_style(
        gesture_radius_cm=0.0,
        hand_height_cm=15.0,
        speed=1.0,
        symmetry=0.0,
        handedness=1.0,
        beat_amplitude_cm=15.0,
    )
    expansive = pinned_style(
        gesture_radius_cm=25.0,
        hand_height_cm=15.0,
        speed=1.0,
        symmetry=1.0,
        handedness=1.0,
        beat_amplitude_cm=15.0,
    )
    outward_share = {}
    for name, config in (("compact", compact), ("expansive", expansive)):
        conv = generate_conversation(30.0, seed=5, config=config)
        travel = stroke_travel(conv)
        # An outward sweep moves the wrist away from the midline by at least 40 % of its travel.
        outward_share[name] = np.mean(
            [(d[0] if hand == "left" else -d[0]) > 0.4 * np.linalg.norm(d) for _, hand, d in travel]
        )
        if name == "compact":  # right-handed, one hand at a time: the left one stays low
            positions = conv.positions.astype(np.float64)
            assert {p.hands for p in conv.events.gesture_phrases} == {"right"}
            left = positions[:, JOINT_INDEX["left_wrist"], 1]
            right = positions[gesturing(conv, "right"), JOINT_INDEX["right_wrist"], 1]
            assert left.max() < home_wrist("left", conv.style)[1] + 3.0  # never above home
            assert np.median(right) > left.max() + 2.0
    assert outward_share["compact"] < 0.05 < 0.2 < outward_share["expansive"]


# --------------------------------------------------------------------------- the rules


def test_listening_is_less_active_than_speaking(conversation):
    positions, fps = conversation.positions.astype(np.float64), conversation.fps
    wrist_speed = split_by_activity(speed(positions, fps)[:, WRISTS], conversation.activity)
    distance = split_by_activity(distance_from_mean_pose(positions), conversation.activity)
    speaking, listening = Activity.A_SPEAKS, Activity.B_SPEAKS
    assert wrist_speed[listening].mean() < 0.5 * wrist_speed[speaking].mean()
    assert distance[listening][:, WRISTS].mean() < 0.85 * distance[speaking][:, WRISTS].mean()
    assert distance[listening].mean() < distance[speaking].mean()  # over all joints too


def test_listening_is_calmer_and_closer_to_the_mean_pose_across_conversations():
    # Pooled over several conversations (each measured from its own mean pose), so that one
    # conversation with little listening cannot decide the outcome.
    speeds, distances = {}, {}
    for seed in (40, 41, 42, 43):
        conv = generate_conversation(30.0, seed=seed)
        positions = conv.positions.astype(np.float64)
        for mode, code in (("speaking", Activity.A_SPEAKS), ("listening", Activity.B_SPEAKS)):
            speeds.setdefault(mode, []).append(
                split_by_activity(speed(positions, conv.fps)[:, WRISTS], conv.activity)[code]
            )
            distances.setdefault(mode, []).append(
                split_by_activity(distance_from_mean_pose(positions), conv.activity)[code]
            )
    wrist_speed = {mode: np.concatenate(v).mean() for mode, v in speeds.items()}
    distance = {mode: np.concatenate(v) for mode, v in distances.items()}
    assert wrist_speed["listening"] < 0.5 * wrist_speed["speaking"]
    for joints, share in ((WRISTS, 0.8), (ELBOWS, 0.85), (slice(None), 0.9)):
        listening, speaking = distance["listening"][:, joints], distance["speaking"][:, joints]
        assert listening.mean() < share * speaking.mean()


@pytest.mark.parametrize("lead_s", [0.12, 0.32])
def test_wrist_speed_leads_the_audio_emphasis_by_the_configured_time(lead_s):
    config = ConversationConfig(motion=MotionConfig(stroke_lead_s=lead_s))
    conv = generate_conversation(40.0, seed=21, config=config)
    measured = measure_stroke_lead(
        conv.audio, conv.sample_rate, conv.activity, conv.positions, conv.fps
    )
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
        motion=MotionConfig(listening_nod_probability=1.0),
    )
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
