"""Tests for gesturelib.features: audio loading/saving, frame-aligned speech features, activity."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.fft
import scipy.signal
import soundfile

from data_synth import ConversationConfig, generate_conversation
from data_synth.config import VoiceConfig
from gesturelib import features
from gesturelib.conventions import Activity
from gesturelib.features import (
    MEL_FLOOR,
    PROSODY_FEATURES,
    AudioError,
    activity_from_one_hot,
    activity_one_hot,
    load_audio,
    mel_spectrogram,
    mfcc,
    num_frames,
    prosody,
    save_audio,
)

LOG_ENERGY, LOG_F0, D_LOG_ENERGY, D_LOG_F0 = range(4)


def sine(frequency, seconds, sample_rate, amplitude=0.5):
    t = np.arange(round(seconds * sample_rate)) / sample_rate
    return (amplitude * np.sin(2 * np.pi * frequency * t)).astype(np.float32)


def peak_frequency(audio, sample_rate):
    spectrum = np.abs(np.fft.rfft(audio * np.hanning(audio.size)))
    return np.fft.rfftfreq(audio.size, 1 / sample_rate)[spectrum.argmax()]


# --------------------------------------------------------------------------- load_audio


@pytest.mark.parametrize(
    ("subtype", "tolerance"),
    [
        ("PCM_U8", 2**-7),
        ("PCM_16", 2**-15),
        ("PCM_24", 2**-23),
        ("PCM_32", 1e-6),
        ("FLOAT", 0.0),
        ("DOUBLE", 1e-7),
    ],
)
def test_load_audio_reads_every_wav_sample_format(tmp_path, subtype, tolerance):
    original = sine(440, 0.25, 16000)
    path = tmp_path / f"{subtype}.wav"
    soundfile.write(path, original, 16000, subtype=subtype)
    audio, rate = load_audio(path)
    assert rate == 16000
    assert audio.dtype == np.float32 and audio.shape == original.shape
    np.testing.assert_allclose(audio, original, atol=tolerance + 1e-7)


def test_load_audio_averages_stereo_channels(tmp_path):
    left, right = sine(440, 0.25, 16000, 0.6), sine(1000, 0.25, 16000, 0.2)
    path = tmp_path / "stereo.wav"
    soundfile.write(path, np.stack([left, right], axis=1), 16000, subtype="FLOAT")
    audio, _ = load_audio(path)
    assert audio.ndim == 1
    np.testing.assert_allclose(audio, (left + right) / 2, atol=1e-7)


@pytest.mark.parametrize("file_rate", [8000, 11025, 22050, 44100])
def test_load_audio_resamples_keeping_length_and_pitch(tmp_path, file_rate):
    path = tmp_path / "tone.wav"
    original = sine(440, 0.9, file_rate)
    soundfile.write(path, original, file_rate, subtype="PCM_16")
    audio, rate = load_audio(path, sample_rate=16000)
    assert rate == 16000 and audio.dtype == np.float32
    assert audio.size == int(np.ceil(original.size * 16000 / file_rate))
    assert abs(peak_frequency(audio, rate) - 440) <= 2
    assert np.abs(audio).max() <= 1.0


def test_load_audio_keeps_the_file_rate_when_asked(tmp_path):
    path = tmp_path / "tone.wav"
    soundfile.write(path, sine(440, 0.5, 22050), 22050)
    audio, rate = load_audio(path, sample_rate=None)
    assert rate == 22050 and audio.size == 11025


def test_load_audio_reads_flac(tmp_path):
    original = sine(440, 0.25, 16000)
    path = tmp_path / "tone.flac"
    soundfile.write(path, original, 16000, subtype="PCM_16")
    audio, _ = load_audio(path)
    np.testing.assert_allclose(audio, original, atol=2**-15)


def test_load_audio_scales_float_files_louder_than_full_scale(tmp_path):
    path = tmp_path / "loud.wav"
    soundfile.write(path, 2 * sine(440, 0.25, 16000, 1.0), 16000, subtype="FLOAT")
    with pytest.warns(UserWarning, match="beyond"):
        audio, _ = load_audio(path)
    assert np.abs(audio).max() == pytest.approx(1.0)


def test_load_audio_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.wav"):
        load_audio(tmp_path / "nothing.wav")


def test_load_audio_directory(tmp_path):
    folder = tmp_path / "folder.wav"
    folder.mkdir()
    with pytest.raises(AudioError, match="folder.wav is a directory"):
        load_audio(folder)


def test_load_audio_empty_file(tmp_path):
    path = tmp_path / "empty.wav"
    path.touch()
    with pytest.raises(AudioError, match=r"empty.wav is an empty file \(0 bytes\)"):
        load_audio(path)


def test_load_audio_text_file_renamed_wav(tmp_path):
    path = tmp_path / "notes.wav"
    path.write_text("these are my notes, not a recording\n")
    with pytest.raises(AudioError, match="notes.wav could not be read as audio"):
        load_audio(path)


def test_load_audio_file_without_samples(tmp_path):
    path = tmp_path / "header_only.wav"
    soundfile.write(path, np.zeros(0), 16000)
    with pytest.raises(AudioError, match="header_only.wav contains no samples"):
        load_audio(path)


def test_load_audio_all_nan(tmp_path):
    path = tmp_path / "nan.wav"
    soundfile.write(path, np.full(1600, np.nan), 16000, subtype="FLOAT")
    with pytest.raises(AudioError, match="nan.wav: every sample is NaN"):
        load_audio(path)


def test_load_audio_some_infinite_samples(tmp_path):
    signal = sine(440, 0.1, 16000)
    signal[[10, 20]] = np.inf
    path = tmp_path / "inf.wav"
    soundfile.write(path, signal, 16000, subtype="FLOAT")
    with pytest.raises(AudioError, match="inf.wav: 2 of 1600 samples are NaN or infinite"):
        load_audio(path)


@pytest.mark.parametrize("subtype", ["PCM_16", "FLOAT"])
def test_load_audio_refuses_a_wav_file_cut_short(tmp_path, subtype):
    path = tmp_path / "cut.wav"
    soundfile.write(path, sine(440, 0.5, 16000), 16000, subtype=subtype)
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) // 2])  # libsndfile alone would return half the samples
    with pytest.raises(AudioError, match=r"cut.wav is truncated: .* \((49|50)%\)"):
        load_audio(path)


def test_load_audio_reads_a_wav_file_with_a_chunk_after_its_samples(tmp_path):
    path = tmp_path / "tagged.wav"
    soundfile.write(path, sine(440, 0.25, 16000), 16000, subtype="PCM_16")
    path.write_bytes(path.read_bytes() + b"LIST\x05\x00\x00\x00hello\x00")
    audio, _ = load_audio(path)
    assert audio.size == 4000


def test_load_audio_accepts_a_numpy_integer_rate(tmp_path):
    path = tmp_path / "tone.wav"
    soundfile.write(path, sine(440, 0.25, 22050), 22050)
    audio, rate = load_audio(path, sample_rate=np.int64(16000))
    assert rate == 16000 and type(rate) is int and audio.size == 4000


# --------------------------------------------------------------------------- save_audio


def test_save_audio_round_trip_as_16_bit_pcm(tmp_path):
    original = sine(440, 0.25, 22050)
    path = tmp_path / "out.wav"
    save_audio(path, original, 22050)
    info = soundfile.info(path)
    assert info.subtype == "PCM_16" and info.samplerate == 22050 and info.channels == 1
    audio, rate = load_audio(path, sample_rate=None)
    assert rate == 22050
    np.testing.assert_allclose(audio, original, atol=2**-15)


def test_save_audio_clips_to_full_scale(tmp_path):
    path = tmp_path / "loud.wav"
    save_audio(path, np.array([1.5, -2.0, 0.25]), 16000)
    audio, _ = load_audio(path)
    np.testing.assert_allclose(audio, [1.0, -1.0, 0.25], atol=2**-15)


def test_save_audio_refuses_to_overwrite(tmp_path):
    path = tmp_path / "take.wav"
    save_audio(path, sine(440, 0.1, 16000), 16000)
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="take.wav already exists; pass overwrite=True"):
        save_audio(path, sine(880, 0.1, 16000), 16000)
    assert path.read_bytes() == before
    save_audio(path, sine(880, 0.1, 16000), 16000, overwrite=True)
    assert path.read_bytes() != before


@pytest.mark.parametrize(
    ("audio", "message"),
    [
        (np.zeros((100, 2)), r"shape \(n,\), got shape \(100, 2\)"),
        (np.array([0.1, np.nan]), "1 NaN or infinite"),
        (np.zeros(0), "empty"),
    ],
)
def test_save_audio_rejects_bad_signals(tmp_path, audio, message):
    with pytest.raises(AudioError, match=message):
        save_audio(tmp_path / "bad.wav", audio, 16000)
    assert not (tmp_path / "bad.wav").exists()


def test_save_audio_rejects_other_extensions_and_missing_folders(tmp_path):
    with pytest.raises(ValueError, match=r"should end in \.wav"):
        save_audio(tmp_path / "out.mp3", sine(440, 0.1, 16000), 16000)
    with pytest.raises(FileNotFoundError, match="the folder .*missing does not exist"):
        save_audio(tmp_path / "missing" / "out.wav", sine(440, 0.1, 16000), 16000)


# --------------------------------------------------------------------------- frame counts


RATES_AND_FPS = [(rate, fps) for rate in (8000, 16000, 22050, 44100, 11025) for fps in (25, 30)]
RATES_AND_FPS += [(44100, 60), (16000, 60)]


@pytest.mark.parametrize(("sample_rate", "fps"), RATES_AND_FPS)
def test_every_feature_has_one_row_per_whole_motion_frame(sample_rate, fps):
    rng = np.random.default_rng(0)
    for seconds in (1 / fps, 0.5, 17 / fps, 0.7 + 0.3 / fps, 1.2345):
        n = int(round(seconds * sample_rate))
        for n_samples in (n - 1, n, n + 1):
            expected = math.floor(Fraction(n_samples, sample_rate) * fps)  # exact rationals
            if expected == 0:
                continue
            audio = 0.1 * rng.standard_normal(n_samples).astype(np.float32)
            assert num_frames(n_samples, sample_rate, fps) == expected
            mel = mel_spectrogram(audio, sample_rate, fps)
            assert mel.shape == (expected, 27) and mel.dtype == np.float32
            assert mfcc(audio, sample_rate, fps).shape == (expected, 13)
            prosodic = prosody(audio, sample_rate, fps)
            assert prosodic.shape == (expected, len(PROSODY_FEATURES))
            assert np.isfinite(prosodic).all() and np.isfinite(mel).all()


def test_exact_frame_boundaries_for_fractional_frame_lengths():
    # 8000 Hz at 30 fps: 266.67 samples a frame, so 800 samples are exactly 3 frames.
    assert num_frames(800, 8000, 30) == 3
    assert num_frames(799, 8000, 30) == 2
    assert mel_spectrogram(np.zeros(800), 8000, 30).shape == (3, 27)
    assert mel_spectrogram(np.zeros(799), 8000, 30).shape == (2, 27)
    # 22050 Hz at 30 fps: 735 samples a frame.
    assert num_frames(735 * 7, 22050, 30) == 7
    assert num_frames(735 * 7 - 1, 22050, 30) == 6


# --------------------------------------------------------------------------- alignment


@pytest.mark.parametrize(
    ("sample_rate", "fps"), [(16000, 25), (22050, 30), (8000, 30), (11025, 25)]
)
@pytest.mark.parametrize("frame", [0, 7, 1499])
def test_a_click_inside_frame_t_lights_up_row_t(sample_rate, fps, frame):
    n_frames = 1500  # a minute at 25 fps: any drift of the frame grid would show by the end
    audio = np.zeros(int(np.ceil(n_frames * sample_rate / fps)), dtype=np.float32)
    click = int((frame + 0.5) * sample_rate / fps)
    audio[click : click + 3] = 0.9
    mel = mel_spectrogram(audio, sample_rate, fps)
    assert mel.shape[0] == n_frames
    loudness = mel.sum(axis=1)
    assert loudness.argmax() == frame
    far = np.abs(np.arange(n_frames) - frame) >= 2
    np.testing.assert_allclose(mel[far], np.log(MEL_FLOOR), rtol=1e-6)
    energy = prosody(audio[: 2 * click + 10], sample_rate, fps)[:, LOG_ENERGY]
    assert energy.argmax() == frame


@pytest.mark.parametrize(("sample_rate", "fps"), [(16000, 25), (22050, 30), (11025, 25)])
def test_a_tone_burst_filling_frame_t_is_seen_in_row_t_only(sample_rate, fps):
    frame, n_frames = 11, 20
    audio = np.zeros(n_frames * sample_rate // fps + 1, dtype=np.float32)
    start, end = round(frame * sample_rate / fps), round((frame + 1) * sample_rate / fps)
    audio[start:end] = sine(1000, 1.0, sample_rate)[: end - start]
    mel = mel_spectrogram(audio, sample_rate, fps)
    energy = prosody(audio, sample_rate, fps)[:, LOG_ENERGY]
    for feature in (mel.max(axis=1), energy):
        assert feature.argmax() == frame
        others = np.delete(feature, frame)
        assert feature[frame] > others.max() + 10  # e^10: orders of magnitude louder


def test_mel_matches_librosa_where_the_hop_is_a_whole_number_of_samples():
    import librosa

    sample_rate, fps, window = 16000, 25, 640
    audio = np.random.default_rng(1).standard_normal(sample_rate).astype(np.float32)
    ours = mel_spectrogram(audio, sample_rate, fps)
    # librosa centres a 640-sample window in each 1024-sample FFT frame; shift the signal so that
    # its windows start where ours do (0, 640, 1280, ...). Zero-padding does not change the power.
    offset = (1024 - window) // 2
    shifted = np.pad(audio, (offset, 1024))
    power = librosa.feature.melspectrogram(
        y=shifted,
        sr=sample_rate,
        n_fft=1024,
        hop_length=window,
        win_length=window,
        center=False,
        n_mels=27,
    )[:, : ours.shape[0]]
    np.testing.assert_allclose(ours, np.log(power.T + MEL_FLOOR), rtol=1e-4, atol=1e-4)


# --------------------------------------------------------------------------- feature values


def test_silence_gives_finite_features():
    silence = np.zeros(16000, dtype=np.float32)
    mel = mel_spectrogram(silence, 16000)
    np.testing.assert_allclose(mel, np.log(MEL_FLOOR), rtol=1e-6)
    assert np.isfinite(mfcc(silence, 16000)).all()
    prosodic = prosody(silence, 16000)
    assert np.isfinite(prosodic).all()
    np.testing.assert_allclose(prosodic[:, LOG_F0], np.log(features.F0_MIN), rtol=1e-6)
    np.testing.assert_array_equal(prosodic[:, [D_LOG_ENERGY, D_LOG_F0]], 0.0)


def test_louder_signal_has_higher_log_energy_by_the_log_power_ratio():
    noise = np.random.default_rng(2).standard_normal(16000).astype(np.float32)
    quiet, loud = prosody(0.05 * noise, 16000), prosody(0.2 * noise, 16000)
    np.testing.assert_allclose(loud[:, LOG_ENERGY] - quiet[:, LOG_ENERGY], np.log(16), rtol=1e-4)
    assert (mel_spectrogram(0.2 * noise, 16000) > mel_spectrogram(0.05 * noise, 16000)).all()


@pytest.mark.parametrize(("frequency", "sample_rate"), [(120, 16000), (220, 22050), (400, 8000)])
def test_log_f0_of_a_sine_is_log_of_its_frequency(frequency, sample_rate):
    prosodic = prosody(sine(frequency, 1.0, sample_rate), sample_rate)
    np.testing.assert_allclose(prosodic[:, LOG_F0], np.log(frequency), atol=0.01)
    assert np.abs(prosodic[2:-2, D_LOG_F0]).max() < 0.1


def test_rising_chirp_gives_the_right_positive_d_log_f0():
    sample_rate, seconds = 16000, 2.0
    t = np.arange(int(seconds * sample_rate)) / sample_rate
    # F0 doubles from 150 to 300 Hz in 2 s: d log F0 / dt = log(2) / 2 per second.
    chirp = 0.5 * scipy.signal.chirp(t, 150, seconds, 300, method="logarithmic")
    prosodic = prosody(chirp.astype(np.float32), sample_rate)
    centres = (np.arange(prosodic.shape[0]) + 0.5) / 25
    np.testing.assert_allclose(prosodic[:, LOG_F0], np.log(150 * 2 ** (centres / 2)), atol=0.02)
    interior = prosodic[2:-2, D_LOG_F0]
    assert (interior > 0).all()
    assert np.median(interior) == pytest.approx(np.log(2) / 2, rel=0.1)


def test_log_f0_is_interpolated_across_unvoiced_gaps_without_spikes():
    sample_rate = 16000
    tone, gap = sine(200, 0.4, sample_rate), np.zeros(int(0.4 * sample_rate), np.float32)
    noise = 0.3 * np.random.default_rng(3).standard_normal(gap.size).astype(np.float32)
    for unvoiced in (gap, noise):
        prosodic = prosody(np.concatenate([tone, unvoiced, tone]), sample_rate)
        np.testing.assert_allclose(prosodic[:, LOG_F0], np.log(200), atol=0.03)
        assert np.abs(prosodic[:, D_LOG_F0]).max() < 0.5  # a voicing spike would be ~100/s


def test_noise_alone_is_unvoiced():
    noise = 0.3 * np.random.default_rng(4).standard_normal(16000).astype(np.float32)
    np.testing.assert_allclose(prosody(noise, 16000)[:, LOG_F0], np.log(features.F0_MIN))


def syllables(seconds: float, sample_rate: int = 16000) -> np.ndarray:
    """Speech-like sound: 0.15 s tone bursts (200 Hz, amplitude 0.5) every 0.2 s."""
    t = np.arange(int(seconds * sample_rate)) / sample_rate
    return (0.5 * np.sin(2 * np.pi * 200 * t) * ((t % 0.2) < 0.15)).astype(np.float32)


@pytest.mark.parametrize("noise", [0.0, 0.005, 0.02])
def test_voice_activity_finds_speech_between_silences_even_in_steady_noise(noise):
    silence = np.zeros(16000, np.float32)
    audio = np.concatenate([silence, syllables(2.0), silence, syllables(0.5), silence])
    audio += noise * np.random.default_rng(6).standard_normal(audio.size).astype(np.float32)
    voiced = features.voice_activity(audio, 16000)
    expected = np.zeros(len(voiced), bool)
    expected[25:75] = expected[100:112] = True  # frames 25 per second
    assert np.mean(voiced == expected) > 0.95  # the syllables' 0.05 s gaps filled in
    assert not voiced[:20].any() and not voiced[80:95].any() and not voiced[-20:].any()


@pytest.mark.parametrize("dip_db", [3.0, 6.0, 10.0])
def test_speech_without_pauses_stays_voiced(dip_db):
    """No silence at all: the quietest frames are speech, and must not be gated as noise."""
    t = np.arange(5 * 16000) / 16000
    level = np.where((t % 0.25) < 0.18, 1.0, 10 ** (-dip_db / 20))  # syllables, shallow dips
    level = level * np.where((t % 2.0) < 1.5, 1.0, 10 ** (-10 / 20))  # a quieter phrase
    audio = (0.5 * level * np.sin(2 * np.pi * 180 * t)).astype(np.float32)
    assert features.voice_activity(audio, 16000).mean() > 0.95


def test_voice_activity_drops_clicks_and_finds_no_voice_in_silence():
    click = np.zeros(48000, np.float32)
    click[24010:24300] = 0.5  # under 0.02 s, inside one frame: a click, not a syllable
    assert not features.voice_activity(click, 16000).any()
    assert not features.voice_activity(np.zeros(16000, np.float32), 16000).any()


def speech_between_silences(noise: float = 0.0, gain: float = 1.0) -> np.ndarray:
    """1 s of silence, 2 s of voiced syllables, 1 s of silence (frames 25-75 hold speech).

    The syllables have a voice's many harmonics (a 150 Hz sawtooth), which reach every band.
    """
    t = np.arange(2 * 16000) / 16000
    voiced = 0.5 * scipy.signal.sawtooth(2 * np.pi * 150 * t) * ((t % 0.2) < 0.15)
    silence = np.zeros(16000)
    audio = np.concatenate([silence, voiced, silence]).astype(np.float32)
    audio += noise * np.random.default_rng(8).standard_normal(audio.size).astype(np.float32)
    return gain * audio


@pytest.mark.parametrize("gain", [0.05, 0.3, 1.9])
def test_speech_features_do_not_depend_on_the_recording_level(gain):
    clean = features.speech_features(speech_between_silences(noise=1e-3), 16000)
    scaled = features.speech_features(speech_between_silences(noise=1e-3, gain=gain), 16000)
    np.testing.assert_allclose(scaled, clean, atol=0.02)


@pytest.mark.parametrize("gain", [0.5, 0.01, 1e-4])
def test_a_gain_changes_nothing_beside_digital_silence(gain):
    """A 16-bit recording whose pauses are exact zeros and whose quiet frames hold a few steps of
    quantisation: at any gain those frames stay far above the log's floor, so nothing moves."""
    audio = speech_between_silences(noise=1e-4, gain=0.05)
    audio = np.round(audio * 32767) / 32767  # 16-bit steps: the quiet frames hold a few
    audio[:8000] = 0.0  # half a second of an editor's digital silence
    at_full_gain = features.speech_features(audio, 16000)
    np.testing.assert_allclose(
        features.speech_features(gain * audio, 16000), at_full_gain, atol=1e-3
    )


