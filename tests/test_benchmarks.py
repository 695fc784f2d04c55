"""The flow benchmarks still run (docs/benchmarks.md quotes them), on tiny settings."""

from __future__ import annotations

import re
import shutil
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


def test_flows_against_zuko_prints_each_model_and_their_paired_gap():
    pytest.importorskip("zuko", reason="the comparison needs the [bench] extra")
    output = run(
        "flows_vs_reference.py",
        *("--densities", "eight_gaussians", "--steps", "3", "--seeds", "2", "--first-seed", "3"),
        *("--flow-steps", "2", "--hidden", "8"),
    )
    rows = {
        model: row
        for row in output.splitlines()
        for model in ("zuko RealNVP", "gesturelib Glow", "ours - zuko", "true density")
        if row.startswith("eight_gaussians") and model in row
    }
    assert len(rows) == 4, output
    params = {
        model: int(re.search(r"(\d+) parameters", rows[model]).group(1)) for model in list(rows)[:2]
    }
    assert params["zuko RealNVP"] >= params["gesturelib Glow"]  # never the smaller budget for zuko
    assert "seeds 3..4" in output.splitlines()[0]
    per_seed = [row for row in output.splitlines() if "per seed:" in row]
    assert len(per_seed) == 2 and all(re.search(r"3: \S+, 4: \S+$", row) for row in per_seed)
    assert re.search(r"standard error \d\.\d+\); time per step \d+\.\d+ x", rows["ours - zuko"])
    refused = launch("flows_vs_reference.py", "--seeds", "0")
    assert refused.returncode != 0 and "--seeds must be at least 1, got 0" in refused.stderr


def test_flow_speed_benchmark_runs():
    output = run("bench_flows.py", "--repeats", "1", "--hidden", "8", "--frames", "4")
    rows = [row.split()[0] for row in output.splitlines()[3:]]
    assert rows == ["MLP", "LSTM"], output


def test_generator_benchmark_measures_a_run_against_the_references(moglow_run):
    output = run("bench_generators.py", str(moglow_run), "--samples", "2")
    for row in ("parameters", "training", "streaming, 1 sample", "streaming, 8 sample"):
        assert any(line.startswith(row) for line in output.splitlines()), output
    systems = ("ground truth", "floor", "mismatched", "mean_pose", "moglow, T = 1")
    for system in systems:
        line = next(line for line in output.splitlines() if line.startswith(system))
        assert re.search(r"hellinger +\d\.\d{3} ± .*ratio .*lead ", line), line
    refused = launch("bench_generators.py", str(moglow_run / "missing"), "--samples", "0")
    assert refused.returncode == 2 and "--samples must be at least 1, got 0" in refused.stderr


def test_flowvae_ablation_benchmark_reports_both_losses_over_seeds():
    output = run("bench_flowvae_ablation.py", "--quick", "--seeds", "2")
    for label in ("with d(h')", "without"):
        assert re.search(rf"{re.escape(label)}: hellinger \S+ ± ", output), output
    assert re.search(r"sample_mse [+-]\S+ \(\S+\)", output), output
    refused = launch("bench_flowvae_ablation.py", "--seeds", "1")
    assert refused.returncode == 2 and "--seeds must be at least 2" in refused.stderr


def test_own_voice_benchmark_reports_each_recording():
    arguments = ("gesturelib/pretrained/moglow", "--samples", "1", "--generated", "1")
    output = run("bench_own_voice.py", *arguments)
    rows = [line for line in output.splitlines() if line.startswith("| `")]
    assert len(rows) == 5  # the recordings of tests/data/voices
    ratios = [float(row.split("|")[2]) for row in rows]
    median = re.search(r"moglow: median ratio ([0-9.]+)", output)
    assert median and float(median[1]) == pytest.approx(sorted(ratios)[2], abs=0.006)
    reference = re.search(
        r"layout \(1 conversation\): ground truth ([0-9.]+), moglow [0-9.]+", output
    )
    assert reference and float(reference[1]) > 1, output  # the data's agent moves more in speech
    # At T = 0 every sample of a recording is the same motion: the same leads.
    arguments = ("gesturelib/pretrained/flowvae", "--temperature", "0", "--generated", "0")
    output = run("bench_own_voice.py", *arguments)
    assert "layout" not in output
    rows = [line for line in output.splitlines() if line.startswith("| `")]
    leads = [{lead.strip() for lead in row.split("|")[3].split(",")} for row in rows]
    assert len(rows) == 5 and all(len(same) == 1 for same in leads), rows
    refused = launch("bench_own_voice.py", "--temperature", "-1")
    assert refused.returncode == 2 and "--temperature: temperature must lie in" in refused.stderr
    refused = launch("bench_own_voice.py", "--generated", "-1")
    assert refused.returncode == 2 and "--generated must be at least 0" in refused.stderr


