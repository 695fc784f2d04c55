"""Speech features at the motion frame rate: audio I/O, log-mel, MFCC, prosody, speech activity.

Every feature here has exactly one row per motion frame. A recording of ``n`` samples at
``sample_rate`` Hz lasts ``n / sample_rate`` seconds and covers

    T = floor(n / sample_rate * fps)          (see :func:`num_frames`)

whole motion frames; a trailing partial frame is dropped. Row ``t`` describes the audio of motion
frame ``t``, i.e. the time interval ``[t / fps, (t + 1) / fps)``. In samples that interval starts
at ``t * sample_rate / fps``, which need not be an integer (22050 Hz at 30 fps gives 735 samples a
frame, 8000 Hz at 30 fps gives 266.67). We therefore place every frame at its exact position and
round to the nearest sample, so the rows never drift away from the motion, however long the clip.
(``librosa.stft`` only takes an integer hop, which would drift; we use librosa for the mel filter
bank, the window and the DCT, and do the framing here.)

Conventions:

* Log-mel (:func:`mel_spectrogram`): natural log of the mel power spectrum plus :data:`MEL_FLOOR`,
  so silence gives ``log(MEL_FLOOR)`` (about -23), never ``-inf``. The analysis window is a Hann
  window one motion frame long (40 ms at 25 fps, the 27 log-mel bands from 40 ms windows of the
  Flow-VAE paper), centred on the middle of the frame, ``(t + 0.5) / fps``: it spans the frame's
  interval and nothing else. Bands run from 0 Hz to the Nyquist frequency, so features are only
  comparable between recordings at the same sample rate; :func:`load_audio` resamples to 16 kHz.
* MFCC (:func:`mfcc`): the DCT-II (orthonormal) of that log-mel, i.e. the same frames.
* What the models hear (:func:`speech_features`): that log-mel normalised per recording, from
  its noise floor (0) to its speech level (1), so that recordings made at other levels and in
  other noise look alike.
* Prosody (:func:`prosody`): the four features of Kucherenko et al. (2021), named in
  :data:`PROSODY_FEATURES`; see that function for how unvoiced frames are handled.
* Speech activity (:func:`activity_one_hot`): one :class:`~gesturelib.conventions.Activity` code
  per motion frame, one-hot encoded for the models.
"""

from __future__ import annotations

import functools
import numbers
import os
import struct
import warnings
from pathlib import Path

import librosa
import numpy as np
import scipy.fft
import scipy.optimize
import soundfile

from gesturelib.conventions import FPS, N_MELS, SAMPLE_RATE, Activity

#: Added to the mel power before the log: silence gives log(1e-10) ~ -23 instead of -inf.
#: It sits below the quantisation noise of 16-bit audio, so it only affects true digital silence.
MEL_FLOOR = 1e-10
#: Added to the mean-square amplitude before the log in the prosody energy (-100 dB full scale).
ENERGY_FLOOR = 1e-10

#: Columns of :func:`prosody`, in order.
PROSODY_FEATURES = ("log_energy", "log_f0", "d_log_energy", "d_log_f0")
#: F0 search range in Hz: Praat's default pitch floor and ceiling (Kucherenko et al. used Praat).
F0_MIN = 75.0
F0_MAX = 600.0
#: A pitch frame is voiced when the signal correlates with itself one period later at least this
#: much (Praat's default voicing threshold)...
VOICING_THRESHOLD = 0.45
#: ...and its peak amplitude reaches this fraction of the recording's peak (Praat's silence
#: threshold).
SILENCE_THRESHOLD = 0.03
#: Pitch frames per motion frame: F0 is estimated at this finer rate, then averaged per frame.
PITCH_FRAMES_PER_FRAME = 4

#: The feature functions take samples as floats at full scale [-1, 1]. A signal whose peak is
#: beyond this (40 dB above full scale) is refused: it is almost surely integer PCM values stored
#: as floats, and its features would be far off (log-mel about 21 nats too high for 16-bit
#: values); it also keeps the float32 mel power far from overflow, so features stay finite.
MAX_PEAK = 100.0

_FRAMES_PER_BLOCK = 4096  # frames analysed at once: bounds memory on long recordings


class AudioError(ValueError):
    """An audio file or signal that cannot be used: empty, unreadable, truncated, non-finite,
    integer-valued, far beyond full scale, or too short."""


# --------------------------------------------------------------------------- audio files


