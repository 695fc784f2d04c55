"""gesturelib.evaluation.table and ``python -m gesturelib evaluate``: rows, spreads, references."""

import csv

import numpy as np
import pytest

from gesturelib.cli import main
from gesturelib.evaluation.report import read_table, write_table
from gesturelib.evaluation.table import (
    METRICS,
    REFERENCES,
    diversity,
    reference_draws,
    score_system,
)


@pytest.fixture(scope="module")
def conversations():
    from data_synth import generate_conversation

    return [generate_conversation(30.0, seed=seed) for seed in (4, 5, 6)]


def test_diversity_is_the_mean_distance_between_samples():
    motion = np.zeros((20, 9, 3))
    moved = motion + np.array([3.0, 0.0, 4.0])  # every keypoint 5 cm away
    assert diversity([[motion, motion], [moved, moved]]) == pytest.approx(5.0)
    assert diversity([[motion], [moved], [motion]]) == pytest.approx(10 / 3)  # pairs: 5, 0, 5
    assert np.isnan(diversity([[motion]]))


def test_the_references_rank_as_they_must(conversations):
    """On every measure where it must hold: the floor is as good as motion gets, the mean pose
    the least natural, and motion of another conversation breaks every rule the floor keeps."""
    held_out, others = conversations[:2], conversations[2:]
    mean_pose = np.mean([c.positions.mean(0) for c in conversations], axis=0)
    draws = reference_draws(held_out, others, mean_pose, samples=2, seed=1)
    assert list(draws) == list(REFERENCES)
    rows = {
        name: score_system(held_out, runs, None, name == "mean_pose")
        for name, runs in draws.items()
    }
    truth, floor, mismatched, still = (rows[name] for name in REFERENCES)
    assert truth["hellinger"] == 0 and np.isnan(truth["hellinger_sd"]) and truth["seeds"] == 1
    assert np.isnan(truth["diversity"]) and floor["diversity"] > 0 and still["diversity"] == 0
    for name in ("hellinger", "hellinger_elbows", "hellinger_all"):
        assert floor[name] < mismatched[name] < still[name]
        assert floor[f"{name}_sd"] > 0  # two draws: a spread
    assert still["acceleration"] == 0 and np.isnan(still["lead_error"])
    for name in ("accent_hits", "nods"):  # higher is better
        assert floor[name] > mismatched[name] >= still[name]
    assert floor["lead_error"] < mismatched["lead_error"]
    assert abs(floor["lead"] - 0.2) < abs(mismatched["lead"] - 0.2)
    assert abs(floor["ratio"] - truth["ratio"]) < abs(mismatched["ratio"] - truth["ratio"])


def test_a_row_is_the_mean_and_spread_over_every_draw_of_every_run(monkeypatch):
    from gesturelib.evaluation import table

    values = iter([1.0, 2.0, 6.0, 5.0])
    monkeypatch.setattr(
        table, "score_draw", lambda *_: dict.fromkeys(METRICS, next(values)) | {"lead": 0.5}
    )
    motion = np.zeros((10, 9, 3))
    runs = [[motion, motion + 1.0], [motion, motion + 3.0]]  # 2 seeds, 2 samples each
    row = score_system([None], [[[m] for m in run] for run in runs])
    assert row["seeds"] == 2 and row["hellinger"] == pytest.approx(3.5)
    assert row["hellinger_sd"] == pytest.approx(np.std([1, 2, 6, 5], ddof=1))
    assert row["lead"] == 0.5 and row["lead_sd"] == 0.0
    # Diversity, one value per run (1 cm and 3 cm apart at every keypoint... along x, y, z):
    assert row["diversity"] == pytest.approx(2 * np.sqrt(3))
    assert row["diversity_sd"] == pytest.approx(np.std([np.sqrt(3), 3 * np.sqrt(3)], ddof=1))
    assert np.isnan(row["transfer"])  # no model that replays a reference
    values = iter([1.0, np.nan])
    row = score_system([None], [[[motion]], [[motion]]], deterministic=True, transfer=[0.2, 0.4])
    assert np.isnan(row["hellinger"]) and row["diversity"] == 0.0  # undefined once: undefined
    assert row["transfer"] == pytest.approx(0.3)  # one value per run, like diversity
    assert row["transfer_sd"] == pytest.approx(np.std([0.2, 0.4], ddof=1))
    assert np.isnan(row["drift"])  # none given: a reference
    values = iter([1.0, 2.0])
    row = score_system([None], [[[motion]], [[motion]]], drifts=[1.0, 1.5])
    assert row["drift"] == pytest.approx(1.25)  # one value per run, too


def test_runs_of_several_seeds_share_a_row_named_by_their_folders():
    from gesturelib.cli import _common_name

    class MoGlow:
        pass

    assert _common_name(["moglow-1", "moglow-2"], MoGlow()) == "moglow"
    assert _common_name(["flowvae_v2-0", "flowvae_v2_1"], MoGlow()) == "flowvae_v2"
    assert _common_name(["first", "second"], MoGlow()) == "MoGlow"


