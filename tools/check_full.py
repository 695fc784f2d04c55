"""Execute the chapters in full mode, with their exercises' solutions, and fail if any claim (an
``assert`` in a cell) does not hold or a solution does not run.

Usage (through the Makefile)::

    make check-full            # every notebook, in order
    make check-full NB=04      # the notebooks whose name starts with 04

Each notebook runs in a fresh kernel with ``GESTURELIB_QUICK=0``, from ``notebooks/``, followed by
every ``python`` block of its solutions in ``docs/solutions/`` (one cell each, in the notebook's
namespace, as a student runs them). The executed copy, solutions included, with its pictures, is
written to ``outputs/check-full/`` so that a person can read the chapter as a student sees it;
``tools/run_solutions.py`` prints what each solution prints, to quote it. Trained models are
cached in ``checkpoints/`` by the notebooks' own load-or-train helper, so a second run only
retrains what changed. Quick mode shows that the code runs; this shows that the text is true.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

REPO = Path(__file__).resolve().parent.parent
NOTEBOOKS = REPO / "notebooks"
SOLUTIONS = REPO / "docs" / "solutions"
OUT = REPO / "outputs" / "check-full"


def chapters(prefix: str) -> list[Path]:
    """The notebooks whose file name starts with ``prefix`` (all for an empty prefix), in order."""
    found = sorted(NOTEBOOKS.glob(f"{prefix}*.ipynb"))
    if not found:
        raise SystemExit(f"check-full: no notebook in {NOTEBOOKS} starts with {prefix!r}")
    return found


def solution_blocks(path: Path) -> list[tuple[str, str]]:
    """``(heading, code)`` of every python block of a solutions file, in order."""
    blocks, heading = [], ""
    for part in re.split(r"(^## .*$)", path.read_text(), flags=re.MULTILINE):
        if part.startswith("## "):
            heading = part[3:].strip()
            continue
        blocks += [(heading, code) for code in re.findall(r"```python\n(.*?)```", part, re.S)]
    return blocks


def solutions_of(path: Path) -> list[tuple[str, str]]:
    """The solution blocks of the chapter ``path`` (none if it has no solutions file)."""
    found = sorted(SOLUTIONS.glob(f"{path.name[:2]}_*.md"))
    assert len(found) <= 1, f"more than one solutions file for {path.name}: {found}"
    return solution_blocks(found[0]) if found else []


def execute(path: Path) -> tuple[bool, float, str]:
    """Run one notebook in full mode, then its solutions; return (passed, seconds, the failure's
    last lines)."""
    notebook = nbformat.read(path, as_version=4)
    notebook.cells += [nbformat.v4.new_code_cell(code) for _, code in solutions_of(path)]
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