def load_audio(
    path: str | os.PathLike, sample_rate: int | None = SAMPLE_RATE
) -> tuple[np.ndarray, int]:
    """Read an audio file as a mono float32 signal ``(n,)`` in [-1, 1], resampled on request.

    Reads any WAV that libsndfile understands (8-bit unsigned, 16/24/32-bit integer PCM, 32/64-bit
    float; any number of channels; any rate), and FLAC or OGG too. Channels are down-mixed by
    averaging. A float file whose peak exceeds 1 is scaled down to peak 1 (with a warning) rather
    than clipped; resampling (``librosa.resample``, soxr) can overshoot by a hair, which is clipped.

    Args:
        path: the audio file.
        sample_rate: rate in Hz to resample to; ``None`` keeps the file's own rate.

    Returns:
        ``(audio, rate)``: the signal ``(n,)`` float32 and its sample rate in Hz.

    Raises:
        FileNotFoundError: if ``path`` does not exist.
        AudioError: if ``path`` is a directory, an empty file, not audio, a WAV file cut short
            (its header promises more samples than it holds), has no samples, or contains NaN
            or infinite values. The message names the file.
    """
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"path must be a file path (a str or Path), got {type(path).__name__}")
    path = Path(path)
    if sample_rate is not None:
        sample_rate = _positive_int(sample_rate, "sample_rate")
    if not path.exists():
        raise FileNotFoundError(f"audio file not found: {path}")
    if path.is_dir():
        raise AudioError(f"{path} is a directory, not an audio file")
    if path.stat().st_size == 0:
        raise AudioError(f"{path} is an empty file (0 bytes), not audio")
    promised, present = _wav_data_bytes(path)
    if present < promised:
        raise AudioError(
            f"{path} is truncated: its header promises {promised} bytes of samples but the file "
            f"holds {present} ({present / promised:.0%}); it was cut short (an interrupted copy, "
            "download or recording): copy or write it again"
        )
    try:
        info = soundfile.info(path)
    except (soundfile.LibsndfileError, RuntimeError) as error:
        raise AudioError(
            f"{path} could not be read as audio ({error}); expected a WAV, FLAC or OGG file"
        ) from error
    file_rate = int(info.samplerate)
    if not MIN_FILE_RATE <= file_rate <= MAX_FILE_RATE:
        raise AudioError(
            f"{path} claims a sample rate of {file_rate} Hz, which no recording has (expected "
            f"{MIN_FILE_RATE} to {MAX_FILE_RATE} Hz): its header is wrong; convert it again"
        )
    if info.frames == 0:
        raise AudioError(f"{path} contains no samples (a header without audio data)")
    target = file_rate if sample_rate is None else sample_rate
    audio, peak = _read_mono(path, file_rate, target, info.frames)
    if peak > 1.0:
        warnings.warn(
            f"{path}: float samples reach {peak:.3g}, beyond [-1, 1]; scaled down to peak 1",
            stacklevel=2,
        )
        audio /= np.float32(peak)
    if target != file_rate:  # resampling can overshoot by a hair
        np.clip(audio, -1.0, 1.0, out=audio)
    return audio, target


#: The sample rates a recording can have; a header claiming another is damaged.
MIN_FILE_RATE, MAX_FILE_RATE = 4000, 384_000
#: Seconds of a file read at once: a long recording is streamed, so that memory stays bounded
#: (an hour at 16 kHz is 230 MB of float32, whatever the file's rate and channels).
_BLOCK_S = 10


def _read_mono(path: Path, file_rate: int, target: int, frames: int) -> tuple[np.ndarray, float]:
    """The file's samples down-mixed (the mean of its channels) and resampled to ``target``
    block by block (soxr's high quality, as ``librosa.resample``): ``(audio (n,), peak before
    any scaling)``.

    Raises:
        AudioError: naming the file, for NaN or infinite samples or an unreadable block.
    """
    import soxr

    length = frames if target == file_rate else -(-frames * target // file_rate)
    audio = np.zeros(length, np.float32)
    stream = (
        None
        if target == file_rate
        else soxr.ResampleStream(file_rate, target, 1, dtype="float32", quality="HQ")
    )
    filled, not_finite, peak, mixed_energy, channel_energy = 0, 0, 0.0, 0.0, 0.0
    try:
        blocks = soundfile.blocks(
            path, blocksize=int(_BLOCK_S * file_rate), dtype="float32", always_2d=True
        )
        for last, block in _with_last(blocks):
            mono = block.mean(axis=1, dtype=np.float32)
            finite = np.isfinite(mono)
            not_finite += int((~finite).sum())
            if not finite.all():
                continue
            peak = max(peak, float(np.abs(mono).max(initial=0.0)))
            mixed_energy += float(np.square(mono, dtype=np.float64).sum())
            channel_energy += float(np.square(block, dtype=np.float64).mean(axis=1).sum())
            if stream is not None:
                mono = stream.resample_chunk(mono, last=last)
            taken = min(len(mono), length - filled)
            audio[filled : filled + taken] = mono[:taken]
            filled += taken
    except (soundfile.LibsndfileError, RuntimeError) as error:
        raise AudioError(f"{path} could not be read to its end ({error}); copy it again") from error
    if not_finite:
        raise AudioError(
            f"{path}: {'every sample is' if not_finite == frames else f'{not_finite} of {frames} samples are'} "
            "NaN or infinite; the signal is unusable"
        )
    if mixed_energy < 1e-6 * channel_energy:
        raise AudioError(
            f"{path}: its channels cancel out when mixed to one (one is the other inverted); "
            "keep one channel, e.g. with sox or Audacity, and try again"
        )
    return audio, peak


def _with_last(items):
    """``(is_last, item)`` for each item of an iterable."""
    iterator = iter(items)
    previous = next(iterator, None)
    for item in iterator:
        yield False, previous
        previous = item
    if previous is not None:
        yield True, previous


def _wav_data_bytes(path: Path) -> tuple[int, int]:
    """Bytes of samples a RIFF/WAVE file's header promises, and the bytes the file holds after it.

    libsndfile quietly reads what is there when a WAV file was cut short, so we compare the
    ``data`` chunk's declared size with the file's size ourselves. Other formats, and WAV files
    whose writer did not know the size (0 or 0xFFFFFFFF, as in streamed or RF64 files), give
    ``(0, 0)``: nothing to compare.
    """
    with open(path, "rb") as file:
        header = file.read(12)
        if len(header) < 12 or header[:4] != b"RIFF" or header[8:12] != b"WAVE":
            return 0, 0
        while len(chunk := file.read(8)) == 8:
            size = struct.unpack("<I", chunk[4:])[0]
            if chunk[:4] == b"data":
                if size in (0, 0xFFFFFFFF):
                    return 0, 0
                return size, path.stat().st_size - file.tell()
            file.seek(size + size % 2, os.SEEK_CUR)  # chunks are padded to an even length
    return 0, 0


def save_audio(
    path: str | os.PathLike, audio: np.ndarray, sample_rate: int, overwrite: bool = False
) -> None:
    """Write a mono signal ``(n,)`` as a 16-bit PCM WAV file.

    Samples outside [-1, 1] are clipped to [-1, 1] (16-bit PCM cannot hold them); scale the
    signal first if it is louder than full scale.

    Args:
        path: the file to write; must end in ``.wav`` and its folder must exist.
        audio: the signal ``(n,)``, floats at full scale [-1, 1] (peak at most :data:`MAX_PEAK`),
            finite, at least one sample.
        sample_rate: its rate in Hz (any integer type).
        overwrite: replace an existing file; by default an existing file is an error.

    Raises:
        FileExistsError: if ``path`` exists and ``overwrite`` is False.
        FileNotFoundError: if the folder of ``path`` does not exist.
        ValueError: for a path not ending in ``.wav``, or a bad signal (:class:`AudioError`).
    """
    path = Path(path)
    audio = _check_signal(audio, "audio")
    sample_rate = _positive_int(sample_rate, "sample_rate")
    if path.suffix.lower() != ".wav":
        raise ValueError(f"save_audio writes WAV files; {path} should end in .wav")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"cannot write {path}: the folder {path.parent} does not exist")
    if path.is_dir():
        raise IsADirectoryError(f"cannot write {path}: it is a folder")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} already exists; pass overwrite=True to replace it")
    try:
        soundfile.write(
            path, np.clip(audio, -1.0, 1.0), sample_rate, subtype="PCM_16", format="WAV"
        )
    except soundfile.SoundFileError as error:  # libsndfile says "System error." for a full disk
        raise OSError(f"cannot write {path}: {error} (is the disk full, or read-only?)") from error


