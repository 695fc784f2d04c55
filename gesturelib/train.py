"""One training loop for every model of the course, with checkpoints that survive interruptions.

The model protocol
------------------
Every model trained here is an ``nn.Module`` that

* computes its own loss: ``model.loss(batch) -> dict[str, Tensor]``. ``batch`` is a dict of named
  tensors, batch axis first, as a ``DataLoader`` stacks :class:`gesturelib.data.WindowDataset`
  items (``pose (B, L, 54)``, ``past_pose (B, L, tau, 54)``, ``speech (B, L, W, 27)``,
  ``activity (B, L, W, 4)``). The result holds ``"loss"``, the scalar to minimise, and any other
  scalars worth logging (``"kl"``, ``"mse"``, ...). With the loss in the model, this loop is the
  same for an autoencoder, a VAE, a flow or the Flow-VAE;
* keeps its config dataclass (JSON-able values, working defaults) as ``model.config``;
* names that dataclass in the class attribute ``config_class`` and is built from it alone,
  ``Model(config)``, so a checkpoint can rebuild it (:func:`gesturelib.checkpoints.load_model`).

A minimal model::

    @dataclass(frozen=True)
    class RegressorConfig:
        hidden: int = 64

    class Regressor(nn.Module):
        config_class = RegressorConfig

        def __init__(self, config: RegressorConfig):
            super().__init__()
            self.config = config
            self.net = nn.Sequential(
                nn.LazyLinear(config.hidden), nn.ReLU(), nn.Linear(config.hidden, 54)
            )

        def loss(self, batch):
            prediction = self.net(batch["speech"].flatten(2))       # (B, L, 54)
            return {"loss": F.mse_loss(prediction, batch["pose"])}

The loop
--------
:func:`train` runs Adam with the Noam schedule of MoGlow and the Flow-VAE paper
(:func:`noam_learning_rate`), clips the gradient norm, and after every epoch evaluates on the
validation data in ``eval()`` mode without gradients (no dropout), keeps the best weights, stops
early when validation stops improving, and writes checkpoints. Every random draw (the shuffle
order, dropout, a VAE's noise) comes from generators seeded by ``TrainConfig.seed``, so the same
initial weights, seed and data give the same model (:func:`load_or_train` draws the initial
weights from the seed too). A NaN or infinite loss or gradient raises
:class:`NonFiniteLossError` *before* the optimiser step, so no NaN weight is ever written.

Checkpoints and resuming
------------------------
With ``checkpoint_dir``, ``last.pt`` (everything needed to resume) is written before the first
epoch and after each one, and ``best.pt`` (the best weights, the configs, the normaliser and the
history) whenever validation improves and at the end; both atomically
(:mod:`gesturelib.checkpoints`). Calling :func:`train` again with the same folder continues from
``last.pt`` and ends with the same result as an uninterrupted run; a folder of another model or
config is refused unless ``overwrite=True``. :func:`load_or_train` builds on this for notebooks:
it loads a finished run from a cache folder keyed by the model, its config, the training config and
the data, and trains (or resumes) otherwise.

The device is ``TrainConfig.device`` and no state is global (each call forks and seeds its own
random stream), so training on a GPU takes only ``device="cuda"``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from gesturelib.checkpoints import (
    RunFolder,
    config_to_dict,
    dataclass_from_dict,
    dataset_fingerprint,
    load_state,
    read_checkpoint,
    run_key,
    state_fingerprint,
)
from gesturelib.history import History

if TYPE_CHECKING:
    from gesturelib.data import Normaliser

#: Training-config fields that change how a run executes, not what it computes: they may differ
#: when resuming and are left out of :func:`load_or_train`'s cache key.
EXECUTION_FIELDS = frozenset({"device", "num_workers"})
#: Fields that may differ when resuming: also ``epochs``, so that a finished run can be extended.
RESUMABLE_FIELDS = EXECUTION_FIELDS | {"epochs"}


class NonFiniteLossError(FloatingPointError):
    """The loss or its gradient became NaN or infinite; training stopped before the update."""


@dataclass(frozen=True)
class TrainConfig:
    """How a model is trained: the papers' optimiser settings by default; :meth:`quick` for CI.

    Attributes:
        epochs: passes over the training data (at most; early stopping may end sooner).
        batch_size: items per optimiser step (and per validation batch).
        warmup_steps: optimiser steps of linear warm-up to ``lr_max`` (Noam schedule).
        lr_max: peak learning rate (1.5e-3 in MoGlow and the Flow-VAE paper).
        lr_min: floor of the inverse-square-root decay (1.5e-4 in both papers).
        grad_clip_norm: largest total gradient norm; None = no clipping.
        patience: stop after this many epochs without a better validation loss; None = never.
        drop_last: drop the last, smaller training batch of each epoch (for batch norm).
        seed: seeds the shuffle order and every random draw of the model during training.
        num_workers: ``DataLoader`` worker processes (0 = load in the main process).
        device: where to train, e.g. ``"cpu"``, ``"cuda"``, ``"cuda:1"``.
    """

    epochs: int = 50
    batch_size: int = 64
    warmup_steps: int = 1000
    lr_max: float = 1.5e-3
    lr_min: float = 1.5e-4
    grad_clip_norm: float | None = 5.0
    patience: int | None = 10
    drop_last: bool = False
    seed: int = 0
    num_workers: int = 0
    device: str = "cpu"

    def __post_init__(self):
        _require_int(self, "epochs", 1)
        _require_int(self, "batch_size", 1)
        _require_int(self, "warmup_steps", 1)
        _require_int(self, "seed", 0)
        _require_int(self, "num_workers", 0)
        if self.patience is not None:
            _require_int(self, "patience", 1, "or None (no early stopping)")
        for name in ("lr_max", "lr_min"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (math.isfinite(value) and value > 0)
            ):
                raise ValueError(f"TrainConfig.{name} must be a number > 0, got {value!r}")
        if self.lr_min > self.lr_max:
            raise ValueError(
                f"TrainConfig.lr_min ({self.lr_min}) must not exceed lr_max ({self.lr_max})"
            )
        clip = self.grad_clip_norm
        if clip is not None and (
            isinstance(clip, bool) or not isinstance(clip, int | float) or not clip > 0
        ):
            raise ValueError(
                f"TrainConfig.grad_clip_norm must be a number > 0 or None (no clipping), got {clip!r}"
            )
        if not isinstance(self.drop_last, bool):
            raise ValueError(f"TrainConfig.drop_last must be True or False, got {self.drop_last!r}")
        try:
            torch.device(self.device)
        except (RuntimeError, TypeError) as error:
            raise ValueError(
                f"TrainConfig.device={self.device!r} is not a device, e.g. 'cpu' or 'cuda'"
            ) from error

    @classmethod
    def quick(cls, **changes) -> TrainConfig:
        """A few short epochs for CI and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(epochs=3, batch_size=32, warmup_steps=20), **changes)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> TrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        return dataclass_from_dict(cls, data)


