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
from gesturelib.pipeline import speech_to_motion, train_model
from gesturelib.pose_surface import project
from gesturelib.recipes import RECIPES
from gesturelib.sampling import recording_batch
from gesturelib.skeleton import JOINT_INDEX, forward_kinematics

REPO = Path(__file__).resolve().parents[1]
WRISTS = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]


def one_step(model, normaliser, conversation, generator) -> tuple[np.ndarray, np.ndarray, slice]:
    """Keypoints ``(N, 9, 3)`` of the last true pose and of the one-step draw of every frame
    with a whole control, and the frames of the conversation they stand for."""
    batch = recording_batch(model, normaliser, conversation)
    frames = batch["pose"].shape[1]
    with torch.no_grad():
        control = model.conditioning(batch)
        last = batch["past_pose"][:, :, -1]
        change = batch["pose"] - last
        state, drawn = None, []
        for t in range(frames):
            noise = torch.randn(1, 1, change.shape[-1], generator=generator)
            x, _, _ = model.flow.inverse(noise, control[:, t : t + 1], state)
            drawn.append(x[0, 0] + last[0, t])
            _, _, state = model.flow(change[:, t : t + 1], control[:, t : t + 1], state)

    def keypoints(pose):
        raw = normaliser.denormalise_pose(pose.double().numpy())
        return forward_kinematics(project(torch.as_tensor(raw).reshape(-1, 9, 6)).numpy())

    end = len(conversation.activity) - model.config.speech_future
    return keypoints(last[0]), keypoints(torch.stack(drawn)), slice(end - frames, end)


def hands(label: str, speeds: np.ndarray) -> None:
    """Print the measures of wrist speeds ``(N, 2)`` cm/s."""
    still, fast = speeds < 4, speeds > 16
    parted = (still[:, 0] & fast[:, 1]) | (still[:, 1] & fast[:, 0])
    correlation = np.corrcoef(speeds[:, 0], speeds[:, 1])[0, 1]
    print(
        f"{label:>9}: wrists still {still.mean():.2f}  one rests, one strokes {parted.mean():.2f}"
        f"  speed correlation {correlation:.2f}"
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
    generator = torch.Generator().manual_seed(0)
    speeds = {"truth": [], "one step": [], "free": []}
    for conversation in splits["test"]:
        last, drawn, frames = one_step(trained.model, trained.normaliser, conversation, generator)
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
        speaking = conversation.activity[frames] == Activity.A_SPEAKS
        truth = conversation.positions[frames]
        for name, motion, before in (
            ("truth", truth, last),
            ("one step", drawn, last),
            ("free", free[frames], free[frames.start - 1 : frames.stop - 1]),
        ):
            step = np.linalg.norm(motion[:, WRISTS] - before[:, WRISTS], axis=-1) * FPS
            speeds[name].append(step[speaking])
    print(f"frames where the agent speaks, seed {args.seed} {' '.join(args.change)}")
    for name, parts in speeds.items():
        hands(name, np.concatenate(parts))


if __name__ == "__main__":
    main()