def mix_voices(agent: np.ndarray, partner: np.ndarray) -> np.ndarray:
    """Both voices in one track ``(n,)``: their sum, scaled down only if it would clip (trimmed
    to the shorter recording)."""
    n = min(len(agent), len(partner))
    both = agent[:n] + partner[:n]
    peak = float(np.abs(both).max())
    return both / peak if peak > 1.0 else both


# --------------------------------------------------------------------------- frame alignment


def num_frames(n_samples: int, sample_rate: int, fps: int = FPS) -> int:
    """Number of whole motion frames in ``n_samples`` of audio: ``floor(n_samples / sample_rate * fps)``.

    Computed in integers, so there is no floating-point rounding at frame boundaries. Every
    argument is an integer (Python's or NumPy's).
    """
    sample_rate = _positive_int(sample_rate, "sample_rate")
    fps = _positive_int(fps, "fps")
    n_samples = _integer(n_samples, "n_samples")
    if n_samples < 0:
        raise ValueError(f"n_samples must be >= 0, got {n_samples}")
    return n_samples * fps // sample_rate


def _frame_window_starts(n_frames: int, sample_rate: int, fps: int) -> tuple[np.ndarray, int]:
    """First sample ``(T,)`` of each frame's analysis window, and the window length in samples.

    The window is ``W = round(sample_rate / fps)`` samples long and centred on the middle of motion
    frame ``t``, ``(t + 0.5) * sample_rate / fps``; its start ``centre - W / 2`` is rounded to
    the nearest sample. Integer arithmetic keeps this exact for any rate and frame count.
    """
    window = (2 * sample_rate + fps) // (2 * fps)
    t = np.arange(n_frames, dtype=np.int64)
    # round(((2t + 1) * sr - W * fps) / (2 * fps)) == floor((... + fps) / (2 * fps))
    starts = ((2 * t + 1) * sample_rate - window * fps + fps) // (2 * fps)
    return starts, window


def _frame_boundaries(n_frames: int, sample_rate: int, fps: int) -> np.ndarray:
    """Sample index ``(T + 1,)`` where each motion frame starts, ``round(t * sr / fps)``, and the end."""
    t = np.arange(n_frames + 1, dtype=np.int64)
    return (2 * t * sample_rate + fps) // (2 * fps)


# --------------------------------------------------------------------------- spectral features


def mel_spectrogram(
    audio: np.ndarray, sample_rate: int, fps: int = FPS, n_mels: int = N_MELS
) -> np.ndarray:
    """Log-mel spectrogram ``(T, n_mels)`` float32 with one row per motion frame.

    ``T = floor(len(audio) / sample_rate * fps)``. Row ``t`` is the natural log of the mel power
    spectrum (plus :data:`MEL_FLOOR`) of a Hann window one motion frame long (40 ms at 25 fps),
    centred on ``(t + 0.5) / fps`` seconds, i.e. covering the interval ``[t / fps, (t + 1) / fps)``.
    The window is zero-padded to the next power of two for the FFT; the mel filter bank is
    ``librosa.filters.mel`` (Slaney scale and normalisation) from 0 Hz to ``sample_rate / 2``.

    Args:
        audio: mono signal ``(n,)`` of floats at full scale [-1, 1] (as :func:`load_audio`
            gives), finite, at least one motion frame long.
        sample_rate: its rate in Hz (an integer, Python's or NumPy's).
        fps: motion frames per second (an integer).
        n_mels: number of mel bands.

    Raises:
        AudioError: for non-1-D, empty, non-finite, integer-valued (PCM: divide by the full
            scale first), far too loud (peak above :data:`MAX_PEAK`) or shorter-than-one-frame
            audio.
    """
    audio, sample_rate, fps, n_frames = _check_features_input(audio, sample_rate, fps)
    n_mels = _positive_int(n_mels, "n_mels")
    starts, window_length = _frame_window_starts(n_frames, sample_rate, fps)
    n_fft, mel_basis = _mel_filter_bank(window_length, sample_rate, n_mels)
    window = librosa.filters.get_window("hann", window_length, fftbins=True).astype(np.float32)

    # Rounding the last window's start can push its end one sample past the audio: pad with zeros.
    overhang = int(starts[-1]) + window_length - audio.size
    if overhang > 0:
        audio = np.pad(audio, (0, overhang))
    offsets = np.arange(window_length)
    mel_power = np.empty((n_frames, n_mels), dtype=np.float32)
    for first in range(0, n_frames, _FRAMES_PER_BLOCK):
        block = slice(first, first + _FRAMES_PER_BLOCK)
        frames = audio[starts[block, None] + offsets] * window  # (frames, W)
        spectrum = scipy.fft.rfft(frames, n=n_fft, axis=1)  # (frames, n_fft // 2 + 1)
        power = spectrum.real**2 + spectrum.imag**2
        mel_power[block] = power @ mel_basis.T
    return np.log(mel_power + np.float32(MEL_FLOOR))


