"""The checks a flow makes where data enters it: shapes, conditions, dtypes, finite values.

Only the public entry points of :class:`~gesturelib.flows.Flow` and
:class:`~gesturelib.flows.RecurrentFlow` call :func:`check_input`; the layers inside trust what it
checked. Every error names the argument, the shape that was expected and the one given, e.g.
``x must have shape (B, D) = (B, 54) or (B, T, D) = (B, T, 54), got (8, 53)``, so that a mistake
is reported where it is made and not as a matrix-size error deep inside torch.
"""

from __future__ import annotations

import numbers

import torch


def _expected(features: int, letter: str, sequence: bool) -> str:
    vector, seq = f"(B, {letter}) = (B, {features})", f"(B, T, {letter}) = (B, T, {features})"
    return seq if sequence else f"{vector} or {seq}"


def check_input(
    x,
    cond,
    *,
    dim: int,
    cond_dim: int,
    dtype: torch.dtype,
    name: str = "x",
    sequence: bool = False,
) -> None:
    """Raise unless ``x`` and ``cond`` fit a flow over ``dim`` features with ``cond_dim``.

    Args:
        x: ``(B, D)`` or ``(B, T, D)`` (only ``(B, T, D)`` if ``sequence``), finite.
        cond: None if ``cond_dim == 0``, else ``(B, C)`` / ``(B, T, C)`` matching ``x``, finite.
        dtype: the flow's parameter dtype, which both must have.
        name: what ``x`` is called in messages (``"x"``, ``"z"``).
    Raises:
        TypeError: for a non-tensor or a dtype other than the flow's.
        ValueError: for a wrong shape, a missing or unexpected condition, NaN or infinity.
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if x.dim() not in ((3,) if sequence else (2, 3)) or x.shape[-1] != dim:
        raise ValueError(
            f"{name} must have shape {_expected(dim, 'D', sequence)}, got {tuple(x.shape)}"
        )
    if cond_dim == 0 and cond is not None:
        raise ValueError(
            "this flow is unconditional (cond_dim=0) but cond was given; build it with "
            "cond_dim=C to condition on a (B, C) or (B, T, C) tensor, or pass cond=None"
        )
    letters = "(B, C)" if x.dim() == 2 else "(B, T, C)"
    wanted = (*x.shape[:-1], cond_dim)
    if cond_dim and cond is None:
        raise ValueError(f"this flow is conditional (cond_dim={cond_dim}): pass cond {wanted}")
    if cond is not None and not isinstance(cond, torch.Tensor):
        raise TypeError(f"cond must be a torch.Tensor, got {type(cond).__name__}")
    if cond is not None and tuple(cond.shape) != wanted:
        raise ValueError(
            f"cond must have shape {letters} = {wanted} to match {name} of shape "
            f"{tuple(x.shape)}, got {tuple(cond.shape)}"
        )
    for tensor, label in ((x, name), (cond, "cond")):
        if tensor is None:
            continue
        if tensor.dtype != dtype:
            raise TypeError(
                f"{label} has dtype {tensor.dtype} but the flow's parameters are {dtype}; "
                "convert one of them (e.g. flow.double() or tensor.float())"
            )
        finite = torch.isfinite(tensor)
        if not bool(finite.all()):
            bad = (~finite).reshape(tensor.shape[0], -1).any(dim=1).nonzero().flatten()
            raise ValueError(
                f"{label} contains {int((~finite).sum())} non-finite values (NaN or inf) in "
                f"{len(bad)} of its {tensor.shape[0]} samples (first: {bad[:5].tolist()}); "
                "clean or drop them first"
            )


def sum_per_sample(values: torch.Tensor) -> torch.Tensor:
    """Sum every axis but the first: ``(B, ...)`` -> ``(B,)``."""
    return values.flatten(1).sum(1) if values.dim() > 1 else values


def check_sizes(**sizes) -> None:
    """Raise unless every size is an integer: ``cond_dim`` >= 0, ``dim`` >= 2, others >= 1."""
    for name, value in sizes.items():
        least = {"cond_dim": 0, "dim": 2}.get(name, 1)
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
            raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
