"""The agent's hand gestures: where each wrist should be, as keyframes of minimum-jerk movements.

Three places for the hands (left hand, in cm in the body frame: spine base at the origin, y up,
facing +z, the sternum 50 cm up, the shoulders at x = +-18; the right hand is the mirror image):

* **Rest** (:data:`REST_WRIST`, 17 cm up): the hands lie in the lap, a seated listener's posture.
* **Home** (:func:`home_wrist`): in front of the belly, 70 % of the way up from rest to the
  gesture space, 32 cm in front of the spine. A speaker's hands wait here between turns and
  while the partner talks, ready to rise again. It lies close to the agent's *mean* pose, so a
  listener stays near the mean pose, as Taylor et al. observed of their speakers: the agent
  speaks most of the time, so the mean pose is close to the gesture space, not to the lap.
* **Gesture space** (:func:`gesture_centre`): in front of the chest, ``style.hand_height_cm``
  above rest, ``12 + 0.3 * style.gesture_radius_cm`` cm to the side, and forwards enough that the
  hand is at least :data:`MIN_REACH_CM` from the shoulder (a raised hand is held out in front,
  not folded against the chest). While the agent gestures, its wrists are 24-41 cm up and
  27-37 cm in front of the spine (5th-95th percentiles over many conversations).

Rules (parameters in :class:`data_synth.config.MotionConfig` and the conversation's
:class:`data_synth.style.Style`; durations marked * are divided by ``style.speed``):

* **Gesture phrases.** Every phrase of the agent (speaker A; not its backchannels) is a gesture
  phrase. It uses both hands, mirror-symmetrically, with probability ``style.symmetry``;
  otherwise one hand, the right one with probability ``style.handedness`` (the dominant hand).
  A phrase that follows the previous one within :data:`CATCHMENT_GAP_S` keeps its hands with
  probability :data:`CATCHMENT_PROBABILITY`, as speakers do over a run of related phrases.
* **Where.** Each phrase has its own centre, drawn within ``style.gesture_radius_cm`` x
  :data:`PHRASE_SPREAD` of the gesture space's centre; each beat is centred within
  ``style.gesture_radius_cm`` x :data:`BEAT_SPREAD` of the phrase's centre (70 % of the way from
  the previous beat's, so the hands drift rather than jump). Successive phrases are performed at
  different heights, widths and depths.
* **Preparation.** The hands rise into position in ``preparation_s`` *, arriving 50 ms before the
  phrase starts (or before its first beat, if that comes earlier). The upper arm lifts with them:
  the elbow swings outwards and forwards (:mod:`data_synth.motion`).
* **Beats.** Every accent of the phrase gets a beat: a stroke of ``style.beat_amplitude_cm *
  emphasis`` (+-10 %) through the beat's centre, lasting ``stroke_duration_s`` *; the hand then
  rises to the start of the next stroke. A phrase has one stroke form: *down* (a little forwards;
  the commonest), *outward* (a downward sweep away from the body: with both hands, they part) or
  *press* (palm down, forwards and down, towards the listener). Expansive speakers (a large
  ``style.gesture_radius_cm``) sweep outwards more often (:data:`OUTWARD_PER_RADIUS`). The stroke's
  wrist speed peaks in its middle, at ``accent time - stroke_lead_s`` (+ Gaussian jitter of
  ``stroke_timing_jitter_s``): the gesture *leads* the stressed syllable, as in real speech. A
  beat that cannot fit after the previous movement is left out (and absent from the event log).
* **After the last beat** the hand rebounds to that stroke's start in ``rebound_s`` * and holds
  until the phrase ends. Then it retracts home in ``retraction_s`` * if there is time to prepare
  again for the agent's next phrase; if there is not, it holds in the gesture space, unless the
  partner speaks in between: a listener's hands come down, so it retracts faster (down to 0.4 s).
* **Idle hand.** A hand that a phrase does not use drops into the lap while the other prepares;
  when the gesturing hands go home after the phrase, it joins them there.
* **Settling.** A hand that has waited at home for :data:`HOME_DWELL_S` after the agent's
  phrase and will not be needed for a while (a long turn of the partner, a long silence) sinks
  into the lap in :data:`SETTLE_S`. The conversation starts with the hands at home.

Every segment between keyframes is a minimum-jerk movement
(:func:`data_synth.kinematics.minimum_jerk_path`): hands start and stop smoothly, and a stroke of
``a`` cm in ``d`` s peaks at ``1.875 a / d`` cm/s (about 60-200 cm/s here, like a real speaker's
beats). No movement may peak above :data:`MAX_WRIST_SPEED`; one that would is slowed down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_synth.config import MotionConfig
from data_synth.events import Accent, GesturePhrase, Phrase, Stroke
from data_synth.style import Style
from gesturelib.skeleton import JOINT_INDEX, T_POSE_OFFSETS

HANDS = ("left", "right")
#: +1 for the left hand (the agent's left is +x), -1 for the right.
SIDE = {"left": 1.0, "right": -1.0}
#: The left hand's coordinates from the right hand's (and back): mirror x.
MIRROR = np.array([-1.0, 1.0, 1.0])
#: The left shoulder in the body frame (before breathing), cm.
SHOULDER = T_POSE_OFFSETS[JOINT_INDEX["sternum"]] + T_POSE_OFFSETS[JOINT_INDEX["left_shoulder"]]

# Where the hands go (left hand, cm, body frame).
#: Wrist at rest, in the lap.
REST_WRIST = np.array([11.0, 17.0, 28.0])
#: Home: this share of the way up from rest to the gesture space, at this x and z.
HOME_SHARE = 0.7
HOME_X_CM = 14.0
HOME_Z_CM = 32.0
#: The gesture space's centre: GESTURE_X_CM + GESTURE_X_PER_RADIUS x the style's gesture radius
#: from the midline, GESTURE_Z_CM in front of the spine (before the reach is enforced).
GESTURE_X_CM = 12.0
GESTURE_X_PER_RADIUS = 0.3
GESTURE_Z_CM = 27.0
#: How far a phrase's centre spreads around the gesture space's centre, and a beat's centre
#: around its phrase's centre (x, y, z), in units of the style's gesture radius.
PHRASE_SPREAD = np.array([0.8, 0.4, 0.4])
BEAT_SPREAD = np.array([0.4, 0.25, 0.2])
#: Bounds of a stroke: its start no higher than GESTURE_TOP_CM (the sternum is at 50), between
#: GESTURE_DEPTH_CM in front of the spine and at least MIN_REACH_CM from the shoulder; its end
#: at least STROKE_FLOOR_CM above rest (the hands do not hit the lap) and both ends at least
#: MIN_MIDLINE_CM from the body's midline.
GESTURE_TOP_CM = 41.0
GESTURE_DEPTH_CM = (22.0, 40.0)
MIN_REACH_CM = 32.0
STROKE_FLOOR_CM = 6.0
MIN_MIDLINE_CM = 4.0

# How the hands are used.
#: Stroke forms: the chance of an outward sweep grows by OUTWARD_PER_RADIUS per cm of the style's
#: gesture radius; palm-down presses have a fixed chance; the rest are down beats.
OUTWARD_PER_RADIUS = 0.02
PRESS_PROBABILITY = 0.2
#: A phrase that follows the agent's previous one within CATCHMENT_GAP_S keeps its hands with
#: this probability.
CATCHMENT_PROBABILITY = 0.6
CATCHMENT_GAP_S = 1.0

# When and how fast.
#: A hand waits at home HOME_DWELL_S before it may settle to rest, and settling takes SETTLE_S;
#: it settles only if it can then stay at rest for at least MIN_REST_S (s, not style-scaled).
HOME_DWELL_S = 4.0
SETTLE_S = 1.0
MIN_REST_S = 1.5
#: The smallest duration of a movement between two different keyframes.
MIN_SEGMENT_S = 0.05
#: Hand tracks start (at home) this early, before the audio.
TRACK_START_S = -10.0
#: No keyframe movement is faster than this (peak wrist speed, cm/s): a movement that would be is
#: slowed down. Real beat strokes peak at 50-200 cm/s.
MAX_WRIST_SPEED = 200.0
#: Peak speed of a minimum-jerk movement over distance d in time T is 1.875 d / T.
MINIMUM_JERK_PEAK = 1.875
#: The shortest preparation, when the previous movement ends late.
MIN_PREPARATION_S = 0.25
#: Hands arrive in the gesture space this long before the phrase (or its first beat).
READY_MARGIN_S = 0.05
#: The quickest retraction, when the partner speaks briefly between two phrases of the agent.
MIN_RETRACTION_S = 0.4


def rest_wrist(hand: str) -> np.ndarray:
    """The rest position ``(3,)`` of one wrist in the body frame, cm."""
    return REST_WRIST * np.array([SIDE[hand], 1.0, 1.0])


def gesture_centre(style: Style) -> np.ndarray:
    """The centre ``(3,)`` of the left hand's gesture space in the body frame, cm."""
    return np.array(
        [
            GESTURE_X_CM + GESTURE_X_PER_RADIUS * style.gesture_radius_cm,
            REST_WRIST[1] + style.hand_height_cm,
            GESTURE_Z_CM,
        ]
    )