@functools.lru_cache(maxsize=8)
def _mel_filter_bank(window_length: int, sample_rate: int, n_mels: int) -> tuple[int, np.ndarray]:
    """``(n_fft, mel_basis)``: the FFT length for a window (the next power of two) and the filter
    bank ``(n_mels, n_fft // 2 + 1)`` float32 of :func:`mel_spectrogram` (shared: do not write
    to it)."""
    n_fft = 1 << (window_length - 1).bit_length()
    mel_basis = librosa.filters.mel(sr=sample_rate, n_fft=n_fft, n_mels=n_mels).astype(np.float32)
    return n_fft, mel_basis


def _white_noise_bands(sample_rate: int, fps: int, n_mels: int) -> np.ndarray:
    """White noise's log power in each band of :func:`mel_spectrogram` ``(n_mels,)``, up to one
    constant: the noise holds the same power in every FFT bin, so a band holds its filter's sum
    (an empty filter, at a low sample rate, holds next to none)."""
    _, window_length = _frame_window_starts(0, sample_rate, fps)
    _, mel_basis = _mel_filter_bank(window_length, sample_rate, n_mels)
    return np.log(np.maximum(mel_basis.sum(axis=1), 1e-30))


def mfcc(
    audio: np.ndarray, sample_rate: int, fps: int = FPS, n_mfcc: int = 13, n_mels: int = N_MELS
) -> np.ndarray:
    """Mel-frequency cepstral coefficients ``(T, n_mfcc)`` float32, aligned like the log-mel.

    The orthonormal DCT-II (``librosa.feature.mfcc``) of each row of :func:`mel_spectrogram`;
    coefficient 0 is the overall log level. ``n_mfcc`` must not exceed ``n_mels``.
    """
    n_mfcc = _positive_int(n_mfcc, "n_mfcc")
    if n_mfcc > n_mels:
        raise ValueError(f"n_mfcc={n_mfcc} cannot exceed n_mels={n_mels}")
    log_mel = mel_spectrogram(audio, sample_rate, fps=fps, n_mels=n_mels)  # (T, n_mels)
    coefficients = librosa.feature.mfcc(S=log_mel.T, n_mfcc=n_mfcc)  # (n_mfcc, T)
    return coefficients.T.astype(np.float32)


#: The quietest frames of a recording, this percentage of them by mean log-mel, give its noise
#: floor (:func:`speech_features`)...
NOISE_FLOOR_PERCENTILE = 10
#: ...and percentile, over frames, of the mean height above the floors taken as the speech level.
SPEECH_LEVEL_PERCENTILE = 95
#: The speech level is at least this many nats above the floor (about 9 dB of power; speech
#: rises 20 dB and more above a pause), so that a recording of silence or of steady noise is not
#: blown up into speech-sized features.
MIN_SPEECH_RANGE = 2.0
#: ...and at most this many (about 35 dB): wider than the range of any conversation the course
#: generates (30 to 60 s, noise floors 30 to 60 dB under the peak). A recording with a wider one is
#: heard as if white noise brought it down to this (:func:`speech_features`).
MAX_SPEECH_RANGE = 8.0


def speech_features(
    audio: np.ndarray, sample_rate: int, fps: int = FPS, n_mels: int = N_MELS
) -> np.ndarray:
    """What the models hear: the log-mel ``(T, n_mels)`` float32, normalised per recording.

    Each band is measured from the recording's own noise floor (the band's mean over the
    recording's quietest :data:`NOISE_FLOOR_PERCENTILE` % of frames), in units of the recording's
    speech level (the :data:`SPEECH_LEVEL_PERCENTILE`-th percentile over frames of the mean height
    above the floor). Silence and steady background noise then read about 0 and loud speech
    about 1, whatever the level, the microphone gain or the noise a recording was made with: a
    person's recording in a quiet room, a noisy one and the generator's tracks look alike to the
    model. Frames align as in :func:`mel_spectrogram`; the arguments are the same.

    Frames of digital silence (exact zeros, as editors and speech synthesisers write between
    sentences) hold no sound to measure: they read 0 and play no part in the floor or the level
    (nor do the frames beside them, which hold zeros in part,
    :func:`_measurable`); otherwise they would pull the floor far below a room's own noise,
    making its quiet pauses read as speech. A recording of nothing but digital silence reads 0
    throughout.

    The speech level is taken as at most :data:`MAX_SPEECH_RANGE` nats above the floor, more than
    the course's conversations span. A recording whose range is wider (one whose room echoes into
    digital silence: its floor is the echo's last whisper) is heard as if white noise lay under
    it, as under the generator's, just loud enough to bring the range down to that
    (:func:`_under_white_noise`). An echo far below the speech then reads near 0, as it would in
    any recording the models learned from, and how far down the recording's own floor lies, or
    whether it was written as floats or as 16-bit, no longer matters.

    The statistics are the recording's, so features of a clip cut from a longer recording differ
    slightly from the same frames of the whole: compute them on what the model will hear.
    """
    # At the recording's own scale, so that MEL_FLOOR sits as far below a quiet recording's
    # sound as below a loud one's: a gain then changes nothing, even beside digital silence.
    audio = _check_signal(audio, "audio")
    peak = float(np.max(np.abs(audio), initial=0.0))
    log_mel = mel_spectrogram(audio / max(peak, 1e-30), sample_rate, fps=fps, n_mels=n_mels)
    loudness = log_mel.mean(axis=1)  # (T,)
    sound = loudness > np.log(MEL_FLOOR) + 1.0  # a nat above the floor of the log: not zeros
    if not sound.any():
        return np.zeros_like(log_mel)
    measured = _measurable(sound)
    quiet = measured & (loudness <= np.percentile(loudness[measured], NOISE_FLOOR_PERCENTILE))
    floor = log_mel[quiet].mean(axis=0)  # (n_mels,)
    above = log_mel - floor  # (T, n_mels)
    above[~sound] = 0.0
    level = np.percentile(above[measured].mean(axis=1), SPEECH_LEVEL_PERCENTILE)
    if level > MAX_SPEECH_RANGE:
        # int(): mel_spectrogram has checked them, and NumPy's integers lack bit_length
        white = _white_noise_bands(int(sample_rate), int(fps), n_mels) - floor  # (n_mels,)
        above = _under_white_noise(above, measured, white, MAX_SPEECH_RANGE)
        level = MAX_SPEECH_RANGE
    return (above / max(float(level), MIN_SPEECH_RANGE)).astype(np.float32)


