"""What each speaker says, as sounds: syllables, stress and intonation (no audio yet).

Rules (parameters in :class:`data_synth.config.VoiceConfig`):

* **Syllables.** A phrase of duration ``d`` holds ``round(d * rate)`` syllables, the rate drawn
  per phrase from ``syllable_rate_hz`` (4-6 a second, natural speech). A syllable is an optional
  onset consonant, a vowel (a, e, i, o, u) and an optional coda, with the probabilities of
  :data:`ONSETS` and :data:`CODAS`. Fricatives (s, sh, f, h) are noise; plosives (p, t, k) are a
  silent closure and then a burst of noise; nasals and liquids (m, n, l, r) are voiced.
* **Stress.** Accents fall every ``accent_spacing_syllables`` syllables (3-5), the first on one of
  the first three. Each accent has an *emphasis* ``e`` from ``emphasis_range``; the last one of a
  phrase (the nuclear accent) gets the upper half of the range. An accented syllable is
  ``accent_lengthening`` times longer (1.4), its vowel ``accent_gain_db * e`` louder (up to
  +8 dB) and its pitch ``accent_pitch_semitones * e`` higher (up to +4 semitones, a Gaussian
  peak 60 ms wide on the vowel). The loudness of the vowel is what marks the accent in the
  mel features; consonants are not emphasised.
* **Timing inside a phrase.** Syllable durations are drawn around ``d / n`` (+-20 %), accented
  and final syllables lengthened (``final_lengthening``), then scaled to fill the phrase exactly.
* **Intonation.** Along a phrase the pitch baseline falls by ``declination_semitones``
  (declination) and the loudness by 2 dB; the last syllable falls 2 semitones, or rises 4 for a
  question (``question_probability``). A slow wander of 0.5 semitone and +-0.5 semitone per
  syllable keep it from sounding robotic.
* **Backchannels** ("mm-hm", "yeah") are one or two unaccented syllables, quieter by
  ``backchannel_level_db``, on a nasal "m" or a vowel, with a small rise.

The *accent time* (:class:`~data_synth.events.Accent`) is the middle of the accented vowel's
attack: the instant its loudness rises, which is what the agent's beats are timed against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from data_synth.config import VoiceConfig
from data_synth.events import Accent, Phrase, Syllable

#: Every kind of sound segment; :mod:`data_synth.voice` gives each its source and filter.
VOWELS = ("a", "e", "i", "o", "u")
VOICED_CONSONANTS = ("l", "r", "m", "n")
FRICATIVES = ("s", "sh", "f", "h")
PLOSIVES = ("p", "t", "k")
SEGMENT_KINDS = VOWELS + VOICED_CONSONANTS + FRICATIVES + PLOSIVES
KIND_INDEX = {kind: i for i, kind in enumerate(SEGMENT_KINDS)}

#: Onset consonants and their probabilities ("" is no consonant).
ONSETS = {
    "": 0.15,
    "s": 0.12,
    "sh": 0.05,
    "f": 0.07,
    "h": 0.06,
    "p": 0.08,
    "t": 0.12,
    "k": 0.10,
    "m": 0.08,
    "n": 0.08,
    "l": 0.05,
    "r": 0.04,
}
#: Coda consonants and their probabilities.
CODAS = {"": 0.6, "n": 0.12, "s": 0.1, "t": 0.1, "m": 0.08}
#: Amplitude of each consonant relative to an unstressed vowel (after each filter is normalised
#: to unit output power): consonants are much weaker than vowels.
CONSONANT_LEVEL = {
    "l": 0.5,
    "r": 0.5,
    "m": 0.35,
    "n": 0.35,
    "s": 0.22,
    "sh": 0.25,
    "f": 0.1,
    "h": 0.1,
    "p": 0.4,
    "t": 0.45,
    "k": 0.45,
}
#: A vowel reaches full loudness in this time; the accent time is the middle of this attack.
VOWEL_ATTACK_S = 0.015
VOWEL_RELEASE_S = 0.03
#: Plosive burst and the aspiration after it.
BURST_S = 0.012
ASPIRATION_S = 0.02
#: The pitch contour is computed at this rate and interpolated to audio samples.
CONTROL_RATE_HZ = 100
#: Width (standard deviation) of an accent's pitch peak.
ACCENT_PITCH_WIDTH_S = 0.06
#: Loudness decline along a phrase, dB.
INTENSITY_DECLINATION_DB = 2.0
FINAL_FALL_SEMITONES = -2.0
QUESTION_RISE_SEMITONES = 4.0


@dataclass
class Segments:
    """Every sound a speaker makes, one row per segment, as parallel arrays ``(S,)``.

    ``kind`` indexes :data:`SEGMENT_KINDS`; ``level`` is a linear amplitude; times in seconds.
    """

    kind: np.ndarray
    start_s: np.ndarray
    duration_s: np.ndarray
    level: np.ndarray
    attack_s: np.ndarray
    release_s: np.ndarray


@dataclass
class SpeechPlan:
    """Everything one speaker says: the events, the sound segments and the pitch contour.

    ``pitch_semitones`` ``(n_control,)`` is the pitch relative to the speaker's base F0 at
    :data:`CONTROL_RATE_HZ`, sample ``i`` at time ``i / CONTROL_RATE_HZ``.
    """

    speaker: str
    syllables: list[Syllable]
    accents: list[Accent]
    segments: Segments
    pitch_semitones: np.ndarray


class _SegmentList:
    """Collects segments row by row, then turns them into :class:`Segments`."""

    def __init__(self):
        self.rows: list[tuple] = []

    def add(
        self, kind: str, start: float, duration: float, level: float, attack: float, release: float
    ) -> None:
        if duration > 0 and level > 0:
            self.rows.append((KIND_INDEX[kind], start, duration, level, attack, release))

    def to_segments(self) -> Segments:
        table = np.array(self.rows, dtype=float).reshape(-1, 6)
        return Segments(table[:, 0].astype(np.int64), *table[:, 1:].T)


def plan_speech(
    utterances: list[Phrase],
    speaker: str,
    config: VoiceConfig,
    duration_s: float,
    rng: np.random.Generator,
) -> SpeechPlan:
    """Plan the syllables, accents, sound segments and pitch of one speaker's utterances."""
    own = sorted((u for u in utterances if u.speaker == speaker), key=lambda u: u.start)
    segments = _SegmentList()
    syllables: list[Syllable] = []
    pitch_moves: list[tuple[float, float, float]] = []  # (start, end, semitones): final movements
    for utterance in own:
        if utterance.kind == "phrase":
            new = _plan_phrase(utterance, config, rng, segments)
            final = (
                QUESTION_RISE_SEMITONES
                if rng.random() < config.question_probability
                else FINAL_FALL_SEMITONES
            )
        else:
            new = _plan_backchannel(utterance, config, rng, segments)
            final = 1.5
        pitch_moves.append((new[-1].vowel_onset, new[-1].end, final))
        syllables.extend(new)
    accents = [
        Accent(speaker, s.vowel_onset + VOWEL_ATTACK_S / 2, s.emphasis)
        for s in syllables
        if s.emphasis > 0
    ]
    pitch = _pitch_contour(own, syllables, pitch_moves, config, duration_s, rng)
    return SpeechPlan(speaker, syllables, accents, segments.to_segments(), pitch)