def home_wrist(hand: str, style: Style) -> np.ndarray:
    """The home position ``(3,)`` of one wrist in the body frame, cm (see the module rules)."""
    centre = gesture_centre(style)
    home = np.array(
        [HOME_X_CM, REST_WRIST[1] + HOME_SHARE * (centre[1] - REST_WRIST[1]), HOME_Z_CM]
    )
    return home * np.array([SIDE[hand], 1.0, 1.0])


@dataclass
class GesturePlan:
    """Keyframes of both wrists and what was done.

    ``key_times[hand]`` ``(K,)`` seconds and ``key_points[hand]`` ``(K, 3)`` cm in the body frame
    (before the torso's sway), for ``hand`` in :data:`HANDS`.
    """

    key_times: dict[str, np.ndarray]
    key_points: dict[str, np.ndarray]
    strokes: list[Stroke]
    gesture_phrases: list[GesturePhrase]


class _HandTrack:
    """The keyframes of one wrist, appended in time order."""

    def __init__(self, hand: str, style: Style):
        self.rest = rest_wrist(hand)
        self.home = home_wrist(hand, style)
        self.times = [TRACK_START_S]
        self.points = [self.home]

    @property
    def last_time(self) -> float:
        return self.times[-1]

    @property
    def last_point(self) -> np.ndarray:
        return self.points[-1]

    def is_at(self, point: np.ndarray) -> bool:
        return bool(np.allclose(self.last_point, point))

    def hold_until(self, time: float) -> None:
        """Stay where the hand is until ``time``."""
        if time > self.last_time + 1e-6:
            self.times.append(time)
            self.points.append(self.last_point)

    def move(self, time: float, point: np.ndarray) -> None:
        """Arrive at ``point`` at ``time``, or later if the movement would be too short (under
        MIN_SEGMENT_S) or too fast (its peak speed above MAX_WRIST_SPEED)."""
        point = np.asarray(point, dtype=float)
        distance = float(np.linalg.norm(point - self.last_point))
        shortest = max(MIN_SEGMENT_S, MINIMUM_JERK_PEAK * distance / MAX_WRIST_SPEED)
        self.times.append(max(time, self.last_time + shortest))
        self.points.append(point)

    def go(self, point: np.ndarray, start: float, duration: float) -> None:
        """Move to ``point`` in ``duration``, starting no earlier than ``start``."""
        if not self.is_at(point):
            self.hold_until(start)
            self.move(self.last_time + duration, point)