def _under_white_noise(
    above: np.ndarray, measured: np.ndarray, white: np.ndarray, speech_range: float
) -> np.ndarray:
    """``above`` ``(T, n_mels)``, each band in nats over its floor, as heard with white noise
    added: just enough that the speech level reads ``speech_range`` nats over the new floors.

    ``white`` ``(n_mels,)`` is white noise's log power in each band over the band's floor, up to
    one constant for all bands. A band ``a`` nats over its floor holds ``e^a`` times the floor's
    power; with ``n`` floors of noise more, it holds ``e^a + n`` over a floor of ``1 + n``. Digital
    silence (0) stays 0."""
    white = white - white.mean()

    def heard(log_noise: float) -> np.ndarray:
        noise = (white + log_noise).astype(above.dtype)  # (n_mels,): log n in each band
        zero = np.zeros(1, above.dtype)  # so that the result stays in above's precision
        return np.logaddexp(above, noise) - np.logaddexp(zero, noise)

    def excess(log_noise: float) -> float:
        level = np.percentile(heard(log_noise)[measured].mean(axis=1), SPEECH_LEVEL_PERCENTILE)
        return level - speech_range

    # At the lower end the noise is e^-40 of every band's floor or less: the level is the
    # recording's own, above speech_range; at the upper end it is e^40 of every band's loudest
    # frame or more: the level is about 0.
    quietest = -40.0 - float(white.max())
    loudest = 40.0 + float(above.max() - white.min())
    return heard(scipy.optimize.brentq(excess, quietest, loudest, xtol=1e-6))


def _measurable(sound: np.ndarray) -> np.ndarray:
    """The frames ``(T,)`` bool whose level says something about the recording's sound: frames
    with sound whose neighbours have sound too (a frame beside digital silence holds zeros in
    part, and reads quieter than the room). All frames with sound where none qualifies."""
    inner = sound & np.r_[True, sound[:-1]] & np.r_[sound[1:], True]
    return inner if inner.any() else sound


# --------------------------------------------------------------------------- prosody


def prosody(audio: np.ndarray, sample_rate: int, fps: int = FPS) -> np.ndarray:
    """Prosodic features ``(T, 4)`` float32: columns :data:`PROSODY_FEATURES`, aligned like the mel.

    As in Kucherenko et al. (2021): energy, log-F0 and their time derivatives.

    * ``log_energy``: natural log of the mean squared amplitude over exactly the samples of the
      frame, ``[t / fps, (t + 1) / fps)``, plus :data:`ENERGY_FLOOR` (silence gives about -23).
    * ``log_f0``: natural log of F0 in Hz. F0 is estimated with YIN (``librosa.yin``, searching
      :data:`F0_MIN` to :data:`F0_MAX` Hz) :data:`PITCH_FRAMES_PER_FRAME` times per motion frame.
      A pitch frame counts as voiced when the signal correlates with itself one period later by at
      least :data:`VOICING_THRESHOLD` and is not silent (peak at least :data:`SILENCE_THRESHOLD`
      of the recording's peak). Unvoiced pitch frames get log-F0 linearly interpolated between
      the neighbouring voiced ones (held constant before the first and after the last), so the
      contour, and its derivative, stay continuous across voicing boundaries; the pitch frames
      whose centres fall in a motion frame are then averaged. A recording with no voiced frame
      at all gets the constant ``log(F0_MIN)``.
    * ``d_log_energy``, ``d_log_f0``: time derivatives per second (central differences,
      one-sided at the ends; zero for a single frame).

    YIN keeps this fast (about 1.5 s for 10 minutes of 16 kHz audio on two CPU cores); pYIN
    would decide voicing itself but takes about 1.5 minutes for the same audio.

    Args:
        audio: mono signal ``(n,)`` of floats at full scale [-1, 1], finite, at least one motion
            frame long (see :func:`mel_spectrogram`).
        sample_rate: its rate in Hz, at least ``2 * F0_MAX``.
        fps: motion frames per second (an integer).
    """
    audio, sample_rate, fps, n_frames = _check_features_input(audio, sample_rate, fps)
    if sample_rate < 2 * F0_MAX:
        raise AudioError(
            f"prosody needs sample_rate >= {2 * F0_MAX:g} Hz to find pitch up to {F0_MAX:g} Hz, "
            f"got {sample_rate}"
        )
    boundaries = _frame_boundaries(n_frames, sample_rate, fps)
    squares = np.square(audio[: boundaries[-1]], dtype=np.float64)
    mean_square = np.add.reduceat(squares, boundaries[:-1]) / np.diff(boundaries)
    log_energy = np.log(mean_square + ENERGY_FLOOR)
    log_f0 = _log_f0_per_frame(audio, sample_rate, fps, n_frames)

    columns = [log_energy, log_f0]
    for contour in (log_energy, log_f0):
        if n_frames > 1:
            columns.append(np.gradient(contour, 1.0 / fps))
        else:
            columns.append(np.zeros(1))
    return np.stack(columns, axis=1).astype(np.float32)


