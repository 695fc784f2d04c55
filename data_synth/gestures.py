"""The agent's hand gestures: where each wrist should be, as keyframes of minimum-jerk movements.

Rules (parameters in :class:`data_synth.config.MotionConfig` and the conversation's
:class:`data_synth.style.Style`; durations marked * are divided by ``style.speed``):

* **Rest.** Outside its gesture phrases a hand rests in front of the belly (:data:`REST_WRIST`),
  the relaxed posture of a seated listener.
* **Gesture phrases.** Every phrase of the agent (speaker A; not its backchannels) is a gesture
  phrase. It uses both hands, mirror-symmetrically, with probability ``style.symmetry``;
  otherwise one hand, the right one with probability ``style.handedness``.
* **Preparation.** The hands rise into the gesture space in ``preparation_s`` *, arriving 50 ms
  before the phrase starts (or before its first beat, if that comes earlier). The gesture space
  is centred ``style.hand_height_cm`` above the rest position, 2 cm further forward and
  ``0.2 * style.gesture_radius_cm`` outwards; each beat starts from a *home* position drawn within
  ``style.gesture_radius_cm`` x :data:`HOME_SPREAD` of that centre (70 % of the way from the
  previous home, so the hands drift rather than jump).
* **Beats.** Every accent of the phrase gets a beat: a stroke downwards (and a little forwards
  and outwards) of ``style.beat_amplitude_cm * emphasis`` (+-10 %) from the home position, lasting
  ``stroke_duration_s`` *; the hand then rises to the next home position until the next stroke.
  The stroke's wrist speed peaks in its middle, at ``accent time - stroke_lead_s`` (+ Gaussian
  jitter of ``stroke_timing_jitter_s``): the gesture *leads* the stressed syllable, as in real
  speech. A beat that cannot fit after the previous movement is left out (and absent from the
  event log).
* **After the last beat** the hand rebounds to its home in ``rebound_s`` * and holds until the
  phrase ends. Then it retracts to rest in ``retraction_s`` * if there is time to prepare again
  for the agent's next phrase; if there is not, it holds in the gesture space, unless the partner
  speaks in between: a listener's hands rest, so it retracts faster (down to 0.4 s).
* A hand that a phrase does not use returns to rest (if it was up) while the other prepares.

Every segment between keyframes is a minimum-jerk movement
(:func:`data_synth.kinematics.minimum_jerk_path`): hands start and stop smoothly, and a stroke of
``a`` cm in ``d`` s peaks at ``1.875 a / d`` cm/s (about 50-150 cm/s here, like a real speaker's
beats). No movement may peak above :data:`MAX_WRIST_SPEED`; one that would is slowed down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_synth.config import MotionConfig
from data_synth.events import Accent, GesturePhrase, Phrase, Stroke
from data_synth.style import Style

HANDS = ("left", "right")
#: +1 for the left hand (the agent's left is +x), -1 for the right.
SIDE = {"left": 1.0, "right": -1.0}
#: Wrist at rest (left hand; the right one is its mirror image), cm, in the body frame.
REST_WRIST = np.array([10.0, 19.0, 25.0])
#: Centre of the gesture space relative to the rest position, before the style's height.
GESTURE_OFFSET = np.array([0.0, 0.0, 2.0])
#: The smallest duration of a movement between two different keyframes.
MIN_SEGMENT_S = 0.05
#: Hand tracks start at rest this early (before the audio), so that a phrase at the very start
#: of the conversation still gets a full preparation.
TRACK_START_S = -10.0
#: No keyframe movement is faster than this (peak wrist speed, cm/s): a movement that would be is
#: slowed down. Real beat strokes peak at 50-200 cm/s.
MAX_WRIST_SPEED = 180.0
#: Peak speed of a minimum-jerk movement over distance d in time T is 1.875 d / T.
MINIMUM_JERK_PEAK = 1.875
#: The shortest preparation, when the previous movement ends late.
MIN_PREPARATION_S = 0.25
#: Hands arrive in the gesture space this long before the phrase (or its first beat).
READY_MARGIN_S = 0.05
#: The quickest retraction, when the partner speaks briefly between two phrases of the agent.
MIN_RETRACTION_S = 0.4
#: How far the beats' home positions spread around the centre of the gesture space (x, y, z),
#: in units of the style's gesture radius.
HOME_SPREAD = np.array([0.8, 0.6, 0.5])
#: No wrist target is closer than this to the body's midline (x = 0), in cm.
MIN_MIDLINE_CM = 4.0


def rest_wrist(hand: str) -> np.ndarray:
    """The rest position ``(3,)`` of one wrist in the body frame, cm."""
    return REST_WRIST * np.array([SIDE[hand], 1.0, 1.0])


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

    def __init__(self, hand: str):
        self.rest = rest_wrist(hand)
        self.times = [TRACK_START_S]
        self.points = [self.rest]

    @property
    def last_time(self) -> float:
        return self.times[-1]

    @property
    def last_point(self) -> np.ndarray:
        return self.points[-1]

    def at_rest(self) -> bool:
        return bool(np.allclose(self.last_point, self.rest))

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

    def retract(self, start: float, duration: float) -> None:
        """Return to rest, starting no earlier than ``start``."""
        if not self.at_rest():
            self.hold_until(start)
            self.move(self.last_time + duration, self.rest)


@dataclass
class _Beat:
    time: float  # the wrist-speed peak
    accent: Accent
    home: np.ndarray  # right-hand coordinates; mirrored for the left hand
    direction: np.ndarray
    amplitude_cm: float


@dataclass
class _PhrasePlan:
    phrase: Phrase
    hands: tuple[str, ...]
    beats: list[_Beat]
    ready: float  # when the hands should be in the gesture space
    partner_speaks_after: bool  # B has a phrase between this phrase and the agent's next one

    @property
    def label(self) -> str:
        return "both" if len(self.hands) == 2 else self.hands[0]


def plan_gestures(utterances: list[Phrase], accents: list[Accent], style: Style,
                  config: MotionConfig, rng: np.random.Generator) -> GesturePlan:
    """Plan the wrist keyframes of every gesture phrase of the agent (see the module rules).

    Args:
        utterances: every phrase and backchannel of both speakers.
        accents: the agent's accents (speaker A).
    """
    phrases = sorted((u for u in utterances if u.speaker == "A" and u.kind == "phrase"),
                     key=lambda u: u.start)
    accent_times = np.array([a.time for a in accents])
    timing = _Timing(config, style)
    centre = rest_wrist("right") + GESTURE_OFFSET * np.array([-1.0, 1.0, 1.0]) \
        + np.array([-0.2 * style.gesture_radius_cm, style.hand_height_cm, 0.0])
    partner = [u for u in utterances if u.speaker == "B" and u.kind == "phrase"]
    plans = []
    for index, phrase in enumerate(phrases):
        next_start = phrases[index + 1].start if index + 1 < len(phrases) else np.inf
        partner_speaks_after = any(phrase.end < u.end and u.start < next_start for u in partner)
        if rng.random() < style.symmetry:
            hands = HANDS
        else:
            hands = ("right",) if rng.random() < style.handedness else ("left",)
        inside = np.flatnonzero((accent_times >= phrase.start) & (accent_times < phrase.end))
        beats = _draw_beats([accents[i] for i in inside], centre, style, config, rng)
        first_top = beats[0].time - timing.stroke / 2 if beats else phrase.start
        plans.append(_PhrasePlan(phrase, hands, beats,
                                 min(phrase.start, first_top) - READY_MARGIN_S,
                                 partner_speaks_after))

    tracks = {hand: _HandTrack(hand) for hand in HANDS}
    strokes: list[Stroke] = []
    gesture_phrases: list[GesturePhrase] = []
    for index, plan in enumerate(plans):
        next_ready = plans[index + 1].ready if index + 1 < len(plans) else np.inf
        for hand in HANDS:
            if hand not in plan.hands:
                tracks[hand].retract(plan.ready - timing.preparation, timing.retraction)
        performed: dict[int, tuple[float, list[str]]] = {}  # beat -> (peak time, hands)
        starts, ends = [], []
        for hand in plan.hands:
            start, done = _gesture_phrase(tracks[hand], plan, hand, next_ready, timing)
            for index, peak_time in done:
                performed.setdefault(index, (peak_time, []))[1].append(hand)
            starts.append(start)
            ends.append(tracks[hand].last_time)
        phrase = plan.phrase
        gesture_phrases.append(GesturePhrase(float(min(starts)), float(max(ends)), plan.label,
                                             phrase.start, phrase.end))
        for index in sorted(performed):
            peak_time, hands = performed[index]
            beat = plan.beats[index]
            strokes.append(Stroke(float(peak_time), float(beat.accent.time),
                                  "both" if len(hands) == 2 else hands[0],
                                  float(beat.amplitude_cm)))

    return GesturePlan(
        key_times={hand: np.array(tracks[hand].times) for hand in HANDS},
        key_points={hand: np.array(tracks[hand].points) for hand in HANDS},
        strokes=strokes,
        gesture_phrases=gesture_phrases,
    )


class _Timing:
    """Durations of the movements at the style's speed, seconds."""

    def __init__(self, config: MotionConfig, style: Style):
        self.stroke = config.stroke_duration_s / style.speed
        self.rebound = config.rebound_s / style.speed
        self.preparation = config.preparation_s / style.speed
        self.retraction = config.retraction_s / style.speed


