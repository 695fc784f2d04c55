"""Input validation shared by the flow modules.

Every check raises a ``ValueError`` (or ``TypeError``) that names the argument, the shape that
was expected and the shape that was given, e.g.
``x must have shape (B, D) = (B, 54) or (B, T, D) = (B, T, 54), got (8, 53)``, so that a mistake
is reported where it is made and not as a matrix-size error deep inside torch.

Shapes used throughout :mod:`gesturelib.flows`: a batch of vectors is ``(B, D)``, a batch of
sequences is ``(B, T, D)`` (batch first); a condition has the same leading shape and ``C``
features, ``(B, C)`` or ``(B, T, C)``.
"""

from __future__ import annotations

import torch


def expected_shape(features: int, letter: str, sequence: bool | None) -> str:
    """Describe an expected shape, e.g. ``(B, T, D) = (B, T, 54)``.

    Args:
        features: size of the last axis.
        letter: its name, ``"D"`` for data or ``"C"`` for a condition.
        sequence: True for ``(B, T, .)`` only, False for ``(B, .)`` only, None for either.
    """
    vector = f"(B, {letter}) = (B, {features})"
    seq = f"(B, T, {letter}) = (B, T, {features})"
    return {True: seq, False: vector, None: f"{vector} or {seq}"}[sequence]


def check_features(x, dim: int, name: str = "x", sequence: bool | None = None) -> None:
    """Raise unless ``x`` is a tensor of shape ``(B, dim)`` or ``(B, T, dim)``.

    Args:
        x: the tensor to check.
        dim: the number of features expected on the last axis.
        name: the argument's name, for the message.
        sequence: True requires ``(B, T, dim)``, False requires ``(B, dim)``, None allows both.
    """
    if not isinstance(x, torch.Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    allowed_ndims = {True: (3,), False: (2,), None: (2, 3)}[sequence]
    if x.dim() not in allowed_ndims or x.shape[-1] != dim:
        raise ValueError(
            f"{name} must have shape {expected_shape(dim, 'D', sequence)}, got {tuple(x.shape)}"
        )


def check_cond(cond, cond_dim: int, x: torch.Tensor, x_name: str = "x") -> None:
    """Raise unless ``cond`` suits a module with ``cond_dim`` condition features and input ``x``.

    An unconditional module (``cond_dim == 0``) must get ``cond=None``; a conditional one must get
    a tensor whose leading shape is that of ``x``: ``(B, C)`` for ``x (B, D)``, ``(B, T, C)`` for
    ``x (B, T, D)``.
    """
    if cond_dim == 0:
        if cond is not None:
            raise ValueError(
                "this module is unconditional (cond_dim=0) but cond was given; build it with "
                "cond_dim=C to condition on a (B, C) or (B, T, C) tensor, or pass cond=None"
            )
        return
    letters = "(B, C)" if x.dim() == 2 else "(B, T, C)"
    wanted = (*x.shape[:-1], cond_dim)
    if cond is None:
        raise ValueError(
            f"this module is conditional (cond_dim={cond_dim}): pass cond of shape "
            f"{letters} = {wanted}"
        )
    if not isinstance(cond, torch.Tensor):
        raise TypeError(f"cond must be a torch.Tensor, got {type(cond).__name__}")
    if tuple(cond.shape) != wanted:
        raise ValueError(
            f"cond must have shape {letters} = {wanted} to match {x_name} of shape "
            f"{tuple(x.shape)}, got {tuple(cond.shape)}"
        )


def check_finite(x: torch.Tensor, name: str) -> None:
    """Raise if ``x`` holds NaN or infinity, saying how many entries and in which samples."""
    finite = torch.isfinite(x)
    if not bool(finite.all()):
        bad_samples = (~finite).reshape(x.shape[0], -1).any(dim=1).nonzero().flatten()
        shown = bad_samples[:5].tolist()
        raise ValueError(
            f"{name} contains {int((~finite).sum())} non-finite values (NaN or inf) in "
            f"{len(bad_samples)} of its {x.shape[0]} samples (first: {shown}); "
            "clean or drop them before computing a likelihood"
        )


def frames_per_sample(x: torch.Tensor) -> int:
    """How many frames each sample has: ``T`` for ``(B, T, D)``, 1 for ``(B, D)``."""
    return x.shape[1] if x.dim() == 3 else 1


def sum_per_sample(values: torch.Tensor) -> torch.Tensor:
    """Sum every axis but the first: ``(B, ...)`` -> ``(B,)``."""
    return values.reshape(values.shape[0], -1).sum(dim=1)
