"""One recipe, changed or not, from several seeds: the evaluation table's measures with spreads.

The harness behind the model-quality experiments of ``docs/benchmarks.md``: trains a recipe
(``python -m gesturelib train``'s, full mode unless ``--quick``) with the given model and training
changes from each seed through the load-or-train cache (``checkpoints/``: the chapters' and
``make results``' runs are reused), draws 3 samples per held-out conversation (``--split val``:
per validation conversation, to choose a setting without the test set), and prints per seed
and as mean ± sd over seeds: the wrist-speed Hellinger distance, wrist jerk, FGD, the
speaking/listening ratio, the stroke lead, the accents hit, the listener's nods and their
precision, the 99th percentile of the head's downward pitch speed, the correlation of the two
wrists' speeds while the agent speaks (:func:`hand_correlation`), the wrists' mean speed while
it speaks and in its pauses of under 4 s (:func:`gesturelib.evaluation.pause_wrist_speed`: its
hands retract and rise again), the two parts of the speaking/listening ratio that differ most
from the truth's, the drift (:func:`gesturelib.evaluation.headline.drift`: the limb-angle error
to the truth in the last 10 s of the held-out conversations over the first 10 s, averaged over
the samples first), the parameters and the training minutes; for a model trained with style
inputs (``--change style=True``), also the share of a style change asked that its samples
realise, per feature (:func:`gesturelib.evaluation.style_control.style_response`, 2 samples).

Usage (``make benchmark`` runs it without arguments: the Flow-VAE's recipe, seeds 0-2)::

    .venv/bin/python benchmarks/bench_quality.py moglow --seeds 0 1 2
    .venv/bin/python benchmarks/bench_quality.py flowvae --change latent_noise=0 --train epochs=20
    .venv/bin/python benchmarks/bench_quality.py moglow --temperature 0.8   # same models, colder
    .venv/bin/python benchmarks/bench_quality.py flowvae --temperature 1.2 --split val
    .venv/bin/python benchmarks/bench_quality.py diffusion --sampling steps=50 method=ddpm
    .venv/bin/python benchmarks/bench_quality.py moglow --change style=True
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from data_synth import course_data, load_dataset
from gesturelib.conventions import FPS
from gesturelib.evaluation.fgd import feature_network
from gesturelib.evaluation.headline import (
    drift,
    hand_sharing,
    pause_wrist_speed,
    speaking_wrist_speeds,
)
from gesturelib.evaluation.rules import head_pitch
from gesturelib.evaluation.style_control import style_response
from gesturelib.evaluation.table import score_draw
from gesturelib.models import Sampling
from gesturelib.pipeline import speech_to_motion, train_model
from gesturelib.recipes import RECIPES
from gesturelib.skeleton import forward_kinematics

REPO = Path(__file__).resolve().parents[1]
COLUMNS = (
    "hellinger",
    "jerk",
    "fgd",
    "ratio",
    "lead",
    "accent_hits",
    "nods",
    "nod_precision",
    "head_speed",
    "hand_correlation",
    "speaking_speed",
    "pause_speed",
    "drift",
    "minutes",
)


def parse_changes(pairs: list[str]) -> dict:
    """``["latent_noise=0", "residual=True"]`` -> ``{"latent_noise": 0, "residual": True}``."""
    changes = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        try:
            changes[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            changes[key] = value
    return changes


def fgd_features(splits, quick: bool):
    """The FGD's feature network of the course's data (trained once, then cached)."""
    return feature_network(
        [c.positions for c in splits["train"]],
        [c.positions for c in splits["val"]],
        REPO / "checkpoints",
        quick=quick,
        progress=False,
    )


def head_speed(motions: list) -> float:
    """The 99th percentile of the head's downward pitch speed (deg/s) over every frame: how
    fast the fastest nods go (the generator's nods peak at 50-150)."""
    speeds = [np.degrees(np.diff(head_pitch(m))) * FPS for m in motions]
    return float(np.percentile(np.concatenate(speeds), 99))


def hand_correlation(motions: list, conversations) -> float:
    """The correlation of the two wrists' speeds over the frames where the agent speaks
    (:func:`~gesturelib.evaluation.hand_sharing`)."""
    return hand_sharing(speaking_wrist_speeds(motions, conversations))["correlation"]


def score(
    trained, conversations, features, samples: int, temperature: float | None, save=None
) -> dict:
    """The measures of one trained model, averaged over ``samples`` draws; ``save``: a file to
    write the draws' keypoints to (``sample<k>_conversation<i>``, ``(T, 9, 3)``)."""
    per_conversation = [
        speech_to_motion(
            trained.model,
            trained.normaliser,
            c.audio,
            c.sample_rate,
            activity=c.activity,
            samples=samples,
            temperature=temperature,
            seed=0,
            progress=False,
        ).rotations
        for c in conversations
    ]
    draws, saved = [], {}
    for k in range(samples):
        motions = [forward_kinematics(r[k]) for r in per_conversation]
        row = score_draw(conversations, motions, features)
        row["head_speed"] = head_speed(motions)
        row["hand_correlation"] = hand_correlation(motions, conversations)
        row["speaking_speed"] = float(speaking_wrist_speeds(motions, conversations).mean())
        row["pause_speed"] = pause_wrist_speed(motions, conversations)
        draws.append(row)
        saved |= {f"sample{k}_conversation{i}": m for i, m in enumerate(motions)}
    if save is not None:
        np.savez_compressed(save, **saved)
    per_draw = [key for key in COLUMNS if key not in ("drift", "minutes")]
    row = {key: float(np.mean([d[key] for d in draws])) for key in per_draw}
    row["drift"] = drift([[r[k] for r in per_conversation] for k in range(samples)], conversations)
    row["minutes"] = sum(trained.history.epoch_seconds) / 60
    if getattr(trained.model.config, "style", False):
        responses = style_response(
            trained.model, trained.normaliser, conversations, samples=2, temperature=temperature
        )
        row |= {f"{name}_share": response.share for name, response in responses.items()}
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default="flowvae", choices=list(RECIPES))
    parser.add_argument("--change", nargs="*", default=[], help="model config fields: key=value")
    parser.add_argument("--train", nargs="*", default=[], help="training config fields: key=value")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--samples", type=int, default=3, help="draws per held-out conversation")
    parser.add_argument("--temperature", type=float, default=None, help="the model's own if unset")
    parser.add_argument(
        "--sampling", nargs="*", default=[], help="a diffusion model's Sampling fields: key=value"
    )
    parser.add_argument(
        "--split",
        choices=("test", "val"),
        default="test",
        help="the conversations to score: the held-out test set, or the validation set (to "
        "choose a setting, such as --temperature, without looking at the test set)",
    )
    parser.add_argument("--quick", action="store_true", help="quick data and configs")
    parser.add_argument("--save", type=Path, help="a folder for each seed's draws (.npz)")
    args = parser.parse_args()
    model_changes, train_changes = parse_changes(args.change), parse_changes(args.train)
    sampling = parse_changes(args.sampling)
    try:  # the configs, checked before any training
        RECIPES[args.model].settings(args.quick, model_changes, **train_changes)
        if sampling:
            Sampling(**sampling)
    except (TypeError, ValueError) as error:
        parser.error(str(error))
    torch.set_num_threads(1)
    splits = load_dataset(course_data(args.quick))
    conversations = splits[args.split]
    features = fgd_features(splits, args.quick)
    truth = [c.positions for c in conversations]
    print(
        f"ground truth: head_speed {head_speed(truth):.4g}  "
        f"hand_correlation {hand_correlation(truth, conversations):.4g}  "
        f"speaking_speed {speaking_wrist_speeds(truth, conversations).mean():.4g}  "
        f"pause_speed {pause_wrist_speed(truth, conversations):.4g}",
        flush=True,
    )
    label = " ".join([args.model, *args.change, *args.train, *args.sampling]) + (
        f" T={args.temperature}" if args.temperature is not None else ""
    )
    if args.split != "test":
        label += f" ({args.split})"
    rows = []
    for seed in args.seeds:
        started = time.perf_counter()
        trained = train_model(
            args.model,
            splits,
            quick=args.quick,
            seed=seed,
            model_changes=model_changes,
            train_changes=train_changes,
            cache=REPO / "checkpoints",
            progress=False,
        )
        if sampling:
            trained.model.sampling = dataclasses.replace(trained.model.sampling, **sampling)
        save = None
        if args.save is not None:
            args.save.mkdir(parents=True, exist_ok=True)
            save = args.save / f"seed{seed}.npz"
        rows.append(score(trained, conversations, features, args.samples, args.temperature, save))
        parameters = sum(p.numel() for p in trained.model.parameters())
        print(
            f"{label} | seed {seed} | {parameters:,} parameters | "
            + "  ".join(f"{k} {v:.4g}" for k, v in rows[-1].items())
            + f" | {time.perf_counter() - started:.0f} s",
            flush=True,
        )
    if len(rows) > 1:
        values = {k: np.array([r[k] for r in rows]) for k in rows[0]}
        print(
            f"{label} | mean ± sd over {len(rows)} seeds | "
            + "  ".join(f"{k} {v.mean():.4g} ± {v.std(ddof=1):.2g}" for k, v in values.items()),
            flush=True,
        )


if __name__ == "__main__":
    main()