#: A frame has voice when its energy is within this many decibels of the loud frames of the
#: recording (its 95th percentile of frame energy); :func:`voice_activity`.
VOICE_THRESHOLD_DB = 30.0
#: ... and at least this many decibels above the recording's noise floor (its 5th percentile of
#: frame energy), so that steady background noise is not taken for voice: with white noise
#: 34 dB below the speech, the threshold alone marked every frame as voiced ...
NOISE_MARGIN_DB = 6.0
#: ... unless that would ask more than this many decibels below the loud frames: in a recording
#: that never pauses the "noise floor" is quiet speech, which must stay voiced.
NOISE_GATE_LIMIT_DB = 15.0


def voice_activity(
    audio: np.ndarray, sample_rate: int, fps: int = FPS, gap_s: float = 0.3, blip_s: float = 0.1
) -> np.ndarray:
    """Which motion frames hold speech, ``(T,)`` bool, from the energy of a recording of one voice.

    A frame has voice when its energy is within :data:`VOICE_THRESHOLD_DB` of the recording's loud
    frames and :data:`NOISE_MARGIN_DB` above its quietest (the noise floor; never asking more than
    :data:`NOISE_GATE_LIMIT_DB` below the loud frames, so speech without pauses stays voiced); pauses shorter than ``gap_s`` inside speech count as speech (the gaps between syllables
    and words), and stretches of voice shorter than ``blip_s`` do not (clicks). Relative to the
    recording, so the level it was recorded at does not matter; digital silence (exact zeros)
    takes no part in the loud frames or the noise floor, as in :func:`speech_features`, and a
    recording without any sound (all frames below the energy floor) has no voice.

    Args:
        audio, sample_rate, fps: as for :func:`mel_spectrogram`.
        gap_s: the longest silence that does not end a stretch of speech.
        blip_s: the shortest stretch of sound that counts as speech.
    """
    audio, sample_rate, fps, n_frames = _check_features_input(audio, sample_rate, fps)
    boundaries = _frame_boundaries(n_frames, sample_rate, fps)
    energy_db = 10 * np.log10(_frame_energy(audio, boundaries) + ENERGY_FLOOR)
    sound = energy_db > 10 * np.log10(ENERGY_FLOOR) + 1  # not digital silence
    if not sound.any():
        return np.zeros(n_frames, dtype=bool)
    loud, noise_floor = np.percentile(energy_db[_measurable(sound)], [95, 5])
    gate = min(noise_floor + NOISE_MARGIN_DB, loud - NOISE_GATE_LIMIT_DB)
    voiced = sound & (energy_db > max(loud - VOICE_THRESHOLD_DB, gate))
    voiced = ~_short_runs(~voiced, round(gap_s * fps), keep_ends=True)  # fill short pauses
    return _short_runs(voiced, round(blip_s * fps), keep_ends=False)  # drop short blips


def _frame_energy(audio: np.ndarray, boundaries: np.ndarray) -> np.ndarray:
    """The mean square of each frame's samples ``(T,)``, without the recording's DC offset (a
    constant is no sound; digital silence stays exact zeros), in blocks of frames so that memory
    stays small for an hour of audio."""
    used = audio[: boundaries[-1]]
    nonzero = np.count_nonzero(used)
    offset = float(used.sum(dtype=np.float64)) / nonzero if nonzero else 0.0
    energy = np.empty(len(boundaries) - 1)
    step = 10_000  # frames a block
    for first in range(0, len(energy), step):
        edges = boundaries[first : first + step + 1]
        block = used[edges[0] : edges[-1]].astype(np.float64)
        block[block != 0] -= offset
        energy[first : first + len(edges) - 1] = np.add.reduceat(
            np.square(block), edges[:-1] - edges[0]
        ) / np.diff(edges)
    return energy


def who_is_talking(
    agent: np.ndarray, sample_rate: int, partner: np.ndarray | None = None, fps: int = FPS
) -> np.ndarray:
    """Who is talking, ``(T,)`` int64 :class:`~gesturelib.conventions.Activity` codes, from a
    recording of the agent's voice and, if given, one of its partner's at the same rate: each
    speaks where its recording holds speech (:func:`voice_activity`).

    Raises:
        AudioError: for unusable audio, a partner's recording that covers another number of
            whole frames than the agent's, or when neither recording holds speech (the agent
            would only rest).
    """
    shortest = 0.1  # voice_activity's blip_s: shorter sound is not counted as speech
    for name, recording in (("the recording", agent), ("the partner's recording", partner)):
        if recording is not None and 0 < len(recording) < shortest * sample_rate:
            raise AudioError(
                f"{name} lasts {1000 * len(recording) / sample_rate:.0f} ms, too short to hear "
                f"speech in (at least {1000 * shortest:.0f} ms); give a longer recording"
            )
    speaking = voice_activity(agent, sample_rate, fps, blip_s=shortest)
    _check_speech_like(agent, sample_rate, speaking, fps, "the recording")
    listening = np.zeros_like(speaking)
    if partner is not None:
        if num_frames(len(partner), sample_rate, fps) != len(speaking):
            raise AudioError(
                f"the partner's recording lasts {len(partner) / sample_rate:.3f} s and the "
                f"agent's {len(agent) / sample_rate:.3f} s; it must have the agent's length (to "
                f"within a frame, {1000 // fps} ms)"
            )
        listening = voice_activity(partner, sample_rate, fps, blip_s=shortest)
        _check_speech_like(partner, sample_rate, listening, fps, "the partner's recording")
    if not (speaking.any() or listening.any()):
        heard = (
            "the recording holds no speech" if partner is None else "neither recording holds speech"
        )
        raise AudioError(
            f"{heard} (silent, or too quiet to tell from silence): the agent would only rest; "
            "give a recording of speech"
        )
    return np.select(
        [speaking & listening, speaking, listening],
        [Activity.BOTH, Activity.A_SPEAKS, Activity.B_SPEAKS],
        Activity.NONE,
    ).astype(np.int64)


