"""Speech-like audio by source-filter synthesis, and the mix of the two voices into one track.

A voice is a *source* shaped by a *filter*, as in the human vocal tract:

* **Voiced sounds** (vowels, m, n, l, r): the source is the glottis, a pulse train at the pitch
  F0 whose harmonics fall off by 6 dB an octave (a band-limited sawtooth, made alias-free with
  PolyBLEP), plus a little breath noise. The filter is a cascade of second-order resonators
  (Klatt 1980), one per formant, run with ``scipy.signal.sosfilt``: the formants F1-F3 of
  :data:`FORMANTS` (Peterson and Barney's adult male averages) and a fixed F4. Speaker B's
  formants are ``b_formant_scale`` higher (a shorter vocal tract).
* **Noise sounds** (s, sh, f, h and the bursts of p, t, k): white noise through a band-pass
  filter of :data:`NOISE_BANDS`.

Each filter is normalised to unit output power, so the loudness of a segment is set by its level
alone (a stressed vowel is louder because its level is, not because of its vowel). Every segment
has a raised-cosine attack and release. The segments of one kind are gathered into one array,
filtered in one call and added back: the work is vectorised per kind, not per syllable.

Voices (:class:`Voice`, drawn per conversation): A is lower (base F0 drawn from ``VoiceConfig.a_f0_hz``),
B higher (``b_f0_hz``), quieter by ``b_level_db`` and muffled by a low-pass at ``b_lowpass_hz``: B is
off-microphone. :func:`mix` adds the two tracks and a noise floor (from a quiet studio to a noisy
room, drawn per conversation), and scales the result to ``peak_level``: a mono float32 track that
never clips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from data_synth.config import VoiceConfig
from data_synth.prosody import (
    CONTROL_RATE_HZ,
    SEGMENT_KINDS,
    VOICED_CONSONANTS,
    VOWELS,
    SpeechPlan,
)

#: Formants (frequency, bandwidth) in Hz of speaker A's voiced sounds. Vowels from Peterson and
#: Barney (1952); m, n, l, r rough values for nasal murmurs and liquids.
FORMANTS = {
    "a": ((730, 90), (1090, 110), (2440, 170)),
    "e": ((530, 70), (1840, 100), (2480, 160)),
    "i": ((270, 60), (2290, 100), (3010, 170)),
    "o": ((570, 80), (840, 90), (2410, 160)),
    "u": ((300, 60), (870, 90), (2240, 150)),
    "l": ((360, 80), (1100, 150), (2700, 200)),
    "r": ((420, 80), (1300, 120), (1600, 150)),
    "m": ((250, 60), (1000, 300), (2200, 400)),
    "n": ((250, 60), (1600, 300), (2600, 400)),
}
#: A fourth formant shared by all voiced sounds; it gives the voice some brightness.
FOURTH_FORMANT = (3300, 250)
#: Pass bands in Hz of the noise sounds (upper edges are kept below 0.47 x the sample rate).
NOISE_BANDS = {
    "s": (4000, 7500),
    "sh": (2000, 5000),
    "f": (1000, 7000),
    "h": (400, 3000),
    "p": (300, 1500),
    "t": (3000, 7000),
    "k": (1200, 3200),
}
#: Breath noise mixed into the glottal source, relative to the source's amplitude.
BREATHINESS = 0.08
#: A filtered segment rings on after its end; this much of the ringing is kept.
RING_S = 0.03


@dataclass(frozen=True)
class Voice:
    """One speaker's voice: base pitch, formant scale, level in dB re speaker A, low-pass."""

    speaker: str
    f0_hz: float
    formant_scale: float
    level_db: float
    lowpass_hz: float | None


