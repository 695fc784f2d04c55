"""Make the recordings of speech that the tests and chapter 08 drive the agent with.

Speech the generator did not make: text-to-speech voices of espeak-ng, degraded with sox (noise,
reverb, a telephone's band), as a person's recordings are. Each recording is two seconds of
silence, then phrases with pauses of 3-4 s between them (long enough for the agent of our data to
retract its hands and rest before it prepares the next gesture), then two seconds of silence, so
that the speech and the silences are known (written beside the recordings in ``voices.csv``).

A second set, the *selection* recordings, is made the same way with other sentences, mostly other
voices (one is the test's female voice in the test's reverberant room), and is not committed:
eight recordings to choose a front end or a recipe by, so that the five stay a test that nothing
was tuned on (``benchmarks/bench_own_voice.py --recordings DIR``).

Needs Debian's espeak-ng and sox (``apt-get install espeak-ng sox``). Run from the repository root:

    python tools/make_test_voices.py                       # writes tests/data/voices/
    python tools/make_test_voices.py --selection DIR       # the eight selection recordings
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import soundfile

OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "voices"
PHRASES = (
    "So I went down to the harbour, and the boats were all gone.",
    "Nobody knew where they had sailed, not even the old captain.",
    "And then, at midnight, every one of them came back at once!",
    "I think we should try the other road tomorrow morning.",
    "It is longer, but the view from the hill is really worth it.",
    "Bring a coat, because the wind up there can be very cold.",
)
#: name -> (espeak-ng voice, words per minute, pitch 0-99, sox effects, white noise amplitude
#: (None: none), output rate in Hz)
RECORDINGS = {
    "us_clean": ("en-us", 160, 45, [], None, 22050),
    "rp_reverb": ("en-gb-x-rp", 150, 40, ["reverb", "50", "50", "80"], None, 22050),
    "us_female_noise": ("en-us+f3", 170, 60, [], "0.02", 16000),
    "scottish_phone": ("en-gb-scotland", 155, 35, ["sinc", "300-3400"], "0.01", 8000),
    "caribbean_room": ("en-029", 165, 55, ["reverb", "30", "50", "60"], "0.01", 24000),
}
#: The selection set: other sentences, other voices, the same kinds of degradation.
SELECTION_PHRASES = (
    "The train was late again, so we walked the whole way to the station.",
    "My sister said the market had the best bread she had ever tasted.",
    "We waited for an hour, and then the rain finally stopped for good.",
    "Could you send me the pictures from the party last weekend, please?",
    "I never thought that a small garden could grow so many tomatoes.",
    "After the concert we talked about the music until very late.",
)
SELECTION = {
    "v_us_m3_clean": ("en-us+m3", 165, 50, [], None, 22050),
    "v_gb_f2_reverb": ("en-gb+f2", 155, 55, ["reverb", "60", "50", "90"], None, 22050),
    "v_rp_f4_noise": ("en-gb-x-rp+f4", 160, 55, [], "0.015", 16000),
    "v_029_m2_phone": ("en-029+m2", 150, 40, ["sinc", "300-3400"], "0.01", 8000),
    "v_scot_f1_room": ("en-gb-scotland+f1", 170, 60, ["reverb", "40", "50", "70"], "0.005", 24000),
    "v_us_f3_reverb": ("en-us+f3", 160, 60, ["reverb", "50", "50", "80"], None, 22050),
    "v_gb_noise": ("en-gb", 150, 35, [], "0.02", 22050),
    "v_us_m7_clean": ("en-us+m7", 175, 45, [], None, 16000),
}
SILENCE_S = 2.0  # before the first phrase and after the last
PAUSES_S = (3.0, 4.0)  # the agent retracts its hands for a second after a phrase


def speak(text: str, voice: str, words_per_minute: int, pitch: int, folder: Path) -> np.ndarray:
    """One phrase from espeak-ng, as float samples at 22050 Hz without leading/trailing silence."""
    path = folder / "phrase.wav"
    subprocess.run(
        ["espeak-ng", "-v", voice, "-s", str(words_per_minute), "-p", str(pitch), "-w", path, text],
        check=True,
    )
    audio, rate = soundfile.read(path, dtype="float32")
    assert rate == 22050
    loud = np.flatnonzero(np.abs(audio) > 0.01)
    return audio[loud[0] : loud[-1] + 1]


def degrade(
    audio: np.ndarray, effects: list[str], noise_level: str | None, rate: int, folder: Path
) -> np.ndarray:
    """Apply sox ``effects``, resample to ``rate``, then add white noise of amplitude
    ``noise_level`` (sox's own, seeded) unless it is None."""
    clean, out = folder / "clean.wav", folder / "out.wav"
    soundfile.write(clean, audio, 22050, subtype="FLOAT")
    subprocess.run(["sox", "-R", clean, out, *effects, "rate", str(rate)], check=True)
    if noise_level is not None:
        noise = folder / "noise.wav"
        seconds = str(soundfile.info(out).duration)
        subprocess.run(
            ["sox", "-R", "-n", "-r", str(rate), "-c", "1", noise, "synth", seconds, "whitenoise"]
            + ["vol", noise_level],
            check=True,
        )
        mixed = folder / "mixed.wav"
        subprocess.run(["sox", "-R", "-m", "-v", "1", out, "-v", "1", noise, mixed], check=True)
        out = mixed
    degraded, got = soundfile.read(out, dtype="float32")
    assert got == rate
    return degraded


def make(out: Path, recordings: dict, phrase_pool: tuple[str, ...]) -> None:
    """Write ``recordings`` (name -> recipe, as :data:`RECORDINGS`) into ``out`` with
    ``voices.csv``; recording ``i`` speaks the first three sentences of ``phrase_pool`` when ``i``
    is even, the last three when odd."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for number, (name, recipe) in enumerate(recordings.items()):
        voice, speed, pitch, effects, noise_level, rate = recipe
        with tempfile.TemporaryDirectory() as folder:
            folder = Path(folder)
            phrases = phrase_pool[3 * (number % 2) : 3 * (number % 2) + 3]
            pieces, spans, at = [np.zeros(int(SILENCE_S * 22050), np.float32)], [], SILENCE_S
            for index, text in enumerate(phrases):
                spoken = speak(text, voice, speed, pitch, folder)
                spans.append((at, at + len(spoken) / 22050))
                pause = PAUSES_S[index % 2] if index < len(phrases) - 1 else SILENCE_S
                pieces += [spoken, np.zeros(int(pause * 22050), np.float32)]
                at = spans[-1][1] + pause
            audio = np.concatenate(pieces)
            audio = 0.7 * audio / np.abs(audio).max()
            degraded = degrade(audio, effects, noise_level, rate, folder)
        # Headroom: 0.9 of the level sox gave, and never a peak above 0.81 of full scale.
        degraded = 0.9 * degraded / max(1.0, float(np.abs(degraded).max()) / 0.9)
        path = out / f"{name}.flac"
        soundfile.write(path, degraded, rate, subtype="PCM_16")
        for start, end in spans:
            rows.append(
                {
                    "recording": path.name,
                    "speech_start_s": f"{start:.3f}",
                    "speech_end_s": f"{end:.3f}",
                }
            )
        print(
            f"{path}: {len(degraded) / rate:.1f} s at {rate} Hz, {voice}, "
            f"{' '.join(effects) or 'no effects'}, noise {noise_level}"
        )
    with open(out / "voices.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--selection",
        type=Path,
        metavar="DIR",
        help="write the eight selection recordings into DIR instead of the committed five",
    )
    args = parser.parse_args()
    if args.selection is None:
        make(OUT, RECORDINGS, PHRASES)
        return 0
    folder = args.selection.resolve()
    if folder == OUT.resolve() or OUT.resolve() in folder.parents:
        parser.error(f"{args.selection} is in the committed recordings' folder; choose another")
    if folder.exists() and not folder.is_dir():
        parser.error(f"{args.selection} is a file; give a folder for the selection recordings")
    make(folder, SELECTION, SELECTION_PHRASES)
    return 0


if __name__ == "__main__":
    sys.exit(main())
