"""The Flow-VAE's novel loss term, ablated over seeds: with and without MSE(x, d(h')).

Trains the full-mode Flow-VAE (``python -m gesturelib train flowvae``'s recipe) from several
seeds with the paper's loss and without its decoded-sample term (``sample_weight=0``), through
the load-or-train cache that notebook 06 uses (``checkpoints/``: the notebook's seeds are reused),
and reports for each: the held-out headline measures (3 samples per test conversation, T = 1),
the validation reconstruction and decoded-sample errors, and the training time; then mean ± sd
over seeds, and the paired difference with its standard error.

Usage::

    .venv/bin/python benchmarks/bench_flowvae_ablation.py [--seeds 5] [--quick]
"""

from __future__ import annotations

import argparse
import math
import statistics
from pathlib import Path

import numpy as np
import torch

from data_synth import course_data, load_dataset
from gesturelib.evaluation import generate_for, headline_measures
from gesturelib.pipeline import train_model

REPO = Path(__file__).resolve().parents[1]
COLUMNS = ("hellinger", "ratio", "lead", "mse", "sample_mse", "minutes")


def run(quick: bool, seed: int, weight: float, splits) -> dict:
    """One training run (cached) and its figures."""
    trained = train_model(
        "flowvae",
        splits,
        quick=quick,
        seed=seed,
        model_changes={"sample_weight": weight},
        cache=REPO / "checkpoints",
        progress=False,
    )
    model, history, normaliser = trained.model, trained.history, trained.normaliser
    test = splits["test"]
    motions = generate_for(test, model, normaliser, samples=3, seed=0)
    scores = [headline_measures(test, [m[k] for m in motions]) for k in range(3)]
    row = {key: float(np.mean([s[key] for s in scores])) for key in ("hellinger", "ratio", "lead")}
    best = history.best_epoch - 1  # the epoch whose weights the model holds
    row["mse"] = history.val["mse"][best]
    row["sample_mse"] = history.val["sample_mse"][best]
    row["minutes"] = sum(history.epoch_seconds) / 60
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="training seeds 0 .. N-1")
    parser.add_argument("--quick", action="store_true", help="quick data and configs")
    args = parser.parse_args()
    if args.seeds < 2:
        parser.error(f"--seeds must be at least 2 (for a spread), got {args.seeds}")
    torch.set_num_threads(1)
    splits = load_dataset(course_data(args.quick))
    rows = {}
    for label, weight in (("with d(h')", 1.0), ("without", 0.0)):
        for seed in range(args.seeds):
            rows[label, seed] = row = run(args.quick, seed, weight, splits)
            print(
                f"{label:>10} seed {seed}: " + "  ".join(f"{k} {row[k]:.4g}" for k in COLUMNS),
                flush=True,
            )
    print(f"\nmean ± sd over {args.seeds} seeds (held-out, 3 samples per conversation, T = 1)")
    for label in ("with d(h')", "without"):
        parts = []
        for key in COLUMNS:
            values = [rows[label, seed][key] for seed in range(args.seeds)]
            parts.append(f"{key} {statistics.mean(values):.4g} ± {statistics.stdev(values):.2g}")
        print(f"{label:>10}: " + "  ".join(parts))
    print("\nwith - without, paired by seed (standard error)")
    for key in COLUMNS:
        gaps = [rows["with d(h')", s][key] - rows["without", s][key] for s in range(args.seeds)]
        error = statistics.stdev(gaps) / math.sqrt(len(gaps))
        print(f"  {key:10} {statistics.mean(gaps):+.4g} ({error:.2g})")


if __name__ == "__main__":
    main()