@dataclass
class _Beat:
    time: float  # the wrist-speed peak
    accent: Accent
    start: np.ndarray  # where the stroke starts, right-hand coordinates (mirrored for the left)
    direction: np.ndarray
    amplitude_cm: float


@dataclass
class _PhrasePlan:
    phrase: Phrase
    hands: tuple[str, ...]
    centre: np.ndarray  # right-hand coordinates
    beats: list[_Beat]
    ready: float  # when the hands should be in the gesture space
    partner_speaks_after: bool  # B has a phrase between this phrase and the agent's next one

    @property
    def label(self) -> str:
        return "both" if len(self.hands) == 2 else self.hands[0]


def plan_gestures(
    utterances: list[Phrase],
    accents: list[Accent],
    style: Style,
    config: MotionConfig,
    rng: np.random.Generator,
) -> GesturePlan:
    """Plan the wrist keyframes of every gesture phrase of the agent (see the module rules).

    Args:
        utterances: every phrase and backchannel of both speakers.
        accents: the agent's accents (speaker A).
    """
    timing = _Timing(config, style)
    plans = _plan_phrases(utterances, accents, style, config, timing, rng)
    tracks = {hand: _HandTrack(hand, style) for hand in HANDS}
    first_ready = plans[0].ready if plans else np.inf
    for track in tracks.values():  # the hands wait at home when the conversation starts
        track.hold_until(min(0.0, first_ready - timing.preparation))
        _settle(track, 0.0, first_ready, timing)
    strokes: list[Stroke] = []
    gesture_phrases: list[GesturePhrase] = []
    for index, plan in enumerate(plans):
        next_ready = plans[index + 1].ready if index + 1 < len(plans) else np.inf
        for hand in [h for h in HANDS if h not in plan.hands]:  # the idle hand rests in the lap
            tracks[hand].go(tracks[hand].rest, plan.ready - timing.preparation, timing.retraction)
        performed: dict[int, tuple[float, list[str]]] = {}  # beat -> (peak time, hands)
        starts, ends = [], []
        for hand in plan.hands:
            start, done = _gesture_phrase(tracks[hand], plan, hand, next_ready, timing)
            for beat_index, peak_time in done:
                performed.setdefault(beat_index, (peak_time, []))[1].append(hand)
            starts.append(start)
            ends.append(tracks[hand].last_time)
        phrase = plan.phrase
        if all(tracks[hand].is_at(tracks[hand].home) for hand in plan.hands):
            for hand in HANDS:  # the idle hand joins the other at home
                tracks[hand].go(tracks[hand].home, phrase.end, timing.retraction)
        for track in tracks.values():
            _settle(track, phrase.end, next_ready, timing)
        gesture_phrases.append(
            GesturePhrase(
                float(min(starts)), float(max(ends)), plan.label, phrase.start, phrase.end
            )
        )
        for beat_index in sorted(performed):
            peak_time, hands = performed[beat_index]
            beat = plan.beats[beat_index]
            strokes.append(
                Stroke(
                    float(peak_time),
                    float(beat.accent.time),
                    "both" if len(hands) == 2 else hands[0],
                    float(beat.amplitude_cm),
                )
            )

    return GesturePlan(
        key_times={hand: np.array(tracks[hand].times) for hand in HANDS},
        key_points={hand: np.array(tracks[hand].points) for hand in HANDS},
        strokes=strokes,
        gesture_phrases=gesture_phrases,
    )


