"""Checkpoint files: how a trained model is stored, written atomically and read back with checks.

A checkpoint is a dictionary of plain values (tensors, numbers, strings, booleans, None, lists and
dicts) written with ``torch.save``. Nothing else goes in, so it is read with
``torch.load(path, weights_only=True)``, which never runs code from the file. Every checkpoint
names what it belongs to: ``format`` and ``version`` (:data:`FORMAT`), ``kind``, ``model_class``
(the class name), ``model_config`` and ``train_config`` (the config dataclasses as JSON-able dicts,
:func:`config_to_dict`) and ``model`` (the ``state_dict``).

A training run keeps two in its folder (:class:`RunFolder`):

* ``best.pt``: the weights to use (best on validation), ``epoch`` (which one), ``score``,
  ``epochs_done``, ``history`` and ``normaliser`` (the statistics the model was trained with,
  ``Normaliser.to_dict()``, or None). :func:`load_model` rebuilds the model from it:
  ``Model(config)``, then the weights, after checking every parameter's shape.
* ``last.pt``: everything needed to continue: the current weights, ``optimizer`` state, ``epoch``
  and ``step`` done, ``history``, ``best_score``, ``best_model`` (None when the best weights are
  the current ones) and the random generators' state ``rng``.

Writing is atomic (:func:`save_checkpoint`): the bytes go to a temporary file in the same folder,
are flushed to disk, and the temporary file is renamed over the target with ``os.replace``, which
is atomic on POSIX and Windows. A crash or Ctrl-C while saving leaves the previous file whole.

Every error a user can meet (a missing, corrupt or half-written file; a checkpoint of another model
class, config or parameter shapes) is a :class:`CheckpointError` naming the file and the mismatch.
Cached runs are named by :func:`run_key` and :func:`dataset_fingerprint`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
from torch import nn

FORMAT = "gesturelib-checkpoint"
VERSION = 1
KINDS = ("best", "last")
#: Keys every checkpoint has (:class:`RunFolder` adds more per kind).
COMMON_KEYS = ("format", "version", "kind", "model_class", "model_config", "train_config", "model")


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, unreadable or not a checkpoint of this project."""


class CheckpointMismatchError(CheckpointError):
    """A checkpoint belongs to another model class, config or parameter shapes."""


# ---------------------------------------------------------------------------------------------
# Configs as JSON-able dictionaries
# ---------------------------------------------------------------------------------------------


def config_to_dict(config) -> dict:
    """A config dataclass as the JSON-able dict stored in checkpoints (tuples become lists).

    Uses ``config.to_dict()`` when the class defines it (e.g. for nested configs), else
    :func:`dataclasses.asdict`.

    Raises:
        TypeError: if ``config`` is not a dataclass instance or holds values JSON cannot store.
    """
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"a config must be a dataclass instance, got {type(config).__name__}")
    data = config.to_dict() if hasattr(config, "to_dict") else dataclasses.asdict(config)
    try:
        return json.loads(json.dumps(data))
    except (TypeError, ValueError) as error:
        raise TypeError(
            f"{type(config).__name__} must hold only JSON-able values (numbers, strings, "
            f"booleans, None, lists/tuples, dicts) so that it can be stored: {error}"
        ) from error


