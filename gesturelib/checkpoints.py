"""Run folders and checkpoint files: how a trained model is stored, written atomically, read back.

A run folder (what ``python -m gesturelib train`` and :func:`gesturelib.train.train` write) holds

* ``best.pt``: the weights to use (best on validation), with ``epoch``, ``score``, ``epochs_done``,
  ``history`` and ``normaliser`` (``Normaliser.to_dict()`` or None);
* ``last.pt``: everything needed to continue: the current weights, ``optimizer``, ``epoch``,
  ``step``, ``history``, ``best_score``, ``best_model`` (None when the best weights are the
  current ones) and the random generators' state ``rng``.

Both are dictionaries of plain values (tensors, numbers, strings, lists, dicts), read with
``torch.load(..., weights_only=True)``, which never runs code from a file, and both name the run
they belong to: ``format`` and ``version`` (:data:`FORMAT`, :data:`VERSION`), ``kind``, and the
run's identity: ``model_class``, ``model_config``, ``train_config`` and ``data`` (a fingerprint of
the training data). A folder is refused for another run: another model, config or data.

Writing is atomic (:func:`save_checkpoint`): the bytes go to a temporary file in the same folder,
are flushed to disk, and the temporary file is renamed over the target, so a crash or Ctrl-C
while saving leaves the previous file whole. Every error a user can meet is a
:class:`CheckpointError` naming the file and what to do.
"""

from __future__ import annotations

import ast
import contextlib
import errno
import functools
import hashlib
import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from gesturelib.configs import config_from_dict
from gesturelib.locks import LockedError, exclusive
from gesturelib.runtime import device_of

# The version changes whenever a run of older code would load but compute nonsense: 4 is the
# speech of gesturelib.features.speech_features, normalised per recording. Runs of version 3 made
# before that change were fitted to the raw log-mel; they cannot be told apart from later ones,
# so every version-3 run is refused.
FORMAT, VERSION = "gesturelib-run", 4
IDENTITY = ("model_class", "model_config", "train_config", "data")
_LABELS = {
    "model_class": "model class",
    "model_config": "model config",
    "train_config": "training config",
    "data": "training data",
    "judge": "judge",
}


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, unreadable or not a checkpoint of this project."""


class CheckpointMismatchError(CheckpointError):
    """A checkpoint belongs to another model class, config, data or parameter shapes."""


def save_checkpoint(contents: dict, path: str | Path) -> None:
    """Write ``contents`` (plain values only; ``format`` and ``version`` set to this code's) to
    ``path`` atomically, creating its folder. On any error ``path`` keeps its previous contents.

    Raises:
        CheckpointError: when the disk is full (naming the file); other ``OSError`` s as they are.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    contents = {**contents, "format": FORMAT, "version": VERSION}
    descriptor, temporary = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=".tmp", dir=path.parent
    )
    try:
        with os.fdopen(descriptor, "wb") as file:
            torch.save(contents, file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        if _out_of_space(error):
            raise CheckpointError(
                f"no space left on the device to write {path}; the previous file is intact. "
                "Free some space and run the same command again to continue."
            ) from error
        raise
    if os.name == "posix":  # make the rename itself durable
        folder = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)


def _out_of_space(error: BaseException) -> bool:
    """Whether ``error`` or an error it was raised from is "no space left on the device" (torch
    reports a full disk as a ``RuntimeError`` raised while handling the ``OSError``)."""
    while error is not None:
        if isinstance(error, OSError) and error.errno == errno.ENOSPC:
            return True
        error = error.__cause__ or error.__context__
    return False