@pytest.mark.parametrize("noise", [1e-4, 0.003, 0.02])
def test_speech_features_read_silence_as_zero_and_speech_as_one_in_any_noise(noise):
    speech = features.speech_features(speech_between_silences(noise), 16000)
    loudness = speech.mean(axis=1)  # (T,)
    assert abs(np.median(loudness[:20])) < 0.1 and abs(np.median(loudness[-20:])) < 0.1
    assert 0.8 < np.median(loudness[30:70]) < 1.2


@pytest.mark.parametrize("lead_in", [16000, 16600])  # whole frames of zeros, or ending mid-frame
def test_digital_silence_neither_sets_the_floor_nor_lifts_a_room_s_pauses(lead_in):
    """A second of exact zeros before a noisy recording (an editor's lead-in) changes nothing:
    the zeros read 0, the room's noisy pauses still read about 0 and hold no voice, and the
    speech still reads about 1."""
    noisy = speech_between_silences(noise=0.01)
    led_in = np.r_[np.zeros(lead_in, np.float32), noisy]
    alone, heard = (features.speech_features(x, 16000).mean(axis=1) for x in (noisy, led_in))
    np.testing.assert_allclose(heard[:25], 0.0, atol=1e-6)
    assert abs(np.median(heard[27:45]) - np.median(alone[2:20])) < 0.02  # the pause
    assert abs(np.median(heard[56:95]) - np.median(alone[30:70])) < 0.05  # the speech
    voiced = features.voice_activity(led_in, 16000)
    assert not voiced[:45].any()
    assert abs(int(voiced.sum()) - int(features.voice_activity(noisy, 16000).sum())) <= 1


