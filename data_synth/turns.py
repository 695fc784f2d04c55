"""Turn-taking: who speaks when, as phrases in continuous time, and the activity of each frame.

The process (parameters in :class:`data_synth.config.TurnConfig`):

1. The conversation opens with a silence of ``lead_in_s``; A speaks first with probability
   ``first_speaker_a_probability``.
2. A *turn* is ``1 + Poisson(m - 1)`` phrases of one speaker, with mean ``m`` =
   ``a_phrases_per_turn`` (3) for A and ``b_phrases_per_turn`` (1.7) for B, so A holds the floor
   about two thirds of the time, as in the Flow-VAE dataset. A phrase lasts ``a_phrase_s`` or
   ``b_phrase_s``; phrases of a turn are separated by pauses of ``phrase_pause_s``.
3. In such a pause the listener says "mm-hm" (a *backchannel* of ``backchannel_s``) with
   probability ``backchannel_probability``, starting 0-0.3 s after the phrase ends; it may run
   into the next phrase (a moment of cross-talk).
4. After a turn the other speaker takes the floor, except with ``keep_turn_probability``. The
   change is a gap of ``turn_gap_s``, or with ``overlap_probability`` an overlap of ``overlap_s``
   (the next speaker starts before the current one stops: cross-talk), or with
   ``long_silence_probability`` a silence of ``long_silence_s``. A speaker who keeps the turn
   never overlaps with itself: it gets an ordinary gap instead.
5. Phrases that would not end 0.1 s before the end of the audio are left out, so no word is cut.

One speaker's utterances never overlap each other. :func:`activity_codes` turns the phrases into
one :class:`~gesturelib.conventions.Activity` code per motion frame.
"""

from __future__ import annotations

import numpy as np

from data_synth.config import TurnConfig
from data_synth.events import Phrase
from gesturelib.conventions import Activity

#: No phrase ends later than this before the end of the audio.
END_MARGIN_S = 0.1
#: The smallest silence between two utterances of the same speaker.
MIN_OWN_GAP_S = 0.1
#: A backchannel starts between 0 and this long after the phrase it answers.
BACKCHANNEL_DELAY_S = 0.3


def sample_turns(duration_s: float, config: TurnConfig, rng: np.random.Generator) -> list[Phrase]:
    """Draw the phrases and backchannels of both speakers for ``duration_s`` seconds.

    Returns:
        The utterances sorted by start time (see :class:`~data_synth.events.Phrase`).
    """
    limit = duration_s - END_MARGIN_S
    utterances: list[Phrase] = []
    last_end = {"A": -np.inf, "B": -np.inf}
    speaker = "A" if rng.random() < config.first_speaker_a_probability else "B"
    t = rng.uniform(*config.lead_in_s)

    def add(who: str, start: float, length: float, kind: str) -> bool:
        start = max(start, last_end[who] + MIN_OWN_GAP_S)
        if start + length > limit:
            return False
        utterances.append(Phrase(who, float(start), float(start + length), kind))
        last_end[who] = start + length
        return True

    while True:
        listener = "B" if speaker == "A" else "A"
        mean_phrases = config.a_phrases_per_turn if speaker == "A" else config.b_phrases_per_turn
        phrase_range = config.a_phrase_s if speaker == "A" else config.b_phrase_s
        n_phrases = 1 + int(rng.poisson(mean_phrases - 1.0))
        for index in range(n_phrases):
            if not add(speaker, t, rng.uniform(*phrase_range), "phrase"):
                return sorted(utterances, key=lambda u: u.start)
            t = last_end[speaker]
            if index < n_phrases - 1:
                pause = rng.uniform(*config.phrase_pause_s)
                if rng.random() < config.backchannel_probability:
                    delay = rng.uniform(0.0, min(BACKCHANNEL_DELAY_S, pause))
                    add(listener, t + delay, rng.uniform(*config.backchannel_s), "backchannel")
                t += pause
        keep = rng.random() < config.keep_turn_probability
        draw = rng.random()
        if not keep and draw < config.overlap_probability:
            t -= rng.uniform(*config.overlap_s)
        elif 0.0 <= draw - config.overlap_probability < config.long_silence_probability:
            t += rng.uniform(*config.long_silence_s)
        else:
            t += rng.uniform(*config.turn_gap_s)
        speaker = speaker if keep else listener


def opening_phrase_fits(config: TurnConfig) -> tuple[float, float]:
    """Durations in seconds from which the opening phrase fits: for some draws, for every draw.

    The lead-in and the first speaker's first phrase must end :data:`END_MARGIN_S` before the
    end. A conversation shorter than the first duration never has speech; one at least as long
    as the second always has.
    """
    openers = []
    if config.first_speaker_a_probability > 0:
        openers.append(config.a_phrase_s)
    if config.first_speaker_a_probability < 1:
        openers.append(config.b_phrase_s)
    some = config.lead_in_s[0] + min(low for low, _ in openers) + END_MARGIN_S
    every = config.lead_in_s[1] + max(high for _, high in openers) + END_MARGIN_S
    return some, every


def speaking_mask(utterances: list[Phrase], speaker: str, times: np.ndarray) -> np.ndarray:
    """Whether ``speaker`` is talking at each of ``times`` ``(T,)``: a boolean ``(T,)``.

    An utterance covers the half-open interval ``[start, end)``.
    """
    intervals = np.array([(u.start, u.end) for u in utterances if u.speaker == speaker])
    if intervals.size == 0:
        return np.zeros(times.shape, dtype=bool)
    intervals = intervals[np.argsort(intervals[:, 0])]
    # Utterances of one speaker do not overlap: the last start at or before t decides.
    index = np.searchsorted(intervals[:, 0], times, side="right") - 1
    inside = index >= 0
    inside[inside] = times[inside] < intervals[index[inside], 1]
    return inside


def frame_times(n_frames: int, fps: int) -> np.ndarray:
    """The time ``(T,)`` in seconds that stands for each frame: its centre, ``(t + 0.5) / fps``.

    Frame ``t`` covers ``[t / fps, (t + 1) / fps)``, the interval whose audio
    :func:`gesturelib.features.mel_spectrogram` describes in row ``t``; poses and activity are
    sampled at its centre.
    """
    return (np.arange(n_frames) + 0.5) / fps


def activity_codes(utterances: list[Phrase], n_frames: int, fps: int) -> np.ndarray:
    """One :class:`~gesturelib.conventions.Activity` code per frame, ``(T,)`` int64.

    A frame belongs to a speaker when one of the speaker's utterances (phrases and backchannels)
    covers the frame's centre; both speakers give ``BOTH``, neither ``NONE``.
    """
    times = frame_times(n_frames, fps)
    a_talks = speaking_mask(utterances, "A", times)
    b_talks = speaking_mask(utterances, "B", times)
    codes = np.full(n_frames, int(Activity.NONE), dtype=np.int64)
    codes[a_talks & ~b_talks] = Activity.A_SPEAKS
    codes[b_talks & ~a_talks] = Activity.B_SPEAKS
    codes[a_talks & b_talks] = Activity.BOTH
    return codes
