"""Command line: ``python -m gesturelib <command>`` (also installed as ``gesturelib``).

Commands:
    demo   generate a short synthetic conversation and render the agent with its speech into a
           folder a person can open (a video with sound, pictures, the raw files).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

#: Written into every folder the demo fills, so that a second run may replace what the first made
#: but never files a person put there.
DEMO_MARKER = ".gesturelib-demo"


class CommandError(Exception):
    """A problem the user can fix; reported as one line, without a traceback."""


def _prepare_output_folder(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise CommandError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / DEMO_MARKER).exists() and not overwrite:
        raise CommandError(
            f"{out} already holds files that the demo did not make; choose another --out "
            "or pass --overwrite to write into it anyway"
        )
    out.mkdir(parents=True, exist_ok=True)
    (out / DEMO_MARKER).write_text("This folder was written by `python -m gesturelib demo`.\n")


def run_demo(out: Path, seconds: float, seed: int, overwrite: bool = False) -> list[Path]:
    """Generate a conversation and write it, rendered, into ``out``; return the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from data_synth import generate_conversation, save_conversation
    from gesturelib import viz
    from gesturelib.features import mel_spectrogram

    if seconds <= 0:
        raise CommandError(f"--seconds must be positive, got {seconds}")
    _prepare_output_folder(out, overwrite)
    print(f"Generating a {seconds:g} s conversation (seed {seed}) ...")
    conversation = generate_conversation(seconds, seed=seed)
    written = save_conversation(conversation, out / "conversation", overwrite=True)

    print("Rendering the agent with its speech ...")
    anim = viz.animate(conversation.positions, fps=conversation.fps, titles=["agent (speaker A)"])
    written.append(
        viz.save_animation(
            anim,
            out / "agent.mp4",
            audio=conversation.audio,
            sample_rate=conversation.sample_rate,
            overwrite=True,
        )
    )

    mel = mel_spectrogram(conversation.audio, conversation.sample_rate, fps=conversation.fps)
    figure = viz.plot_timeline(
        mel,
        conversation.activity,
        fps=conversation.fps,
        title="Speech (log-mel) and who is talking",
    )
    written.append(out / "timeline.png")
    figure.savefig(written[-1], dpi=120)
    plt.close(figure)

    # One pose a second, overlaid, as in the Flow-VAE paper's figures.
    figure = viz.plot_pose(
        conversation.positions[:: int(conversation.fps)], title="The agent's poses, one a second"
    )
    written.append(out / "poses.png")
    figure.savefig(written[-1], dpi=120)
    plt.close(figure)
    return [Path(p) for p in written]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gesturelib", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    demo = commands.add_parser("demo", help="render a synthetic conversation into a folder")
    demo.add_argument("--out", type=Path, default=Path("outputs/demo"), help="output folder")
    demo.add_argument("--seconds", type=float, default=20.0, help="length of the conversation")
    demo.add_argument("--seed", type=int, default=0, help="seed of the conversation")
    demo.add_argument(
        "--overwrite", action="store_true", help="write into a folder that holds other files"
    )
    args = parser.parse_args(argv)

    try:
        if args.command == "demo":
            files = run_demo(args.out, args.seconds, args.seed, args.overwrite)
            print(f"\nWrote {len(files)} files to {args.out}/:")
            for path in files:
                print(f"  {path.name}")
            print("Open agent.mp4 to watch and hear the agent.")
    except (CommandError, FileExistsError, FileNotFoundError, ValueError) as error:
        print(f"gesturelib {args.command}: error: {error}", file=sys.stderr)
        return 2
    return 0