def in_a_room(audio: np.ndarray, rt60: float = 0.6) -> np.ndarray:
    """``audio`` in a room whose echo dies away by 60 dB in ``rt60`` s, written as floats: the echo
    fades into the digital silence of the pauses, as in an editor's or a synthesiser's file."""
    t = np.arange(int(rt60 * 16000)) / 16000
    tail = np.random.default_rng(3).standard_normal(t.size) * np.exp(-6.9 * t / rt60)
    response = tail / np.sqrt(np.sum(tail**2))
    response[0] += 1.0  # the direct sound
    return scipy.signal.fftconvolve(audio, response)[: audio.size].astype(np.float32)


def test_how_far_down_a_recording_s_floor_lies_does_not_matter():
    """A room echoing into digital silence has a far wider range than any recording the models
    learned from: it is heard as if white noise lay under it, so that a noise 60, 80 or 100 dB
    under its peak, or none, or 16-bit samples leave its speech at 1, its echo fading alike and
    its zeros at 0."""
    # 0.5 s of zeros (12.5 frames), 1 s of silence, speech in frames 37-87, then its echo
    wet = np.r_[np.zeros(8000, np.float32), in_a_room(speech_between_silences())]
    noise = np.abs(wet).max() * np.random.default_rng(1).standard_normal(wet.size)
    heard = {None: features.speech_features(wet, 16000)}  # (T, n_mels)
    in_16_bits = (np.round(wet * 32767) / 32767).astype(np.float32)
    heard["16-bit"] = features.speech_features(in_16_bits, 16000)
    for db in (-100, -80, -60):
        noisy = (wet + 10 ** (db / 20) * noise).astype(np.float32)
        heard[db] = features.speech_features(noisy, 16000)
    np.testing.assert_array_equal(heard[None][:12], 0.0)  # the digital silence
    echo = heard[None][88:92].mean(axis=1)  # the first 0.16 s after the speech
    assert 0.2 < echo[-1] < echo[0] < 0.9  # fading
    for bands in heard.values():
        assert abs(np.percentile(bands[12:].mean(axis=1), 95) - 1.0) < 0.05  # the speech level
        np.testing.assert_allclose(bands[88:92].mean(axis=1), echo, atol=0.03)
        np.testing.assert_allclose(bands[12:], heard[None][12:], atol=0.25)  # band by band


