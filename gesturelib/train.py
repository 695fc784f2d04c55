"""One training loop for every model of the course, with checkpoints that survive interruptions.

The model protocol: every model trained here is an ``nn.Module`` that

* computes its own loss, ``model.loss(batch) -> dict[str, Tensor]``, from a dict of named tensors
  stacked by a ``DataLoader`` (e.g. :class:`gesturelib.data.WindowDataset` items: ``pose (B, L,
  54)``, ``speech (B, L, W, 27)``, ...). The dict holds ``"loss"``, the scalar to minimise, and
  any other scalars worth logging (``"kl"``, ``"mse"``, ...). With the loss in the model, this
  loop is the same for an autoencoder, a VAE, a flow or the Flow-VAE;
* keeps its config dataclass as ``model.config``, names that class ``config_class`` and is built
  from it alone, ``Model(config)``, so that a checkpoint can rebuild it.

:func:`train` runs Adam with the Noam schedule of MoGlow and the Flow-VAE paper, clips the
gradient norm, evaluates on the validation data after every epoch in ``eval()`` mode without
gradients (no dropout), keeps the best weights and stops early when validation stops improving.
A run may also be *judged*: a ``judge`` scores the model after each of its last epochs (the
pipeline's judges the motion it generates for the validation conversations), and the best-judged
of those epochs is kept rather than the best validation loss, a teacher-forced score that can
keep falling while generation gets worse.
Every random draw (shuffle order, dropout, noise) comes from generators seeded by
``TrainConfig.seed``, so the same initial weights, seed and data give the same model. A NaN or
infinite loss or gradient raises :class:`NonFiniteLossError` *before* the optimiser step.

With a ``checkpoint_dir`` the run is written to a run folder (:mod:`gesturelib.checkpoints`):
``last.pt`` after every epoch, ``best.pt`` whenever the epoch kept changes. Calling :func:`train`
again with the same folder continues from ``last.pt`` and ends as an uninterrupted run would; a
folder of another model, config or data is refused unless ``overwrite=True``.
:func:`load_or_train` builds on this for notebooks: a finished run is loaded from a cache folder
keyed by everything that determines it, anything else is trained (or resumed).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from gesturelib import distributed
from gesturelib.checkpoints import (
    VERSION,
    RunFolder,
    code_fingerprint,
    dataset_fingerprint,
    load_state,
    read_checkpoint,
    rng_state,
    run_key,
    set_rng_state,
    state_fingerprint,
)
from gesturelib.configs import check_fields, config_from_dict, config_to_dict
from gesturelib.history import History
from gesturelib.locks import exclusive
from gesturelib.runtime import device, device_of

#: Training-config fields that change how a run executes, not what it computes.
EXECUTION_FIELDS = frozenset({"device", "num_workers"})
#: The code every cached run depends on, besides its model's module (the cache key's
#: :func:`~gesturelib.checkpoints.code_fingerprint` follows their imports): the training loop and
#: the windows and normalisation of the data.
_TRAINING_CODE = ("gesturelib.train", "gesturelib.data")
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
        patience: stop after this many epochs without a better validation loss (or judged
            score); None = never.
        judged_epochs: how many of the last epochs ``train``'s judge scores; the best-judged of
            them is kept instead of the best validation loss (a run that stops early before
            them judges none). 0: none (and no judge).
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
    judged_epochs: int = 0
    drop_last: bool = False
    seed: int = 0
    num_workers: int = 0
    device: str = "cpu"

    def __post_init__(self):
        check_fields(
            self,
            positive=("epochs", "batch_size", "warmup_steps"),
            counts=("seed", "num_workers", "judged_epochs"),
            flags=("drop_last",),
        )
        if self.patience is not None:
            check_fields(self, positive=("patience",))
        for name in ("lr_max", "lr_min", "grad_clip_norm"):
            value = getattr(self, name)
            if name == "grad_clip_norm" and value is None:
                continue
            check_fields(self, non_negative=(name,))
            if value == 0:
                raise ValueError(f"TrainConfig.{name} must be a number > 0, got {value!r}")
        if self.lr_min > self.lr_max:
            raise ValueError(f"TrainConfig.lr_min ({self.lr_min}) must not exceed lr_max")
        try:
            torch.device(self.device)
        except (RuntimeError, TypeError) as error:
            raise ValueError(f"TrainConfig.device={self.device!r} is not a device") from error

    @classmethod
    def quick(cls, **changes) -> TrainConfig:
        """A few short epochs for CI and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(epochs=3, batch_size=32, warmup_steps=20), **changes)

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> TrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        return config_from_dict(cls, data)


