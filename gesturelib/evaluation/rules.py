"""Appropriateness, measured against the generator's own rules, and the field's proxy for it.

Real recordings cannot tell whether a gesture fits its speech: nobody knows where the strokes
*should* have been. The synthetic conversations can: their event log
(:class:`data_synth.events.Events`) says where every accent of the agent is, when the partner
ended a phrase, and what the rules then do (``data_synth.config.MotionConfig``). Each measure
below detects events in motion alone, from keypoints, and checks them against those rules:

* :func:`accent_leads`: for each accent of the agent, the lead of the nearest stroke (a peak of
  wrist speed, :func:`stroke_times`). The rule: strokes peak ``stroke_lead_s`` before every
  accent. From it come the **accent hit rate** (accents with a stroke within
  ``STROKE_TOLERANCE_S`` of the rule) and the **lead error** (median distance from the rule).
* :func:`partner_nods`: for each end of a partner's phrase that the agent answers with silence,
  whether the head nods (a peak of downward head pitch speed, :func:`nod_times`) when the rule
  says a listening nod comes. Their mean is the **nod response**.
* Hit rates alone reward motion that strikes and nods all the time (jitter does), so each comes
  with a **precision**: the share of the strokes found that lie on a rule's time
  (:func:`on_rule_strokes`), of the nods found that lie in a rule's window (:func:`on_rule_nods`:
  after the partner's phrases, on the agent's accents and with its own "mm-hm"). Natural motion
  has more speed peaks than strokes (preparations, retractions): compare a system's precision
  with the ground truth's, not with 1.
* :func:`beat_alignment`: Bailando's beat-alignment score (Li et al. 2022, their code), the
  field's proxy: how close *kinematic beats* (local minima of the joints' mean speed) come to
  onsets of the audio. It needs no events, so it applies to any data, but it knows nothing of
  the rules: compare it with the exact measures.

Times are in seconds from the start of the audio; the speed between frames ``t - 1`` and ``t``
stands for the time ``t / fps`` (frame ``t`` is sampled at its centre, ``(t + 0.5) / fps``).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import argrelextrema, find_peaks

from gesturelib.conventions import FPS, Activity
from gesturelib.metrics import speed
from gesturelib.skeleton import JOINT_INDEX

#: A stroke counts as hitting its accent within this distance of the rule's time (two frames:
#: the generator's timing jitter is 0.02 s, the frame quantisation 0.04 s).
STROKE_TOLERANCE_S = 0.08
#: Strokes searched around each accent: from this long before it ...
STROKE_SEARCH_BEFORE_S = 0.6
#: ... to this long after it.
STROKE_SEARCH_AFTER_S = 0.4
#: A stroke is a peak of the faster wrist's speed at least this prominent (cm/s): the slow sway
#: of idle hands has peaks of a few cm/s, the generator's smallest beats tens of cm/s.
STROKE_PROMINENCE = 10.0
#: A nod is a peak of the head's downward pitch speed above this (degrees per second); the
#: generator's nods of 4-9 degrees over 0.45 s peak at 50-150 deg/s, sway at under 10.
NOD_MIN_SPEED_DEG = 20.0
#: A nod counts as answering the partner within this margin of the rule's window.
NOD_TOLERANCE_S = 0.08
#: Bailando's sigma: 3 frames at their 60 fps.
BEAT_SIGMA_S = 3 / 60


def stroke_times(positions: np.ndarray, fps: int = FPS) -> np.ndarray:
    """Times ``(S,)`` of the strokes in keypoints ``(T, 9, 3)``: peaks of the faster wrist's speed
    with a prominence of at least :data:`STROKE_PROMINENCE`, at least 0.2 s apart."""
    wrists = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]
    fastest = speed(positions, fps)[:, wrists].max(axis=1)
    peaks, _ = find_peaks(fastest, prominence=STROKE_PROMINENCE, distance=max(1, fps // 5))
    return (peaks + 1) / fps


def head_pitch(positions: np.ndarray) -> np.ndarray:
    """Pitch ``(T,)`` in radians of the head-to-nose limb (positive: nose down), from keypoints
    ``(T, 9, 3)`` (x to the agent's left, y up, z forward)."""
    limb = positions[:, JOINT_INDEX["nose"]] - positions[:, JOINT_INDEX["head"]]
    return np.arctan2(-limb[:, 1], limb[:, 2])


def nod_times(positions: np.ndarray, fps: int = FPS) -> np.ndarray:
    """Times ``(N,)`` of the nods in keypoints ``(T, 9, 3)``: peaks of the head's downward pitch
    speed above :data:`NOD_MIN_SPEED_DEG`, at least 0.2 s apart."""
    down = np.degrees(np.diff(head_pitch(positions))) * fps
    peaks, _ = find_peaks(
        down, height=NOD_MIN_SPEED_DEG, prominence=NOD_MIN_SPEED_DEG, distance=max(1, fps // 5)
    )
    return (peaks + 1) / fps


def accent_leads(conversation, positions: np.ndarray) -> np.ndarray:
    """For each accent of the agent, the lead in seconds (accent time minus stroke time) of the
    stroke nearest to the rule's time among those from :data:`STROKE_SEARCH_BEFORE_S` before to
    :data:`STROKE_SEARCH_AFTER_S` after the accent; NaN where there is none.

    Args:
        conversation: a :class:`data_synth.Conversation` (its events and motion config).
        positions: ``(T, 9, 3)`` keypoints of any motion for its speech.
    Returns:
        ``(A,)`` leads, one per accent of the agent.
    """
    rule = conversation.config.motion.stroke_lead_s
    strokes = stroke_times(positions, conversation.fps)
    leads = []
    for accent in conversation.events.accents_of("A"):
        lead = accent.time - strokes
        near = lead[(lead <= STROKE_SEARCH_BEFORE_S) & (lead >= -STROKE_SEARCH_AFTER_S)]
        leads.append(near[np.argmin(np.abs(near - rule))] if near.size else np.nan)
    return np.asarray(leads, dtype=np.float64)


def on_rule_strokes(conversation, positions: np.ndarray) -> np.ndarray:
    """For each stroke found in ``positions`` (:func:`stroke_times`), whether it lies within
    :data:`STROKE_TOLERANCE_S` of the rule's time for one of the agent's accents: ``(S,)`` bool."""
    strokes = stroke_times(positions, conversation.fps)
    rule = conversation.config.motion.stroke_lead_s
    targets = np.array([a.time - rule for a in conversation.events.accents_of("A")])
    if targets.size == 0:
        return np.zeros(strokes.size, dtype=bool)
    return np.abs(strokes[:, None] - targets[None]).min(axis=1) <= STROKE_TOLERANCE_S


def answered_phrase_ends(conversation) -> np.ndarray:
    """Times ``(E,)`` of the partner's phrase ends that the agent answers with silence (for the
    next ``LISTENING_WINDOW_S``): where the rules may put a listening nod."""
    from data_synth.nods import LISTENING_WINDOW_S

    agent = conversation.events.phrases_of("A", kind=None)
    return np.array(
        [
            p.end
            for p in conversation.events.phrases_of("B")
            if not any(u.start < p.end + LISTENING_WINDOW_S and u.end > p.end for u in agent)
        ],
        dtype=np.float64,
    )


def nod_windows(conversation) -> dict[str, np.ndarray]:
    """Where the rules put the agent's nods, as ``(W, 2)`` arrays of ``[start, end]`` times (the
    time of fastest downward motion, widened by :data:`NOD_TOLERANCE_S`), by cause:

    * ``partner``: after each phrase end of the partner that the agent answers with silence
      (:func:`answered_phrase_ends`): ``nod_delay_s`` plus a quarter of the nod cycle;
    * ``accent``: ``stroke_lead_s`` before each of the agent's accents (with a chance that grows
      with the accent's emphasis);
    * ``backchannel``: a quarter cycle after the start of each of the agent's own "mm-hm".
    """
    motion = conversation.config.motion
    quarter_cycle = motion.nod_duration_s / conversation.style.speed / 4
    earliest, latest = (d + quarter_cycle for d in motion.nod_delay_s)
    agent = conversation.events.phrases_of("A", kind=None)
    ends = answered_phrase_ends(conversation)
    accents = [a.time - motion.stroke_lead_s for a in conversation.events.accents_of("A")]
    backchannels = [u.start + quarter_cycle for u in agent if u.kind == "backchannel"]
    tolerance = NOD_TOLERANCE_S

    def windows(starts, first, last):
        return np.array([[t + first - tolerance, t + last + tolerance] for t in starts]).reshape(
            -1, 2
        )

    return {
        "partner": windows(ends, earliest, latest),
        "accent": windows(accents, 0.0, 0.0),
        "backchannel": windows(backchannels, 0.0, 0.0),
    }


def partner_nods(conversation, positions: np.ndarray) -> np.ndarray:
    """For each phrase end of the partner that the rules answer with a listening nod
    (:func:`nod_windows`' ``partner``), whether ``positions`` nod in its window: ``(E,)`` bool
    (the generator nods at ``listening_nod_probability`` of them)."""
    nods = nod_times(positions, conversation.fps)
    return np.array(
        [
            np.any((nods >= start) & (nods <= end))
            for start, end in nod_windows(conversation)["partner"]
        ],
        dtype=bool,
    )


def head_drops_after_phrase_ends(
    conversation, positions: np.ndarray, previous: np.ndarray, first: int, seconds: float = 0.6
) -> np.ndarray:
    """The head's downward pitch speed (deg/s) into each frame of the ``seconds`` after each of
    the partner's phrase ends that the agent answers with silence (:func:`answered_phrase_ends`),
    the window a listening nod falls in: ``(E, round(seconds * fps))``, one row an end (the ends
    whose window ``positions`` does not cover are left out).

    Args:
        conversation: a :class:`data_synth.Conversation` (its events and frame rate).
        positions: keypoints ``(N, 9, 3)`` of the conversation's frames ``first`` to
            ``first + N - 1``.
        previous: the keypoints ``(N, 9, 3)`` each frame moved from: the frame before it, or,
            for a frame drawn one step ahead of a recording, the recorded frame before it.
        first: the conversation's frame that ``positions[0]`` is.
    Raises:
        ValueError: ``positions`` and ``previous`` of different shapes.
    """
    if np.shape(positions) != np.shape(previous):
        raise ValueError(
            f"positions and previous must be alike, one previous frame per frame: got "
            f"{np.shape(positions)} and {np.shape(previous)}"
        )
    fps = conversation.fps
    down = np.degrees(head_pitch(positions) - head_pitch(previous)) * fps
    frames = round(seconds * fps)
    rows = []
    for end in answered_phrase_ends(conversation):
        start = round(end * fps) - first
        if 0 <= start and start + frames <= len(down):
            rows.append(down[start : start + frames])
    return np.asarray(rows, dtype=np.float64).reshape(-1, frames)


def on_rule_nods(conversation, positions: np.ndarray) -> np.ndarray:
    """For each nod found in ``positions`` (:func:`nod_times`), whether it lies in a window where
    the rules put a nod (:func:`nod_windows`, every cause): ``(N,)`` bool."""
    nods = nod_times(positions, conversation.fps)
    windows = np.concatenate(list(nod_windows(conversation).values()))
    inside = (nods[:, None] >= windows[None, :, 0]) & (nods[:, None] <= windows[None, :, 1])
    return inside.any(axis=1)


def kinematic_beats(positions: np.ndarray, fps: int = FPS) -> np.ndarray:
    """Bailando's motion beats: times ``(B,)`` of the local minima of the joints' mean speed,
    smoothed by a Gaussian of 5 frames at 60 fps (their code), from keypoints ``(T, J, 3)``."""
    mean_speed = speed(positions, fps).mean(axis=1)
    smoothed = gaussian_filter1d(mean_speed, sigma=5 / 60 * fps)
    return (argrelextrema(smoothed, np.less)[0] + 1) / fps


def beat_alignment_score(audio_beats: np.ndarray, motion_beats: np.ndarray) -> float:
    """Bailando's formula: the mean over audio beats of ``exp(-d^2 / (2 sigma^2))``, ``d`` the
    distance in seconds to the nearest motion beat, sigma :data:`BEAT_SIGMA_S`; 1 when every
    audio beat has a motion beat on it, towards 0 when none is near. NaN without audio beats;
    0 without motion beats."""
    audio_beats, motion_beats = np.asarray(audio_beats), np.asarray(motion_beats)
    if audio_beats.size == 0:
        return float("nan")
    if motion_beats.size == 0:
        return 0.0
    nearest = np.abs(audio_beats[:, None] - motion_beats[None]).min(axis=1)
    return float(np.mean(np.exp(-(nearest**2) / (2 * BEAT_SIGMA_S**2))))


def speech_onsets(audio: np.ndarray, sample_rate: int, activity: np.ndarray, fps: int = FPS):
    """Onset times ``(O,)`` of the audio (librosa's onset detector) where the agent speaks."""
    import librosa

    onsets = librosa.onset.onset_detect(y=audio, sr=sample_rate, units="time")
    frames = np.minimum((onsets * fps).astype(int), len(activity) - 1)
    return onsets[np.isin(np.asarray(activity)[frames], (Activity.A_SPEAKS, Activity.BOTH))]


def beat_alignment(conversation, positions: np.ndarray) -> float:
    """:func:`beat_alignment_score` of ``positions``' kinematic beats against the onsets of the
    conversation's audio while the agent speaks."""
    onsets = speech_onsets(
        conversation.audio, conversation.sample_rate, conversation.activity, conversation.fps
    )
    return beat_alignment_score(onsets, kinematic_beats(positions, conversation.fps))


def rule_measures(conversations, motions) -> dict[str, float]:
    """The appropriateness measures of ``motions`` (one ``(T, 9, 3)`` per conversation), pooled
    over the conversations.

    Returns:
        ``accent_hits`` (fraction of the agent's accents with a stroke on the rule's time),
        ``stroke_precision`` (fraction of the strokes found that are on a rule's time),
        ``lead_error`` (median seconds between a found stroke's lead and the rule's), ``nods``
        (fraction of the partner's phrase ends answered by a nod in the rule's window),
        ``nod_precision`` (fraction of the nods found that are in a rule's window) and
        ``beat_align`` (Bailando's score, mean over conversations). Measures that need the
        generator's events are NaN for conversations without them (``events`` None); so is
        ``lead_error`` for motion without any stroke near an accent, and a precision for motion
        in which no stroke or nod is found.
    """
    pairs = list(zip(conversations, motions, strict=True))
    beat = float(np.mean([beat_alignment(c, m) for c, m in pairs]))
    if any(getattr(c, "events", None) is None for c in conversations):
        return {name: np.nan for name in RULE_MEASURES} | {"beat_align": beat}
    leads = np.concatenate([accent_leads(c, m) for c, m in pairs])
    rules = np.concatenate(
        [
            np.full(len(c.events.accents_of("A")), c.config.motion.stroke_lead_s)
            for c in conversations
        ]
    )
    error = np.abs(leads - rules)
    missed = np.nan_to_num(error, nan=np.inf)  # an accent without a stroke near it misses
    answered = np.concatenate([partner_nods(c, m) for c, m in pairs])
    strokes = np.concatenate([on_rule_strokes(c, m) for c, m in pairs])
    nods = np.concatenate([on_rule_nods(c, m) for c, m in pairs])
    return {
        "accent_hits": float(np.mean(missed <= STROKE_TOLERANCE_S)) if error.size else np.nan,
        "stroke_precision": _share(strokes),
        "lead_error": float(np.nanmedian(error)) if np.isfinite(missed).any() else np.nan,
        "nods": _share(answered),
        "nod_precision": _share(nods),
        "beat_align": beat,
    }


#: What :func:`rule_measures` returns, in order.
RULE_MEASURES = (
    "accent_hits",
    "stroke_precision",
    "lead_error",
    "nods",
    "nod_precision",
    "beat_align",
)


def _share(flags: np.ndarray) -> float:
    return float(flags.mean()) if flags.size else np.nan
