"""The generative models on this machine: training and streaming speed, size, held-out motion.

Measures run folders that ``python -m gesturelib train MODEL --out RUN`` wrote, for any model
that generates motion (``moglow``, ``flowvae``, ``flowvae_elbo``), one after the other:

* training: frames per second (the training frames of all epochs over the training time the run
  recorded) and the training time itself;
* generation: how many times faster than real time (25 fps) one motion streams frame by frame on
  one core, and a batch of 8 samples for the same speech;
* parameters;
* on the held-out test conversations, at the temperatures asked for (K samples each): the
  headline measures of :mod:`gesturelib.evaluation` (wrist-speed Hellinger distance to the ground
  truth, speaking/listening wrist-speed ratio, stroke lead over the speech's accents), beside the
  ground truth and the references (the floor of resampled motion, mismatched motion, the mean
  pose; the mismatched motion comes from the validation conversations). Mean ± sd over the
  samples;
* for a model with style control: the style realised in its samples when each feature is held at
  the 15th, 50th and 85th percentile of the training values (the others at their median), the
  share of the change asked that is realised, and the rank correlation between asked and
  realised levels over conversations and samples
  (:func:`gesturelib.evaluation.style_control.style_response`).

Usage (a missing run folder named after a model, e.g. ``runs/flowvae``, is trained first with
``python -m gesturelib train``)::

    .venv/bin/python benchmarks/bench_generators.py [RUN ...] [--temperatures 1.0 0.8] [--samples 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import torch

from data_synth import load_dataset
from gesturelib import cli
from gesturelib.data import make_datasets
from gesturelib.evaluation import generate_for, headline_measures, reference_motions
from gesturelib.evaluation.style_control import style_response
from gesturelib.features import speech_features
from gesturelib.history import History
from gesturelib.pose_surface import project
from gesturelib.pretrained import load_run
from gesturelib.recipes import RECIPES
from gesturelib.sampling import generate
from gesturelib.skeleton import forward_kinematics

MEASURES = ("hellinger", "ratio", "lead")


def training_speed(run: Path, checkpoint, splits) -> tuple[float, float]:
    """``(training seconds, training frames per second)`` of a run folder."""
    summary = json.loads((run / "run.json").read_text())
    windows, _, _ = RECIPES[summary["model"]].settings(summary["quick"])
    datasets, _ = make_datasets({"train": splits["train"]}, windows)
    history = History.from_dict(checkpoint["history"])
    seconds = sum(history.epoch_seconds)
    frames = len(datasets["train"]) * windows.sequence_length * history.epochs
    return seconds, frames / seconds


def streaming_speed(model, normaliser, conversation, samples: int) -> float:
    """How many times faster than real time ``samples`` motions of 20 s stream (best of 3)."""
    speech = speech_features(conversation.audio, conversation.sample_rate)[:500]
    activity = conversation.activity[:500]
    best = float("inf")
    for _ in range(3):
        started = time.perf_counter()
        generate(model, normaliser, speech, activity, samples=samples, seed=0)
        best = min(best, time.perf_counter() - started)
    return len(speech) / 25 / best


def summarise(scores: list[dict]) -> str:
    """``measure mean ± sd`` over samples, for each headline measure."""
    parts = []
    for name in MEASURES:
        values = [s[name] for s in scores]
        spread = statistics.stdev(values) if len(values) > 1 else 0.0
        parts.append(f"{name} {statistics.mean(values):7.3f} ± {spread:.3f}")
    return "   ".join(parts)


def print_style_response(model, normaliser, conversations, samples: int) -> None:
    """Asked vs realised level of each style feature (:func:`style_response`): prints a table."""
    for name, response in style_response(model, normaliser, conversations, samples).items():
        print(
            f"  {name:15} asked {' / '.join(f'{v:7.2f}' for v in response.asked)}   realised "
            f"{' / '.join(f'{v:7.2f}' for v in response.realised)}   share "
            f"{response.share:.2f}   rank correlation {response.rank_correlation:.2f}"
        )


def measure(run: Path, temperatures: list[float], samples: int) -> None:
    """Print the figures of one run folder."""
    model, normaliser, checkpoint = load_run(run)
    if not hasattr(model, "step"):
        raise SystemExit(f"{run} holds a {type(model).__name__}, which does not generate motion")
    summary = json.loads((run / "run.json").read_text())
    splits = load_dataset(summary["data"])
    test = splits["test"]
    seconds, frames_per_second = training_speed(run, checkpoint, splits)
    parameters = sum(p.numel() for p in model.parameters())
    print(f"run {run}: {summary['model']} {json.dumps(checkpoint['model_config'])}")
    print(f"parameters {parameters:,}")
    print(f"training {seconds / 60:.1f} min, {frames_per_second:,.0f} frames/s (one thread)")
    for count in (1, 8):
        speed = streaming_speed(model, normaliser, test[0], count)
        print(f"streaming, {count} sample(s) at once: {speed:.1f}x real time (one thread)")

    test_s = sum(len(c.positions) for c in test) / 25
    print(f"\nheld-out: {len(test)} test conversations, {test_s:.0f} s in all")
    truth = [c.positions for c in test]
    print(f"{'ground truth':22} {summarise([headline_measures(test, truth)])}")
    raw_mean = torch.as_tensor(normaliser.pose_mean, dtype=torch.float64).reshape(9, 6)
    mean_pose = forward_kinematics(project(raw_mean).numpy())
    for name, motions in reference_motions(
        test, mean_pose, seed=1000, others=splits["val"]
    ).items():
        print(f"{name:22} {summarise([headline_measures(test, motions)])}")
    for temperature in temperatures:
        motions = generate_for(
            test, model, normaliser, samples=samples, temperature=temperature, seed=0
        )
        scores = [headline_measures(test, [m[k] for m in motions]) for k in range(samples)]
        label = f"{summary['model']}, T = {temperature:g}"
        print(f"{label:22} {summarise(scores)}   ({samples} samples)")
    if getattr(model.config, "style", False):
        print("\nstyle control (at the model's own temperature):")
        print_style_response(model, normaliser, test, samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "runs",
        type=Path,
        nargs="*",
        default=[Path("runs/moglow"), Path("runs/flowvae")],
        help="run folders (default: runs/moglow runs/flowvae)",
    )
    parser.add_argument("--temperatures", type=float, nargs="+", default=[1.0])
    parser.add_argument("--samples", type=int, default=3, help="samples per conversation")
    args = parser.parse_args()
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    for run in args.runs:
        if (run / "best.pt").exists():
            continue
        if run.name not in RECIPES:
            parser.error(
                f"{run} holds no trained model; train one with `python -m gesturelib train`"
            )
        print(f"{run} holds no trained model: training a {run.name}")
        if cli.main(["train", run.name, "--out", str(run)]) != 0:
            raise SystemExit(2)
    torch.set_num_threads(1)
    for number, run in enumerate(args.runs):
        if number:
            print()
        measure(run, args.temperatures, args.samples)


if __name__ == "__main__":
    main()
