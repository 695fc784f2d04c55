"""Ye et al.'s ablation on our data: the flow with and without its global encoder, with and
without its gesture perceptual loss, over seeds.

Trains ``python -m gesturelib train styleflow``'s full-mode recipe from each seed as it is, with
``global_size=0`` (no global encoder: MoGlow with GRUs and both loss terms) and with
``perceptual=0`` (no perceptual loss), through the load-or-train cache the chapters share
(``checkpoints/``: chapter 09's seed 0 is reused), and scores every run on the held-out
conversations as chapter 07 does (3 samples per conversation, T = 1; FGD with the course's
feature network; style transfer by latent codes). Prints each run's row, then mean ± sd over the
seeds of each variant and its paired difference from the full model (standard error): Ye et al.
report that each part lowers the FGD and raises the diversity.

Usage::

    .venv/bin/python benchmarks/bench_styleflow_ablation.py [--seeds 0 1 2]
    .venv/bin/python benchmarks/bench_styleflow_ablation.py --variants "no perceptual loss" &
"""

from __future__ import annotations

import argparse
import math
import statistics
from pathlib import Path

import torch

from data_synth import course_data, load_dataset
from gesturelib.evaluation.fgd import feature_network
from gesturelib.evaluation.table import evaluate_models
from gesturelib.pipeline import train_model

REPO = Path(__file__).resolve().parents[1]
VARIANTS = {
    "Ye et al.": {},
    "no global encoder": {"global_size": 0},
    "no perceptual loss": {"perceptual": 0.0},
}
COLUMNS = ("hellinger", "fgd", "diversity", "jerk", "ratio", "nods", "transfer", "nll", "minutes")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument(
        "--variants",
        nargs="+",
        choices=list(VARIANTS),
        default=list(VARIANTS),
        help="train and score only these (to share the work between processes); summary if all",
    )
    args = parser.parse_args()
    if len(args.seeds) < 2:
        parser.error(f"give at least two --seeds (for a spread), got {args.seeds}")
    torch.set_num_threads(1)
    splits = load_dataset(course_data(False, progress=False))
    features = feature_network(
        [c.positions for c in splits["train"]],
        [c.positions for c in splits["val"]],
        REPO / "checkpoints",
        progress=False,
    )
    rows = {}
    for name in args.variants:
        for seed in args.seeds:
            model, history, normaliser = train_model(
                "styleflow",
                splits,
                quick=False,
                seed=seed,
                model_changes=VARIANTS[name],
                cache=REPO / "checkpoints",
                progress=False,
            )
            scored, _ = evaluate_models({"run": [(model, normaliser)]}, splits, 3, features)
            row = {key: scored["run"][key] for key in COLUMNS[:-2]}
            row["nll"] = min(history.val["nll"])
            row["minutes"] = sum(history.epoch_seconds) / 60
            rows[name, seed] = row
            cells = "  ".join(f"{key} {row[key]:.4g}" for key in COLUMNS)
            print(f"{name:>18} seed {seed}: {cells}", flush=True)
    if args.variants != list(VARIANTS):
        return
    print(f"\nmean ± sd over seeds {args.seeds} (held-out, 3 samples per conversation, T = 1)")
    print("| variant | " + " | ".join(COLUMNS) + " |\n|---|" + "---|" * len(COLUMNS))
    for name in VARIANTS:
        cells = []
        for key in COLUMNS:
            values = [rows[name, seed][key] for seed in args.seeds]
            cells.append(f"{statistics.mean(values):.3g} ± {statistics.stdev(values):.2g}")
        print(f"| {name} | " + " | ".join(cells) + " |")
    print("\nvariant - Ye et al., paired by seed: mean (standard error)")
    for name in list(VARIANTS)[1:]:
        cells = []
        for key in COLUMNS:
            gaps = [rows[name, s][key] - rows["Ye et al.", s][key] for s in args.seeds]
            error = statistics.stdev(gaps) / math.sqrt(len(gaps))
            cells.append(f"{key} {statistics.mean(gaps):+.3g} ({error:.2g})")
        print(f"{name:>18}: " + "  ".join(cells))


if __name__ == "__main__":
    main()
