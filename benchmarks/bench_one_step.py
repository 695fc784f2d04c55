"""A recurrent flow one frame ahead of the true past, against the flow running free.

For each held-out conversation, every frame of a trained model (``MODEL``: MoGlow's recipe by
default, or Ye et al.'s flow's or a Flow-VAE's; ``--change`` alters its config) is drawn twice:
**one step** ahead of the true motion (the flow's memory and control built from the recorded
past, teacher forcing, as in training) and **free** (``speech_to_motion``: each frame fed back, as
in use). It prints for the truth and both:

* over the frames where the agent speaks, the share of wrist-frames slower than 4 cm/s, the
  share of frames where one hand rests (< 4 cm/s) while the other strokes (> 16 cm/s), and the
  correlation of the two wrists' speeds;
* the listener's nod: the head's downward pitch speed (deg/s) in the 0.6 s after each of the
  partner's phrase ends that the agent answers with silence (where the rules nod, most of the
  time), averaged over them.

A one-step frame's speed is measured from the recorded frame before it (for a Flow-VAE, that
frame through its autoencoder), a free frame's from the model's own. A model that does one step
ahead what it fails to do running free has learned the rule and loses it to its own output
(exposure); one that fails one step ahead has not learned it.

Usage::

    .venv/bin/python benchmarks/bench_one_step.py [MODEL] [--change dropout=0.2] [--seed 0]
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
from gesturelib.evaluation.rules import head_drops_after_phrase_ends
from gesturelib.metrics import JOINT_GROUPS
from gesturelib.pipeline import speech_to_motion, train_model
from gesturelib.recipes import RECIPES
from gesturelib.sampling import one_step_ahead, through_autoencoder
from gesturelib.skeleton import forward_kinematics

REPO = Path(__file__).resolve().parents[1]
#: The recipes of recurrent flows, which :func:`one_step_ahead` can draw one step ahead.
RECURRENT_FLOWS = ("moglow", "styleflow", "flowvae", "flowvae_elbo")
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
    parser.add_argument("model", nargs="?", default="moglow", choices=RECURRENT_FLOWS)
    parser.add_argument("--change", nargs="*", default=[], help="model config fields: key=value")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="quick data and configs")
    args = parser.parse_args()
    try:
        changes = parse_changes(args.change)
        RECIPES[args.model].settings(args.quick, changes)
    except (TypeError, ValueError) as error:
        parser.error(str(error))
    torch.set_num_threads(1)
    splits = load_dataset(course_data(args.quick))
    trained = train_model(
        args.model,
        splits,
        quick=args.quick,
        seed=args.seed,
        model_changes=changes,
        cache=REPO / "checkpoints",
        progress=False,
    )
    config = trained.model.config
    first = max(config.past_poses, config.speech_past)
    names = ("truth", "one step", "free")
    speeds, nods = {name: [] for name in names}, {name: [] for name in names}
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
        # and the one-step draws (for a Flow-VAE's, that pose through its autoencoder), from
        # the motion's own pose before it for the free run.
        before = conversation.positions[frames.start - 1 : frames.stop - 1]
        drawn_from = before
        if args.model.startswith("flowvae"):  # a flow over an autoencoder's latent
            rotations = conversation.rotations[frames.start - 1 : frames.stop - 1]
            drawn_from = forward_kinematics(
                through_autoencoder(trained.model, trained.normaliser, rotations)
            )
        speaking = conversation.activity[frames] == Activity.A_SPEAKS
        for name, motion, previous in (
            ("truth", conversation.positions[frames], before),
            ("one step", drawn, drawn_from),
            ("free", free[frames], free[frames.start - 1 : frames.stop - 1]),
        ):
            step = motion[:, WRISTS] - previous[:, WRISTS]
            speeds[name].append(np.linalg.norm(step, axis=-1)[speaking] * FPS)
            nods[name].append(head_drops_after_phrase_ends(conversation, motion, previous, first))
    print(f"{args.model}, seed {args.seed} {' '.join(args.change)}")
    print("frames where the agent speaks:")
    for name, parts in speeds.items():
        hands(name, np.concatenate(parts))
    drops = {name: np.concatenate(rows) for name, rows in nods.items()}
    print(
        f"the head's downward speed (deg/s) after {len(drops['truth'])} phrase ends of the "
        f"partner, every {1000 // FPS} ms from 0 to {1000 * (drops['truth'].shape[1] - 1) // FPS} ms:"
    )
    for name, rows in drops.items():
        print(f"{name:>9}: " + " ".join(f"{round(value):4d}" for value in rows.mean(axis=0)))


if __name__ == "__main__":
    main()