def test_a_wide_range_is_heard_alike_whatever_integers_give_the_rate():
    wet = in_a_room(speech_between_silences())
    expected = features.speech_features(wet, 16000)
    np.testing.assert_array_equal(features.speech_features(wet, np.int64(16000)), expected)
    np.testing.assert_array_equal(features.speech_features(wet, 16000, fps=np.int32(25)), expected)


def test_speech_features_of_steady_noise_or_silence_stay_small():
    """No speech to set the scale: the floor-to-speech range is not blown up to 1."""
    noise = 0.01 * np.random.default_rng(9).standard_normal(32000).astype(np.float32)
    assert np.abs(features.speech_features(noise, 16000).mean(axis=1)).max() < 0.3
    silence = features.speech_features(np.zeros(16000, np.float32), 16000)
    np.testing.assert_allclose(silence, 0.0, atol=1e-5)


@pytest.mark.parametrize("seed", range(8))
def test_the_course_s_conversations_are_heard_as_they_are(seed, monkeypatch):
    """At the quietest noise floor the generator draws, a conversation as long as the course's
    shortest (30 s) stays within MAX_SPEECH_RANGE: what the models learned from is never heard
    under added noise."""
    quietest = VoiceConfig().noise_floor_db[0]
    config = ConversationConfig(voice=VoiceConfig(noise_floor_db=(quietest, quietest)))
    conversation = generate_conversation(30.0, seed, config)
    heard = features.speech_features(conversation.audio, conversation.sample_rate)
    monkeypatch.setattr(features, "MAX_SPEECH_RANGE", np.inf)
    uncapped = features.speech_features(conversation.audio, conversation.sample_rate)
    np.testing.assert_array_equal(heard, uncapped)


