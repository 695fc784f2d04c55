"""Run folders as models you can use, and the small trained models that ship with the repository.

* :func:`load_run` rebuilds the model of any run folder (``train``'s, the notebooks' cache, or a
  shipped one) with the normalisation statistics it was trained with.
* ``gesturelib/pretrained/<name>/best.pt`` holds a trained model of each :data:`NAMES`, so that
  ``make demo`` and the explorer animate speech before any training. They are the full-mode
  recipes trained from seed 0 on the course's dataset, their weights stored as float16 (half the
  size; loaded back as float32): ``python tools/make_pretrained.py`` makes them again, which a
  release does only when a change to the data or the models needs it (each retrain stays in the
  repository's history). :func:`export_run` writes such a folder from a run.
"""

from __future__ import annotations

from pathlib import Path

from gesturelib.checkpoints import (
    CheckpointError,
    load_model,
    read_checkpoint,
    save_checkpoint,
)

#: Where the shipped models live, one run folder each.
PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"
#: The shipped models: the course's flows and its diffusion model.
NAMES = ("moglow", "flowvae", "diffusion")


def load_run(folder: str | Path, device: str = "cpu"):
    """The model of a run folder's ``best.pt``, on ``device`` in eval mode.

    Returns:
        ``(model, normaliser, checkpoint)``: the model, its
        :class:`~gesturelib.data.Normaliser`, and the checkpoint's other contents (configs,
        history).
    Raises:
        CheckpointError: if ``folder`` is not a folder, its ``best.pt`` is missing or unreadable,
            or holds a model this version does not know or no normalisation statistics.
        ValueError: for an unknown ``device``.
    """
    from gesturelib.data import Normaliser
    from gesturelib.history import History
    from gesturelib.recipes import MODEL_CLASSES
    from gesturelib.runtime import device as checked_device

    device = checked_device(device)
    folder = Path(folder)
    if folder.is_file():
        raise CheckpointError(f"{folder} is a file; give the run folder that holds best.pt")
    if not folder.is_dir():
        raise CheckpointError(f"{folder} is not a run folder (no such folder)")
    path = folder / "best.pt"
    checkpoint = read_checkpoint(path, kind="best")
    name = checkpoint["model_class"]
    if name not in MODEL_CLASSES:
        known = ", ".join(sorted(MODEL_CLASSES))
        raise CheckpointError(
            f"{path} holds a {name!r}, a model this version cannot load (it knows {known})"
        )
    if checkpoint["normaliser"] is None:
        raise CheckpointError(f"{path} has no normalisation statistics; retrain it with `train`")
    try:
        normaliser = Normaliser.from_dict(checkpoint["normaliser"])
        History.from_dict(checkpoint["history"])
    except (TypeError, ValueError) as error:
        raise CheckpointError(f"{path} is damaged ({error}); retrain the model") from error
    model = load_model(path, MODEL_CLASSES[name], device)
    damaged = [n for n, p in model.state_dict().items() if not p.isfinite().all()]
    if damaged:
        raise CheckpointError(
            f"{path} holds NaN or infinite weights ({damaged[0]}"
            + (f" and {len(damaged) - 1} more" if len(damaged) > 1 else "")
            + "): the run diverged or the file is damaged; retrain the model"
        )
    return model, normaliser, checkpoint


def read_summary(folder: str | Path) -> dict:
    """The ``run.json`` of a run folder (what ``train`` wrote: the data, seed, ...), or ``{}``
    where there is none (the notebooks' cached runs).

    Raises:
        CheckpointError: naming the file, if it is not a JSON object with the expected types.
    """
    import json

    path = Path(folder) / "run.json"
    if not path.exists():
        return {}
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CheckpointError(
            f"{path} is not valid JSON ({error}); delete it or retrain"
        ) from error
    types = {"data": str, "model": str, "seed": int, "quick": bool}
    wrong = [
        key
        for key, kind in types.items()
        if isinstance(summary, dict) and key in summary and not isinstance(summary[key], kind)
    ]
    if not isinstance(summary, dict) or wrong:
        raise CheckpointError(
            f"{path} is damaged ({'not a JSON object' if not wrong else 'wrong type: ' + ', '.join(wrong)});"
            " delete it or retrain"
        )
    return summary


def pretrained_folder(name: str) -> Path:
    """The run folder of the shipped model ``name`` (one of :data:`NAMES`).

    Raises:
        ValueError: for another name.
        CheckpointError: if the model is missing (a checkout without its files).
    """
    if name not in NAMES:
        raise ValueError(f"no shipped model {name!r}; the shipped models are {', '.join(NAMES)}")
    folder = PRETRAINED_DIR / name
    if not (folder / "best.pt").is_file():
        raise CheckpointError(
            f"the shipped model {name!r} is missing from {folder}; make it again with "
            "`python tools/make_pretrained.py`"
        )
    return folder


def export_run(run: str | Path, out: str | Path, overwrite: bool = False) -> Path:
    """Write ``run``'s ``best.pt`` into the folder ``out`` with float16 weights; return the file.

    Everything but the weights is kept (configs, normaliser, history), so the result is a run
    folder that :func:`load_run`, ``generate`` and ``evaluate`` read like any other.

    Raises:
        FileExistsError: if ``out/best.pt`` exists and ``overwrite`` is False.
    """
    checkpoint = read_checkpoint(Path(run) / "best.pt", kind="best")
    path = Path(out) / "best.pt"
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} already exists; pass overwrite=True to replace it")
    checkpoint["model"] = {
        key: value.half() if value.is_floating_point() else value
        for key, value in checkpoint["model"].items()
    }
    save_checkpoint(checkpoint, path)
    return path