def _plan_phrases(
    utterances: list[Phrase],
    accents: list[Accent],
    style: Style,
    config: MotionConfig,
    timing: _Timing,
    rng: np.random.Generator,
) -> list[_PhrasePlan]:
    """Hands, centre and beats of each of the agent's phrases, in time order."""
    phrases = sorted(
        (u for u in utterances if u.speaker == "A" and u.kind == "phrase"), key=lambda u: u.start
    )
    partner = [u for u in utterances if u.speaker == "B" and u.kind == "phrase"]
    accent_times = np.array([a.time for a in accents])
    centre = gesture_centre(style) * MIRROR  # right-hand coordinates
    plans: list[_PhrasePlan] = []
    for index, phrase in enumerate(phrases):
        next_start = phrases[index + 1].start if index + 1 < len(phrases) else np.inf
        partner_speaks_after = any(phrase.end < u.end and u.start < next_start for u in partner)
        follows = bool(plans) and phrase.start - plans[-1].phrase.end < CATCHMENT_GAP_S
        if follows and rng.random() < CATCHMENT_PROBABILITY:
            hands = plans[-1].hands
        elif rng.random() < style.symmetry:
            hands = HANDS
        else:
            hands = ("right",) if rng.random() < style.handedness else ("left",)
        phrase_centre = _clear_of_midline(
            centre + style.gesture_radius_cm * PHRASE_SPREAD * rng.uniform(-1.0, 1.0, 3)
        )
        inside = np.flatnonzero((accent_times >= phrase.start) & (accent_times < phrase.end))
        beats = _draw_beats([accents[i] for i in inside], phrase_centre, style, config, rng)
        first_top = beats[0].time - timing.stroke / 2 if beats else phrase.start
        plans.append(
            _PhrasePlan(
                phrase,
                hands,
                phrase_centre,
                beats,
                min(phrase.start, first_top) - READY_MARGIN_S,
                partner_speaks_after,
            )
        )
    return plans