def test_who_is_talking_from_the_agent_s_and_the_partner_s_recordings():
    """The agent speaks in frames 25-75 (1-3 s); its partner from 2 s to the end."""
    agent = speech_between_silences(noise=1e-3)
    partner = np.roll(agent, 16000)
    activity = features.who_is_talking(agent, 16000, partner)
    assert activity.dtype == np.int64 and activity.shape == (100,)
    for frames, expected in ((slice(5, 20), Activity.NONE), (slice(30, 45), Activity.A_SPEAKS)):
        assert (activity[frames] == expected).all()
    assert (activity[55:70] == Activity.BOTH).all() and (activity[80:95] == Activity.B_SPEAKS).all()
    assert set(features.who_is_talking(agent, 16000).tolist()) == {Activity.NONE, Activity.A_SPEAKS}
    with pytest.raises(AudioError, match="the agent's length"):
        features.who_is_talking(agent, 16000, partner[:-1000])
    silence = np.zeros_like(agent)
    with pytest.raises(AudioError, match="neither recording holds speech"):
        features.who_is_talking(silence, 16000, silence)


def test_mfcc_is_the_dct_of_the_log_mel():
    audio = np.random.default_rng(5).standard_normal(8000).astype(np.float32)
    expected = scipy.fft.dct(mel_spectrogram(audio, 16000), type=2, norm="ortho", axis=1)[:, :13]
    np.testing.assert_allclose(mfcc(audio, 16000), expected, rtol=1e-4, atol=1e-4)
    with pytest.raises(ValueError, match="n_mfcc=30 cannot exceed n_mels=27"):
        mfcc(audio, 16000, n_mfcc=30)