def _require_int(config, name: str, minimum: int, alternative: str = "") -> None:
    value = getattr(config, name)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(
            f"TrainConfig.{name} must be an integer >= {minimum}{' ' + alternative if alternative else ''}"
            f", got {value!r}"
        )


def noam_learning_rate(step: int, warmup_steps: int, lr_max: float, lr_min: float) -> float:
    """The Noam schedule: linear warm-up to ``lr_max``, then decay as ``1 / sqrt(step)``.

    With ``s = step + 1`` and ``w = warmup_steps``::

        lr = lr_max * s / w                             for s <= w   (warm-up)
        lr = max(lr_min, lr_max * sqrt(w / s))          for s > w    (decay, floored)

    as in MoGlow's reference code (floor after warm-up). The rate peaks at ``lr_max`` on the last
    warm-up step and reaches the floor after ``w * (lr_max / lr_min)**2`` steps.

    Args:
        step: optimiser steps already taken (0 for the first update).
        warmup_steps: ``w >= 1``.
        lr_max, lr_min: peak and floor, ``0 < lr_min <= lr_max``.
    """
    if isinstance(step, bool) or not isinstance(step, int | np.integer) or step < 0:
        raise ValueError(f"step must be an integer >= 0, got {step!r}")
    if warmup_steps < 1:
        raise ValueError(f"warmup_steps must be >= 1, got {warmup_steps!r}")
    if not 0 < lr_min <= lr_max:
        raise ValueError(f"need 0 < lr_min <= lr_max, got lr_min={lr_min}, lr_max={lr_max}")
    position = step + 1
    if position <= warmup_steps:
        return lr_max * position / warmup_steps
    return max(lr_min, lr_max * math.sqrt(warmup_steps / position))


# ---------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------