def read_checkpoint(path: str | Path, kind: str | None = None) -> dict:
    """Load a checkpoint (on the CPU, ``weights_only=True``) and check that it is one of ours.

    Args:
        path: the ``.pt`` file.
        kind: ``"best"`` or ``"last"`` to require that kind; None accepts both.
    Raises:
        CheckpointError: naming ``path``, if it is missing, corrupt, truncated, holds anything but
            plain values, is of another format version or lacks the entries of a checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # zip, pickle and EOF errors all mean the same thing to a user
        first_line = str(error).splitlines()[0] if str(error) else ""
        raise CheckpointError(
            f"cannot read checkpoint {path}: the file is corrupt, truncated or not a plain "
            f"checkpoint ({type(error).__name__}: {first_line}). Delete it, or retrain."
        ) from error
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a {FORMAT} file (no format tag {FORMAT!r})")
    if checkpoint.get("version") != VERSION:
        raise CheckpointError(
            f"{path} has run format version {checkpoint.get('version')!r}; this code reads "
            f"version {VERSION}. Retrain the model with this version of the code."
        )
    missing = [key for key in ("kind", *IDENTITY, "model") if key not in checkpoint]
    if missing or checkpoint["kind"] not in ("best", "last"):
        raise CheckpointError(f"{path} is damaged: it lacks {missing or 'a valid kind'}")
    if kind is not None and checkpoint["kind"] != kind:
        raise CheckpointError(f"{path} is a {checkpoint['kind']!r} checkpoint, expected {kind!r}")
    if checkpoint["kind"] == "best":
        problems = [
            f"{key} ({what})"
            for key, what, fits in (
                ("history", "a dictionary", lambda v: isinstance(v, dict)),
                ("score", "a number", lambda v: isinstance(v, int | float) and v == v),
                ("epochs_done", "an integer", lambda v: isinstance(v, int)),
                ("normaliser", "a dictionary or None", lambda v: v is None or isinstance(v, dict)),
            )
            if not fits(checkpoint.get(key))
        ]
        if problems:
            raise CheckpointError(
                f"{path} is damaged: these entries are missing or of the wrong type: "
                f"{', '.join(problems)}. Retrain the model."
            )
    return checkpoint


def load_state(model: nn.Module, state: dict, path: str | Path) -> None:
    """``model.load_state_dict(state)`` after checking names and shapes, naming ``path`` if not.

    Raises:
        CheckpointMismatchError: listing missing and unexpected entries and shape differences.
    """
    if not isinstance(state, dict):
        raise CheckpointMismatchError(f"{path}: the model weights are not a state_dict")
    expected = model.state_dict()
    problems = [f"missing entry {key!r}" for key in expected if key not in state]
    problems += [f"unexpected entry {key!r}" for key in state if key not in expected]
    problems += [
        f"{key}: the file has shape {tuple(state[key].shape)}, the model {tuple(value.shape)}"
        for key, value in expected.items()
        if isinstance(state.get(key), torch.Tensor) and state[key].shape != value.shape
    ]
    if problems:
        raise CheckpointMismatchError(
            f"{path} does not fit {type(model).__name__}:\n  "
            + "\n  ".join(problems)
            + "\nIt holds another model, or one saved by a version of gesturelib whose layers "
            "differ: retrain it with this version."
        )
    model.load_state_dict(state)


def load_model(path: str | Path, model_class: type[nn.Module], device: str = "cpu") -> nn.Module:
    """Rebuild a model from a checkpoint: ``model_class(config)`` with the file's weights.

    Args:
        path: a ``best.pt`` (or ``last.pt``).
        model_class: the model's class; it names its config dataclass as ``config_class``.
        device: where to put the model.
    Returns:
        The model on ``device`` in eval mode. The normalisation statistics it was trained with
        are in ``read_checkpoint(path)["normaliser"]``.
    Raises:
        CheckpointError: if the file is unreadable; :class:`CheckpointMismatchError` if it holds
            another model class, a config the class rejects, or other parameter shapes.
    """
    checkpoint = read_checkpoint(path)
    if checkpoint["model_class"] != model_class.__name__:
        raise CheckpointMismatchError(
            f"{path} holds a {checkpoint['model_class']!r}, not a {model_class.__name__!r}"
        )
    try:
        config = config_from_dict(model_class.config_class, checkpoint["model_config"])
    except (TypeError, ValueError) as error:
        raise CheckpointMismatchError(
            f"{path}: its model config does not fit {model_class.config_class.__name__}: {error}"
        ) from error
    model = model_class(config)
    load_state(model, checkpoint["model"], path)
    return model.to(device).eval()


class RunFolder:
    """``last.pt`` and ``best.pt`` of one training run, identified by its model, configs and data.

    Args:
        folder: where the files live (created on the first save).
        identity: ``model_class`` (a name), ``model_config`` and ``train_config`` (JSON-able
            dicts) and ``data`` (a fingerprint, or None when unknown).
    """

    def __init__(self, folder: str | Path, identity: dict):
        self.folder = Path(folder)
        self.last, self.best = self.folder / "last.pt", self.folder / "best.pt"
        self.identity = identity

    @contextlib.contextmanager
    def writing(self):
        """Hold the folder's lock while training writes it: an operating-system lock on
        ``.lock`` (which names the process), released even when the process dies.

        Raises:
            CheckpointError: while another process holds it.
        """
        if self.folder.exists() and not self.folder.is_dir():
            raise CheckpointError(f"{self.folder} is a file, not a folder for checkpoints")
        self.folder.mkdir(parents=True, exist_ok=True)
        with contextlib.ExitStack() as held:
            try:
                held.enter_context(exclusive(self.folder / ".lock", remove=True))
            except LockedError as error:
                raise CheckpointError(
                    f"{error.holder} is writing {self.folder} (another training run); wait for "
                    "it to end, or choose another folder"
                ) from None
            yield

    def claim(self, may_differ: Iterable[str], overwrite: bool) -> None:
        """Make sure the folder is this run's: delete its checkpoints if ``overwrite``, else check
        them against this run's identity.

        Args:
            may_differ: training-config fields that may differ (the device, the epochs, ...).
        Raises:
            CheckpointError: if the folder is a file, or a checkpoint there is unreadable;
                :class:`CheckpointMismatchError` if one belongs to another run.
        """
        if self.folder.exists() and not self.folder.is_dir():
            raise CheckpointError(f"{self.folder} is a file, not a folder for checkpoints")
        for path in (self.last, self.best):
            if overwrite:
                path.unlink(missing_ok=True)
            elif path.exists():
                self.check(read_checkpoint(path), path, may_differ)

    def check(self, checkpoint: dict, path: Path, may_differ: Iterable[str], advice=None) -> None:
        """Raise :class:`CheckpointMismatchError`, listing every difference, unless ``checkpoint``
        belongs to this run."""
        ignore = set(may_differ)
        problems = []
        for key in (*IDENTITY, "judge"):  # a judged run's identity also holds its judge's
            stored, wanted = checkpoint.get(key), self.identity.get(key)
            if key == "train_config":
                stored = {k: v for k, v in stored.items() if k not in ignore}
                wanted = {k: v for k, v in wanted.items() if k not in ignore}
            if isinstance(stored, dict) and isinstance(wanted, dict):
                problems += [
                    f"{_LABELS[key]}.{name}: the file has {stored.get(name, '(none)')!r}"
                    f", expected {wanted.get(name, '(none)')!r}"
                    for name in sorted(set(stored) | set(wanted))
                    if stored.get(name) != wanted.get(name)
                ]
            elif stored != wanted:
                problems.append(f"{_LABELS[key]}: the file has {stored!r}, expected {wanted!r}")
        if problems:
            advice = advice or (
                "Replace it (overwrite=True; --overwrite on the command line), or use another folder."
            )
            raise CheckpointMismatchError(
                f"{path} belongs to a different run:\n  " + "\n  ".join(problems) + f"\n{advice}"
            )

    def save(self, kind: str, contents: dict) -> None:
        """Write ``best.pt`` or ``last.pt`` with this run's identity and ``contents``."""
        save_checkpoint({"kind": kind, **self.identity, **contents}, self.folder / f"{kind}.pt")