def test_own_voice_benchmark_measures_another_folder_of_recordings(tmp_path):
    voices = Path(__file__).resolve().parent / "data" / "voices"
    shutil.copy(voices / "us_clean.flac", tmp_path / "mine.FLAC")
    (tmp_path / ".mine.wav").write_bytes(b"not a recording: a dotfile is passed over")
    arguments = ("gesturelib/pretrained/flowvae", "--samples", "1", "--generated", "0")
    output = run("bench_own_voice.py", *arguments, "--recordings", str(tmp_path))
    rows = [line for line in output.splitlines() if line.startswith("| `")]
    assert len(rows) == 1 and rows[0].startswith("| `mine` |"), output
    (tmp_path / "mine.FLAC").unlink()
    refused = launch("bench_own_voice.py", "--recordings", str(tmp_path))
    assert refused.returncode == 2 and "holds no .flac or .wav recordings" in refused.stderr
    refused = launch("bench_own_voice.py", "--recordings", str(tmp_path / "absent"))
    assert refused.returncode == 2 and "is not a folder" in refused.stderr


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux's /proc")
def test_long_audio_benchmark_reports_each_stage():
    output = run("bench_long_audio.py", "--minutes", "1")
    for stage in ("load_audio", "+ who_is_talking", "+ speech_features"):
        assert re.search(rf"{re.escape(stage)}: peak +\d+ MB", output), output


def test_the_quality_benchmark_scores_each_seed_and_their_spread():
    output = run(
        "bench_quality.py",
        *("flowvae", "--quick", "--seeds", "0", "1", "--samples", "2"),
        *("--change", "residual=True", "leak=0.1", "detach_prior=True", "latent_noise=0.0"),
    )
    rows = [row for row in output.splitlines() if row.startswith("flowvae residual=True")]
    assert [row.split(" | ")[1] for row in rows] == ["seed 0", "seed 1", "mean ± sd over 2 seeds"]
    columns = ("hellinger", "jerk", "fgd", "ratio", "nods", "head_speed", "hand_correlation")
    columns += ("speaking_speed", "pause_speed")
    for column in (*columns, "drift", "minutes"):
        assert all(re.search(rf"\b{column} [-\d.]", row) for row in rows), (column, output)
    assert re.search(
        r"ground truth: head_speed \d+\S*  hand_correlation 0\.\d+  speaking_speed \d+\S*  "
        r"pause_speed \d",
        output,
    )
    output = run(
        "bench_quality.py",
        *("flowvae", "--quick", "--seeds", "0", "--samples", "1"),
        "--split",
        "val",
    )
    assert re.search(r"^flowvae \(val\) \| seed 0 \|", output, re.MULTILINE), output
    refused = launch("bench_quality.py", "flowvae", "--quick", "--change", "lek=0.1")
    assert refused.returncode == 2 and "unexpected keyword argument 'lek'" in refused.stderr


@pytest.mark.parametrize("model", ["moglow", "flowvae"])
def test_the_one_step_benchmark_measures_hands_and_nods_of_truth_one_step_and_free_motion(model):
    output = run("bench_one_step.py", model, "--quick", "--change", "dropout=0.2")
    assert output.splitlines()[0] == f"{model}, seed 0 dropout=0.2", output
    for name in ("truth", "one step", "free"):
        assert re.search(
            rf"{name}: wrists still 0\.\d\d  one rests, one strokes 0\.\d\d  "
            rf"speed correlation -?[01]\.\d\d",
            output,
        ), (name, output)
        assert re.search(rf"{name}: (\s+-?\d+){{15}}$", output, re.MULTILINE), (name, output)
    assert re.search(r"after \d+ phrase ends of the partner, every 40 ms from 0 to 560 ms", output)
    refused = launch("bench_one_step.py", "--quick", "--change", "dropot=0.2")
    assert refused.returncode == 2 and "dropot" in refused.stderr
    refused = launch("bench_one_step.py", "aud2pose", "--quick")
    assert refused.returncode == 2 and "invalid choice: 'aud2pose'" in refused.stderr


def test_the_epoch_benchmark_scores_each_epoch_and_the_epochs_each_rule_would_keep():
    output = run("bench_epochs.py", "flowvae", "--quick", "--seed", "1", "--first", "2")
    epochs = re.findall(r"^epoch (\d+) \| validation loss \d\.\d+ \| val: hellinger ", output, re.M)
    assert epochs == ["2", "3"], output
    assert all(
        re.search(r"test: hellinger \S+  fgd \S+  ratio \S+  nods \S+  drift \S+ \| train: ", row)
        for row in output.splitlines()
        if row.startswith("epoch ")
    )
    for rule in ("validation loss", "validation FGD", "training FGD"):
        assert re.search(rf"{re.escape(rule)}: [23] \| test: hellinger ", output), (rule, output)
    refused = launch("bench_epochs.py", "flowvae", "--quick", "--first", "9")
    assert (
        refused.returncode == 2 and "--first must be an epoch of the recipe's 1-3" in refused.stderr
    )


def test_the_video_benchmark_times_each_write():
    output = run("bench_video.py", "--seconds", "1", "--repeats", "2")
    assert re.search(r"1\.0 s of two motions \(25 frames\): \d+\.\d+ s, \d+\.\d+ s", output), output
    assert re.search(r"median \d+\.\d+ s, \d+\.\d+ ms a frame", output), output