def train(
    model: nn.Module,
    train_data,
    val_data,
    config: TrainConfig,
    checkpoint_dir: str | Path | None = None,
    *,
    normaliser: Normaliser | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> History:
    """Train ``model`` on ``train_data``; end with its best weights (on validation) loaded.

    Args:
        model: follows the model protocol (module docstring).
        train_data: a map-style dataset of dict items (a :class:`~gesturelib.data.WindowDataset`,
            a list of dicts of tensors, ...).
        val_data: the same for validation, or None: then the training loss chooses the best epoch
            and drives early stopping.
        config: the training settings.
        checkpoint_dir: folder for ``last.pt`` and ``best.pt``. If it holds a run of this model
            and these configs, training resumes from it (the model's weights are replaced by the
            checkpoint's); ``config.epochs``, ``device`` and ``num_workers`` may differ. None: no
            files.
        normaliser: a :class:`~gesturelib.data.Normaliser`, stored in ``best.pt``.
        progress: show a progress bar (``tqdm.auto``: a widget in notebooks).
        overwrite: start afresh, deleting the checkpoints in ``checkpoint_dir`` (of this run or
            another) instead of resuming or refusing.
    Returns:
        The :class:`History`. The model is on ``config.device``, back in the mode (train or eval)
        it came in.
    Raises:
        NonFiniteLossError: on a NaN/inf loss or gradient, before the update.
        CheckpointError: if ``checkpoint_dir`` holds a corrupt file or another run's.
    """
    _check_model(model)
    if not isinstance(config, TrainConfig):
        raise TypeError(f"config must be a TrainConfig, got {type(config).__name__}")
    _check_dataset(train_data, "train_data", config.batch_size if config.drop_last else 1)
    if val_data is not None:
        _check_dataset(val_data, "val_data", 1)
    was_training = model.training
    run = _Run(model, config, checkpoint_dir, normaliser)
    # A random stream of our own, seeded: training neither depends on nor disturbs the caller's.
    with torch.random.fork_rng(devices=_cuda_indices(run.device)):
        torch.manual_seed(config.seed)
        run.start(overwrite)
        epochs_before = run.epoch
        try:
            run.fit(train_data, val_data, progress)
        except NonFiniteLossError:
            raise
        except BaseException as error:
            if run.folder is not None:
                error.add_note(
                    f"{run.folder.last} (after epoch {run.saved_epoch}) is intact: call train() "
                    "again with the same checkpoint_dir to resume."
                )
            raise
    run.finish(trained=run.epoch > epochs_before)
    model.train(was_training)
    return run.history


class _Run:
    """One call of :func:`train`: the model and its optimiser, where the run stands, its files."""

    def __init__(
        self, model: nn.Module, config: TrainConfig, folder, normaliser: Normaliser | None
    ):
        self.device = _device(config.device)
        self.model = model.to(self.device)
        self.config, self.normaliser = config, normaliser
        self.optimizer = torch.optim.Adam(model.parameters(), lr=config.lr_max)
        self.parameters = [p for p in model.parameters() if p.requires_grad]
        self.history = History()
        self.epoch = 0  # epochs completed
        self.saved_epoch = 0  # epochs completed as of last.pt
        self.step = 0  # optimiser steps taken
        self.learning_rate = 0.0
        self.best_score = math.inf
        self.best_weights: dict | None = None  # on the CPU
        self.folder = None
        if folder is not None:
            model_config, train_config = config_to_dict(model.config), config_to_dict(config)
            self.folder = RunFolder(folder, type(model).__name__, model_config, train_config)

    def start(self, overwrite: bool) -> None:
        """Resume from ``last.pt`` if there is one, else save the initial state as epoch 0."""
        if self.folder is None:
            return
        self.folder.claim(RESUMABLE_FIELDS, overwrite)
        saved = self.folder.restore_last(self.model, self.optimizer)
        if saved is None:
            self.save_last()
            return
        self.epoch = self.saved_epoch = int(saved["epoch"])
        self.step = int(saved["step"])
        self.history = History.from_dict(saved["history"])
        self.best_score = float(saved["best_score"])
        self.best_weights = saved["best_model"]
        if self.best_weights is None and self.history.best_epoch is not None:
            self.best_weights = self.current_weights()  # the best were the last ones

    def fit(self, train_data, val_data, progress: bool) -> None:
        """The epochs from ``self.epoch + 1`` to ``config.epochs``, unless stopped early."""
        size, batch_size = len(train_data), self.config.batch_size
        per_epoch = size // batch_size if self.config.drop_last else math.ceil(size / batch_size)
        total = per_epoch * self.config.epochs
        name = type(self.model).__name__
        bar = tqdm(total=total, initial=min(self.step, total), disable=not progress, desc=name)
        with bar:
            for epoch in range(self.epoch + 1, self.config.epochs + 1):
                if self.history.stopped_early:
                    break
                started = time.perf_counter()
                train_means = self.train_epoch(train_data, epoch, bar)
                val_means = {}
                if val_data is not None:
                    val_means = evaluate(self.model, val_data, batch_size)
                    if not math.isfinite(val_means["loss"]):
                        where = f"the validation of epoch {epoch}"
                        raise NonFiniteLossError(self.message("validation loss", val_means, where))
                self.end_epoch(epoch, train_means, val_means, time.perf_counter() - started)
                val_loss = val_means.get("loss", math.nan)
                bar.set_postfix(
                    epoch=epoch, train=f"{train_means['loss']:.4g}", val=f"{val_loss:.4g}"
                )

    def train_epoch(self, data, epoch: int, bar) -> dict[str, float]:
        """One pass over shuffled batches; the mean of each logged scalar over the items."""
        self.model.train()
        sums, count = {}, 0
        for number, batch in enumerate(_batches(data, self.config, self.device, epoch), start=1):
            values = self.update(batch, f"epoch {epoch}, batch {number}")
            size = _batch_size(batch)
            for key, value in values.items():
                sums[key] = sums.get(key, 0.0) + value * size
            count += size
            bar.update(1)
            bar.set_postfix(epoch=epoch, loss=f"{values['loss']:.4g}", refresh=False)
        return {key: total / count for key, total in sums.items()}

    def update(self, batch: dict, where: str) -> dict[str, float]:
        """One optimiser step on ``batch``, unless the loss or gradient is not finite."""
        config = self.config
        self.learning_rate = noam_learning_rate(
            self.step, config.warmup_steps, config.lr_max, config.lr_min
        )
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate
        self.optimizer.zero_grad(set_to_none=True)
        terms = _loss_terms(self.model, batch)
        values = {key: float(value.detach()) for key, value in terms.items()}
        where = f"{where} (optimiser step {self.step + 1})"
        if not math.isfinite(values["loss"]):
            raise NonFiniteLossError(self.message("loss", values, where, before_update=True))
        terms["loss"].backward()
        clip = math.inf if config.grad_clip_norm is None else config.grad_clip_norm
        norm = float(torch.nn.utils.clip_grad_norm_(self.parameters, clip))
        if not math.isfinite(norm):
            values = {"gradient norm": norm}
            raise NonFiniteLossError(self.message("gradient", values, where, before_update=True))
        self.optimizer.step()
        self.step += 1
        return values

    def end_epoch(self, epoch: int, train_means: dict, val_means: dict, seconds: float) -> None:
        """Record the epoch, keep the weights if best, decide on early stopping, save."""
        self.history.append(train_means, val_means, self.learning_rate, seconds)
        self.epoch = epoch
        score = (val_means or train_means)["loss"]
        if score < self.best_score:
            self.best_score, self.history.best_epoch = score, epoch
            self.best_weights = self.current_weights()
            self.save_best()
        elif self.config.patience is not None:
            self.history.stopped_early = epoch - self.history.best_epoch >= self.config.patience
        self.save_last()

    def finish(self, trained: bool) -> None:
        """Load the best weights; write the final ``best.pt`` (with the whole history)."""
        if self.best_weights is not None:
            self.model.load_state_dict(self.best_weights)
        if self.folder is not None and (trained or not self.folder.best.exists()):
            self.save_best()

    def current_weights(self) -> dict:
        return {k: v.detach().to("cpu", copy=True) for k, v in self.model.state_dict().items()}

    def save_last(self) -> None:
        if self.folder is None:
            return
        best_is_current = self.history.best_epoch == self.epoch  # then it need not be stored twice
        progress = {
            "epoch": self.epoch,
            "step": self.step,
            "history": self.history.to_dict(),
            "best_score": self.best_score,
            "best_model": None if best_is_current else self.best_weights,
        }
        self.folder.save_last(self.model, self.optimizer, progress)
        self.saved_epoch = self.epoch

    def save_best(self) -> None:
        if self.folder is None:
            return
        progress = {
            "epoch": self.history.best_epoch,
            "score": self.best_score,
            "epochs_done": self.epoch,
            "history": self.history.to_dict(),
        }
        weights = self.best_weights if self.best_weights is not None else self.current_weights()
        self.folder.save_best(weights, progress, self.normaliser)

    def message(self, what: str, values: dict, where: str, before_update: bool = False) -> str:
        shown = ", ".join(f"{key}={value:.4g}" for key, value in values.items())
        text = f"non-finite {what} at {where} ({shown}); training stopped"
        if before_update:
            text += " before the update, so the weights are still finite"
        if self.folder is not None:
            text += f". {self.folder.last} still holds epoch {self.saved_epoch}"
        return text + ". Try a lower lr_max or grad_clip_norm, or look for NaN/inf in the data."


@torch.no_grad()
def evaluate(model: nn.Module, data, batch_size: int = 64) -> dict[str, float]:
    """Mean of each scalar of ``model.loss`` over ``data``, in eval mode (no dropout), no gradients.

    Args:
        model: follows the model protocol; the batches go to the device of its parameters.
        data: a map-style dataset of dict items.
        batch_size: items per batch (the result does not depend on it, up to rounding).
    Returns:
        ``{"loss": ..., ...}``, each averaged over items. The model is back in its previous mode.
    """
    _check_dataset(data, "data", 1)
    device = _device_of(model)
    was_training = model.training
    model.eval()
    try:
        sums, count = {}, 0
        for batch in DataLoader(data, batch_size=batch_size, pin_memory=device.type == "cuda"):
            batch = _to_device(batch, device)
            size = _batch_size(batch)
            for key, value in _loss_terms(model, batch).items():
                sums[key] = sums.get(key, 0.0) + float(value) * size
            count += size
    finally:
        model.train(was_training)
    return {key: total / count for key, total in sums.items()}


def _batches(data, config: TrainConfig, device: torch.device, epoch: int):
    """The epoch's shuffled batches on ``device``; the order depends on (seed, epoch) alone."""
    seed = int(np.random.SeedSequence([config.seed, epoch]).generate_state(1)[0])
    loader = DataLoader(
        data,
        batch_size=config.batch_size,
        shuffle=True,
        drop_last=config.drop_last,
        num_workers=config.num_workers,
        generator=torch.Generator().manual_seed(seed),
        pin_memory=device.type == "cuda",
    )
    for batch in loader:
        yield _to_device(batch, device)


def _to_device(batch, device: torch.device) -> dict:
    if not isinstance(batch, dict):
        raise TypeError(
            "dataset items must be dicts of named tensors (see gesturelib.data), got "
            f"{type(batch).__name__}"
        )
    return {
        key: value.to(device, non_blocking=True) if isinstance(value, torch.Tensor) else value
        for key, value in batch.items()
    }


def _batch_size(batch: dict) -> int:
    for value in batch.values():
        if isinstance(value, torch.Tensor) and value.ndim > 0:
            return len(value)
    raise ValueError(f"a batch needs a tensor with a batch axis; got the keys {sorted(batch)}")


def _loss_terms(model: nn.Module, batch: dict) -> dict[str, torch.Tensor]:
    """``model.loss(batch)``, checked: a dict with ``"loss"``, of scalar tensors."""
    terms = model.loss(batch)
    name = type(model).__name__
    if not isinstance(terms, dict) or "loss" not in terms:
        got = sorted(terms) if isinstance(terms, dict) else type(terms).__name__
        raise TypeError(f"{name}.loss(batch) must return a dict with the key 'loss', got {got}")
    for key, value in terms.items():
        if not isinstance(value, torch.Tensor) or value.numel() != 1:
            got = tuple(value.shape) if isinstance(value, torch.Tensor) else type(value).__name__
            raise ValueError(f"{name}.loss(batch)[{key!r}] must be a scalar tensor, got {got}")
    if torch.is_grad_enabled() and not terms["loss"].requires_grad:
        raise ValueError(f"{name}.loss(batch)['loss'] does not depend on any trainable parameter")
    return terms


def _check_model(model) -> None:
    if not isinstance(model, nn.Module):
        raise TypeError(f"model must be an nn.Module, got {type(model).__name__}")
    if not callable(getattr(model, "loss", None)):
        raise TypeError(f"{type(model).__name__} has no method loss(batch) -> dict of scalars")
    config = getattr(model, "config", None)
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(
            f"{type(model).__name__}.config must be an instance of the model's config "
            f"dataclass, got {type(config).__name__}"
        )


def _check_dataset(data, name: str, minimum: int) -> None:
    if not (hasattr(data, "__len__") and hasattr(data, "__getitem__")):
        raise TypeError(
            f"{name} must be a map-style dataset (len and indexing), got {type(data).__name__}"
        )
    if len(data) < minimum:
        raise ValueError(f"{name} has {len(data)} items; it needs at least {minimum}")


def _device(name: str) -> torch.device:
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"TrainConfig.device is {name!r}, but no CUDA GPU is available")
    return device