def _draw_beats(accents: list[Accent], centre: np.ndarray, style: Style, config: MotionConfig,
                rng: np.random.Generator) -> list[_Beat]:
    """One beat per accent, in right-hand coordinates: timing, home, direction, amplitude."""
    spread = style.gesture_radius_cm * HOME_SPREAD
    home = centre + spread * rng.uniform(-1.0, 1.0, 3)
    beats = []
    for accent in accents:
        home = 0.3 * home + 0.7 * (centre + spread * rng.uniform(-1.0, 1.0, 3))
        home[0] = min(home[0], -MIN_MIDLINE_CM)
        direction = np.array([-rng.uniform(-0.1, 0.3), -1.0, rng.uniform(0.1, 0.5)])
        direction /= np.linalg.norm(direction)
        amplitude = style.beat_amplitude_cm * accent.emphasis * rng.uniform(0.9, 1.1)
        time = accent.time - config.stroke_lead_s + rng.normal(0.0, config.stroke_timing_jitter_s)
        beats.append(_Beat(time, accent, home.copy(), direction, amplitude))
    return beats


def _gesture_phrase(track: _HandTrack, plan: _PhrasePlan, hand: str, next_ready: float,
                    timing: _Timing) -> tuple[float, list[tuple[int, float]]]:
    """Append one hand's preparation, beats and retraction (or hold) to its track.

    ``next_ready`` is when the hands must be up for the agent's next phrase.
    Returns the time the hand starts moving, and ``(index, peak time)`` of each beat it
    performed (the peak is where the rule puts it unless a too-fast movement was slowed down).
    """
    mirror = np.array([-1.0 if hand == "left" else 1.0, 1.0, 1.0])
    beats = plan.beats
    first_home = (beats[0].home if beats else _hold_point(track)) * mirror
    start = max(plan.ready - timing.preparation, track.last_time)
    track.hold_until(start)
    track.move(max(plan.ready, start + MIN_PREPARATION_S), first_home)

    done = []
    for index, beat in enumerate(beats):
        home, bottom = beat.home * mirror, (beat.home + beat.amplitude_cm * beat.direction) * mirror
        top_time = beat.time - timing.stroke / 2
        moves = not np.allclose(home, track.last_point)
        if top_time < track.last_time + (MIN_SEGMENT_S if moves else 0.0):
            continue  # no room after the previous movement
        track.move(top_time, home)  # back up from the previous beat (or hold at home)
        track.move(beat.time + timing.stroke / 2, bottom)  # the stroke
        done.append((index, (track.times[-2] + track.times[-1]) / 2))
    # Rebound to the home position, unless the next phrase's preparation needs the time.
    rebound_end = min(track.last_time + timing.rebound, next_ready - MIN_PREPARATION_S)
    if done and rebound_end >= track.last_time + timing.rebound / 2:
        track.move(rebound_end, beats[done[-1][0]].home * mirror)
    # Retract if there is time to come back up for the next phrase, or (faster) if the partner
    # speaks before it: a listener's hands rest. Otherwise hold.
    end = max(plan.phrase.end, track.last_time)
    spare = next_ready - end - timing.preparation
    if spare >= timing.retraction:
        track.retract(end, timing.retraction)
    elif plan.partner_speaks_after:
        track.retract(end, max(spare, MIN_RETRACTION_S))
    return start, done


def _hold_point(track: _HandTrack) -> np.ndarray:
    """Where the hand goes for a phrase without beats: where it is, or a little up from rest."""
    point = track.last_point if not track.at_rest() else track.rest + np.array([0.0, 6.0, 6.0])
    return point * np.array([-1.0 if point[0] > 0 else 1.0, 1.0, 1.0])  # in right-hand coordinates
