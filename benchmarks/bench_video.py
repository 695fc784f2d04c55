"""How long a video takes to write: ``viz.save_animation`` for a clip of two motions side by side.

Renders the first ``--seconds`` of a quick-mode held-out conversation's motion next to itself
(front and side views of each, 25 frames a second, with its sound) into an MP4, ``--repeats``
times, and prints the time of each write and their median.

Usage::

    .venv/bin/python benchmarks/bench_video.py [--seconds 10] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from data_synth import course_data, load_dataset  # noqa: E402
from gesturelib import viz  # noqa: E402
from gesturelib.conventions import FPS  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="length of the clip")
    parser.add_argument("--repeats", type=int, default=3, help="writes to time")
    args = parser.parse_args()
    if args.seconds <= 0 or args.repeats < 1:
        parser.error("--seconds must be positive and --repeats at least 1")
    if viz.ffmpeg_executable() is None:
        parser.error("no ffmpeg: install imageio-ffmpeg (make setup does)")
    conversation = load_dataset(course_data(True))["test"][0]
    frames = min(int(args.seconds * FPS), len(conversation.positions))
    motion = conversation.positions[:frames]
    audio = conversation.audio[: int(frames / FPS * conversation.sample_rate)]
    times = []
    with tempfile.TemporaryDirectory() as folder:
        for repeat in range(args.repeats):
            anim = viz.animate([motion, motion], titles=["a", "b"])
            started = time.perf_counter()
            viz.save_animation(
                anim, Path(folder) / f"clip{repeat}.mp4", audio, conversation.sample_rate
            )
            times.append(time.perf_counter() - started)
    print(
        f"{frames / FPS:.1f} s of two motions ({frames} frames): "
        + ", ".join(f"{t:.2f} s" for t in times)
    )
    print(
        f"median {statistics.median(times):.2f} s, {statistics.median(times) / frames * 1000:.1f} ms a frame"
    )


if __name__ == "__main__":
    main()
