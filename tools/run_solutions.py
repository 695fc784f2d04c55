"""Run a chapter's exercise solutions after the chapter, in full mode, and show what they print.

Usage::

    .venv/bin/python tools/run_solutions.py 05          # docs/solutions/05_*.md after notebook 05
    .venv/bin/python tools/run_solutions.py 05 --quick  # the same in quick mode

The solutions in ``docs/solutions/`` are written to run at the end of their notebook, in its
namespace; the figures they quote must come from such a run. This executes the notebook and then
every ``python`` code block of the solutions file, one cell each, in a fresh kernel, and prints
each block's output under its exercise's heading. The executed notebook, solutions included, is
written to ``outputs/solutions/`` with its pictures. (``make check-full`` runs the solutions too,
after each chapter, and fails where one does not run; this prints what they print.)
"""

from __future__ import annotations

import argparse
import os
import sys

import nbformat
from check_full import NOTEBOOKS, REPO, chapters, solutions_of
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

OUT = REPO / "outputs" / "solutions"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("prefix", help="the chapter, e.g. 05")
    parser.add_argument("--quick", action="store_true", help="quick mode instead of full mode")
    args = parser.parse_args()
    (notebook_path,) = chapters(args.prefix)
    blocks = solutions_of(notebook_path)
    if not blocks:
        raise SystemExit(f"run_solutions: {notebook_path.name} has no solutions to run")
    os.environ["GESTURELIB_QUICK"] = "1" if args.quick else "0"
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    notebook = nbformat.read(notebook_path, as_version=4)
    first = len(notebook.cells)
    notebook.cells += [nbformat.v4.new_code_cell(code) for _, code in blocks]
    client = NotebookClient(
        notebook, timeout=None, kernel_name="python3", resources={"metadata": {"path": NOTEBOOKS}}
    )
    failed = False
    try:
        client.execute()
    except CellExecutionError as error:
        print("\n".join(str(error).strip().splitlines()[-12:]))
        failed = True
    OUT.mkdir(parents=True, exist_ok=True)
    nbformat.write(notebook, OUT / notebook_path.name)
    for (heading, _), cell in zip(blocks, notebook.cells[first:], strict=True):
        print(f"== {heading}")
        for output in cell.get("outputs", []):
            if output.get("output_type") == "stream":
                print(output["text"], end="")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
