"""What an evaluation writes: ``metrics.csv``, ``models.csv``, its figures and the README's table.

``docs/architecture.md`` states the files' contract; :data:`~gesturelib.evaluation.table.METRICS`
lists the measures.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from gesturelib.evaluation.style_control import StyleResponse
from gesturelib.evaluation.table import METRICS, REFERENCES, mean_pose_of
from gesturelib.style import STYLE_FEATURES

#: Columns of ``models.csv``.
MODEL_COLUMNS = (
    "system",
    "model",
    "parameters",
    "training_minutes",
    "training_minutes_sd",
    "epochs",
    "seeds",
)


def write_table(rows: dict[str, dict[str, float]], path: str | Path) -> Path:
    """Write ``rows`` (system name -> :func:`score_system` row) as CSV: a ``system`` column, then
    ``seeds``, then each measure and its ``_sd``; NaN as an empty cell."""
    columns = ["system", "seeds"] + [c for name in METRICS for c in (name, f"{name}_sd")]
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(columns)
        for system, row in rows.items():
            cells = [system] + [row[c] for c in columns[1:]]
            writer.writerow([_cell(value) for value in cells])
    return Path(path)


def read_table(path: str | Path) -> dict[str, dict[str, float]]:
    """Inverse of :func:`write_table` (empty cells as NaN)."""
    with open(path, newline="") as file:
        return {
            row.pop("system"): {k: float(v) if v != "" else np.nan for k, v in row.items()}
            for row in csv.DictReader(file)
        }


def _cell(value) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return "" if np.isnan(value) else f"{value:.6g}"


def models_table(models: dict) -> dict[str, dict]:
    """Each model row's class, parameters, training minutes (mean and standard deviation over
    its runs, from their histories), epochs and seeds.

    Args:
        models: row name -> ``[(model, history), ...]``, one per training seed.
    """
    rows = {}
    for name, runs in models.items():
        minutes = np.array([sum(history.epoch_seconds) / 60 for _, history in runs])
        model = runs[0][0]
        rows[name] = {
            "model": type(model).__name__,
            "parameters": sum(p.numel() for p in model.parameters()),
            "training_minutes": float(minutes.mean()),
            "training_minutes_sd": float(minutes.std(ddof=1)) if len(runs) > 1 else np.nan,
            "epochs": float(np.mean([history.epochs for _, history in runs])),
            "seeds": len(runs),
        }
    return rows


def write_models(rows: dict[str, dict], path: str | Path) -> Path:
    """Write :func:`models_table`'s rows as ``models.csv``."""
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(MODEL_COLUMNS)
        for system, row in rows.items():
            writer.writerow([system] + [_cell(row[c]) for c in MODEL_COLUMNS[1:]])
    return Path(path)


def write_evaluation(rows: dict, draws: dict, histories: dict, splits, folder: str | Path) -> list:
    """Everything an evaluation writes into ``folder``: ``metrics.csv`` (:func:`write_table` of
    ``rows``), ``models.csv`` (:func:`models_table` of ``histories``) and the figures
    (:func:`write_figures` of ``draws``). Returns the paths written."""
    folder = Path(folder)
    return [
        write_table(rows, folder / "metrics.csv"),
        write_models(models_table(histories), folder / "models.csv"),
        *write_figures(draws, splits, folder),
    ]


def write_figures(draws: dict, splits, folder: str | Path) -> list[Path]:
    """The evaluation's figures (:mod:`gesturelib.evaluation.figures`) as PNG files in
    ``folder``, from the first draw of each system in ``draws`` (as
    :func:`~gesturelib.evaluation.table.evaluate_models` returns them)."""
    import matplotlib.pyplot as plt

    from gesturelib.evaluation import figures

    folder = Path(folder)
    mean_pose = mean_pose_of(splits["train"])
    shown = {name: runs[0][0] for name, runs in draws.items()}
    truth = shown.pop("ground_truth")
    everyone = {"ground_truth": truth, **shown}
    pictures = {
        "speeds.png": figures.plot_speed_histograms(shown, truth),
        "mean_pose_distance.png": figures.plot_mean_pose_distance(everyone, mean_pose),
        "speaking_listening.png": figures.plot_speaking_listening(
            everyone, splits["test"], mean_pose
        ),
        "overlays.png": figures.plot_overlays(everyone),
    }
    written = []
    for file, figure in pictures.items():
        figure.savefig(folder / file, dpi=120)
        plt.close(figure)
        written.append(folder / file)
    return written


