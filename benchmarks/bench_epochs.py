"""One run of a recipe scored after each of its last epochs, on validation and on test.

Training picks the epoch with the best *validation loss* (teacher forced: every frame one step
ahead of the recorded past), unless its recipe judges its last epochs. This asks whether that is
the epoch whose *generated* motion is best, and whether the validation conversations would tell:
the recipe is trained from ``--seed`` into a scratch run folder one epoch at a time, unjudged
(each call resumes the folder, its random state included, so the run is the one ``make results``
trains: judging changes which epoch is kept, not the training), and the weights after each epoch from
``--first`` on (``last.pt``) are scored with ``bench_quality.py``'s measures, 3 samples per
conversation of the validation and of the test split, and of the first ``--train-conversations``
training ones (rollouts on speech the model was trained on: a judge with more minutes than the
validation split's three). At the end, for a few ways of choosing an epoch without the test
split, the epoch chosen and its test measures.

Usage::

    .venv/bin/python benchmarks/bench_epochs.py flowvae --seed 1 --first 21
    .venv/bin/python benchmarks/bench_epochs.py flowvae --seed 1 --change dropout=0.2
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import torch
from bench_quality import (
    fgd_features,
    parse_changes,
    score,
)  # this folder is on the path when run as a script

from data_synth import course_data, load_dataset
from gesturelib.pipeline import train_model
from gesturelib.recipes import RECIPES

REPO = Path(__file__).resolve().parents[1]
MEASURES = ("hellinger", "fgd", "ratio", "nods", "drift")
#: Ways of choosing an epoch from its validation measures (lower is better).
CHOICES = {
    "validation loss": lambda row: row["loss"],
    "validation FGD": lambda row: row["val"]["fgd"],
    "validation Hellinger": lambda row: row["val"]["hellinger"],
    "training FGD": lambda row: row["train"]["fgd"],
    "training Hellinger": lambda row: row["train"]["hellinger"],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default="flowvae", choices=list(RECIPES))
    parser.add_argument("--change", nargs="*", default=[], help="model config fields: key=value")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--first", type=int, default=21, help="the first epoch scored")
    parser.add_argument(
        "--train-conversations", type=int, default=6, help="training conversations scored"
    )
    parser.add_argument("--quick", action="store_true", help="quick data and configs")
    args = parser.parse_args()
    changes = parse_changes(args.change)
    try:
        _, _, training = RECIPES[args.model].settings(args.quick, changes)
    except (TypeError, ValueError) as error:
        parser.error(str(error))
    if not 1 <= args.first <= training.epochs:
        parser.error(f"--first must be an epoch of the recipe's 1-{training.epochs}")
    if args.train_conversations < 1:
        parser.error("--train-conversations must be at least 1")
    torch.set_num_threads(1)
    splits = load_dataset(course_data(args.quick))
    features = fgd_features(splits, args.quick)
    judged = {
        "val": splits["val"],
        "test": splits["test"],
        "train": splits["train"][: args.train_conversations],
    }
    rows = {}
    with tempfile.TemporaryDirectory() as scratch:
        for epoch in range(args.first, training.epochs + 1):
            trained = train_model(
                args.model,
                splits,
                quick=args.quick,
                seed=args.seed,
                model_changes=changes,
                train_changes={"epochs": epoch, "judged_epochs": 0},
                out=scratch,
                progress=False,
            )
            (last,) = Path(scratch).rglob("last.pt")
            trained.model.load_state_dict(torch.load(last, weights_only=False)["model"])
            trained.model.eval()
            row = {"loss": trained.history.val["loss"][-1]}
            for split, conversations in judged.items():
                row[split] = score(trained, conversations, features, 3, None)
            rows[epoch] = row
            print(
                f"epoch {epoch} | validation loss {row['loss']:.5f} | "
                + " | ".join(
                    f"{split}: " + "  ".join(f"{k} {row[split][k]:.3g}" for k in MEASURES)
                    for split in judged
                ),
                flush=True,
            )
    print(f"{args.model} {' '.join(args.change)} seed {args.seed}: the epoch chosen by")
    for name, key in CHOICES.items():
        epoch = min(rows, key=lambda e: key(rows[e]))
        test = rows[epoch]["test"]
        print(f"  {name}: {epoch} | test: " + "  ".join(f"{k} {test[k]:.3g}" for k in MEASURES))
    spread = {k: np.ptp([r["test"][k] for r in rows.values()]) for k in MEASURES}
    print(
        "  range over the epochs scored (test): "
        + "  ".join(f"{k} {v:.3g}" for k, v in spread.items())
    )


if __name__ == "__main__":
    main()