# --------------------------------------------------------------------------- bad feature input


@pytest.mark.parametrize("extract", [mel_spectrogram, mfcc, prosody, features.speech_features])
@pytest.mark.parametrize(
    ("audio", "error", "message"),
    [
        (np.zeros((16000, 2)), AudioError, r"shape \(n,\), got shape \(16000, 2\)"),
        (np.r_[np.zeros(1000), np.nan, np.inf], AudioError, "2 NaN or infinite samples"),
        (np.zeros(0), AudioError, "empty"),
        (np.zeros(639), AudioError, "shorter than one motion frame"),
        (np.zeros(1000, dtype=complex), AudioError, "real-valued"),
    ],
)
def test_features_reject_bad_audio(extract, audio, error, message):
    with pytest.raises(error, match=message):
        extract(audio, 16000)


def test_features_reject_non_integer_rates():
    with pytest.raises(ValueError, match="fps must be a positive integer, got 29.97"):
        mel_spectrogram(np.zeros(16000), 16000, fps=29.97)
    with pytest.raises(ValueError, match="sample_rate must be a positive integer"):
        mel_spectrogram(np.zeros(16000), -16000)
    with pytest.raises(AudioError, match="prosody needs sample_rate >= 1200"):
        prosody(np.zeros(1000), 1000)