def rng_state(model: nn.Module) -> dict:
    """The random generators training draws from (the CPU's, and the model's GPU's)."""
    device = device_of(model)
    cuda = torch.cuda.get_rng_state(device) if device.type == "cuda" else None
    return {"cpu": torch.get_rng_state(), "cuda": cuda}


def set_rng_state(state: dict, model: nn.Module) -> None:
    """Restore what :func:`rng_state` saved."""
    torch.set_rng_state(state["cpu"])
    device = device_of(model)
    if state["cuda"] is not None and device.type == "cuda":
        torch.cuda.set_rng_state(state["cuda"], device)


# ---------------------------------------------------------------------------------------------
# Naming runs and their data
# ---------------------------------------------------------------------------------------------


def dataset_fingerprint(*datasets) -> str:
    """A short hash of datasets (or None) that changes when any of their data does.

    A dataset with a ``fingerprint()`` method (:class:`gesturelib.data.WindowDataset`: its arrays
    and window config) is hashed by it; any other is hashed item by item, every item, so that a
    change anywhere in it gives another fingerprint. For a large dataset of your own, give it a
    ``fingerprint()`` method or pass ``data_fingerprint`` to the training functions.
    """
    hasher = hashlib.sha256()
    for data in datasets:
        if data is None:
            hasher.update(b"none")
        elif callable(getattr(data, "fingerprint", None)):
            hasher.update(f"dataset {data.fingerprint()}".encode())
        else:
            hasher.update(f"len={len(data)}".encode())
            for index in range(len(data)):
                hash_value(hasher, data[index])
    return hasher.hexdigest()[:16]