def noam_learning_rate(step: int, warmup_steps: int, lr_max: float, lr_min: float) -> float:
    """The Noam schedule: linear warm-up to ``lr_max``, then decay as ``1 / sqrt(step)``.

    With ``s = step + 1`` and ``w = warmup_steps``: ``lr = lr_max * s / w`` for ``s <= w``, then
    ``max(lr_min, lr_max * sqrt(w / s))``, as in MoGlow's reference code. The rate peaks on the
    last warm-up step and reaches the floor after ``w * (lr_max / lr_min)**2`` steps.
    """
    if not (isinstance(step, int | np.integer) and step >= 0 and warmup_steps >= 1):
        raise ValueError(f"need step >= 0 and warmup_steps >= 1, got {step!r}, {warmup_steps!r}")
    if not 0 < lr_min <= lr_max:
        raise ValueError(f"need 0 < lr_min <= lr_max, got lr_min={lr_min}, lr_max={lr_max}")
    position = step + 1
    if position <= warmup_steps:
        return lr_max * position / warmup_steps
    return max(lr_min, lr_max * math.sqrt(warmup_steps / position))


def train(
    model: nn.Module,
    train_data,
    val_data,
    config: TrainConfig,
    checkpoint_dir: str | Path | None = None,
    *,
    normaliser=None,
    progress: bool = True,
    overwrite: bool = False,
    data_fingerprint: str | None = None,
    judge: Judge | None = None,
) -> History:
    """Train ``model`` on ``train_data``; end with its best weights (on validation, or the
    best-judged) loaded.

    Args:
        model: follows the model protocol (module docstring).
        train_data: a map-style dataset of dict items (a ``WindowDataset``, a list of dicts...).
        val_data: the same for validation, or None: then the training loss picks the best epoch.
        config: the training settings.
        checkpoint_dir: the run folder for ``last.pt`` and ``best.pt``; training resumes from a
            run of this model, configs and data found there (``epochs``, ``device`` and
            ``num_workers`` may differ). None: no files.
        normaliser: a :class:`~gesturelib.data.Normaliser`, stored in ``best.pt``.
        progress: show a progress bar (``tqdm.auto``: a widget in notebooks).
        overwrite: start afresh, deleting the checkpoints in ``checkpoint_dir``.
        data_fingerprint: identifies the data in the run folder; by default
            :func:`~gesturelib.checkpoints.dataset_fingerprint` of both datasets.
        judge: scores the model after each of the last ``config.judged_epochs`` epochs
            (:class:`Judge`); needed exactly when ``judged_epochs`` > 0.
    Returns:
        The :class:`History`. The model is on ``config.device``, in the mode it came in.
    Raises:
        NonFiniteLossError: on a NaN/inf loss or gradient, before the update.
        CheckpointError: if ``checkpoint_dir`` holds a corrupt file or another run's.
    """
    _check_model(model)
    _check_judge(judge, config)
    for name, data in (("train_data", train_data), ("val_data", val_data)):
        if data is not None and not (hasattr(data, "__getitem__") and hasattr(data, "__len__")):
            raise TypeError(f"{name} must be a map-style dataset (len and indexing)")
        if data is not None and len(data) < (config.batch_size if config.drop_last else 1):
            raise ValueError(f"{name} has {len(data)} items: too few for one batch")
    target = device(config.device)
    model.to(target)
    inputs = (model, train_data, val_data, config)
    if checkpoint_dir is None:
        return _fit(*inputs, None, normaliser, judge, progress, target)
    fingerprint = data_fingerprint or dataset_fingerprint(train_data, val_data)
    folder = RunFolder(checkpoint_dir, _identity(model, config, fingerprint, judge))
    if distributed.world()[0] > 0:  # under torchrun: process 0 claims the folder and writes it
        return _fit(*inputs, folder, normaliser, judge, progress, target)
    with folder.writing():  # one training run at a time in a folder
        folder.claim(RESUMABLE_FIELDS, overwrite)
        return _fit(*inputs, folder, normaliser, judge, progress, target)


