"""MoGlow one frame ahead of the true past, against MoGlow running free: where the hands part.

For each held-out conversation, every frame of a trained MoGlow (the recipe, with ``--change``)
is drawn twice: **one step** ahead of the true motion (the flow's memory and control built from
the recorded past, teacher forcing, as in training) and **free** (``speech_to_motion``: each
frame fed back, as in use). Over the frames where the agent speaks, it prints for the truth and
both: the share of wrist-frames slower than 4 cm/s, the share of frames where one hand rests
(< 4 cm/s) while the other strokes (> 16 cm/s), and the correlation of the two wrists' speeds.
A model that keeps the hands apart one step ahead but not when running free has learned the
rule and loses it to its own output (exposure).

Usage::

    .venv/bin/python benchmarks/bench_one_step.py [--change dropout=0.2] [--seed 0] [--quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from bench_quality import parse_changes  # this folder is on the path when run as a script

from data_synth import course_data, load_dataset
from gesturelib.conventions import FPS, Activity
from gesturelib.evaluation import hand_sharing
from gesturelib.metrics import JOINT_GROUPS
from gesturelib.pipeline import speech_to_motion, train_model
from gesturelib.recipes import RECIPES
from gesturelib.sampling import one_step_ahead
from gesturelib.skeleton import forward_kinematics

REPO = Path(__file__).resolve().parents[1]
WRISTS = list(JOINT_GROUPS["wrists"])


def hands(label: str, speeds: np.ndarray) -> None:
    """Print :func:`hand_sharing` of wrist speeds ``(N, 2)`` cm/s."""
    shared = hand_sharing(speeds)
    print(
        f"{label:>9}: wrists still {shared['still']:.2f}  one rests, one strokes "
        f"{shared['one_hand']:.2f}  speed correlation {shared['correlation']:.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--change", nargs="*", default=[], help="model config fields: key=value")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="quick data and configs")
    args = parser.parse_args()
    try:
        changes = parse_changes(args.change)
        RECIPES["moglow"].settings(args.quick, changes)
    except (TypeError, ValueError) as error:
        parser.error(str(error))
    torch.set_num_threads(1)
    splits = load_dataset(course_data(args.quick))
    trained = train_model(
        "moglow",
        splits,
        quick=args.quick,
        seed=args.seed,
        model_changes=changes,
        cache=REPO / "checkpoints",
        progress=False,
    )
    config = trained.model.config
    first = max(config.past_poses, config.speech_past)
    speeds = {"truth": [], "one step": [], "free": []}
    for conversation in splits["test"]:
        drawn = forward_kinematics(one_step_ahead(trained.model, trained.normaliser, conversation))
        frames = slice(first, first + len(drawn))
        free = forward_kinematics(
            speech_to_motion(
                trained.model,
                trained.normaliser,
                conversation.audio,
                conversation.sample_rate,
                activity=conversation.activity,
                seed=0,
                progress=False,
            ).rotations[0]
        )
        # Speeds into each frame of `frames`: from the recorded pose before it for the truth
        # and the one-step draws, from the motion's own pose before it for the free run.
        before = conversation.positions[frames.start - 1 : frames.stop - 1]
        speaking = conversation.activity[frames] == Activity.A_SPEAKS
        for name, motion, previous in (
            ("truth", conversation.positions[frames], before),
            ("one step", drawn, before),
            ("free", free[frames], free[frames.start - 1 : frames.stop - 1]),
        ):
            step = motion[:, WRISTS] - previous[:, WRISTS]
            speeds[name].append(np.linalg.norm(step, axis=-1)[speaking] * FPS)
    print(f"frames where the agent speaks, seed {args.seed} {' '.join(args.change)}")
    for name, parts in speeds.items():
        hands(name, np.concatenate(parts))


if __name__ == "__main__":
    main()
