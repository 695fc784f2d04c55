"""Training on one process against several (torchrun): MoGlow's seconds per epoch here.

Three settings train the full MoGlow recipe (its model and batch size) for ``--epochs`` epochs
on the course's quick data, or ``--data``:

* 1 process, 1 thread (the course's default);
* 1 process, ``--processes`` threads;
* ``--processes`` processes with 1 thread each (``torchrun``, gloo; each takes a share of every
  batch, the gradients are averaged: :mod:`gesturelib.distributed`).

It prints the median seconds per epoch of each (the first epoch left out as warm-up) and the
final training loss, which the three should share to rounding.

Usage:
    .venv/bin/python benchmarks/bench_scaling.py [--processes 2] [--epochs 4] [--data DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def worker(args) -> None:
    """One setting, in this process (and its torchrun siblings): print its timings as JSON."""
    import numpy as np
    import torch

    from data_synth import course_data
    from gesturelib import distributed
    from gesturelib.datasets import load_dataset
    from gesturelib.pipeline import train_model

    torch.set_num_threads(args.threads)
    distributed.start_from_environment("cpu")
    splits = load_dataset(args.data or course_data(quick=True, progress=False))
    trained = train_model(
        "moglow",
        splits,
        quick=False,
        train_changes={"epochs": args.epochs, "patience": None},
        out=args.out,
        progress=False,
    )
    if distributed.world()[0] == 0:
        seconds = trained.history.epoch_seconds[1:] or trained.history.epoch_seconds
        loss = trained.history.train["loss"][-1]
        print(json.dumps({"seconds": float(np.median(seconds)), "loss": loss}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--processes", type=int, default=2)
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--data", type=Path, help="a dataset folder (default: the quick one)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--threads", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.processes < 2 or args.epochs < 2:
        parser.exit(2, "bench_scaling: --processes and --epochs must be at least 2\n")
    if args.worker:
        worker(args)
        return
    torchrun = [sys.executable, "-m", "torch.distributed.run", "--standalone"]
    settings = {
        "1 process, 1 thread": ([sys.executable], 1),
        f"1 process, {args.processes} threads": ([sys.executable], args.processes),
        f"{args.processes} processes, 1 thread each": (
            [*torchrun, f"--nproc_per_node={args.processes}"],
            1,
        ),
    }
    print(f"MoGlow (full recipe), {args.epochs} epochs; median seconds per epoch after the first")
    with tempfile.TemporaryDirectory() as scratch:
        for number, (name, (launch, threads)) in enumerate(settings.items()):
            command = [*launch, __file__, "--worker", "--threads", str(threads)]
            command += ["--epochs", str(args.epochs), "--out", f"{scratch}/run{number}"]
            command += ["--processes", str(args.processes)]
            if args.data is not None:
                command += ["--data", str(args.data)]
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode != 0:
                sys.exit(f"{name} failed:\n{done.stderr[-2000:]}")
            result = json.loads(done.stdout.strip().splitlines()[-1])
            print(f"{name:>30}: {result['seconds']:6.2f} s/epoch, final loss {result['loss']:.4f}")


if __name__ == "__main__":
    main()