def test_models_table_counts_parameters_and_training_time():
    from torch import nn

    from gesturelib.evaluation.report import models_table
    from gesturelib.history import History

    def history(seconds):
        record = History()
        record.epoch_seconds = list(seconds)
        return record

    model = nn.Linear(3, 2)  # 8 parameters
    rows = models_table({"tiny": [(model, history([60, 60])), (model, history([120, 120]))]})
    assert rows["tiny"]["parameters"] == 8 and rows["tiny"]["seeds"] == 2
    assert rows["tiny"]["training_minutes"] == pytest.approx(3.0)
    assert rows["tiny"]["training_minutes_sd"] == pytest.approx(np.std([2, 4], ddof=1))


def test_the_table_round_trips_with_empty_cells_for_undefined_measures(tmp_path):
    row = {"seeds": 2, **{name: 0.5 for name in METRICS}, **{f"{n}_sd": 0.1 for n in METRICS}}
    row["lead"] = np.nan
    path = write_table({"a": row, "b": {**row, "jerk": 3.25}}, tmp_path / "metrics.csv")
    with open(path) as file:
        lines = list(csv.reader(file))
    assert lines[0][:4] == ["system", "seeds", "hellinger", "hellinger_sd"]
    assert lines[1][lines[0].index("lead")] == ""
    table = read_table(path)
    assert table["b"]["jerk"] == 3.25 and table["a"]["seeds"] == 2 and np.isnan(table["a"]["lead"])


def test_evaluate_writes_the_table_models_and_figures(tmp_path, moglow_run, tiny_data, monkeypatch):
    from gesturelib.evaluation import table as evaluation_table

    # Style transfer: scored for MoGlow alone (one training conversation here: too few
    # references for a slope; style_transfer's own test has its arithmetic).
    monkeypatch.setattr(evaluation_table, "style_transfer", lambda *_: 0.25)
    # Drift compares the last chunk with the first: chunks of 4 s fit the 10 s conversations.
    monkeypatch.setattr(evaluation_table, "DRIFT_CHUNK_S", 4.0)
    out = tmp_path / "evaluation"
    arguments = ["evaluate", str(moglow_run), "--out", str(out), "--quick", "--data"]
    assert main([*arguments, str(tiny_data), "--samples", "2", "--cache", str(tmp_path)]) == 0
    table = read_table(out / "metrics.csv")
    assert list(table) == [*REFERENCES, "moglow"]
    assert table["ground_truth"]["hellinger"] == 0 and table["moglow"]["seeds"] == 1
    assert np.isfinite(table["moglow"]["fgd"]) and table["floor"]["fgd"] < table["mean_pose"]["fgd"]
    assert table["moglow"]["transfer"] == 0.25
    assert all(np.isnan(table[name]["transfer"]) for name in REFERENCES)
    assert table["moglow"]["drift"] > 0 and np.isnan(table["moglow"]["drift_sd"])  # one run
    assert all(np.isnan(table[name]["drift"]) for name in REFERENCES)
    with open(out / "models.csv") as file:
        models = list(csv.DictReader(file))
    assert models[0]["system"] == "moglow" and int(models[0]["parameters"]) > 1000
    for picture in ("speeds", "mean_pose_distance", "speaking_listening", "overlays"):
        assert (out / f"{picture}.png").stat().st_size > 1000


def test_evaluate_refuses_what_it_cannot_score(tmp_path, moglow_run, tiny_data, capsys):
    out = str(tmp_path / "out")
    assert main(["evaluate", str(tmp_path / "nothing"), "--out", out]) == 2
    assert "is not a run folder" in capsys.readouterr().err
    floor = tmp_path / "floor"
    floor.symlink_to(moglow_run, target_is_directory=True)
    assert main(["evaluate", str(floor), "--out", out, "--data", str(tiny_data)]) == 2
    assert "two rows would be called 'floor'" in capsys.readouterr().err
    assert main(["evaluate", str(moglow_run), str(moglow_run), "--out", out]) == 2
    assert "given twice" in capsys.readouterr().err


def test_style_control_summarises_the_shares_over_runs(tmp_path):
    from gesturelib.evaluation.report import (
        style_control,
        style_control_table,
        write_style_control,
    )
    from gesturelib.evaluation.style_control import StyleResponse
    from gesturelib.style import STYLE_FEATURES

    def run(share):
        levels = np.array([0.0, 1.0, 2.0])
        response = StyleResponse(levels, share * levels, share, 1.0)
        return dict.fromkeys(STYLE_FEATURES, response)

    rows = style_control([run(0.4), run(0.6)])
    assert list(rows) == list(STYLE_FEATURES)
    assert rows["hand_speed"]["share"] == pytest.approx(0.5) and rows["hand_speed"]["seeds"] == 2
    assert rows["hand_speed"]["share_sd"] == pytest.approx(np.std([0.4, 0.6], ddof=1))
    table = style_control_table(rows, "moglow, style inputs").splitlines()
    assert table[0].startswith("| system | hand height (share realised) |")
    assert table[2] == "| `moglow, style inputs` |" + " 0.50 ± 0.14 |" * 4
    with open(write_style_control(style_control([run(0.3)]), tmp_path / "style.csv")) as file:
        lines = list(csv.reader(file))
    assert lines[0] == [
        "feature",
        "seeds",
        "share",
        "share_sd",
        "rank_correlation",
        "rank_correlation_sd",
    ]
    assert lines[1] == ["hand_height", "1", "0.3", "", "1", ""]  # one run: no spread
