"""Speech the generator did not make: the models on the recordings of ``tests/data/voices/``.

For each recording (espeak-ng voices, clean, reverberant, noisy, through a telephone's band;
``tools/make_test_voices.py``) and each model, the agent speaks where the recording holds speech
(:func:`gesturelib.features.who_is_talking`) and K samples are drawn (seeds 0..K-1 of one call):

* the speaking/silence ratio: the wrists' mean speed while the voice speaks over their mean speed
  in its pauses, all samples pooled (:func:`~gesturelib.evaluation.speaking_listening_ratio`);
* the lead of each sample's strokes over the speech's emphasis
  (:func:`~gesturelib.evaluation.stroke_lead`; the data's rule is 0.2 s).

Prints one Markdown table (the one in ``docs/benchmarks.md``) and the median ratio per model.

Usage (the shipped models by default; any run folders of generative models otherwise)::

    .venv/bin/python benchmarks/bench_own_voice.py [RUN ...] [--samples 3] [--temperature 0.8]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from gesturelib.configs import check_temperature
from gesturelib.evaluation import speaking_listening_ratio, stroke_lead
from gesturelib.features import load_audio
from gesturelib.pipeline import speech_to_motion
from gesturelib.pretrained import NAMES, load_run, pretrained_folder

VOICES = Path(__file__).resolve().parents[1] / "tests" / "data" / "voices"


def on_recording(
    model, normaliser, recording: Path, samples: int, temperature: float | None = None
) -> tuple[float, list[float]]:
    """``(speaking/silence ratio, one stroke lead per sample)`` of a model on ``recording`` (at
    ``temperature``, or the model's own)."""
    audio, rate = load_audio(recording)
    motion = speech_to_motion(
        model, normaliser, audio, rate, samples=samples, temperature=temperature, seed=0
    )
    activity = motion.activity
    ratio = speaking_listening_ratio(list(motion.positions), [activity] * samples)
    return ratio, [stroke_lead(audio, rate, activity, m) for m in motion.positions]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path, help="run folders (default: shipped models)")
    parser.add_argument("--samples", type=int, default=3, help="samples per recording")
    parser.add_argument("--temperature", type=float, default=None, help="the model's own if unset")
    args = parser.parse_args()
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    if args.temperature is not None:
        try:
            check_temperature(args.temperature)
        except ValueError as error:
            parser.error(f"--temperature: {error}")
    runs = args.runs or [pretrained_folder(name) for name in NAMES]
    if len({run.name for run in runs}) < len(runs):
        parser.error("give run folders of different names: the table is headed by them")
    recordings = sorted(VOICES.glob("*.flac"))
    torch.set_num_threads(1)  # frame-by-frame generation is small work: one thread is fastest

    results = {}  # run name -> [(ratio, leads) per recording]
    for run in runs:
        model, normaliser, _ = load_run(run)
        if not hasattr(model, "step"):
            raise SystemExit(
                f"{run} holds a {type(model).__name__}, which does not generate motion"
            )
        results[run.name] = [
            on_recording(model, normaliser, r, args.samples, args.temperature) for r in recordings
        ]

    header = " | ".join(f"{name} ratio | {name} leads (s)" for name in results)
    print(f"| recording | {header} |")
    print("|---|" + "---|---|" * len(results))
    for index, recording in enumerate(recordings):
        cells = []
        for measured in results.values():
            ratio, leads = measured[index]
            cells += [f"{ratio:.2f}", ", ".join(f"{lead:.2f}" for lead in leads)]
        print(f"| `{recording.stem}` | {' | '.join(cells)} |")
    for name, measured in results.items():
        print(f"{name}: median ratio {np.median([ratio for ratio, _ in measured]):.2f}")


if __name__ == "__main__":
    main()
