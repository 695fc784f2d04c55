"""The documents a newcomer follows hold: the README's command lines run as written, in order, and
the contract (docs/interfaces.md) names every model and metric there is."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gesturelib.evaluation.table import METRICS
from gesturelib.recipes import RECIPES

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    """The command lines of the README's section "The command line", in order."""
    section = (ROOT / "README.md").read_text().split("## The command line", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, flags=re.S)[1]
    return [line.split("  #")[0].strip() for line in block.splitlines() if line.strip()]


def test_the_readme_command_lines_run_as_written_in_order(tmp_path):
    """Quick mode (GESTURELIB_QUICK=1, as the README says), in a folder of its own that sees the
    repository's files: each line exits 0 and writes what the README promises."""
    for name in ("gesturelib", "tests", ".venv"):
        if (ROOT / name).exists():
            (tmp_path / name).symlink_to(ROOT / name)
    environment = {**os.environ, "GESTURELIB_QUICK": "1", "MPLBACKEND": "Agg"}
    for line in readme_commands():
        words = shlex.split(line)
        assert words[:3] == [".venv/bin/python", "-m", "gesturelib"], line
        words[0] = sys.executable  # the interpreter running the tests: .venv's under make test
        done = subprocess.run(
            words, cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, f"{line}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    for folder in ("mine", "mine-flowvae"):
        written = tmp_path / "outputs" / folder
        assert {"motion.npz", "agent.bvh", "agent.mp4"} <= {p.name for p in written.iterdir()}
        assert np.load(written / "motion.npz")["rotations"].shape[1:] == (9, 6)
    metrics = (tmp_path / "outputs" / "evaluation" / "metrics.csv").read_text()
    assert "\nflowvae," in metrics and "\nmoglow," in metrics


def test_the_contract_names_every_model_and_metric():
    contract = (ROOT / "docs" / "interfaces.md").read_text()
    for name in [*RECIPES, *METRICS, "seeds"]:
        assert f"`{name}`" in contract, f"docs/interfaces.md does not mention `{name}`"


@pytest.mark.parametrize(
    "pattern", [r"\.\./shared", r"\bshared/(INTERFACES|DESIGN|ROADMAP|papers)"]
)
def test_no_file_of_the_repository_points_outside_it(pattern):
    tracked = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    if not tracked:
        pytest.skip("not a git checkout")
    found = [
        path
        for path in tracked
        if path.endswith((".md", ".py", ".ipynb", ".yml", ".toml", ".cff", "Makefile"))
        and path != "tests/test_docs.py"
        and re.search(pattern, (ROOT / path).read_text(encoding="utf-8", errors="replace"))
    ]
    assert not found, f"{found} refer to files outside the repository"


def test_every_chapter_with_exercises_has_solutions_that_parse():
    """Each notebook's exercises have a solutions file whose python blocks (run after the chapter
    by ``make check-full``) are valid Python."""
    import ast

    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from check_full import chapters, solutions_of
    finally:
        sys.path.remove(str(ROOT / "tools"))
    for notebook in chapters(""):
        if "## Exercises" not in notebook.read_text():
            continue
        blocks = solutions_of(notebook)
        assert blocks, f"{notebook.name} has exercises but no docs/solutions/ file with code"
        for heading, code in blocks:
            try:
                ast.parse(code)
            except SyntaxError as error:
                raise AssertionError(f"{notebook.name}, solution {heading!r}: {error}") from None