def state_fingerprint(model: nn.Module) -> str:
    """A short hash of a model's weights and buffers (names, shapes, dtypes and values)."""
    hasher = hashlib.sha256()
    hash_value(hasher, dict(model.state_dict()))
    return hasher.hexdigest()[:16]


def hash_value(hasher, value) -> None:
    """Feed ``value`` (dicts, lists, tensors, arrays, plain values) into a hashlib ``hasher``."""
    if isinstance(value, dict):
        for key in sorted(value):
            hasher.update(f"<{key}>".encode())
            hash_value(hasher, value[key])
    elif isinstance(value, list | tuple):
        hasher.update(f"[{len(value)}".encode())
        for item in value:
            hash_value(hasher, item)
            hasher.update(b",")
        hasher.update(b"]")
    elif isinstance(value, torch.Tensor | np.ndarray):
        array = value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else value
        array = np.ascontiguousarray(array)
        hasher.update(f"{array.dtype}{array.shape}".encode())
        hasher.update(array.tobytes())
    else:
        hasher.update(f"{type(value).__name__}:{value!r};".encode())


def run_key(identity: dict) -> str:
    """A stable 12-hex-digit hash of a run's identity (what determines the trained model)."""
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]


#: Modules of the package that cannot change what training computes (they draw, write files,
#: generate from a trained model or score motion): :func:`code_fingerprint` does not follow
#: imports into them.
_PRESENTATION_MODULES = frozenset(
    {
        "__main__.py",
        "bvh.py",
        "cli.py",
        "gaps.py",
        "postprocess.py",
        "pretrained.py",
        "toy_densities.py",
        "viz.py",
        "widgets.py",
        "evaluation/figures.py",
        "outputs.py",
        "sampling.py",
        "evaluation/headline.py",
        "evaluation/report.py",
        "evaluation/rules.py",
        "evaluation/table.py",
    }
)


def _module_path(package: Path, dotted: str) -> Path | None:
    """The file of module ``gesturelib.a.b`` (``a/b.py``, or a package's ``__init__.py``), or
    None for a name that is not a submodule of gesturelib (the package's own ``__init__``, which
    only gathers names, included)."""
    parts = dotted.split(".")
    if parts[0] != "gesturelib" or len(parts) < 2:
        return None
    for candidate in (
        package.joinpath(*parts[1:]).with_suffix(".py"),
        package.joinpath(*parts[1:], "__init__.py"),
    ):
        if candidate.is_file():
            return candidate
    return None


def _imported_modules(tree: ast.Module) -> set[str]:
    """The gesturelib modules a module imports, anywhere in it (``from gesturelib.a import b``
    names ``gesturelib.a`` and, if it is a module, ``gesturelib.a.b``)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names if a.name.split(".")[0] == "gesturelib"}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "gesturelib":
            names.add(node.module)
            names |= {f"{node.module}.{a.name}" for a in node.names}
    return names


@functools.cache
def code_fingerprint(*roots: str) -> str:
    """A hash of the code that training runs: the modules ``roots`` (dotted names, e.g. the
    model's module and ``gesturelib.train``) and every gesturelib module they import, transitively,
    but the presentation ones; as parsed syntax without docstrings, so that a comment, a docstring
    or a reformat keeps cached runs, a change to one model's code retrains that model alone, and
    any other change trains afresh instead of reusing a run of older code."""
    package = Path(__file__).resolve().parent
    pending, trees = list(roots), {}
    while pending:
        path = _module_path(package, pending.pop())
        if path is None or path in trees:
            continue
        name = path.relative_to(package).as_posix()
        if name in _PRESENTATION_MODULES:
            continue
        trees[path] = tree = ast.parse(path.read_text(encoding="utf-8"))
        pending.extend(_imported_modules(tree))
    digest = hashlib.sha256()
    for path in sorted(trees):
        tree = trees[path]
        for node in ast.walk(tree):
            body = getattr(node, "body", None)
            if (
                isinstance(body, list)
                and body
                and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)
            ):
                node.body = body[1:] or [ast.Pass()]
        name = path.relative_to(package).as_posix()
        digest.update(name.encode() + b"\0" + ast.dump(tree).encode() + b"\0")
    return digest.hexdigest()[:12]