class Judge(Protocol):
    """Scores a model after one of the last epochs of a judged run; lower is better.

    ``judge(model) -> float`` is called in eval mode without gradients, with torch's random
    state kept (its draws do not change the training that follows); a NaN counts as the worst
    score. ``identity`` (a dict of plain values) says what determines its scores: it joins the
    run folder's identity and the cache key, so that another judge never resumes or loads the run;
    the cache key also covers the code of the judge's module.
    """

    identity: dict

    def __call__(self, model: nn.Module) -> float: ...


def _fit(
    model, train_data, val_data, config, folder, normaliser, judge, progress, target
) -> History:
    """The loop of :func:`train`, its inputs checked and its folder (or None) claimed."""
    was_training = model.training
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr_max)
    rank, size = distributed.world()
    # A random stream of our own, seeded: training neither depends on nor disturbs the caller's.
    with _own_random_state(target):
        torch.manual_seed(config.seed)
        if rank == 0:  # writes the initial state when starting, so the others can read it
            run = _Run(model, optimizer, folder, normaliser, writes=True)
        distributed.barrier()
        if rank > 0:
            run = _Run(model, optimizer, folder, normaliser, writes=False)
        compute = model.loss
        if size > 1 and run.step == 0:
            # Layers that initialise from their first batch (ActNorm) see the batch one process
            # would start from, in every process alike, not each process's share of it.
            with torch.no_grad():
                model.train()
                model.loss(
                    _to_device(next(iter(_batches(train_data, config, 1, shard=False))), target)
                )
        if size > 1:  # each process its own draws (dropout, noise), from the seed and the step
            torch.manual_seed(
                int(np.random.SeedSequence([config.seed, rank, run.step]).generate_state(1)[0])
            )
            compute = DistributedDataParallel(distributed.LossOf(model))
        first_judged = config.epochs - config.judged_epochs + 1
        if run.history.judged and min(run.history.judged) < first_judged:
            raise ValueError(
                f"the run in {folder.folder} has judged epochs {sorted(run.history.judged)}; with "
                f"epochs={config.epochs} it would judge epochs from {first_judged} on: a judged "
                "run cannot be extended once judging has begun; train a new one"
            )
        epochs_before = run.epoch
        total = len(_batches(train_data, config, 1)) * config.epochs
        bar = tqdm(
            total=total,
            initial=min(run.step, total),
            disable=not progress or rank > 0,
            desc=f"training {type(model).__name__}",
        )
        try:
            with bar:
                for epoch in range(run.epoch + 1, config.epochs + 1):
                    if run.history.stopped_early:
                        break
                    started, sums = time.perf_counter(), {}
                    model.train()
                    for number, batch in enumerate(_batches(train_data, config, epoch), 1):
                        batch = _to_device(batch, target)
                        rate = noam_learning_rate(
                            run.step, config.warmup_steps, config.lr_max, config.lr_min
                        )
                        where = f"epoch {epoch}, batch {number} (optimiser step {run.step + 1})"
                        values = _update(
                            model, compute, optimizer, batch, rate, config.grad_clip_norm, where
                        )
                        _accumulate(sums, values, _batch_size(batch))
                        run.step += 1
                        bar.update(1)
                        bar.set_postfix(epoch=epoch, loss=f"{values['loss']:.4g}", refresh=False)
                    val = evaluate(model, val_data, config.batch_size) if val_data else {}
                    val = distributed.from_first(val)  # one choice of best epoch and stopping
                    if val and not math.isfinite(val["loss"]):
                        where = f"the validation of epoch {epoch}"
                        raise NonFiniteLossError(_message("validation loss", val, where))
                    judged = None
                    if epoch >= first_judged:
                        bar.set_postfix(epoch=epoch, judging="...")
                        judged = _judged(judge, model, target) if rank == 0 else None
                        judged = distributed.from_first(judged)
                    seconds = time.perf_counter() - started
                    sums = distributed.all_sum(sums)  # every process's share of the epoch
                    run.end_epoch(epoch, _means(sums), val, rate, seconds, config.patience, judged)
        except BaseException as error:
            if folder is not None and not isinstance(error, NonFiniteLossError):
                error.add_note(
                    f"{folder.last} (after epoch {run.saved_epoch}) is intact: call train() "
                    "again with the same checkpoint_dir (or `train` with --resume) to resume."
                )
            raise
    if run.best_weights is not None:
        model.load_state_dict(run.best_weights)
    if folder is not None and (run.epoch > epochs_before or not folder.best.exists()):
        run.save_best()
    model.train(was_training)
    return run.history