@pytest.mark.parametrize("extract", [mel_spectrogram, mfcc, prosody, features.speech_features])
@pytest.mark.parametrize(
    ("dtype", "advice"), [(np.int16, "divide by 32768"), (np.uint8, "subtract 128, divide by 128")]
)
def test_features_refuse_integer_pcm(extract, dtype, advice):
    # As floats these would be 2**15 times full scale: log-mel about 21 nats too high.
    pcm = (sine(440, 0.2, 16000) * 100 + (128 if dtype == np.uint8 else 0)).astype(dtype)
    with pytest.raises(AudioError, match=f"holds integers .*{advice}.*load_audio"):
        extract(pcm, 16000)


def test_save_audio_refuses_a_folder(tmp_path):
    (tmp_path / "take.wav").mkdir()
    for overwrite in (False, True):  # "already exists; pass overwrite=True" misled before
        with pytest.raises(IsADirectoryError, match="take.wav: it is a folder"):
            save_audio(tmp_path / "take.wav", sine(440, 0.1, 16000), 16000, overwrite=overwrite)


def test_save_audio_refuses_integer_pcm(tmp_path):
    with pytest.raises(AudioError, match="divide by 32768"):
        save_audio(tmp_path / "pcm.wav", (sine(440, 0.1, 16000) * 32767).astype(np.int16), 16000)
    assert not (tmp_path / "pcm.wav").exists()