def draw_voices(config: VoiceConfig, rng: np.random.Generator) -> dict[str, Voice]:
    """Draw the two voices of a conversation: ``{"A": Voice, "B": Voice}``."""
    return {
        "A": Voice(
            "A", float(rng.uniform(*config.a_f0_hz)), float(rng.uniform(0.97, 1.03)), 0.0, None
        ),
        "B": Voice(
            "B",
            float(rng.uniform(*config.b_f0_hz)),
            float(config.b_formant_scale * rng.uniform(0.97, 1.03)),
            config.b_level_db,
            config.b_lowpass_hz,
        ),
    }


def synthesize_speech(
    plan: SpeechPlan, voice: Voice, n_samples: int, sample_rate: int, rng: np.random.Generator
) -> np.ndarray:
    """Render one speaker's plan into a track ``(n_samples,)`` float64 at ``sample_rate``."""
    track = np.zeros(n_samples)
    segments = plan.segments
    if segments.kind.size == 0:
        return track
    starts = np.round(segments.start_s * sample_rate).astype(np.int64)
    lengths = np.maximum(np.round(segments.duration_s * sample_rate).astype(np.int64), 1)
    ring = int(RING_S * sample_rate)
    voiced_kinds = [SEGMENT_KINDS.index(k) for k in VOWELS + VOICED_CONSONANTS]
    is_voiced = np.isin(segments.kind, voiced_kinds)
    source = _glottal_source(
        plan.pitch_semitones,
        voice.f0_hz,
        starts[is_voiced],
        lengths[is_voiced] + ring,
        n_samples,
        sample_rate,
        rng,
    )
    lowpass = None
    if voice.lowpass_hz is not None:
        lowpass = scipy.signal.butter(2, voice.lowpass_hz, fs=sample_rate, output="sos")

    for kind_index, kind in enumerate(SEGMENT_KINDS):
        rows = np.flatnonzero(segments.kind == kind_index)
        if rows.size == 0:
            continue
        index, local, row = _gather(starts[rows], lengths[rows] + ring, n_samples)
        seconds = local / sample_rate
        envelope = segments.level[rows][row] * _ramp(
            seconds,
            segments.duration_s[rows][row],
            segments.attack_s[rows][row],
            segments.release_s[rows][row],
        )
        if kind in FORMANTS:
            sos = _formant_filter(kind, voice, sample_rate)
            excitation = source[index] + BREATHINESS * rng.standard_normal(index.size)
        else:
            sos = _noise_filter(kind, sample_rate)
            excitation = rng.standard_normal(index.size)
        if lowpass is not None:
            sos = np.concatenate([sos, lowpass])
        np.add.at(track, index, scipy.signal.sosfilt(sos, envelope * excitation))
    return track


def mix(tracks: list[np.ndarray], config: VoiceConfig, rng: np.random.Generator) -> np.ndarray:
    """Add the speakers' tracks ``(n,)`` and a noise floor drawn from ``noise_floor_db``; scale to
    ``peak_level``: float32."""
    total = np.sum(tracks, axis=0)
    peak = float(np.abs(total).max())
    if peak > 0:
        total *= config.peak_level / peak
    noise_level = config.peak_level * 10.0 ** (rng.uniform(*config.noise_floor_db) / 20.0)
    total += noise_level * rng.standard_normal(total.size)
    return total.astype(np.float32)


def _gather(starts: np.ndarray, lengths: np.ndarray, n_samples: int):
    """Sample indices of many segments at once.

    Returns ``(index, local, row)``, each ``(sum(lengths),)`` minus the samples past the end:
    the sample index, the offset within its segment and which segment it belongs to.
    """
    row = np.repeat(np.arange(starts.size), lengths)
    first = np.repeat(np.cumsum(lengths) - lengths, lengths)
    local = np.arange(row.size) - first
    index = starts[row] + local
    keep = (index >= 0) & (index < n_samples)
    return index[keep], local[keep], row[keep]


