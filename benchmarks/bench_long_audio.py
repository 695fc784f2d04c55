"""Memory and time to hear a long recording: load it, find who is talking, compute its speech
features (what ``generate`` does before the model runs), for a 44.1 kHz stereo WAV of
``--minutes`` minutes made from the generator's speech.

    python benchmarks/bench_long_audio.py              # an hour (a 635 MB file in a temporary folder)
    python benchmarks/bench_long_audio.py --minutes 2

Each stage runs in a fresh process, so the peak resident memory it prints is that stage's own
(with the libraries loaded; Linux only). Results: ``docs/benchmarks.md``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import librosa
import numpy as np
import soundfile

from data_synth import generate_conversation

STAGES = {
    "import only": "pass",
    "load_audio": "audio, rate = load_audio(path)",
    "+ who_is_talking": "audio, rate = load_audio(path); who_is_talking(audio, rate)",
    "+ speech_features": (
        "audio, rate = load_audio(path); who_is_talking(audio, rate); speech_features(audio, rate)"
    ),
}
# The peak is the kernel's high-water mark of this process's memory (VmHWM): unlike ru_maxrss it
# starts afresh at exec, so it does not carry the parent's size over.
PROBE = """
import re, sys, time
from pathlib import Path
from gesturelib.features import load_audio, speech_features, who_is_talking
path = sys.argv[1]
started = time.perf_counter()
{stage}
peak = re.search(r"VmHWM:\\s+(\\d+) kB", Path("/proc/self/status").read_text())[1]
print(time.perf_counter() - started, int(peak) / 1e3)
"""


def write_recording(path: Path, minutes: int) -> None:
    """``minutes`` of the generator's conversation audio, 44.1 kHz stereo 16-bit, a minute at a
    time (the file is never held in memory whole)."""
    conversation = generate_conversation(60.0, seed=3)
    minute = librosa.resample(
        conversation.audio, orig_sr=conversation.sample_rate, target_sr=44_100
    )
    with soundfile.SoundFile(path, "w", 44_100, 2, "PCM_16") as file:
        for _ in range(minutes):
            file.write(np.stack([minute, 0.8 * minute], axis=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=int, default=60, help="length of the recording")
    args = parser.parse_args()
    if args.minutes < 1:
        parser.error(f"--minutes must be at least 1, got {args.minutes}")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "long.wav"
        write_recording(path, args.minutes)
        size = path.stat().st_size / 1e6
        print(f"{args.minutes} min, 44.1 kHz stereo 16-bit WAV ({size:.0f} MB)")
        for name, stage in STAGES.items():
            done = subprocess.run(
                [sys.executable, "-c", PROBE.format(stage=stage), str(path)],
                capture_output=True,
                text=True,
                check=True,
            )
            seconds, megabytes = map(float, done.stdout.split())
            print(f"{name:>18}: peak {megabytes:6.0f} MB, {seconds:5.1f} s")


if __name__ == "__main__":
    main()