class _Run:
    """One call of :func:`train`: where the run stands (epochs and steps done, history, best
    weights so far) and how it is saved (its folder, optimiser and normaliser)."""

    def __init__(
        self, model: nn.Module, optimizer, folder: RunFolder | None, normaliser, writes: bool
    ):
        self.model, self.optimizer, self.normaliser = model, optimizer, normaliser
        self.folder = folder
        self.writes = writes and folder is not None  # one process writes the run folder
        self.epoch = self.saved_epoch = self.step = 0
        self.history, self.best_score, self.best_weights = History(), math.inf, None
        if folder is None:
            return
        if not folder.last.exists():
            self.save_last()  # the initial state, as epoch 0
            return
        saved = read_checkpoint(folder.last, kind="last")
        load_state(model, saved["model"], folder.last)
        optimizer.load_state_dict(saved["optimizer"])
        set_rng_state(saved["rng"], model)
        self.epoch = self.saved_epoch = int(saved["epoch"])
        self.step, self.best_score = int(saved["step"]), float(saved["best_score"])
        self.history = History.from_dict(saved["history"])
        self.best_weights = saved["best_model"]
        if self.best_weights is None and self.history.best_epoch is not None:
            self.best_weights = _cpu_copy(model)  # the best were the last ones

    def end_epoch(
        self, epoch: int, train_means, val_means, rate, seconds, patience, judged=None
    ) -> None:
        """Record the epoch, keep the weights if best, decide on early stopping, save.
        ``judged``: the judge's score of a judged epoch. From the first finite one on, only
        judged epochs compete; until then the best validation (or training) loss is kept."""
        self.history.append(train_means, val_means, rate, seconds)
        self.epoch = epoch
        score = (val_means or train_means)["loss"]
        # whether a finite judgement chose the best epoch so far
        judging = math.isfinite(self.history.judged.get(self.history.best_epoch, math.inf))
        if judged is not None:
            self.history.judged[epoch] = judged
            if math.isfinite(judged):
                if not judging:
                    self.best_score = math.inf  # the loss's scale is not the judge's
                score = judged
            elif judging:
                score = math.inf  # an epoch the judge cannot score never wins
        if score < self.best_score:
            self.best_score, self.history.best_epoch = score, epoch
            self.best_weights = _cpu_copy(self.model)
            self.save_best()
        elif patience is not None:
            self.history.stopped_early = epoch - self.history.best_epoch >= patience
        self.save_last()

    def save_last(self) -> None:
        if not self.writes:
            return
        best_is_current = self.history.best_epoch == self.epoch  # then it need not be stored twice
        self.folder.save(
            "last",
            {
                "model": self.model.state_dict(),
                "optimizer": self.optimizer.state_dict(),
                "rng": rng_state(self.model),
                "epoch": self.epoch,
                "step": self.step,
                "history": self.history.to_dict(),
                "best_score": self.best_score,
                "best_model": None if best_is_current else self.best_weights,
            },
        )
        self.saved_epoch = self.epoch

    def save_best(self) -> None:
        if not self.writes:
            return
        weights = self.best_weights if self.best_weights is not None else _cpu_copy(self.model)
        self.folder.save(
            "best",
            {
                "model": weights,
                "epoch": self.history.best_epoch,
                "score": self.best_score,
                "epochs_done": self.epoch,
                "history": self.history.to_dict(),
                "normaliser": None if self.normaliser is None else self.normaliser.to_dict(),
            },
        )