def _ramp(
    t: np.ndarray, duration: np.ndarray, attack: np.ndarray, release: np.ndarray
) -> np.ndarray:
    """Raised-cosine attack and release of a segment lasting ``duration``; 0 after its end."""
    rise = np.clip(t / attack, 0.0, 1.0)
    fall = np.clip((duration - t) / release, 0.0, 1.0)
    return (0.5 - 0.5 * np.cos(np.pi * rise)) * (0.5 - 0.5 * np.cos(np.pi * fall))


def _glottal_source(
    pitch_semitones: np.ndarray,
    f0_hz: float,
    starts: np.ndarray,
    lengths: np.ndarray,
    n_samples: int,
    sample_rate: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """A band-limited sawtooth ``(n_samples,)`` at the pitch contour, where voicing is needed.

    Only the samples of the voiced segments are computed; elsewhere the source is zero (those
    samples are never heard: every segment's envelope is zero outside the segment).
    """
    needed = np.zeros(n_samples, dtype=bool)
    index, _, _ = _gather(starts, lengths, n_samples)
    needed[index] = True
    samples = np.flatnonzero(needed)
    control_times = np.arange(pitch_semitones.size) / CONTROL_RATE_HZ
    semitones = np.interp(samples / sample_rate, control_times, pitch_semitones)
    increment = f0_hz * 2.0 ** (semitones / 12.0) / sample_rate  # cycles per sample
    phase = (np.cumsum(increment) + rng.random()) % 1.0
    saw = 2.0 * phase - 1.0
    # PolyBLEP: smooth the jump of the sawtooth over one sample on either side (no aliasing).
    just_after = phase < increment
    x = phase[just_after] / increment[just_after]
    saw[just_after] -= 2.0 * x - x * x - 1.0
    just_before = phase > 1.0 - increment
    x = (phase[just_before] - 1.0) / increment[just_before]
    saw[just_before] -= x * x + 2.0 * x + 1.0
    source = np.zeros(n_samples)
    source[samples] = saw
    return source


def _resonator(frequency: float, bandwidth: float, sample_rate: int) -> np.ndarray:
    """One formant: a second-order resonator with unit gain at 0 Hz (Klatt 1980), as an SOS row."""
    radius = np.exp(-np.pi * bandwidth / sample_rate)
    b1 = 2.0 * radius * np.cos(2.0 * np.pi * frequency / sample_rate)
    b2 = -radius * radius
    return np.array([1.0 - b1 - b2, 0.0, 0.0, 1.0, -b1, -b2])


def _formant_filter(kind: str, voice: Voice, sample_rate: int) -> np.ndarray:
    """The cascade of formant resonators of a voiced sound, normalised to unit output power
    for the speaker's sawtooth source: ``(4, 6)`` second-order sections."""
    formants = [*FORMANTS[kind], FOURTH_FORMANT]
    nyquist_guard = 0.45 * sample_rate
    sos = np.array(
        [
            _resonator(
                min(f * voice.formant_scale, nyquist_guard), b * voice.formant_scale, sample_rate
            )
            for f, b in formants
        ]
    )
    # Power of a sawtooth through the filter: harmonic h has amplitude ~ 1/h.
    harmonics = np.arange(1, int(sample_rate / 2 / voice.f0_hz) + 1)
    _, response = scipy.signal.sosfreqz(sos, worN=harmonics * voice.f0_hz, fs=sample_rate)
    gain = np.sqrt(np.sum(1.0 / harmonics**2) / np.sum(np.abs(response) ** 2 / harmonics**2))
    sos[0, :3] *= gain
    return sos


def _noise_filter(kind: str, sample_rate: int) -> np.ndarray:
    """A band-pass for a noise sound, normalised to unit output power for white noise."""
    low, high = NOISE_BANDS[kind]
    high = min(high, 0.47 * sample_rate)
    sos = scipy.signal.butter(2, [low, high], btype="bandpass", fs=sample_rate, output="sos")
    _, response = scipy.signal.sosfreqz(sos, worN=2048)
    sos[0, :3] /= np.sqrt(np.mean(np.abs(response) ** 2))
    return sos