#: Below both, a recording's voiced frames are a steady sound, not speech: the spread of their
#: loudness (nats of log-mel power; speech 1.2 and more, a tone, hum or noise 0.1 and less) and
#: the median change of their spectrum from frame to frame (speech 1.2 and more, steady 0.45
#: and less; measured on the course's data, the committed recordings and steady signals).
STEADY_LOUDNESS_SPREAD, STEADY_SPECTRAL_CHANGE = 0.5, 0.8


def _check_speech_like(audio, sample_rate: int, voiced: np.ndarray, fps: int, name: str) -> None:
    """Refuse a recording whose voice activity is a steady sound: a tone, a hum, a DC offset or
    steady noise reads as voice by its energy alone, and would make the agent speak throughout."""
    if voiced.sum() < 5:  # too little to tell
        return
    log_mel = mel_spectrogram(audio, sample_rate, fps=fps)
    spread = float(np.std(log_mel.mean(axis=1)[voiced]))
    change = np.abs(np.diff(log_mel, axis=0)).mean(axis=1)[voiced[1:] & voiced[:-1]]
    if spread < STEADY_LOUDNESS_SPREAD and (
        change.size == 0 or float(np.median(change)) < STEADY_SPECTRAL_CHANGE
    ):
        raise AudioError(
            f"{name} holds a steady sound (a tone, hum or noise: its loudness and spectrum barely "
            "change), not speech; give a recording of a voice"
        )


def _short_runs(mask: np.ndarray, shortest: int, keep_ends: bool) -> np.ndarray:
    """``mask`` without its runs of True shorter than ``shortest`` frames (runs touching either
    end of the recording are kept if ``keep_ends``)."""
    result = mask.copy()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        touches_end = start == 0 or end == len(mask)
        if end - start < shortest and not (keep_ends and touches_end):
            result[start:end] = False
    return result