def _device_of(model: nn.Module) -> torch.device:
    parameter = next(model.parameters(), None)
    return torch.device("cpu") if parameter is None else parameter.device


def _cuda_indices(device: torch.device) -> list[int]:
    """The GPU whose random generator training uses (none on the CPU)."""
    if device.type != "cuda":
        return []
    return [device.index if device.index is not None else torch.cuda.current_device()]


# ---------------------------------------------------------------------------------------------
# Load or train, for notebooks
# ---------------------------------------------------------------------------------------------


def load_or_train(
    model_class: type[nn.Module],
    model_config,
    train_data,
    val_data,
    train_config: TrainConfig,
    cache_dir: str | Path,
    normaliser=None,
    *,
    build: Callable[[Any], nn.Module] | None = None,
    data_fingerprint: str | None = None,
    progress: bool = True,
) -> tuple[nn.Module, History]:
    """The model trained on this data with these configs: loaded if cached, else trained.

    The run lives in ``cache_dir/<ModelName>-<hash>/``, the hash (:func:`run_key`) covering the
    model class and config, the training config (not its device or workers) and the data; so
    another notebook asking for the same gets the same files. A finished run loads at once from
    its ``best.pt`` (all it needs); an interrupted one resumes from ``last.pt``; a missing one is
    trained from initial weights drawn with ``train_config.seed``.

    Args:
        model_class: follows the model protocol; built as ``model_class(model_config)``.
        model_config: its config dataclass.
        train_data, val_data, train_config, normaliser: as for :func:`train`.
        cache_dir: the folder of cached runs.
        build: makes the untrained model from ``model_config`` where ``model_class(config)`` is
            not enough: a model that holds another, already trained one, e.g.
            ``lambda config: Aud2Repr2Pose.from_autoencoder(denoiser, config)``. It must return a
            ``model_class``. The hash then also covers the returned model's weights and buffers
            (:func:`state_fingerprint`), so that a retrained inner model never brings back a
            cached run trained around the old one.
        data_fingerprint: identifies the data; by default :func:`dataset_fingerprint` of both.
        progress: show the progress bar while training, or a line naming the file loaded.
    Returns:
        ``(model, history)``: the model with its best weights, on ``train_config.device``, in
        eval mode, and how its training went.
    """
    with torch.random.fork_rng(devices=[]):  # the initial weights depend on the seed alone
        torch.manual_seed(train_config.seed)
        model = model_class(model_config) if build is None else build(model_config)
    if not isinstance(model, model_class):
        raise TypeError(f"build must return a {model_class.__name__}, got {type(model).__name__}")
    # With build, the model's own config is the truth (build may complete the one passed).
    model_dict = config_to_dict(model_config if build is None else model.config)
    train_dict = config_to_dict(train_config)
    fingerprint = data_fingerprint or dataset_fingerprint(train_data, val_data)
    key_config = {k: v for k, v in train_dict.items() if k not in EXECUTION_FIELDS}
    initial_state = None if build is None else state_fingerprint(model)
    key = run_key(model_class.__name__, model_dict, key_config, fingerprint, initial_state)
    folder = RunFolder(
        Path(cache_dir) / f"{model_class.__name__}-{key}",
        model_class.__name__,
        model_dict,
        train_dict,
    )
    if folder.best.exists():
        checkpoint = read_checkpoint(folder.best, kind="best")
        folder.check(checkpoint, folder.best, EXECUTION_FIELDS, advice="Delete it to retrain.")
        history = History.from_dict(checkpoint["history"])
        if history.stopped_early or checkpoint["epochs_done"] >= train_config.epochs:
            load_state(model, checkpoint["model"], folder.best)
            if progress:
                print(f"Loaded {folder.best} (epoch {history.best_epoch} of {history.epochs})")
            return model.to(_device(train_config.device)).eval(), history
    history = train(
        model,
        train_data,
        val_data,
        train_config,
        folder.folder,
        normaliser=normaliser,
        progress=progress,
    )
    return model.eval(), history
