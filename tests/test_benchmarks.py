"""The flow benchmarks still run (their figures are quoted in the README), on tiny settings."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def run(script: str, *arguments: str) -> str:
    result = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *arguments],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_flows_against_zuko_prints_a_row_per_model():
    pytest.importorskip("zuko", reason="the comparison needs the [bench] extra")
    output = run(
        "flows_vs_reference.py",
        "--densities",
        "eight_gaussians",
        "--checkpoints",
        "3",
        "6",
        "--seeds",
        "2",
        "--first-seed",
        "3",
        "--flow-steps",
        "2",
        "--hidden",
        "8",
    )
    rows = {
        model: row
        for row in output.splitlines()
        for model in ("zuko RealNVP", "Glow rotation", "Glow reverse", "true density")
        if row.startswith("eight_gaussians") and model in row
    }
    assert len(rows) == 4, output
    params = {model: int(re.search(r"\s(\d+)\s", rows[model]).group(1)) for model in list(rows)[:3]}
    assert params["zuko RealNVP"] >= params["Glow rotation"]  # never the smaller budget for zuko
    assert "seeds 3..4" in output.splitlines()[0]
    per_seed = [row for row in output.splitlines() if "final NLL per seed" in row]
    assert len(per_seed) == 3 and all(re.search(r"3: \S+, 4: \S+$", row) for row in per_seed)


def test_flow_speed_benchmark_runs():
    output = run("bench_flows.py", "--repeats", "1", "--hidden", "8", "--frames", "4")
    rows = [row.split()[0] for row in output.splitlines()[3:]]
    assert rows == ["MLP", "LSTM"], output
