"""Pieces shared by the model files: checking batches, small layers, eval mode."""

from __future__ import annotations

import contextlib
from collections.abc import Mapping

import torch
from torch import nn


def batch_parts(
    batch: Mapping[str, torch.Tensor], expected: Mapping[str, tuple], owner: str
) -> list[torch.Tensor]:
    """The named parts of a batch, each checked to be a float tensor ``(B, L, *trailing)``.

    Args:
        batch: a dict of tensors as a ``DataLoader`` stacks :class:`gesturelib.data.WindowDataset`
            items. Other keys are ignored.
        expected: part name -> its trailing shape after ``(B, L)``; an int is a required size, a
            string (e.g. ``"tau"``) names a size that may be anything.
        owner: who asks, for the messages (e.g. ``"CVAE.loss"``).
    Returns:
        The tensors, in the order of ``expected``.
    Raises:
        TypeError: if ``batch`` is not a dict or a part is not a floating-point tensor.
        ValueError: naming the part and its expected shape, if it is missing or misshapen, or if
            the parts disagree in ``B`` or ``L``.
    """
    if not isinstance(batch, Mapping):
        raise TypeError(f"{owner}: a batch must be a dict of tensors, got {type(batch).__name__}")
    parts, first = [], None
    for name, trailing in expected.items():
        wanted = "(" + ", ".join(["B", "L", *map(str, trailing)]) + ")"
        if name not in batch:
            raise ValueError(
                f"{owner} needs batch[{name!r}] with shape {wanted}; the batch has only "
                f"{sorted(batch)}"
            )
        part = batch[name]
        if not isinstance(part, torch.Tensor) or not part.is_floating_point():
            got = (
                f"a {part.dtype} tensor" if isinstance(part, torch.Tensor) else type(part).__name__
            )
            raise TypeError(f"{owner}: batch[{name!r}] must be a float tensor {wanted}, got {got}")
        fits = part.ndim == 2 + len(trailing) and all(
            isinstance(size, str) or part.shape[2 + i] == size for i, size in enumerate(trailing)
        )
        if not fits:
            raise ValueError(
                f"{owner}: batch[{name!r}] must have shape {wanted}, got {tuple(part.shape)}"
            )
        if first is None:
            first = (name, tuple(part.shape[:2]))
        elif tuple(part.shape[:2]) != first[1]:
            raise ValueError(
                f"{owner}: batch[{name!r}] has (B, L) = {tuple(part.shape[:2])} but "
                f"batch[{first[0]!r}] has {first[1]}; all parts must cover the same frames"
            )
        parts.append(part)
    return parts


def check_config_type(model: nn.Module, config) -> None:
    """Raise unless ``config`` is an instance of ``model``'s ``config_class``."""
    if not isinstance(config, model.config_class):
        raise TypeError(
            f"{type(model).__name__} needs a {model.config_class.__name__}, got "
            f"{type(config).__name__}"
        )


def mlp(sizes: list[int]) -> nn.Sequential:
    """Linear layers of the given sizes with ReLU between them (none after the last)."""
    layers = []
    for number, (size_in, size_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        if number:
            layers.append(nn.ReLU())
        layers.append(nn.Linear(size_in, size_out))
    return nn.Sequential(*layers)


def first_parameter(module: nn.Module) -> torch.Tensor:
    """A parameter of ``module``: the device and dtype to create new tensors with."""
    return next(module.parameters())


@contextlib.contextmanager
def eval_mode(module: nn.Module):
    """``with eval_mode(model):`` runs in eval mode (no dropout) and restores the mode after."""
    was_training = module.training
    module.eval()
    try:
        yield module
    finally:
        module.train(was_training)