#: The README's columns: (heading, metrics.csv column, digits).
README_COLUMNS = (
    ("wrist-speed Hellinger ↓", "hellinger", 3),
    ("FGD ↓", "fgd", 0),
    ("jerk (cm/s³)", "jerk", 0),
    ("speak/listen", "ratio", 2),
    ("accents hit ↑", "accent_hits", 2),
    ("stroke precision", "stroke_precision", 2),
    ("lead error (s) ↓", "lead_error", 3),
    ("nods", "nods", 2),
    ("nod precision", "nod_precision", 2),
    ("style transfer (1 = full)", "transfer", 2),
    ("drift (1 = none)", "drift", 2),
)


def markdown_table(metrics: dict[str, dict], models: dict[str, dict]) -> str:
    """The README's results table: chosen measures (mean ± sd over samples and seeds) of every
    system, the references first, and each model's size and training time."""
    headings = ["system", *(h for h, _, _ in README_COLUMNS), "parameters", "training (min)"]
    lines = ["| " + " | ".join(headings) + " |", "|" + "---|" * len(headings)]
    for system, row in metrics.items():
        reference = system.split("+")[0] in REFERENCES  # the ground truth smoothed, too
        cells = [system.replace("_", " ").replace("+", ", ") if reference else f"`{system}`"]
        for _, column, digits in README_COLUMNS:
            mean, sd = row[column], row[f"{column}_sd"]
            cell = "" if np.isnan(mean) else f"{mean:.{digits}f}"
            cells.append(cell + (f" ± {sd:.{digits}f}" if cell and not np.isnan(sd) else ""))
        model = models.get(system.split("+")[0])
        cells += (
            [f"{model['parameters']:,}", f"{model['training_minutes']:.1f}"] if model else ["", ""]
        )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def style_control(runs: Sequence[Mapping[str, StyleResponse]]) -> dict[str, dict[str, float]]:
    """Per style feature, over the runs of one model (one
    :func:`~gesturelib.evaluation.style_control.style_response` each): the ``share`` of the change
    asked that its samples realise and the ``rank_correlation`` of asked and realised, each with
    its ``_sd`` over runs (NaN for one run), and ``seeds``."""
    rows = {}
    for feature in STYLE_FEATURES:
        row = {"seeds": len(runs)}
        for measure in ("share", "rank_correlation"):
            values = np.array([getattr(run[feature], measure) for run in runs])
            row[measure] = float(values.mean())
            row[f"{measure}_sd"] = float(values.std(ddof=1)) if len(runs) > 1 else np.nan
        rows[feature] = row
    return rows


def write_style_control(rows: dict[str, dict[str, float]], path: str | Path) -> Path:
    """Write :func:`style_control`'s rows as CSV (``style_control.csv``): a ``feature`` column,
    then ``seeds``, ``share``, ``share_sd``, ``rank_correlation``, ``rank_correlation_sd``."""
    columns = ("seeds", "share", "share_sd", "rank_correlation", "rank_correlation_sd")
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(("feature", *columns))
        for feature, row in rows.items():
            writer.writerow([feature] + [_cell(row[c]) for c in columns])
    return Path(path)


def style_control_table(rows: dict[str, dict[str, float]], system: str) -> str:
    """The README's style-control table: one row, ``system``, with the share of the change asked
    realised per style feature (mean ± sd over runs)."""
    headings = ["system", *(f"{f.replace('_', ' ')} (share realised)" for f in rows)]
    cells = [f"`{system}`"]
    for row in rows.values():
        sd = "" if np.isnan(row["share_sd"]) else f" ± {row['share_sd']:.2f}"
        cells.append(f"{row['share']:.2f}{sd}")
    return "\n".join(
        [
            "| " + " | ".join(headings) + " |",
            "|" + "---|" * len(headings),
            "| " + " | ".join(cells) + " |",
        ]
    )