def _choose(rng: np.random.Generator, table: dict[str, float]) -> str:
    keys = list(table)
    return keys[rng.choice(len(keys), p=np.array(list(table.values())) / sum(table.values()))]


def _plan_phrase(
    phrase: Phrase, config: VoiceConfig, rng: np.random.Generator, segments: _SegmentList
) -> list[Syllable]:
    duration = phrase.end - phrase.start
    n = max(2, round(duration * rng.uniform(*config.syllable_rate_hz)))
    emphasis = np.zeros(n)
    accented = []
    index = int(rng.integers(0, min(3, n)))
    while index < n:
        accented.append(index)
        index += int(
            rng.integers(config.accent_spacing_syllables[0], config.accent_spacing_syllables[1] + 1)
        )
    low, high = config.emphasis_range
    emphasis[accented] = rng.uniform(low, high, len(accented))
    emphasis[accented[-1]] = rng.uniform((low + high) / 2, high)  # the nuclear accent

    weights = rng.uniform(0.8, 1.2, n)
    weights[emphasis > 0] *= config.accent_lengthening
    weights[-1] *= config.final_lengthening
    bounds = phrase.start + duration * np.concatenate([[0.0], np.cumsum(weights) / weights.sum()])
    position = (bounds[:-1] - phrase.start) / duration  # 0 at the phrase start, ~1 at its end
    gain_db = (
        config.accent_gain_db * emphasis
        - INTENSITY_DECLINATION_DB * position
        + rng.normal(0.0, 0.7, n) * (emphasis == 0)
    )
    levels = 10.0 ** (gain_db / 20.0)
    return [
        _plan_syllable(
            phrase.speaker,
            bounds[i],
            bounds[i + 1],
            _choose(rng, ONSETS),
            VOWELS[rng.integers(len(VOWELS))],
            _choose(rng, CODAS),
            levels[i],
            float(emphasis[i]),
            segments,
        )
        for i in range(n)
    ]


def _plan_backchannel(
    phrase: Phrase, config: VoiceConfig, rng: np.random.Generator, segments: _SegmentList
) -> list[Syllable]:
    level = 10.0 ** (config.backchannel_level_db / 20.0)
    if rng.random() < 0.5:  # "mm-hm": two nasal syllables
        parts = [("", "m", ""), ("h", "m", "")]
    else:  # "yeah" / "okay"
        parts = [("", "e", "")] if rng.random() < 0.5 else [("", "o", ""), ("k", "e", "")]
    bounds = np.linspace(phrase.start, phrase.end, len(parts) + 1)
    return [
        _plan_syllable(
            phrase.speaker,
            bounds[i],
            bounds[i + 1],
            *parts[i],
            level,
            0.0,
            segments,
            consonant_gain=level,
        )
        for i in range(len(parts))
    ]