def _judged(judge: Judge, model: nn.Module, target: torch.device) -> float:
    """The judge's score of the model as it stands, with the training's random state kept; a
    non-finite score (generation that blew up) is the worst, ``inf``."""
    model.eval()
    with torch.no_grad(), _own_random_state(target):
        score = float(judge(model))
    return score if math.isfinite(score) else math.inf


def _own_random_state(target: torch.device):
    """A block whose draws from torch's generators (the CPU's, and ``target``'s GPU's) leave
    them as they were."""
    return torch.random.fork_rng(devices=[target.index or 0] if target.type == "cuda" else [])


def _update(model, compute, optimizer, batch, rate: float, grad_clip_norm, where: str) -> dict:
    """One optimiser step at learning rate ``rate``, unless the loss or gradient is not finite;
    ``compute(batch)`` is ``model.loss`` or, in several processes, its distributed wrapper."""
    for group in optimizer.param_groups:
        group["lr"] = rate
    optimizer.zero_grad(set_to_none=True)
    terms = _loss_terms(model, batch, compute)
    values = {key: float(value.detach()) for key, value in terms.items()}
    if not math.isfinite(values["loss"]):
        raise NonFiniteLossError(_message("loss", values, where, before_update=True))
    terms["loss"].backward()
    clip = math.inf if grad_clip_norm is None else grad_clip_norm
    norm = float(torch.nn.utils.clip_grad_norm_(model.parameters(), clip))
    if not math.isfinite(norm):
        values = {"gradient norm": norm}
        raise NonFiniteLossError(_message("gradient", values, where, before_update=True))
    optimizer.step()
    return values


def _message(what: str, values: dict, where: str, before_update: bool = False) -> str:
    shown = ", ".join(f"{key}={value:.4g}" for key, value in values.items())
    text = f"non-finite {what} at {where} ({shown}); training stopped"
    if before_update:
        text += " before the update, so the weights are still finite"
    return text + ". Try a lower lr_max or grad_clip_norm, or look for NaN/inf in the data."


@torch.no_grad()
def evaluate(model: nn.Module, data, batch_size: int = 64) -> dict[str, float]:
    """Mean of each scalar of ``model.loss`` over ``data``, in eval mode (no dropout), no gradients.

    Returns ``{"loss": ..., ...}``, each averaged over items; the model is back in its mode.
    """
    target, was_training = device_of(model), model.training
    model.eval()
    try:
        sums = {}
        for batch in DataLoader(data, batch_size=batch_size, pin_memory=target.type == "cuda"):
            batch = _to_device(batch, target)
            _accumulate(sums, _loss_terms(model, batch), _batch_size(batch))
    finally:
        model.train(was_training)
    return _means(sums)


def _batches(data, config: TrainConfig, epoch: int, shard: bool = True) -> DataLoader:
    """The epoch's shuffled batches; the order depends on (seed, epoch) alone. In several
    processes each takes its share of every batch, unless ``shard`` is False."""
    seed = int(np.random.SeedSequence([config.seed, epoch]).generate_state(1)[0])
    generator = torch.Generator().manual_seed(seed)
    rank, size = distributed.world()
    if size > 1 and shard:  # the same order in every process, each its share of every batch
        shards = distributed.ShardedBatches(
            len(data), config.batch_size, config.drop_last, generator, rank, size
        )
        return DataLoader(
            data,
            batch_sampler=shards,
            num_workers=config.num_workers,
            generator=generator,  # which draws a seed first, as the shuffling loader below does
            pin_memory=config.device.startswith("cuda"),
        )
    return DataLoader(
        data,
        batch_size=config.batch_size,
        shuffle=True,
        drop_last=config.drop_last,
        num_workers=config.num_workers,
        generator=generator,
        pin_memory=config.device.startswith("cuda"),
    )