def dataclass_from_dict(config_class: type, data: dict):
    """Build a flat config dataclass from a dict; unknown keys raise, missing ones take defaults.

    Lists become tuples (frozen configs hold sequences as tuples). A config with nested
    dataclasses defines its own ``from_dict`` instead.

    Raises:
        ValueError: for a non-dict, an unknown key, or a missing key without a default.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{config_class.__name__} needs a dict, got {type(data).__name__}")
    names = {f.name for f in dataclasses.fields(config_class) if f.init}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(
            f"{config_class.__name__} has no field(s) {unknown}; its fields are {sorted(names)}"
        )
    values = {key: tuple(v) if isinstance(v, list) else v for key, v in data.items()}
    try:
        return config_class(**values)
    except TypeError as error:  # a field without a default is missing
        raise ValueError(f"cannot build {config_class.__name__} from {data}: {error}") from error


def config_from_dict(config_class: type, data: dict):
    """Inverse of :func:`config_to_dict`: ``config_class.from_dict`` if defined, else by fields."""
    if hasattr(config_class, "from_dict"):
        return config_class.from_dict(data)
    return dataclass_from_dict(config_class, data)


# ---------------------------------------------------------------------------------------------
# Writing and reading
# ---------------------------------------------------------------------------------------------


def save_checkpoint(contents: dict, path: str | Path) -> None:
    """Write ``contents`` (plain values only) to ``path`` atomically, creating its folder.

    ``format`` and ``version`` are added. Until ``os.replace`` renames the finished temporary file,
    ``path`` keeps its previous contents; on any error the temporary file is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    contents = {"format": FORMAT, "version": VERSION, **contents}
    descriptor, temporary = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=".tmp", dir=path.parent
    )
    try:
        with os.fdopen(descriptor, "wb") as file:
            torch.save(contents, file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise
    _sync_folder(path.parent)


def _sync_folder(folder: Path) -> None:
    """Make the rename itself durable (POSIX; Windows cannot open a folder for syncing)."""
    if os.name != "posix":
        return
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def read_checkpoint(path: str | Path, kind: str | None = None) -> dict:
    """Load a checkpoint (on the CPU, ``weights_only=True``) and check it is one of ours.

    Args:
        path: the ``.pt`` file.
        kind: ``"best"`` or ``"last"`` to require that kind; None accepts both.
    Raises:
        CheckpointError: naming ``path``, if it is missing, corrupt, half-written, holds anything
            but plain values, or lacks the keys of a checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}")
    try:
        checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # zip, pickle and EOF errors all mean the same thing to a user
        raise CheckpointError(
            f"cannot read checkpoint {path}: the file is corrupt, truncated or not a plain "
            f"checkpoint ({type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''})"
            ". Delete it, or retrain."
        ) from error
    if not isinstance(checkpoint, dict) or checkpoint.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a {FORMAT} file (no format tag {FORMAT!r})")
    if checkpoint.get("version") != VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {checkpoint.get('version')!r}; "
            f"this code reads version {VERSION}"
        )
    missing = [key for key in COMMON_KEYS if key not in checkpoint]
    if missing:
        raise CheckpointError(f"{path} lacks the checkpoint entries {missing}")
    if checkpoint["kind"] not in KINDS:
        raise CheckpointError(f"{path} has kind {checkpoint['kind']!r}, not one of {KINDS}")
    if kind is not None and checkpoint["kind"] != kind:
        raise CheckpointError(f"{path} is a {checkpoint['kind']!r} checkpoint, expected {kind!r}")
    return checkpoint


# ---------------------------------------------------------------------------------------------
# Checks that a checkpoint fits
# ---------------------------------------------------------------------------------------------


def check_run_matches(
    checkpoint: dict,
    path: str | Path,
    model_class: str,
    model_config: dict,
    train_config: dict | None = None,
    ignore: Iterable[str] = (),
    advice: str = "",
) -> None:
    """Raise unless ``checkpoint`` was written for this model class and these configs.

    Args:
        checkpoint: from :func:`read_checkpoint`.
        path: its file, for the message.
        model_class: the expected class name.
        model_config, train_config: expected configs as dicts (:func:`config_to_dict`);
            ``train_config=None`` skips that comparison.
        ignore: training-config fields allowed to differ.
        advice: a sentence appended to the message (what the user can do).
    Raises:
        CheckpointMismatchError: listing every difference.
    """
    problems = []
    if checkpoint["model_class"] != model_class:
        problems.append(
            f"model class: the file has {checkpoint['model_class']!r}, expected {model_class!r}"
        )
    else:
        problems += _differences("model config", checkpoint["model_config"], model_config)
    if train_config is not None:
        ignore = set(ignore)
        stored = {k: v for k, v in checkpoint["train_config"].items() if k not in ignore}
        wanted = {k: v for k, v in train_config.items() if k not in ignore}
        problems += _differences("training config", stored, wanted)
    if problems:
        raise CheckpointMismatchError(
            f"{path} belongs to a different run:\n  "
            + "\n  ".join(problems)
            + (f"\n{advice}" if advice else "")
        )


def _differences(what: str, stored: dict, wanted: dict) -> list[str]:
    if not isinstance(stored, dict):
        return [f"{what}: the file holds {type(stored).__name__}, not a dict"]
    lines = []
    for key in sorted(set(stored) | set(wanted)):
        if key not in stored:
            lines.append(f"{what}.{key}: missing in the file (expected {wanted[key]!r})")
        elif key not in wanted:
            lines.append(f"{what}.{key}: the file has {stored[key]!r}, unknown to this config")
        elif stored[key] != wanted[key]:
            lines.append(f"{what}.{key}: the file has {stored[key]!r}, expected {wanted[key]!r}")
    return lines


def load_state(model: nn.Module, state: dict, path: str | Path) -> None:
    """``model.load_state_dict(state)`` after checking names and shapes, naming ``path`` if not.

    Raises:
        CheckpointMismatchError: listing missing and unexpected entries and shape differences.
    """
    expected = model.state_dict()
    if not isinstance(state, dict):
        raise CheckpointMismatchError(f"{path}: the model weights are not a state_dict")
    problems = [f"missing entry {key!r}" for key in expected if key not in state]
    problems += [f"unexpected entry {key!r}" for key in state if key not in expected]
    for key, value in expected.items():
        stored = state.get(key)
        if isinstance(stored, torch.Tensor) and stored.shape != value.shape:
            problems.append(
                f"{key}: the file has shape {tuple(stored.shape)}, the model {tuple(value.shape)}"
            )
    if problems:
        raise CheckpointMismatchError(
            f"{path} does not fit {type(model).__name__}:\n  " + "\n  ".join(problems)
        )
    model.load_state_dict(state)


def load_model(path: str | Path, model_class: type[nn.Module], device: str = "cpu") -> nn.Module:
    """Rebuild a model from a checkpoint: ``model_class(config)`` with the file's weights.

    Args:
        path: a ``best.pt`` (or ``last.pt``) written by :func:`gesturelib.train.train`.
        model_class: the model's class; it names its config dataclass as ``config_class``.
        device: where to put the model.
    Returns:
        The model on ``device`` in eval mode. The normalisation statistics it was trained with,
        if any, are in ``read_checkpoint(path)["normaliser"]`` (``Normaliser.from_dict``).
    Raises:
        CheckpointError: if the file is unreadable; :class:`CheckpointMismatchError` if it holds
            another model class, a config ``config_class`` rejects, or other parameter shapes.
    """
    config_class = getattr(model_class, "config_class", None)
    if config_class is None:
        raise TypeError(
            f"{model_class.__name__} has no class attribute `config_class` naming its config "
            "dataclass, so a checkpoint cannot rebuild it"
        )
    checkpoint = read_checkpoint(path)
    if checkpoint["model_class"] != model_class.__name__:
        raise CheckpointMismatchError(
            f"{path} holds a {checkpoint['model_class']!r}, not a {model_class.__name__!r}"
        )
    try:
        config = config_from_dict(config_class, checkpoint["model_config"])
    except (TypeError, ValueError) as error:
        raise CheckpointMismatchError(
            f"{path}: its model config does not fit {config_class.__name__}: {error}"
        ) from error
    model = model_class(config)
    load_state(model, checkpoint["model"], path)
    return model.to(device).eval()


# ---------------------------------------------------------------------------------------------
# The folder of one training run
# ---------------------------------------------------------------------------------------------


class RunFolder:
    """``last.pt`` and ``best.pt`` of one training run: a model class with its configs.

    Args:
        folder: where the files live (created on the first save).
        model_class: the model's class name.
        model_config, train_config: the configs as dicts (:func:`config_to_dict`).
    """

    def __init__(
        self, folder: str | Path, model_class: str, model_config: dict, train_config: dict
    ):
        self.folder = Path(folder)
        self.last = self.folder / "last.pt"
        self.best = self.folder / "best.pt"
        self.identity = {
            "model_class": model_class,
            "model_config": model_config,
            "train_config": train_config,
        }

    def claim(self, may_differ: Iterable[str], overwrite: bool) -> None:
        """Make sure the folder is this run's: delete its files if ``overwrite``, else check them.

        Args:
            may_differ: training-config fields that may differ (e.g. the device).
            overwrite: start afresh, deleting the files of whatever run is there.
        Raises:
            CheckpointMismatchError: if a file belongs to another run (and not ``overwrite``).
            CheckpointError: if a file there is unreadable.
        """
        if overwrite:
            self.last.unlink(missing_ok=True)
            self.best.unlink(missing_ok=True)
            return
        for path in (self.last, self.best):
            if path.exists():
                self.check(read_checkpoint(path), path, may_differ)

    def check(
        self,
        checkpoint: dict,
        path: Path,
        may_differ: Iterable[str],
        advice: str = "Pass overwrite=True to replace it, or use another folder.",
    ) -> None:
        """Raise :class:`CheckpointMismatchError` unless ``checkpoint`` is this run's."""
        check_run_matches(checkpoint, path, **self.identity, ignore=may_differ, advice=advice)

    def save_last(self, model: nn.Module, optimizer: torch.optim.Optimizer, progress: dict) -> None:
        """Write ``last.pt``: weights, optimiser, the random generators and ``progress``.

        Args:
            progress: ``epoch``, ``step``, ``history`` (a dict), ``best_score`` and
                ``best_model`` (a ``state_dict`` or None).
        """
        device = _device_of(model)
        rng = {
            "cpu": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
        }
        contents = {"kind": "last", **self.identity, "model": model.state_dict()}
        contents |= {"optimizer": optimizer.state_dict(), "rng": rng, **progress}
        save_checkpoint(contents, self.last)

    def restore_last(self, model: nn.Module, optimizer: torch.optim.Optimizer) -> dict | None:
        """Load ``last.pt`` into the model, the optimiser and the random generators.

        Returns:
            The ``progress`` dict given to :meth:`save_last`, or None if there is no ``last.pt``.
        """
        if not self.last.exists():
            return None
        checkpoint = read_checkpoint(self.last, kind="last")
        load_state(model, checkpoint["model"], self.last)
        try:
            optimizer.load_state_dict(checkpoint["optimizer"])
            torch.set_rng_state(checkpoint["rng"]["cpu"])
            device = _device_of(model)
            if checkpoint["rng"]["cuda"] is not None and device.type == "cuda":
                torch.cuda.set_rng_state(checkpoint["rng"]["cuda"], device)
            keys = ("epoch", "step", "history", "best_score", "best_model")
            return {key: checkpoint[key] for key in keys}
        except (KeyError, TypeError, ValueError, RuntimeError) as error:
            raise CheckpointError(
                f"{self.last} is incomplete or damaged ({error!r}); delete it, or pass "
                "overwrite=True to start afresh"
            ) from error

    def save_best(self, weights: dict, progress: dict, normaliser=None) -> None:
        """Write ``best.pt``.

        Args:
            weights: the best ``state_dict``.
            progress: ``epoch`` (the best one), ``score``, ``epochs_done`` and ``history``.
            normaliser: a :class:`~gesturelib.data.Normaliser` or None.
        """
        contents = {"kind": "best", **self.identity, "model": weights, **progress}
        contents["normaliser"] = None if normaliser is None else normaliser.to_dict()
        save_checkpoint(contents, self.best)


def _device_of(model: nn.Module) -> torch.device:
    parameter = next(model.parameters(), None)
    return torch.device("cpu") if parameter is None else parameter.device


# ---------------------------------------------------------------------------------------------
# Naming cached runs
# ---------------------------------------------------------------------------------------------


def dataset_fingerprint(*datasets, samples: int = 5) -> str:
    """A short hash identifying datasets (or None) by their sizes and a few evenly spaced items.

    Cheap (reads ``samples`` items of each) and enough to tell apart the splits, window configs
    and normalisations of the course's data; pass your own fingerprint where it is not.
    """
    hasher = hashlib.sha256()
    for data in datasets:
        if data is None:
            hasher.update(b"none")
            continue
        hasher.update(f"len={len(data)}".encode())
        for index in sorted({int(i) for i in np.linspace(0, len(data) - 1, samples)}):
            _hash_value(hasher, data[index])
    return hasher.hexdigest()[:16]


def _hash_value(hasher, value) -> None:
    if isinstance(value, dict):
        for key in sorted(value):
            hasher.update(f"<{key}>".encode())
            _hash_value(hasher, value[key])
    elif isinstance(value, list | tuple):
        for item in value:
            _hash_value(hasher, item)
    elif isinstance(value, torch.Tensor | np.ndarray):
        array = value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else value
        array = np.ascontiguousarray(array)
        hasher.update(f"{array.dtype}{array.shape}".encode())
        hasher.update(array.tobytes())
    else:
        hasher.update(repr(value).encode())


def state_fingerprint(model: nn.Module) -> str:
    """A short hash of a model's weights and buffers (names, shapes, dtypes and values)."""
    hasher = hashlib.sha256()
    for name, tensor in sorted(model.state_dict().items()):
        hasher.update(f"<{name}>".encode())
        _hash_value(hasher, tensor)
    return hasher.hexdigest()[:16]


def run_key(
    model_class: str,
    model_config: dict,
    train_config: dict,
    data_fingerprint: str,
    initial_state: str | None = None,
) -> str:
    """A stable 12-hex-digit hash of what determines a trained model.

    Args:
        model_class: the class name.
        model_config, train_config: as dicts, leaving out fields that do not change the result.
        data_fingerprint: identifies the data (:func:`dataset_fingerprint`).
        initial_state: :func:`state_fingerprint` of the untrained model, where its config and
            seed do not determine it (a model holding a trained one); None otherwise.
    """
    identity = {
        "model_class": model_class,
        "model_config": model_config,
        "train_config": train_config,
        "data": data_fingerprint,
    }
    if initial_state is not None:  # only then: keys of ordinary runs stay as they were
        identity["initial_state"] = initial_state
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]