def _plan_syllable(
    speaker: str,
    start: float,
    end: float,
    onset: str,
    vowel: str,
    coda: str,
    level: float,
    emphasis: float,
    segments: _SegmentList,
    consonant_gain: float = 1.0,
) -> Syllable:
    """Lay out one syllable's segments between ``start`` and ``end``; return its event.

    ``level`` is the vowel's amplitude (stress included); consonants get their
    :data:`CONSONANT_LEVEL` times ``consonant_gain``, whatever the stress.
    """
    duration = end - start
    if onset in PLOSIVES:
        onset_s = min(max(0.18 * duration, 0.03), 0.06) + BURST_S + ASPIRATION_S
    elif onset:
        onset_s = min(max(0.3 * duration, 0.04), 0.1)
    else:
        onset_s = 0.005
    coda_s = min(max(0.2 * duration, 0.03), 0.08) if coda else 0.0
    squeeze = min(1.0, 0.5 * duration / (onset_s + coda_s))  # the vowel keeps half the syllable
    onset_s, coda_s = onset_s * squeeze, coda_s * squeeze
    vowel_onset = start + onset_s
    vowel_end = end - coda_s

    if onset in PLOSIVES:  # closure (silence), burst, aspiration
        burst = vowel_onset - ASPIRATION_S * squeeze - BURST_S * squeeze
        segments.add(
            onset, burst, BURST_S * squeeze, consonant_gain * CONSONANT_LEVEL[onset], 0.001, 0.008
        )
        segments.add(
            "h",
            burst + BURST_S * squeeze,
            ASPIRATION_S * squeeze + 0.01,
            consonant_gain * CONSONANT_LEVEL["h"],
            0.003,
            0.01,
        )
    elif onset:  # overlaps the vowel's attack a little: coarticulation
        segments.add(
            onset, start, onset_s + 0.01, consonant_gain * CONSONANT_LEVEL[onset], 0.015, 0.015
        )
    vowel_level = level * (CONSONANT_LEVEL["m"] * 2 if vowel == "m" else 1.0)
    segments.add(
        vowel, vowel_onset, vowel_end - vowel_onset, vowel_level, VOWEL_ATTACK_S, VOWEL_RELEASE_S
    )
    if coda:
        segments.add(
            coda,
            vowel_end - 0.01,
            coda_s + 0.01,
            consonant_gain * CONSONANT_LEVEL[coda],
            0.015,
            0.02,
        )
    return Syllable(
        speaker, float(start), float(end), float(vowel_onset), onset, vowel, coda, emphasis
    )


def _pitch_contour(
    utterances: list[Phrase],
    syllables: list[Syllable],
    pitch_moves: list[tuple[float, float, float]],
    config: VoiceConfig,
    duration_s: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Pitch in semitones relative to the base F0, ``(n_control,)`` at :data:`CONTROL_RATE_HZ`."""
    n_control = int(np.ceil(duration_s * CONTROL_RATE_HZ)) + 2
    times = np.arange(n_control) / CONTROL_RATE_HZ
    pitch = np.zeros(n_control)
    if not utterances:
        return pitch
    # Declination: from +D/2 at each phrase start down to -D/2 at its end (held between phrases).
    half = config.declination_semitones / 2
    knots_t = np.array([[u.start, u.end] for u in utterances]).ravel()
    knots_v = np.array(
        [[half, -half] if u.kind == "phrase" else [0.0, 0.0] for u in utterances]
    ).ravel()
    pitch += np.interp(times, knots_t, knots_v)
    # The final fall (or rise) over the last syllable of each utterance.
    for start, end, semitones in pitch_moves:
        i0, i1 = int(start * CONTROL_RATE_HZ), int(np.ceil(end * CONTROL_RATE_HZ))
        pitch[i0:i1] += np.linspace(0.0, semitones, max(i1 - i0, 0))
    # +-0.5 semitone per syllable, softened.
    per_syllable = np.zeros(n_control)
    for syllable in syllables:
        i0, i1 = int(syllable.start * CONTROL_RATE_HZ), int(syllable.end * CONTROL_RATE_HZ)
        per_syllable[i0:i1] = rng.uniform(-0.5, 0.5)
    pitch += gaussian_filter1d(per_syllable, 3.0)
    # Accent peaks: an impulse per accent, spread into a Gaussian of unit peak height.
    sigma = ACCENT_PITCH_WIDTH_S * CONTROL_RATE_HZ
    impulses = np.zeros(n_control)
    for syllable in syllables:
        if syllable.emphasis > 0:
            centre = (syllable.vowel_onset + syllable.end) / 2
            index = min(int(round(centre * CONTROL_RATE_HZ)), n_control - 1)
            impulses[index] += config.accent_pitch_semitones * syllable.emphasis
    pitch += gaussian_filter1d(impulses, sigma) * np.sqrt(2 * np.pi) * sigma
    # A slow wander.
    wander = gaussian_filter1d(rng.standard_normal(n_control), 30.0)
    pitch += 0.5 * wander / max(wander.std(), 1e-9)
    return pitch