def _to_device(batch, target: torch.device) -> dict:
    if not isinstance(batch, dict):
        raise TypeError(f"dataset items must be dicts of named tensors, got {type(batch).__name__}")
    return {
        k: v.to(target, non_blocking=True) if torch.is_tensor(v) else v for k, v in batch.items()
    }


def _batch_size(batch: dict) -> int:
    return next(len(v) for v in batch.values() if torch.is_tensor(v) and v.ndim > 0)


def _accumulate(sums: dict, values: dict, size: int) -> None:
    """Add ``values`` (floats or scalar tensors), weighted by the batch size, to ``sums``."""
    for key, value in values.items():
        total, count = sums.get(key, (0.0, 0))
        sums[key] = (total + float(value) * size, count + size)


def _means(sums: dict) -> dict[str, float]:
    return {key: total / count for key, (total, count) in sums.items()}


def _cpu_copy(model: nn.Module) -> dict:
    return {k: v.detach().to("cpu", copy=True) for k, v in model.state_dict().items()}


def _loss_terms(model: nn.Module, batch: dict, compute=None) -> dict[str, torch.Tensor]:
    """``model.loss(batch)`` (or ``compute(batch)``), checked: a dict with ``"loss"``, of scalar
    tensors."""
    terms, name = (compute or model.loss)(batch), type(model).__name__
    if not isinstance(terms, dict) or "loss" not in terms:
        got = sorted(terms) if isinstance(terms, dict) else type(terms).__name__
        raise TypeError(f"{name}.loss(batch) must return a dict with the key 'loss', got {got}")
    for key, value in terms.items():
        if not torch.is_tensor(value) or value.numel() != 1:
            got = tuple(value.shape) if torch.is_tensor(value) else type(value).__name__
            raise ValueError(f"{name}.loss(batch)[{key!r}] must be a scalar tensor, got {got}")
    if torch.is_grad_enabled() and not terms["loss"].requires_grad:
        raise ValueError(f"{name}.loss(batch)['loss'] does not depend on any trainable parameter")
    return terms


def _check_model(model) -> None:
    if not isinstance(model, nn.Module) or not callable(getattr(model, "loss", None)):
        raise TypeError(f"{type(model).__name__} is no nn.Module with loss(batch) -> dict")
    config = getattr(model, "config", None)
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(
            f"{type(model).__name__}.config must be an instance of the model's config "
            f"dataclass, got {type(config).__name__}"
        )


def _check_judge(judge, config: TrainConfig) -> None:
    if judge is None and config.judged_epochs:
        raise ValueError(
            f"TrainConfig.judged_epochs={config.judged_epochs} needs a judge: pass judge=, or "
            "set judged_epochs=0"
        )
    if judge is not None and not config.judged_epochs:
        raise ValueError("a judge needs TrainConfig.judged_epochs > 0 epochs to judge")
    if judge is not None and not (
        callable(judge) and isinstance(getattr(judge, "identity", None), dict)
    ):
        raise TypeError(
            f"a judge must be callable, judge(model) -> float, with an identity dict; got "
            f"{type(judge).__name__}"
        )


def _identity(model: nn.Module, config: TrainConfig, data: str, judge: Judge | None) -> dict:
    train_config = config_to_dict(config)
    if judge is None:  # as in the runs saved before judging existed, which then still match
        del train_config["judged_epochs"]
    identity = {
        "model_class": type(model).__name__,
        "model_config": config_to_dict(model.config),
        "train_config": train_config,
        "data": data,
    }
    if judge is not None:
        identity["judge"] = judge.identity
    return identity


