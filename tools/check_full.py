"""Execute the chapters in full mode and fail if any claim (an ``assert`` in a cell) does not hold.

Usage (through the Makefile)::

    make check-full            # every notebook, in order
    make check-full NB=04      # the notebooks whose name starts with 04

Each notebook runs in a fresh kernel with ``GESTURELIB_QUICK=0``, from ``notebooks/``. The executed
copy, with its pictures, is written to ``outputs/check-full/`` so that a person can read the
chapter as a student sees it. Trained models are cached in ``checkpoints/`` by the notebooks' own
load-or-train helper, so a second run only retrains what changed. Quick mode shows that the code
runs; this shows that the text is true.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

REPO = Path(__file__).resolve().parent.parent
NOTEBOOKS = REPO / "notebooks"
OUT = REPO / "outputs" / "check-full"


def chapters(prefix: str) -> list[Path]:
    """The notebooks whose file name starts with ``prefix`` (all for an empty prefix), in order."""
    found = sorted(NOTEBOOKS.glob(f"{prefix}*.ipynb"))
    if not found:
        raise SystemExit(f"check-full: no notebook in {NOTEBOOKS} starts with {prefix!r}")
    return found


def execute(path: Path) -> tuple[bool, float, str]:
    """Run one notebook in full mode; return (passed, seconds, the failure's last lines)."""
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(
        notebook, timeout=None, kernel_name="python3", resources={"metadata": {"path": NOTEBOOKS}}
    )
    started = time.perf_counter()
    failure = ""
    try:
        client.execute()
    except CellExecutionError as error:
        failure = "\n".join(str(error).strip().splitlines()[-12:])
    seconds = time.perf_counter() - started
    OUT.mkdir(parents=True, exist_ok=True)
    nbformat.write(notebook, OUT / path.name)
    return not failure, seconds, failure


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("prefix", nargs="?", default="", help="e.g. 04; empty for every notebook")
    args = parser.parse_args()
    os.environ["GESTURELIB_QUICK"] = "0"  # inherited by the kernels
    # The inline backend, as in JupyterLab: with Agg, plt.show() draws nothing into the copies.
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    results = []
    for path in chapters(args.prefix):
        print(f"{path.name} ...", flush=True)
        passed, seconds, failure = execute(path)
        results.append((path.name, passed, seconds))
        print(f"  {'passed' if passed else 'FAILED'} in {seconds:.0f} s", flush=True)
        if failure:
            print(failure, flush=True)
    total = sum(seconds for _, _, seconds in results)
    failed = [name for name, passed, _ in results if not passed]
    print(f"\n{len(results) - len(failed)} of {len(results)} notebooks passed in {total:.0f} s")
    print(f"executed copies with their outputs in {OUT.relative_to(REPO)}/")
    if failed:
        print("failed: " + ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
