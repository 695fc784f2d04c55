"""The course's final table: every model from several seeds against the references, into the README.

Trains every generating model of the course (full mode unless ``--quick``) from ``--seeds``
seeds through the shared load-or-train cache (``checkpoints/``: the chapters' runs are reused,
and an interrupted run resumes), evaluates them with the references on the held-out
conversations (:func:`gesturelib.evaluation.table.evaluate_models`, 3 samples each), and
MoGlow trained with its style inputs on the share of a style asked that comes out
(:func:`gesturelib.evaluation.style_control.style_response`); writes ``metrics.csv``,
``models.csv``, ``style_control.csv`` and the figures to ``outputs/results/``
(``outputs/results-quick/`` in quick mode), and, in full mode, the two tables between the
README's ``results`` markers.

Usage::

    .venv/bin/python tools/results.py [--seeds 3] [--quick]      # or: make results
    .venv/bin/python tools/results.py --models moglow cvae &     # share the training between
    .venv/bin/python tools/results.py --models aud2pose flowvae  # cores, then run it without

Training every model but the diffusion model from three seeds took 73 minutes on one core here (and 7
more to score them); the diffusion model's three seeds take about 45 more. Later calls reuse them.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import torch

from data_synth import course_data, load_dataset
from gesturelib.evaluation import report
from gesturelib.evaluation.fgd import feature_network
from gesturelib.evaluation.style_control import style_response
from gesturelib.evaluation.table import evaluate_models
from gesturelib.pipeline import train_model
from gesturelib.recipes import GENERATORS

REPO = Path(__file__).resolve().parents[1]
MODELS = GENERATORS  # every model of the course that generates motion, in chapter order
MARKERS = ("<!-- results:start -->", "<!-- results:end -->")
#: Samples per held-out conversation and style level for the style control (chapter 05's).
STYLE_SAMPLES = 2


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="training seeds per model")
    parser.add_argument("--samples", type=int, default=3, help="samples per conversation")
    parser.add_argument("--quick", action="store_true", help="quick data and models")
    parser.add_argument(
        "--models",
        nargs="+",
        choices=MODELS,
        default=MODELS,
        help="train only these (e.g. to share the work between processes); evaluate only if all",
    )
    args = parser.parse_args()
    if args.seeds < 1 or args.samples < 1:
        parser.error("--seeds and --samples must be at least 1")
    readme = REPO / "README.md"
    pattern = re.escape(MARKERS[0]) + ".*?" + re.escape(MARKERS[1])
    if not args.quick and not re.search(pattern, readme.read_text(), flags=re.S):
        parser.error(f"README.md has no {MARKERS[0]} ... {MARKERS[1]} markers for the table")
    torch.set_num_threads(1)

    splits = load_dataset(course_data(args.quick))
    cache = REPO / "checkpoints"

    started = time.perf_counter()
    models, histories = {}, {}
    for name in args.models:
        for seed in range(args.seeds):
            print(f"{name}, seed {seed} ...", flush=True)
            run = train_model(
                name, splits, quick=args.quick, seed=seed, cache=cache, progress=False
            )
            models.setdefault(name, []).append((run.model, run.normaliser))
            histories.setdefault(name, []).append((run.model, run.history))
    styled = []  # MoGlow with its style inputs (chapter 05): how much of a style asked comes out
    if "moglow" in args.models:
        for seed in range(args.seeds):
            print(f"moglow with style inputs, seed {seed} ...", flush=True)
            run = train_model(
                "moglow",
                splits,
                quick=args.quick,
                seed=seed,
                model_changes={"style": True},
                cache=cache,
                progress=False,
            )
            styled.append((run.model, run.normaliser))
    print(f"Models ready after {(time.perf_counter() - started) / 60:.1f} min")
    if set(args.models) != set(MODELS):
        return 0

    features = feature_network(
        [c.positions for c in splits["train"]],
        [c.positions for c in splits["val"]],
        cache,
        quick=args.quick,
    )
    rows, draws = evaluate_models(models, splits, args.samples, features)

    out = REPO / "outputs" / ("results-quick" if args.quick else "results")
    out.mkdir(parents=True, exist_ok=True)
    report.write_evaluation(rows, draws, histories, splits, out)
    style = report.style_control(
        [
            style_response(model, normaliser, splits["test"], STYLE_SAMPLES)
            for model, normaliser in styled
        ]
    )
    report.write_style_control(style, out / "style_control.csv")
    table = "\n\n".join(
        [
            report.markdown_table(rows, report.models_table(histories)),
            report.style_control_table(style, "moglow, style inputs"),
        ]
    )
    print(table)
    if not args.quick:
        text = readme.read_text()
        readme.write_text(
            re.sub(pattern, lambda _: f"{MARKERS[0]}\n{table}\n{MARKERS[1]}", text, flags=re.S)
        )
        print("README.md's table updated")
    print(f"Done in {(time.perf_counter() - started) / 60:.1f} min; files in {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
