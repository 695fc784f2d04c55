"""Tests of data_synth's turn-taking and speech audio, measured from the waveform itself."""

from __future__ import annotations

import librosa
import numpy as np
import pytest
import scipy.signal

from data_synth import TurnConfig, generate_conversation
from data_synth.emphasis import loudness
from data_synth.events import Phrase
from data_synth.turns import activity_codes, sample_turns
from gesturelib.conventions import Activity


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(60.0, seed=11)


# --------------------------------------------------------------------------- turn-taking


def test_activity_codes_follow_the_utterances_at_frame_centres():
    utterances = [Phrase("A", 0.1, 0.3), Phrase("B", 0.25, 0.45, "backchannel")]
    # Frame centres at 10 fps: 0.05, 0.15, 0.25, 0.35, 0.45, 0.55.
    codes = activity_codes(utterances, 6, 10)
    expected = [
        Activity.NONE,
        Activity.A_SPEAKS,
        Activity.BOTH,
        Activity.B_SPEAKS,
        Activity.NONE,
        Activity.NONE,
    ]
    np.testing.assert_array_equal(codes, expected)
    assert codes.dtype == np.int64


def test_turn_taking_has_its_ingredients_and_a_speaks_more():
    duration = 600.0
    utterances = sample_turns(duration, TurnConfig(), np.random.default_rng(0))
    codes = activity_codes(utterances, int(duration * 25), 25)
    share = np.bincount(codes, minlength=4) / codes.size
    assert share[Activity.A_SPEAKS] > 1.5 * share[Activity.B_SPEAKS] > 0
    assert 0 < share[Activity.BOTH] < 0.1  # some cross-talk
    assert 0.05 < share[Activity.NONE] < 0.4  # pauses and silences
    assert any(u.kind == "backchannel" and u.speaker == "B" for u in utterances)
    assert any(u.kind == "backchannel" and u.speaker == "A" for u in utterances)
    for speaker in "AB":  # one speaker's utterances never overlap, and all fit in the audio
        own = [u for u in utterances if u.speaker == speaker]
        assert all(b.start >= a.end for a, b in zip(own, own[1:], strict=False))
    assert utterances[-1].end <= duration and all(u.end > u.start for u in utterances)
    phrases = np.array(
        [u.end - u.start for u in utterances if u.speaker == "A" and u.kind == "phrase"]
    )
    assert phrases.min() >= 1.2 and phrases.max() <= 3.0


def test_turns_are_reproducible():
    first = sample_turns(60.0, TurnConfig(), np.random.default_rng(5))
    assert first == sample_turns(60.0, TurnConfig(), np.random.default_rng(5))
    assert first != sample_turns(60.0, TurnConfig(), np.random.default_rng(6))


# --------------------------------------------------------------------------- audio


def test_audio_is_mono_float32_at_the_sample_rate_and_never_clips(conversation):
    audio = conversation.audio
    assert audio.dtype == np.float32 and audio.ndim == 1
    assert audio.size == 60 * conversation.sample_rate == 60 * 16000
    assert np.all(np.isfinite(audio))
    assert 0.5 < np.abs(audio).max() <= 0.81  # scaled to a peak of 0.8, plus the noise floor


def test_frames_align_with_the_audio(conversation):
    n_frames = conversation.audio.size * conversation.fps // conversation.sample_rate
    assert conversation.num_frames == n_frames == 1500
    assert conversation.activity.shape == (n_frames,)
    assert conversation.rotations.shape == (n_frames, 9, 6)
    assert conversation.positions.shape == (n_frames, 9, 3)


def test_speech_is_loud_where_someone_speaks_and_b_is_quieter(conversation):
    level = loudness(conversation.audio, conversation.sample_rate, conversation.fps)
    by_class = {a: np.median(level[conversation.activity == a]) for a in Activity}
    assert by_class[Activity.A_SPEAKS] > 1.5 * by_class[Activity.B_SPEAKS]  # B is off-mic
    assert by_class[Activity.B_SPEAKS] > 3 * by_class[Activity.NONE]  # silence is quiet


def test_syllables_come_at_a_natural_rate(conversation):
    # Count the peaks of the log energy envelope (10 ms hop) inside the agent's phrases.
    audio = conversation.audio.astype(np.float64)
    hop = conversation.sample_rate // 100
    energy = np.convolve(audio**2, np.ones(400) / 400, "same")[::hop]
    peaks, _ = scipy.signal.find_peaks(10 * np.log10(energy + 1e-10), prominence=4, distance=8)
    peak_times = peaks * hop / conversation.sample_rate
    phrases = conversation.events.phrases_of("A")
    inside = sum(any(p.start <= t < p.end for p in phrases) for t in peak_times)
    rate = inside / sum(p.end - p.start for p in phrases)
    assert 4.0 <= rate <= 7.0


def test_speakers_have_their_pitch(conversation):
    audio, sample_rate = conversation.audio, conversation.sample_rate
    hop = sample_rate // 100
    f0 = librosa.yin(audio, fmin=60, fmax=400, sr=sample_rate, frame_length=1024, hop_length=hop)
    frames = np.minimum(
        np.arange(f0.size) * hop * conversation.fps // sample_rate, conversation.num_frames - 1
    )
    rms = librosa.feature.rms(y=audio, frame_length=1024, hop_length=hop)[0][: f0.size]
    voiced = rms > 0.05 * rms.max()
    f0_a = np.median(f0[voiced & (conversation.activity[frames] == Activity.A_SPEAKS)])
    f0_b = np.median(f0[voiced & (conversation.activity[frames] == Activity.B_SPEAKS)])
    assert 90 < f0_a < 185  # a lower voice, base 95-165 Hz plus accents
    assert 190 < f0_b < 240  # a high voice, base 200-220 Hz
    assert f0_a == pytest.approx(conversation.voices["A"].f0_hz, rel=0.12)
    assert f0_b == pytest.approx(conversation.voices["B"].f0_hz, rel=0.12)


def test_stressed_syllables_are_louder_and_longer(conversation):
    level = loudness(conversation.audio, conversation.sample_rate, conversation.fps)
    fps = conversation.fps
    syllables = [s for s in conversation.events.syllables if s.speaker == "A"]

    def peak_loudness(s):
        return level[int(s.vowel_onset * fps) : int(s.end * fps) + 1].max()

    stressed = [s for s in syllables if s.emphasis > 0]
    unstressed = [s for s in syllables if s.emphasis == 0]
    assert len(stressed) > 20 and len(unstressed) > 2 * len(stressed)
    ratio = np.median([peak_loudness(s) for s in stressed]) / np.median(
        [peak_loudness(s) for s in unstressed]
    )
    assert ratio > 1.3  # at least +4 dB of power (loudness ~ power ** 0.3)
    duration = np.median([s.end - s.start for s in stressed]) / np.median(
        [s.end - s.start for s in unstressed]
    )
    assert duration > 1.2