def build_seeded(build: Callable[[Any], nn.Module], config, seed: int) -> nn.Module:
    """``build(config)`` with PyTorch's random draws (the initial weights) seeded by ``seed``
    alone, neither depending on nor disturbing the caller's random state."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return build(config)


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
    judge: Judge | None = None,
    progress: bool = True,
) -> tuple[nn.Module, History]:
    """The model trained on this data with these configs: loaded if cached, else trained.

    The run lives in ``cache_dir/<ModelName>-<hash>/``, the hash covering the model class and
    config, the training config (not its device or workers), the data, the run format's version
    and the code that trains it (:func:`~gesturelib.checkpoints.code_fingerprint`), so another
    notebook asking for the same gets the same files, and changed code trains afresh beside the
    old files instead of reusing a run it would not make. A finished run loads at once from its
    ``best.pt``; an interrupted one resumes from ``last.pt``; a missing one is trained from
    initial weights drawn with ``train_config.seed``.

    Args:
        model_class: follows the model protocol; built as ``model_class(model_config)``.
        model_config, train_data, val_data, train_config, normaliser: as for :func:`train`.
        cache_dir: the folder of cached runs.
        build: makes the untrained model from ``model_config`` where ``model_class(config)`` is
            not enough: a model that holds another, already trained one, e.g.
            ``lambda config: Aud2Repr2Pose.from_autoencoder(denoiser, config)``. The hash then
            also covers the built model's weights, so that a retrained inner model never brings
            back a run trained around the old one.
        judge: as for :func:`train`; its ``identity`` joins the hash.
        data_fingerprint: identifies the data; by default
            :func:`~gesturelib.checkpoints.dataset_fingerprint` of both datasets.
        progress: show the progress bar while training, or a line naming the file loaded.
    Returns:
        ``(model, history)``: the model with its best weights, on ``train_config.device``, in
        eval mode, and how its training went.
    """
    _check_judge(judge, train_config)
    model = build_seeded(build or model_class, model_config, train_config.seed)
    if not isinstance(model, model_class):
        raise TypeError(f"build must return a {model_class.__name__}, got {type(model).__name__}")
    fingerprint = data_fingerprint or dataset_fingerprint(train_data, val_data)
    if build is not None:
        fingerprint = run_key({"data": fingerprint, "initial_state": state_fingerprint(model)})
    identity = _identity(model, train_config, fingerprint, judge)
    key_config = {k: v for k, v in identity["train_config"].items() if k not in EXECUTION_FIELDS}
    key = run_key(
        {
            **identity,
            "train_config": key_config,
            "version": VERSION,
            "code": code_fingerprint(
                *_TRAINING_CODE,
                model_class.__module__,
                *([] if judge is None else [type(judge).__module__]),
            ),
        }
    )
    folder = Path(cache_dir) / f"{model_class.__name__}-{key}"
    folder.mkdir(parents=True, exist_ok=True)
    # Another process asking for the same model at once (a second notebook, a test worker)
    # waits for the first to train it, then loads it.
    with exclusive(folder / ".cache.lock", wait_for=f"training {folder}"):
        best = RunFolder(folder, identity).best
        if best.exists():
            checkpoint = read_checkpoint(best, kind="best")
            RunFolder(folder, identity).check(
                checkpoint, best, EXECUTION_FIELDS, advice="Delete it to retrain."
            )
            history = History.from_dict(checkpoint["history"])
            if history.stopped_early or checkpoint["epochs_done"] >= train_config.epochs:
                load_state(model, checkpoint["model"], best)
                if progress:
                    print(f"Loaded {best} (epoch {history.best_epoch} of {history.epochs})")
                return model.to(device(train_config.device)).eval(), history
        history = train(
            model,
            train_data,
            val_data,
            train_config,
            folder,
            normaliser=normaliser,
            progress=progress,
            data_fingerprint=fingerprint,
            judge=judge,
        )
        return model.eval(), history
