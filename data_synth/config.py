"""The generator's parameters: one frozen dataclass per part, validated when it is built.

* :class:`TurnConfig`: who speaks when (:mod:`data_synth.turns`).
* :class:`VoiceConfig`: syllables, stress, intonation and the two voices (:mod:`data_synth.prosody`,
  :mod:`data_synth.voice`).
* :class:`MotionConfig`: the agent's gestures, nods and idle motion (:mod:`data_synth.gestures`,
  :mod:`data_synth.nods`, :mod:`data_synth.motion`).
* :class:`StyleRanges`: the ranges from which each conversation draws the speaker's gesture style
  (:mod:`data_synth.style`).
* :class:`ConversationConfig`: all of the above plus the frame and sample rates.

A pair ``(low, high)`` is a range from which a value is drawn uniformly. The defaults are what
the dataset uses; change one with ``dataclasses.replace``. Numbers may be Python's or NumPy's
scalars (``np.float64(0.2)``, ``np.int64(16000)``); they are stored as Python numbers, so a
config reads the same and writes the same JSON whichever was given. A bad value raises
:class:`ConfigError` (a ``ValueError``) naming the field, what it got and what it expected, e.g.
``TurnConfig.overlap_probability must be in [0, 1], got 1.5``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from gesturelib.conventions import FPS, SAMPLE_RATE


class ConfigError(ValueError):
    """A generator parameter that cannot be used: a config field, a duration, a seed or a size.

    The message names the parameter, what it got and what it expects.
    """


# --------------------------------------------------------------------------- checks


def check_value(
    value,
    where: str,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    integer: bool = False,
):
    """``value`` as a Python number, which must be finite and in ``[low, high]``.

    ``(low, high]`` if ``low_open``; an integer if ``integer``. NumPy scalars are accepted and
    returned as Python numbers; booleans and strings are refused. Raises :class:`ConfigError`
    naming ``where``.
    """
    if isinstance(value, np.generic):
        value = value.item()  # np.float32(0.5) -> 0.5, np.int64(3) -> 3, np.bool_ -> bool
    if integer and not (isinstance(value, int) and not isinstance(value, bool)):
        raise ConfigError(f"{where} must be an integer, got {value!r}")
    if not (
        isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    ):
        raise ConfigError(f"{where} must be a finite number, got {value!r}")
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        left = "(" if low_open else "["
        interval = f"{left}{'-inf' if low is None else low}, {'inf' if high is None else high}]"
        raise ConfigError(f"{where} must be in {interval}, got {value!r}")
    return value


def _check_number(config, name: str, *args, **kwargs) -> None:
    """``config.name`` must be a finite number in the interval (see :func:`check_value`)."""
    value = check_value(getattr(config, name), f"{type(config).__name__}.{name}", *args, **kwargs)
    object.__setattr__(config, name, value)  # a NumPy scalar becomes a Python number


def _check_range(config, name: str, *args, **kwargs) -> None:
    """``config.name`` must be a pair ``(a, b)`` with ``a <= b``, both in the interval."""
    value = getattr(config, name)
    where = f"{type(config).__name__}.{name}"
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = tuple(value)
    if not (isinstance(value, (tuple, list)) and len(value) == 2):
        raise ConfigError(f"{where} must be a pair (low, high), got {value!r}")
    value = tuple(
        check_value(end, f"both ends of {where} = {value!r}", *args, **kwargs) for end in value
    )
    if value[0] > value[1]:
        raise ConfigError(f"{where} must be a pair (low, high) with low <= high, got {value!r}")
    object.__setattr__(config, name, value)  # a list (from JSON) or an array becomes a tuple


def _probability(config, name: str) -> None:
    _check_number(config, name, 0.0, 1.0)


def _positive(config, name: str) -> None:
    _check_number(config, name, 0.0, low_open=True)


def _non_negative(config, name: str) -> None:
    _check_number(config, name, 0.0)


# --------------------------------------------------------------------------- turn-taking


@dataclass(frozen=True)
class TurnConfig:
    """Turn-taking: a turn is a run of phrases by one speaker; turns alternate.

    Attributes:
        a_phrases_per_turn: mean number of phrases in a turn of A (1 + Poisson); >= 1.
        b_phrases_per_turn: the same for B. A's turns are longer: A speaks more, as in the
            Flow-VAE dataset.
        a_phrase_s: range of the duration of one phrase of A, seconds.
        b_phrase_s: the same for B.
        phrase_pause_s: pause between two phrases of one turn.
        turn_gap_s: silence between two turns.
        overlap_probability: chance that the next speaker starts before the current one ends.
        overlap_s: how long the two then talk at once (cross-talk).
        long_silence_probability: chance of a long silence between turns instead.
        long_silence_s: its duration.
        keep_turn_probability: chance that the same speaker takes the next turn.
        backchannel_probability: chance that the listener says "mm-hm" after a phrase.
        backchannel_s: duration of a backchannel.
        first_speaker_a_probability: chance that A opens the conversation.
        lead_in_s: silence before the first phrase.
    """

    a_phrases_per_turn: float = 3.0
    b_phrases_per_turn: float = 1.7
    a_phrase_s: tuple[float, float] = (1.2, 3.0)
    b_phrase_s: tuple[float, float] = (0.9, 2.4)
    phrase_pause_s: tuple[float, float] = (0.2, 0.6)
    turn_gap_s: tuple[float, float] = (0.2, 0.8)
    overlap_probability: float = 0.2
    overlap_s: tuple[float, float] = (0.15, 0.5)
    long_silence_probability: float = 0.15
    long_silence_s: tuple[float, float] = (1.0, 2.5)
    keep_turn_probability: float = 0.15
    backchannel_probability: float = 0.4
    backchannel_s: tuple[float, float] = (0.3, 0.55)
    first_speaker_a_probability: float = 0.6
    lead_in_s: tuple[float, float] = (0.3, 1.0)

    def __post_init__(self):
        _check_number(self, "a_phrases_per_turn", 1.0)
        _check_number(self, "b_phrases_per_turn", 1.0)
        for name in ("a_phrase_s", "b_phrase_s", "backchannel_s"):
            _check_range(self, name, 0.2)
        for name in ("phrase_pause_s", "turn_gap_s", "overlap_s", "long_silence_s"):
            _check_range(self, name, 0.0, low_open=True)
        _check_range(self, "lead_in_s", 0.0)
        for name in (
            "overlap_probability",
            "long_silence_probability",
            "keep_turn_probability",
            "backchannel_probability",
            "first_speaker_a_probability",
        ):
            _probability(self, name)
        if self.overlap_probability + self.long_silence_probability > 1.0:
            raise ConfigError(
                "TurnConfig.overlap_probability + TurnConfig.long_silence_probability must not "
                f"exceed 1, got {self.overlap_probability} + {self.long_silence_probability}"
            )
        shortest_phrase = min(self.a_phrase_s[0], self.b_phrase_s[0])
        if self.overlap_s[1] >= shortest_phrase:
            raise ConfigError(
                f"TurnConfig.overlap_s must stay below the shortest phrase ({shortest_phrase} s) "
                f"so that an overlap never swallows a whole phrase, got {self.overlap_s!r}"
            )


# --------------------------------------------------------------------------- voices


@dataclass(frozen=True)
class VoiceConfig:
    """Syllables, stress, intonation and the two voices.

    Attributes:
        syllable_rate_hz: syllables per second within a phrase (drawn per phrase).
        accent_spacing_syllables: syllables from one accent to the next (integers >= 2).
        emphasis_range: emphasis of an accent, in (0, 1]; the last accent of a phrase (the
            nuclear accent) gets the upper half of the range.
        accent_gain_db: extra loudness of an accented vowel at emphasis 1, 0 to 40 dB.
        accent_lengthening: duration factor of an accented syllable (>= 1).
        accent_pitch_semitones: height of the pitch peak on an accent at emphasis 1.
        final_lengthening: duration factor of a phrase's last syllable (>= 1).
        declination_semitones: fall of the pitch baseline from a phrase's start to its end.
        question_probability: chance that a phrase ends rising instead of falling.
        a_f0_hz: range of speaker A's base pitch (drawn per conversation): a lower voice, from
            deep to middling, so that the models meet more than one voice.
        b_f0_hz: the same for B: a higher, female voice.
        b_formant_scale: B's formant frequencies relative to A's (a shorter vocal tract).
        b_level_db: B's level relative to A's: B is off-microphone, quieter.
        b_lowpass_hz: B's voice is muffled by this low-pass (off-microphone).
        backchannel_level_db: level of a backchannel relative to its speaker's phrases.
        noise_floor_db: range of the background noise relative to the peak of the mix (drawn per
            conversation): from a quiet studio to a noisy room.
        peak_level: the mix is scaled to this peak amplitude (< 1: never clips).
    """

    syllable_rate_hz: tuple[float, float] = (4.0, 6.0)
    accent_spacing_syllables: tuple[int, int] = (3, 5)
    emphasis_range: tuple[float, float] = (0.4, 1.0)
    accent_gain_db: float = 8.0
    accent_lengthening: float = 1.4
    accent_pitch_semitones: float = 4.0
    final_lengthening: float = 1.3
    declination_semitones: float = 3.0
    question_probability: float = 0.2
    a_f0_hz: tuple[float, float] = (95.0, 165.0)
    b_f0_hz: tuple[float, float] = (200.0, 220.0)
    b_formant_scale: float = 1.17
    b_level_db: float = -9.0
    b_lowpass_hz: float = 3500.0
    backchannel_level_db: float = -4.0
    noise_floor_db: tuple[float, float] = (-60.0, -30.0)
    peak_level: float = 0.8

    def __post_init__(self):
        _check_range(self, "syllable_rate_hz", 0.0, low_open=True)
        _check_range(self, "accent_spacing_syllables", 2, integer=True)
        _check_range(self, "emphasis_range", 0.0, 1.0, low_open=True)
        _check_number(self, "accent_gain_db", 0.0, 40.0)
        _check_number(self, "accent_lengthening", 1.0)
        _non_negative(self, "accent_pitch_semitones")
        _check_number(self, "final_lengthening", 1.0)
        _check_number(self, "declination_semitones")
        _probability(self, "question_probability")
        _check_range(self, "a_f0_hz", 50.0, 500.0)
        _check_range(self, "b_f0_hz", 50.0, 500.0)
        _positive(self, "b_formant_scale")
        _check_number(self, "b_level_db", high=0.0)
        _positive(self, "b_lowpass_hz")
        _check_number(self, "backchannel_level_db", high=0.0)
        _check_range(self, "noise_floor_db", high=-20.0)
        _check_number(self, "peak_level", 0.0, 1.0, low_open=True)


# --------------------------------------------------------------------------- motion


@dataclass(frozen=True)
class MotionConfig:
    """The agent's motion rules (see :mod:`data_synth.motion` for the rules themselves).

    Attributes:
        stroke_lead_s: the peak of wrist speed of a beat comes this long *before* its accent.
        stroke_duration_s: duration of a beat's downward stroke (at style speed 1).
        stroke_timing_jitter_s: standard deviation of a beat's timing around the rule.
        rebound_s: time for the hand to recover after the last beat of a phrase.
        preparation_s: time for the hands to rise into the gesture space before a phrase.
        retraction_s: time for the hands to return home (in front of the belly) after a phrase.
        accent_nod_probability: chance of a head nod on an accent, times its emphasis.
        accent_nod_deg: amplitude of such a nod at emphasis 1, degrees.
        listening_nod_probability: chance of a nod when the partner ends a phrase.
        listening_nod_deg: amplitude range of a listening nod, degrees.
        nod_delay_s: delay of a listening nod after the partner's phrase end.
        nod_duration_s: duration of one down-and-up nod (at style speed 1).
        breathing_rate_hz: range of the breathing rate (drawn per motion draw).
        sway_deg: standard deviation of the slow sway of the torso while gesturing.
        idle_hand_cm: standard deviation of the slow drift of the hands while gesturing.
        listening_activity: scale of the idle motion (sway, head and hand drift) outside the
            agent's gesture phrases, in (0, 1]: a listener moves less.
    """

    stroke_lead_s: float = 0.2
    stroke_duration_s: float = 0.2
    stroke_timing_jitter_s: float = 0.02
    rebound_s: float = 0.35
    preparation_s: float = 0.5
    retraction_s: float = 0.6
    accent_nod_probability: float = 0.5
    accent_nod_deg: float = 6.0
    listening_nod_probability: float = 0.8
    listening_nod_deg: tuple[float, float] = (4.0, 9.0)
    nod_delay_s: tuple[float, float] = (0.1, 0.35)
    nod_duration_s: float = 0.45
    breathing_rate_hz: tuple[float, float] = (0.2, 0.3)
    sway_deg: float = 1.5
    idle_hand_cm: float = 1.5
    listening_activity: float = 0.4

    def __post_init__(self):
        _non_negative(self, "stroke_lead_s")
        for name in (
            "stroke_duration_s",
            "rebound_s",
            "preparation_s",
            "retraction_s",
            "nod_duration_s",
        ):
            _check_number(self, name, 0.05)
        _non_negative(self, "stroke_timing_jitter_s")
        _probability(self, "accent_nod_probability")
        _probability(self, "listening_nod_probability")
        _non_negative(self, "accent_nod_deg")
        _check_range(self, "listening_nod_deg", 0.0, 30.0)
        _check_range(self, "nod_delay_s", 0.0)
        _check_range(self, "breathing_rate_hz", 0.0, 2.0, low_open=True)
        _non_negative(self, "sway_deg")
        _non_negative(self, "idle_hand_cm")
        _check_number(self, "listening_activity", 0.0, 1.0, low_open=True)


@dataclass(frozen=True)
class StyleRanges:
    """Ranges of the per-conversation gesture style (see :class:`data_synth.style.Style`)."""

    gesture_radius_cm: tuple[float, float] = (10.0, 20.0)
    hand_height_cm: tuple[float, float] = (14.0, 20.0)
    speed: tuple[float, float] = (0.8, 1.25)
    symmetry: tuple[float, float] = (0.2, 0.8)
    handedness: tuple[float, float] = (0.3, 0.9)
    beat_amplitude_cm: tuple[float, float] = (11.0, 20.0)

    def __post_init__(self):
        _check_range(self, "gesture_radius_cm", 0.0, 25.0)
        _check_range(self, "hand_height_cm", 0.0, 30.0)
        _check_range(self, "speed", 0.5, 2.0)
        _check_range(self, "symmetry", 0.0, 1.0)
        _check_range(self, "handedness", 0.0, 1.0)
        _check_range(self, "beat_amplitude_cm", 0.0, 25.0)


# --------------------------------------------------------------------------- everything


@dataclass(frozen=True)
class ConversationConfig:
    """Everything :func:`data_synth.generate_conversation` needs besides the duration and seeds.

    Attributes:
        turns, voice, motion, style: the parts above.
        sample_rate: audio samples per second, 16 to 96 kHz (16 kHz at least: the fricatives
            reach 7.5 kHz).
        fps: motion frames per second, 1 to 240.
    """

    turns: TurnConfig = field(default_factory=TurnConfig)
    voice: VoiceConfig = field(default_factory=VoiceConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    style: StyleRanges = field(default_factory=StyleRanges)
    sample_rate: int = SAMPLE_RATE
    fps: int = FPS

    def __post_init__(self):
        for name, kind in (
            ("turns", TurnConfig),
            ("voice", VoiceConfig),
            ("motion", MotionConfig),
            ("style", StyleRanges),
        ):
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(
                    f"ConversationConfig.{name} must be a {kind.__name__}, "
                    f"got {type(getattr(self, name)).__name__}"
                )
        _check_number(self, "sample_rate", 16000, 96000, integer=True)
        _check_number(self, "fps", 1, 240, integer=True)
        shortest_phrase = self.turns.a_phrase_s[0]
        if self.motion.stroke_lead_s >= shortest_phrase:
            raise ConfigError(
                f"MotionConfig.stroke_lead_s ({self.motion.stroke_lead_s} s) must be shorter than "
                f"the shortest phrase of A (TurnConfig.a_phrase_s[0] = {shortest_phrase} s)"
            )
        # Beats must fit between accents: the closest accents are accent_spacing_syllables[0]
        # syllables apart at the fastest syllable rate.
        closest_accents = self.voice.accent_spacing_syllables[0] / self.voice.syllable_rate_hz[1]
        slowest_stroke = self.motion.stroke_duration_s / self.style.speed[0]
        if slowest_stroke >= 0.8 * closest_accents:
            raise ConfigError(
                f"MotionConfig.stroke_duration_s / StyleRanges.speed[0] = {slowest_stroke:.3g} s "
                f"must be below 0.8 x the closest spacing of accents ({closest_accents:.3g} s) "
                "so that consecutive beats do not collide"
            )
        if self.voice.b_lowpass_hz >= self.sample_rate / 2:
            raise ConfigError(
                f"VoiceConfig.b_lowpass_hz ({self.voice.b_lowpass_hz} Hz) must be below the "
                f"Nyquist frequency ({self.sample_rate / 2} Hz)"
            )

    def to_dict(self) -> dict:
        """Plain nested dictionaries, ready for ``json.dump``."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> ConversationConfig:
        """Inverse of :meth:`to_dict`; unknown or missing keys raise ``ValueError``."""
        parts = {
            "turns": TurnConfig,
            "voice": VoiceConfig,
            "motion": MotionConfig,
            "style": StyleRanges,
        }
        _check_keys(data, cls, "config")
        kwargs = {}
        for name, value in data.items():
            if name in parts:
                _check_keys(value, parts[name], f"config[{name!r}]")
                kwargs[name] = parts[name](
                    **{
                        key: tuple(item) if isinstance(item, list) else item
                        for key, item in value.items()
                    }
                )
            else:
                kwargs[name] = value
        return cls(**kwargs)


def _check_keys(data, kind, where: str) -> None:
    if not isinstance(data, dict):
        raise ConfigError(f"{where} must be a dictionary, got {type(data).__name__}")
    expected = {f.name for f in fields(kind)}
    unknown, missing = set(data) - expected, expected - set(data)
    if unknown or missing:
        raise ConfigError(
            f"{where} does not match {kind.__name__}: unknown keys {sorted(unknown)}, "
            f"missing keys {sorted(missing)}"
        )
