"""Speed of the core pose and speech library on this machine.

    python benchmarks/bench_foundation.py

Targets (issue: foundation): log-mel features of 10 minutes of 16 kHz audio well under 5 s;
forward kinematics of 100k frames well under 0.5 s. Each figure is the best of a few repeats.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from gesturelib.conventions import SAMPLE_RATE
from gesturelib.features import mel_spectrogram, mfcc, prosody
from gesturelib.skeleton import NUM_JOINTS, forward_kinematics, rotations_from_positions


def best_time(function, repeats: int = 3) -> float:
    """Shortest wall-clock time of ``repeats`` calls, in seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    rng = np.random.default_rng(0)
    audio = (0.1 * rng.standard_normal(10 * 60 * SAMPLE_RATE)).astype(np.float32)
    rot6d = rng.standard_normal((100_000, NUM_JOINTS, 6))
    positions = forward_kinematics(rot6d)
    rot6d_torch32 = torch.from_numpy(rot6d).float()

    rows = [
        (
            "log-mel, 10 min of 16 kHz audio",
            best_time(lambda: mel_spectrogram(audio, SAMPLE_RATE)),
            5.0,
        ),
        ("MFCC, 10 min of 16 kHz audio", best_time(lambda: mfcc(audio, SAMPLE_RATE)), None),
        (
            "prosody, 10 min of 16 kHz audio",
            best_time(lambda: prosody(audio, SAMPLE_RATE), 1),
            None,
        ),
        (
            "forward kinematics, 100k frames (numpy float64)",
            best_time(lambda: forward_kinematics(rot6d)),
            0.5,
        ),
        (
            "forward kinematics, 100k frames (torch float32)",
            best_time(lambda: forward_kinematics(rot6d_torch32)),
            0.5,
        ),
        (
            "rotations from positions, 100k frames",
            best_time(lambda: rotations_from_positions(positions)),
            None,
        ),
    ]
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    print(f"{'what':<50} {'seconds':>8}  target")
    for name, seconds, target in rows:
        verdict = (
            "" if target is None else f"< {target} s " + ("ok" if seconds < target else "MISSED")
        )
        print(f"{name:<50} {seconds:8.3f}  {verdict}")


if __name__ == "__main__":
    main()