class _Timing:
    """Durations of the movements at the style's speed, seconds."""

    def __init__(self, config: MotionConfig, style: Style):
        self.stroke = config.stroke_duration_s / style.speed
        self.rebound = config.rebound_s / style.speed
        self.preparation = config.preparation_s / style.speed
        self.retraction = config.retraction_s / style.speed


def _clear_of_midline(point: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """``point`` (right-hand coordinates) moved out to MIN_MIDLINE_CM + margin from x = 0."""
    point = point.copy()
    point[0] = min(point[0], -MIN_MIDLINE_CM - margin)
    return point


def _within_reach(point: np.ndarray) -> np.ndarray:
    """``point`` (right-hand coordinates) pushed forwards to MIN_REACH_CM from the shoulder."""
    offset = point - SHOULDER * MIRROR
    lateral = offset[0] ** 2 + offset[1] ** 2
    if lateral + offset[2] ** 2 >= MIN_REACH_CM**2:
        return point
    return np.array([point[0], point[1], SHOULDER[2] + np.sqrt(MIN_REACH_CM**2 - lateral)])


def _stroke_form(style: Style, rng: np.random.Generator) -> str:
    """One phrase's stroke form: ``"outward"``, ``"press"`` or ``"down"`` (module rules)."""
    outward = min(OUTWARD_PER_RADIUS * style.gesture_radius_cm, 1.0 - PRESS_PROBABILITY)
    draw = rng.random()
    return (
        "outward" if draw < outward else "press" if draw < outward + PRESS_PROBABILITY else "down"
    )


def _stroke_direction(form: str, rng: np.random.Generator) -> np.ndarray:
    """Unit direction ``(3,)`` of one stroke in right-hand coordinates (outwards is -x)."""
    if form == "outward":
        direction = np.array([-rng.uniform(0.5, 0.8), -0.8, rng.uniform(0.0, 0.3)])
    elif form == "press":
        direction = np.array([-rng.uniform(-0.1, 0.2), -0.7, rng.uniform(0.6, 0.9)])
    else:
        direction = np.array([-rng.uniform(-0.1, 0.3), -1.0, rng.uniform(0.1, 0.5)])
    return direction / np.linalg.norm(direction)


def _draw_beats(
    accents: list[Accent],
    centre: np.ndarray,
    style: Style,
    config: MotionConfig,
    rng: np.random.Generator,
) -> list[_Beat]:
    """One beat per accent, in right-hand coordinates: timing, start, direction, amplitude.

    ``centre`` is the phrase's centre ``(3,)``. A stroke is centred on its beat's centre, then
    moved (up, out or forwards) as little as needed to respect the bounds of the module.
    """
    spread = style.gesture_radius_cm * BEAT_SPREAD
    form = _stroke_form(style, rng)
    beat_centre = centre + spread * rng.uniform(-1.0, 1.0, 3)
    beats = []
    for accent in accents:
        beat_centre = 0.3 * beat_centre + 0.7 * (centre + spread * rng.uniform(-1.0, 1.0, 3))
        direction = _stroke_direction(form, rng)
        amplitude = style.beat_amplitude_cm * accent.emphasis * rng.uniform(0.9, 1.1)
        stroke = amplitude * direction
        start = _clear_of_midline(beat_centre - 0.5 * stroke, max(stroke[0], 0.0))
        start[1] = np.clip(start[1], REST_WRIST[1] + STROKE_FLOOR_CM - stroke[1], GESTURE_TOP_CM)
        start[2] = np.clip(start[2], *GESTURE_DEPTH_CM)
        time = accent.time - config.stroke_lead_s + rng.normal(0.0, config.stroke_timing_jitter_s)
        beats.append(_Beat(time, accent, _within_reach(start), direction, amplitude))
    return beats


def _gesture_phrase(
    track: _HandTrack, plan: _PhrasePlan, hand: str, next_ready: float, timing: _Timing
) -> tuple[float, list[tuple[int, float]]]:
    """Append one hand's preparation, beats and retraction (or hold) to its track.

    ``next_ready`` is when the hands must be up for the agent's next phrase.
    Returns the time the hand starts moving, and ``(index, peak time)`` of each beat it
    performed (the peak is where the rule puts it unless a too-fast movement was slowed down).
    """
    mirror = MIRROR if hand == "left" else np.ones(3)
    beats = plan.beats
    first_point = (beats[0].start if beats else _within_reach(plan.centre)) * mirror
    start = max(plan.ready - timing.preparation, track.last_time)
    track.hold_until(start)
    track.move(max(plan.ready, start + MIN_PREPARATION_S), first_point)

    done = []
    for index, beat in enumerate(beats):
        top = beat.start * mirror
        bottom = (beat.start + beat.amplitude_cm * beat.direction) * mirror
        top_time = beat.time - timing.stroke / 2
        moves = not track.is_at(top)
        if top_time < track.last_time + (MIN_SEGMENT_S if moves else 0.0):
            continue  # no room after the previous movement
        track.move(top_time, top)  # back up from the previous beat (or hold at its start)
        track.move(beat.time + timing.stroke / 2, bottom)  # the stroke
        done.append((index, (track.times[-2] + track.times[-1]) / 2))
    # Rebound to the beat's start, unless the next phrase's preparation needs the time.
    rebound_end = min(track.last_time + timing.rebound, next_ready - MIN_PREPARATION_S)
    if done and rebound_end >= track.last_time + timing.rebound / 2:
        track.move(rebound_end, beats[done[-1][0]].start * mirror)
    # Retract home if there is time to come back up for the next phrase, or (faster) if the
    # partner speaks before it: a listener's hands come down. Otherwise hold.
    end = max(plan.phrase.end, track.last_time)
    spare = next_ready - end - timing.preparation
    if spare >= timing.retraction:
        track.go(track.home, end, timing.retraction)
    elif plan.partner_speaks_after:
        track.go(track.home, end, max(spare, MIN_RETRACTION_S))
    return start, done


def _settle(track: _HandTrack, idle_from: float, next_ready: float, timing: _Timing) -> None:
    """Let a hand that waits at home, not needed since ``idle_from``, sink to rest if it will not
    be needed until ``next_ready`` either."""
    settle_start = max(track.last_time, idle_from) + HOME_DWELL_S
    if (
        track.is_at(track.home)
        and settle_start + SETTLE_S + MIN_REST_S + timing.preparation <= next_ready
    ):
        track.go(track.rest, settle_start, SETTLE_S)
