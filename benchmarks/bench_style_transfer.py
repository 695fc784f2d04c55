"""Style transfer from a reference, measured against the style the generator drew, over seeds.

For each training seed, the course's MoGlow and Ye et al.'s flow (``styleflow``) are trained (or
loaded from ``checkpoints/``) and speak the first ``--seconds`` of each held-out conversation's
speech with each reference, training conversations at the two ends of every style feature's
range (:mod:`gesturelib.evaluation.transfer`), by two mechanisms:

* ``latents``: the reference's base codes, its motion read through the flow with its own speech,
  replayed with the new speech (Ye et al.'s section 4.5; ``Stream(style_from=...)``);
* ``style code``: Ye et al.'s global encoder's code of the reference's poses, held at every frame
  (``Stream(style_code=...)``; Ye et al.'s flow only);
* ``labels``: the reference's measured style given to chapter 05's MoGlow with style inputs
  (trained as the recipe, as there): what labels buy.

Prints per model and mechanism the slope of the realised style against the reference's and the
share of pairs nearer the reference than the speech's own conversation, per style feature, as
mean ± sd over the seeds (the table in ``docs/benchmarks.md``), and the training minutes.

Usage::

    .venv/bin/python benchmarks/bench_style_transfer.py [--seeds 0 1 2] [--seconds 15]
        [--models moglow styleflow moglow+labels]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from data_synth import course_data, load_dataset
from gesturelib.evaluation.transfer import spanning_references, transfer_pairs, transfer_scores
from gesturelib.pipeline import train_model
from gesturelib.style import STYLE_FEATURES

#: name -> (recipe, model changes, training changes, mechanisms): the labelled MoGlow is chapter
#: 05's, the recipe with style inputs.
MODELS = {
    "moglow": ("moglow", {}, {}, ("latents",)),
    "styleflow": ("styleflow", {}, {}, ("latents", "style code")),
    "moglow+labels": ("moglow", {"style": True}, {}, ("labels", "latents")),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--models", nargs="+", choices=list(MODELS), default=list(MODELS))
    args = parser.parse_args()
    torch.set_num_threads(1)
    splits = load_dataset(course_data(False, progress=False))
    speakers, references = splits["test"], spanning_references(splits["train"])
    print(f"{len(speakers)} speakers x {len(references)} references, {args.seconds:g} s each")
    scores = {}  # (model, mechanism) -> [per seed: {feature: {follows, nearer}}]
    minutes = {name: [] for name in args.models}
    for seed in args.seeds:
        for name in args.models:
            started = time.perf_counter()
            recipe, model_changes, train_changes, mechanisms = MODELS[name]
            model, history, normaliser = train_model(
                recipe,
                splits,
                quick=False,
                seed=seed,
                model_changes=model_changes,
                train_changes=train_changes,
            )
            minutes[name].append(sum(history.epoch_seconds) / 60)
            for mechanism in mechanisms:
                pairs = transfer_pairs(
                    model, normaliser, speakers, references, args.seconds, by=mechanism
                )
                result = transfer_scores(*pairs)
                scores.setdefault((name, mechanism), []).append(result)
            print(f"seed {seed} {name}: {time.perf_counter() - started:.0f} s", flush=True)
        report(scores, minutes)  # after every seed: a long run shows its progress


def report(scores: dict, minutes: dict) -> None:
    """The table so far: mean ± sd over the seeds done."""
    header = " | ".join(STYLE_FEATURES)
    print(f"\n| model, transfer | {header} |\n|---|" + "---|" * len(STYLE_FEATURES))
    for (name, mechanism), runs in scores.items():
        cells = []
        for feature in STYLE_FEATURES:
            follows = [run[feature]["follows"] for run in runs]
            nearer = [run[feature]["nearer"] for run in runs]
            cells.append(
                f"{np.mean(follows):+.2f} ± {np.std(follows):.2f} / "
                f"{np.mean(nearer):.2f} ± {np.std(nearer):.2f}"
            )
        print(f"| {name}, {mechanism} | " + " | ".join(cells) + " |")
    for name, values in minutes.items():
        print(f"{name}: training {np.mean(values):.1f} ± {np.std(values):.1f} min", flush=True)


if __name__ == "__main__":
    main()