def _log_f0_per_frame(audio: np.ndarray, sample_rate: int, fps: int, n_frames: int) -> np.ndarray:
    """Log-F0 ``(T,)`` per motion frame, unvoiced gaps interpolated (see :func:`prosody`)."""
    hop = max(1, sample_rate // (PITCH_FRAMES_PER_FRAME * fps))
    # YIN wants two periods of the lowest pitch inside a frame.
    frame_length = 1 << int(np.ceil(np.log2(2 * sample_rate / F0_MIN + 2)))
    silence_level = SILENCE_THRESHOLD * float(np.abs(audio).max())
    # Pitch frame j is centred on sample j * hop. YIN is run block by block on slices of the
    # zero-padded signal, which keeps memory bounded on long recordings.
    padded = np.pad(audio, frame_length // 2)
    n_pitch_frames = 1 + audio.size // hop
    f0 = np.empty(n_pitch_frames)
    voiced = np.empty(n_pitch_frames, dtype=bool)
    for first in range(0, n_pitch_frames, _FRAMES_PER_BLOCK):
        last = min(first + _FRAMES_PER_BLOCK, n_pitch_frames)
        segment = padded[first * hop : (last - 1) * hop + frame_length]
        f0[first:last] = librosa.yin(
            segment,
            fmin=F0_MIN,
            fmax=F0_MAX,
            sr=sample_rate,
            frame_length=frame_length,
            hop_length=hop,
            center=False,
        )
        frames = librosa.util.frame(segment, frame_length=frame_length, hop_length=hop, axis=0)
        periods = np.rint(sample_rate / f0[first:last]).astype(np.int64)
        voiced[first:last] = (_periodicity(frames, periods) >= VOICING_THRESHOLD) & (
            np.abs(frames).max(axis=1) >= silence_level
        )

    pitch_frame = np.arange(n_pitch_frames)
    if voiced.any():
        log_f0 = np.interp(pitch_frame, pitch_frame[voiced], np.log(f0[voiced]))
    else:
        log_f0 = np.full(n_pitch_frames, np.log(F0_MIN))
    motion_frame = pitch_frame * hop * fps // sample_rate  # the frame holding each centre
    inside = motion_frame < n_frames
    totals = np.bincount(motion_frame[inside], weights=log_f0[inside], minlength=n_frames)
    counts = np.bincount(motion_frame[inside], minlength=n_frames)
    return totals / counts  # every motion frame holds >= PITCH_FRAMES_PER_FRAME pitch frames


def _periodicity(frames: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """Correlation ``(F,)`` of each frame ``(F, L)`` with itself shifted by its period ``(F,)``.

    1 for a perfectly periodic frame, near 0 for noise; 0 for an all-zero frame.
    """
    frame_length = frames.shape[1]
    offsets = np.arange(frame_length)
    periods = periods[:, None]
    overlap = offsets < frame_length - periods  # samples n with n + period inside the frame
    later = np.take_along_axis(frames, np.minimum(offsets + periods, frame_length - 1), axis=1)
    head = np.where(overlap, frames, 0.0)
    tail = np.where(overlap, later, 0.0)
    norms = np.sqrt((head * head).sum(axis=1) * (tail * tail).sum(axis=1))
    return (head * tail).sum(axis=1) / np.maximum(norms, np.finfo(np.float32).tiny)


# --------------------------------------------------------------------------- speech activity


def activity_one_hot(codes: np.ndarray) -> np.ndarray:
    """Activity codes ``(T,)`` (integers 0..3, see :class:`Activity`) -> one-hot ``(T, 4)`` float32."""
    codes = np.asarray(codes)
    if codes.ndim != 1:
        raise ValueError(f"activity codes must have shape (T,), got {codes.shape}")
    if codes.dtype.kind not in "iu":
        raise ValueError(
            f"activity codes must be integers, got dtype {codes.dtype}; {_VALID_CODES}"
        )
    invalid = (codes < 0) | (codes >= len(Activity))
    if invalid.any():
        bad = np.unique(codes[invalid])[:5].tolist()
        raise ValueError(f"invalid activity codes {bad}; {_VALID_CODES}")
    return np.eye(len(Activity), dtype=np.float32)[codes]


def activity_from_one_hot(one_hot: np.ndarray) -> np.ndarray:
    """One-hot activity ``(T, 4)`` -> codes ``(T,)`` int64; the inverse of :func:`activity_one_hot`.

    Every row must hold a single 1 and zeros elsewhere; for probabilities, take
    ``probabilities.argmax(axis=-1)`` instead.
    """
    one_hot = np.asarray(one_hot)
    if one_hot.ndim != 2 or one_hot.shape[1] != len(Activity):
        raise ValueError(
            f"one-hot activity must have shape (T, {len(Activity)}), got {one_hot.shape}; "
            f"{_VALID_CODES}"
        )
    if one_hot.dtype.kind not in "biuf":
        raise ValueError(f"one-hot activity must be numeric, got dtype {one_hot.dtype}")
    is_one_hot = np.isin(one_hot, (0, 1)).all(axis=1) & (one_hot.sum(axis=1) == 1)
    if not is_one_hot.all():
        row = int(np.flatnonzero(~is_one_hot)[0])
        raise ValueError(
            f"row {row} of the one-hot activity is {one_hot[row].tolist()}, not a single 1 among "
            "zeros; for probabilities use .argmax(axis=-1)"
        )
    return one_hot.argmax(axis=1).astype(np.int64)


_VALID_CODES = "valid codes: " + ", ".join(
    f"{member.value} = {member.name} ({member.label})" for member in Activity
)


# --------------------------------------------------------------------------- input checks


def _integer(value, name: str) -> int:
    """``value`` as a Python int: any integral number (``int``, ``numpy.int64``...), not a bool."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return int(value)


def _positive_int(value, name: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral) or value <= 0:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_signal(audio, name: str) -> np.ndarray:
    """A signal at full scale: finite, non-empty, 1-D, float, peak <= MAX_PEAK, as float32 ``(n,)``.

    Raises AudioError otherwise, saying how to fix it.
    """
    audio = np.asarray(audio)
    if audio.dtype.kind in "iu":
        half = 2 ** (8 * audio.dtype.itemsize - 1)  # the full scale of signed PCM
        scale = (
            f"divide by {half}" if audio.dtype.kind == "i" else f"subtract {half}, divide by {half}"
        )
        raise AudioError(
            f"{name} holds integers ({audio.dtype}), but samples must be floats at full scale "
            f"[-1, 1]: convert integer PCM first ({scale}), or read the file with load_audio"
        )
    if audio.dtype.kind != "f":
        raise AudioError(f"{name} must be a real-valued signal, got dtype {audio.dtype}")
    if audio.ndim != 1:
        raise AudioError(
            f"{name} must be a mono signal of shape (n,), got shape {audio.shape}; "
            "down-mix channels first (load_audio does)"
        )
    if audio.size == 0:
        raise AudioError(f"{name} is empty (0 samples)")
    if not np.isfinite(audio).all():
        raise AudioError(f"{name} has {int((~np.isfinite(audio)).sum())} NaN or infinite samples")
    peak = max(float(audio.max()), -float(audio.min()))  # without a copy of an hour's audio
    if peak > MAX_PEAK:
        raise AudioError(
            f"{name} peaks at {peak:.3g}, far beyond full scale (1): samples must be floats in "
            "[-1, 1]; if these are integer PCM values stored as floats, divide by the full scale "
            "(32768 for 16-bit samples), or read the file with load_audio"
        )
    return audio.astype(np.float32, copy=False)


def _check_features_input(audio, sample_rate, fps) -> tuple[np.ndarray, int, int, int]:
    """Validate a signal and its rates for feature extraction.

    Returns ``(audio as float32, sample_rate, fps, T)``, the rates as Python ints.
    """
    audio = _check_signal(audio, "audio")
    n_frames = num_frames(audio.size, sample_rate, fps)
    sample_rate, fps = int(sample_rate), int(fps)  # num_frames checked that they are integers
    if sample_rate < 2 * fps:
        raise ValueError(
            f"sample_rate={sample_rate} Hz is too low for {fps} fps (< 2 samples a frame)"
        )
    if n_frames == 0:
        raise AudioError(
            f"audio of {audio.size} samples ({audio.size / sample_rate * 1000:.1f} ms at "
            f"{sample_rate} Hz) is shorter than one motion frame ({1000 / fps:.1f} ms at {fps} fps)"
        )
    return audio, sample_rate, fps, n_frames
