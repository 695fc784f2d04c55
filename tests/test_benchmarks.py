"""The flow benchmarks still run (their figures are quoted in the README), on tiny settings."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def launch(script: str, *arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *arguments],
        capture_output=True,
        text=True,
        timeout=120,
    )


def run(script: str, *arguments: str) -> str:
    """The standard output of a run that must succeed."""
    result = launch(script, *arguments)
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


def test_flows_against_zuko_clips_the_gradient_only_when_asked():
    pytest.importorskip("zuko", reason="the comparison needs the [bench] extra")
    tiny = ["--densities", "two_moons", "--checkpoints", "5", "--seeds", "1", "--flow-steps", "2"]
    tiny += ["--hidden", "8", "--models", "reverse"]
    plain, clipped = (
        run("flows_vs_reference.py", *tiny),
        run("flows_vs_reference.py", *tiny, "--grad-clip", "1e-3"),
    )
    assert "no gradient clipping" in plain.splitlines()[0]
    assert "gradient norm clipped to 0.001" in clipped.splitlines()[0]

    def final_nll(output: str) -> str:
        row = next(row for row in output.splitlines() if "final NLL per seed" in row)
        return row.split("0: ")[1]

    assert final_nll(plain) != final_nll(clipped)
    refused = launch("flows_vs_reference.py", "--grad-clip", "0")
    assert refused.returncode != 0 and "--grad-clip must be positive, got 0.0" in refused.stderr


def test_flow_speed_benchmark_runs():
    output = run("bench_flows.py", "--repeats", "1", "--hidden", "8", "--frames", "4")
    rows = [row.split()[0] for row in output.splitlines()[3:]]
    assert rows == ["MLP", "LSTM"], output
