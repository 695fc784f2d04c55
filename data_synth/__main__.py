"""Command line: write a synthetic dataset to disk.

    python -m data_synth --out data/synthetic                 # full: 30 minutes, 60 s each
    python -m data_synth --out data/quick --quick             # quick: 3 minutes, 30 s each
    python -m data_synth --minutes 10 --seed 1 --out DIR --overwrite

Without ``--quick`` the size follows ``GESTURELIB_QUICK`` (set in CI), like the notebooks.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from data_synth.dataset import (
    FULL_CONVERSATION_S,
    FULL_MINUTES,
    QUICK_CONVERSATION_S,
    QUICK_MINUTES,
    write_dataset,
)
from gesturelib.runtime import OneLineParser, quick_mode


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments, write the dataset, print a summary; return the exit status."""
    parser = OneLineParser(
        prog="python -m data_synth",
        description="Generate the synthetic dyadic conversation dataset (train/val/test).",
    )
    parser.add_argument("--out", type=Path, required=True, help="dataset folder to write")
    parser.add_argument(
        "--minutes",
        type=float,
        default=None,
        help=f"minutes of conversation (default {FULL_MINUTES:g}, "
        f"or {QUICK_MINUTES:g} with --quick)",
    )
    parser.add_argument("--seed", type=int, default=0, help="dataset seed (default 0)")
    parser.add_argument(
        "--conversation-seconds",
        type=float,
        default=None,
        help=f"length of each conversation (default {FULL_CONVERSATION_S:g}, "
        f"or {QUICK_CONVERSATION_S:g} with --quick)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="the small preset (also chosen by GESTURELIB_QUICK=1)"
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an existing dataset in --out"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)

    try:
        quick = args.quick or quick_mode()
        minutes = (
            args.minutes if args.minutes is not None else (QUICK_MINUTES if quick else FULL_MINUTES)
        )
        seconds = (
            args.conversation_seconds
            if args.conversation_seconds is not None
            else (QUICK_CONVERSATION_S if quick else FULL_CONVERSATION_S)
        )
        start = time.perf_counter()
        manifest = write_dataset(
            args.out,
            minutes,
            args.seed,
            conversation_s=seconds,
            overwrite=args.overwrite,
            progress=not args.no_progress,
        )
    except (OSError, ValueError) as error:
        print(f"python -m data_synth: error: {error}", file=sys.stderr)
        return 2
    print(
        f"Wrote {minutes:g} minutes of conversation to {args.out} "
        f"in {time.perf_counter() - start:.1f} s:"
    )
    for split, entries in manifest["splits"].items():
        print(
            f"  {split:5s} {len(entries):3d} conversations, "
            f"{manifest['durations_s'][split] / 60:.1f} min"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