@pytest.mark.parametrize("scale", [32767.0, 1e20])
def test_features_refuse_signals_far_beyond_full_scale(scale):
    # 1e20 used to give an infinite float32 mel power; 32767 is 16-bit PCM stored as floats.
    loud = sine(440, 0.2, 16000) * np.float32(scale)
    for extract in (mel_spectrogram, mfcc, prosody):
        with pytest.raises(AudioError, match="peaks at .* far beyond full scale"):
            extract(loud, 16000)
    with pytest.raises(AudioError, match="far beyond full scale"):
        mel_spectrogram(sine(440, 0.2, 16000).astype(np.float64) * 1e200, 16000)


def test_features_of_a_signal_louder_than_full_scale_but_plausible_are_finite():
    loud = features.MAX_PEAK * sine(440, 0.2, 16000, amplitude=1.0)
    for extract in (mel_spectrogram, mfcc, prosody):
        assert np.isfinite(extract(loud, 16000)).all()


def test_features_accept_numpy_integer_rates():
    audio = sine(440, 0.3, 16000)
    expected = mel_spectrogram(audio, 16000, fps=25, n_mels=27)
    np.testing.assert_array_equal(
        mel_spectrogram(audio, np.int64(16000), fps=np.int32(25), n_mels=np.int64(27)), expected
    )
    assert mfcc(audio, np.int64(16000), n_mfcc=np.int16(13)).shape == (7, 13)
    assert prosody(audio, np.int64(16000), fps=np.int64(25)).shape == (7, 4)
    assert num_frames(np.int64(4800), np.int32(16000), np.int64(25)) == 7
    with pytest.raises(ValueError, match="n_samples must be an integer, got 4800.5"):
        num_frames(4800.5, 16000)


# --------------------------------------------------------------------------- speech activity


def test_activity_one_hot_round_trip():
    codes = np.array([0, 1, 2, 3, 3, 0], dtype=np.int32)
    one_hot = activity_one_hot(codes)
    assert one_hot.shape == (6, 4) and one_hot.dtype == np.float32
    np.testing.assert_array_equal(one_hot.sum(axis=1), 1.0)
    assert one_hot[0, Activity.A_SPEAKS] == 1 and one_hot[2, Activity.BOTH] == 1
    back = activity_from_one_hot(one_hot)
    assert back.dtype == np.int64
    np.testing.assert_array_equal(back, codes)


@pytest.mark.parametrize(
    ("codes", "message"),
    [
        (np.array([0.0, 1.0]), "must be integers, got dtype float64"),
        (np.array([0, 4]), r"invalid activity codes \[4\]"),
        (np.array([-1, 2]), r"invalid activity codes \[-1\]"),
        (np.zeros((5, 1), dtype=int), r"shape \(T,\), got \(5, 1\)"),
    ],
)
def test_activity_one_hot_rejects_bad_codes(codes, message):
    with pytest.raises(ValueError, match=message) as caught:
        activity_one_hot(codes)
    if "shape" not in message:
        assert "0 = A_SPEAKS (A speaks)" in str(caught.value)
        assert "3 = NONE (none)" in str(caught.value)


def test_activity_from_one_hot_rejects_non_one_hot_rows():
    with pytest.raises(ValueError, match=r"shape \(T, 4\), got \(3, 3\)"):
        activity_from_one_hot(np.eye(3))
    soft = np.array([[1, 0, 0, 0], [0.7, 0.3, 0, 0]])
    with pytest.raises(ValueError, match="row 1 .* not a single 1"):
        activity_from_one_hot(soft)
