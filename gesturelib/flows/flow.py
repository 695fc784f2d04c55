"""Glow steps chained into a complete, optionally conditional, normalising flow.

One :class:`FlowStep` is Glow's step: ActNorm -> invertible linear -> coupling (in the data ->
noise direction). A :class:`Flow` chains ``K`` steps and a base distribution:

    forward:  x --step 1--> ... --step K--> z,   log p(x | c) = log p_Z(z) + sum_k logdet_k
    inverse:  z --step K^-1--> ... --step 1^-1--> x    (sampling)

Conventions (shared with :class:`~gesturelib.flows.RecurrentFlow`):

* ``forward(x, cond) -> (z, logdet)`` maps data to noise, ``logdet = log|det dz/dx|``;
  ``inverse(z, cond) -> (x, logdet)`` maps noise to data, ``logdet = log|det dx/dz|``, the
  negative of the forward log-determinant at that ``x``; so ``log p(x) = log p_Z(z) - logdet``.
* Vectors are ``(B, D)`` with conditions ``(B, C)``; sequences ``(B, T, D)`` with ``(B, T, C)``,
  whose frames this flow treats independently. Log-determinants and log-probabilities are per
  sample, ``(B,)``: for a sequence, summed over its ``T`` frames.
* The public methods of :class:`Flow` check their inputs (shapes, dtype, finite values) once; the
  layers inside trust them.

Use :func:`glow` to build a flow in one call.
"""

from __future__ import annotations

import contextlib
import numbers
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from gesturelib.flows.actnorm import ActNorm
from gesturelib.flows.base import StandardNormal, StudentT
from gesturelib.flows.checks import check_input, check_sizes, sum_per_sample
from gesturelib.flows.coupling import AdditiveCoupling, AffineCoupling
from gesturelib.flows.linear import InvertibleLinear

COUPLINGS = {"affine": AffineCoupling, "additive": AdditiveCoupling}


class UninitialisedFlowError(RuntimeError):
    """A flow was inverted or sampled before its ActNorm layers had seen any data."""


class FlowStep(nn.Module):
    """One Glow step: ActNorm -> invertible linear -> coupling (data -> noise).

    Args:
        dim: number of features ``D`` (at least 2).
        cond_dim: number of condition features ``C`` (0 for none).
        hidden: width of the coupling's MLP conditioner.
        coupling: ``"affine"`` or ``"additive"``.
        linear_init: the linear layer's start, ``"rotation"`` or ``"reverse"``
            (:mod:`gesturelib.flows.linear`).
        generator: torch generator for the linear layer's initial rotation.
    """

    def __init__(
        self,
        dim: int,
        cond_dim: int = 0,
        hidden: int = 64,
        *,
        coupling: str = "affine",
        linear_init: str = "rotation",
        generator: torch.Generator | None = None,
    ):
        super().__init__()
        if coupling not in COUPLINGS:
            raise ValueError(f"unknown coupling {coupling!r}; choose one of {sorted(COUPLINGS)}")
        self.actnorm = ActNorm(dim)
        self.linear = InvertibleLinear(dim, generator=generator, init=linear_init)
        self.coupling = COUPLINGS[coupling](dim, cond_dim, hidden)
        self.fixed = None  # set only inside Flow.fixed_weights()

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None):
        """Data -> noise: ``(y, logdet (B,))``, the three layers' log-determinants summed."""
        x, logdet_actnorm = self.actnorm(x)
        x, logdet_linear = self.linear(x)
        x, logdet_coupling = self.coupling(x, cond)
        return x, logdet_actnorm + logdet_linear + logdet_coupling

    def inverse(self, z: torch.Tensor, cond: torch.Tensor | None = None):
        """Noise -> data: coupling^-1, linear^-1, ActNorm^-1; ``(x, logdet (B,))``."""
        z, logdet_coupling = self.coupling.inverse(z, cond)
        z, logdet = invert_linear_and_actnorm(self, z)
        return z, logdet + logdet_coupling


def invert_linear_and_actnorm(
    step: nn.Module, z: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """A step's linear^-1 then ActNorm^-1 (noise -> data): ``(x, logdet (B,))``.

    Inside :meth:`FlowBase.fixed_weights` the two are one affine map, computed once: frame-by-frame
    sampling calls this for every step of every frame.
    """
    if step.fixed is None:
        z, logdet_linear = step.linear.inverse(z)
        z, logdet_actnorm = step.actnorm.inverse(z)
        return z, logdet_linear + logdet_actnorm
    matrix, bias, logdet = step.fixed
    frames = z.shape[1] if z.dim() == 3 else 1
    return F.linear(z, matrix, bias), (frames * logdet).expand(z.shape[0])


class FlowBase(nn.Module):
    """What :class:`Flow` and :class:`~gesturelib.flows.RecurrentFlow` share: the steps, the
    base distribution, the checks at their entry points and :meth:`fixed_weights`."""

    #: whether inputs must be sequences ``(B, T, D)``
    sequences_only = False

    def __init__(self, steps: Sequence[nn.Module], base: nn.Module):
        super().__init__()
        dims = {(step.coupling.dim, step.coupling.cond_dim) for step in steps}
        if len(dims) != 1 or base.dim != steps[0].coupling.dim:
            raise ValueError(f"the steps and the base must share (dim, cond_dim); got {dims}")
        self.steps = nn.ModuleList(steps)
        self.base = base

    @property
    def dim(self) -> int:
        """``D``, the number of data features (per frame)."""
        return self.steps[0].coupling.dim

    @property
    def cond_dim(self) -> int:
        """``C``, the number of condition features (0 for an unconditional flow)."""
        return self.steps[0].coupling.cond_dim

    def check(self, x, cond, name: str = "x") -> None:
        """Raise a clear error unless ``x`` and ``cond`` fit this flow (see :mod:`.checks`)."""
        dtype = self.steps[0].actnorm.loc.dtype
        sizes = {"dim": self.dim, "cond_dim": self.cond_dim}
        check_input(x, cond, **sizes, dtype=dtype, name=name, sequence=self.sequences_only)

    def check_initialised(self) -> None:
        """Raise :class:`UninitialisedFlowError` if an ActNorm layer has not seen data yet."""
        if not all(bool(step.actnorm.initialized) for step in self.steps):
            raise UninitialisedFlowError(
                "this flow has not seen any data: its ActNorm layers initialise from the first "
                "batch given to forward() or log_prob(). Train it (or load trained weights) "
                "before inverting or sampling."
            )

    def noise(self, shape: tuple[int, ...], temperature: float, generator) -> torch.Tensor:
        """A draw of the base, ``temperature`` times, ``(*shape, D)``, on the flow's device."""
        parameter = self.steps[0].actnorm.loc
        return self.base.sample(shape, temperature, generator, parameter.device, parameter.dtype)

    @contextlib.contextmanager
    def fixed_weights(self):
        """Within ``with flow.fixed_weights():`` no gradients are taken and the weights must not
        change, so each step's linear^-1 and ActNorm^-1 are computed once, as one affine map
        ``x = diag(exp(-s)) W^-1 y + loc``: what frame-by-frame sampling needs to be fast.
        Outside it, every call recomputes them from the weights."""
        with torch.no_grad():
            for step in self.steps:
                scale = torch.exp(-step.actnorm.log_scale)
                logdet = -(step.actnorm.log_scale.sum() + step.linear.log_abs_det())
                step.fixed = (
                    scale[:, None] * step.linear.inverse_matrix(),
                    step.actnorm.loc,
                    logdet,
                )
            try:
                yield self
            finally:
                for step in self.steps:
                    step.fixed = None


class Flow(FlowBase):
    """A normalising flow: ``K`` feed-forward steps and a base distribution.

    Direction: :meth:`forward` maps data to noise, :meth:`inverse` noise to data. See the module
    docstring for shapes and log-determinants.

    Args:
        steps: :class:`FlowStep` s, all with the same ``dim`` and ``cond_dim``, applied in order
            by :meth:`forward`.
        base: base distribution (:mod:`gesturelib.flows.base`) over ``dim`` features.
    """

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None):
        """Data -> noise. ``x`` ``(B, D)`` or ``(B, T, D)``, finite; ``cond`` matching, or None.

        Returns:
            ``(z, logdet)``: ``z`` of the shape of ``x``; ``logdet`` ``(B,)`` = log|det dz/dx|.
        """
        self.check(x, cond)
        logdet = x.new_zeros(x.shape[0])
        for step in self.steps:
            x, step_logdet = step(x, cond)
            logdet = logdet + step_logdet
        return x, logdet

    def inverse(self, z: torch.Tensor, cond: torch.Tensor | None = None):
        """Noise -> data. Arguments as :meth:`forward`, with ``z`` in place of ``x``.

        Returns:
            ``(x, logdet)`` with ``logdet`` ``(B,)`` = log|det dx/dz|.
        """
        self.check(z, cond, name="z")
        self.check_initialised()
        logdet = z.new_zeros(z.shape[0])
        for step in reversed(self.steps):
            z, step_logdet = step.inverse(z, cond)
            logdet = logdet + step_logdet
        return z, logdet

    def log_prob(self, x: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        """``log p(x | cond)`` per sample ``(B,)``, summed over frames for sequences."""
        z, logdet = self(x, cond)
        return sum_per_sample(self.base.log_prob(z)) + logdet

    def sample(
        self,
        n_or_shape: int | Sequence[int] | None = None,
        cond: torch.Tensor | None = None,
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """Draw ``x = inverse(temperature * eps)``, ``eps`` from the base (noise -> data).

        Args:
            n_or_shape: ``n`` (gives ``(n, D)``) or a batch shape ``(B,)`` / ``(B, T)``; may be
                omitted when ``cond`` is given (its leading shape is used).
            cond: ``(B, C)`` or ``(B, T, C)``; None for an unconditional flow.
            temperature: scales the base sample; 0 gives ``inverse(0)``, deterministically.
            generator: torch generator for the base sample.
        Returns:
            ``x`` ``(B, D)`` or ``(B, T, D)``.
        """
        if n_or_shape is None and cond is None:
            raise ValueError("give the number of samples n, a batch shape (B,) or (B, T), or cond")
        shape = tuple(cond.shape[:-1]) if cond is not None else None
        if n_or_shape is not None:
            wanted = (n_or_shape,) if isinstance(n_or_shape, numbers.Integral) else n_or_shape
            if not (
                isinstance(wanted, Sequence)
                and len(wanted) in (1, 2)
                and all(isinstance(n, numbers.Integral) and n >= 1 for n in wanted)
                and (shape is None or tuple(wanted) == shape)
            ):
                raise ValueError(
                    f"the sample shape must be a positive count n, (B,) or (B, T), matching "
                    f"cond's leading shape {shape}; got {n_or_shape!r}"
                )
            shape = tuple(int(n) for n in wanted)
        return self.inverse(self.noise(shape, temperature, generator), cond)[0]


def glow(
    dim: int,
    steps: int,
    hidden: int,
    cond_dim: int = 0,
    *,
    coupling: str = "affine",
    df: float | None = None,
    linear_init: str | None = None,
    seed: int = 0,
) -> Flow:
    """Build a Glow-style flow of ``steps`` x (ActNorm -> invertible linear -> coupling).

    Args:
        dim: number of data features ``D`` (at least 2).
        steps: number of steps ``K``.
        hidden: width of each coupling's MLP conditioner.
        cond_dim: number of condition features ``C`` (0: unconditional).
        coupling: ``"affine"`` or ``"additive"``.
        df: None for a standard normal base; a number for a Student's t base with ``df`` degrees
            of freedom.
        linear_init: the start of the linear layers; None chooses ``"reverse"`` (the swap of the
            two coordinates) in two dimensions and ``"rotation"`` otherwise
            (:mod:`gesturelib.flows.linear` says why).
        seed: seeds every initial weight, so the same arguments build the same flow. The global
            random state is left untouched.
    Returns:
        The :class:`Flow`.
    """
    check_sizes(dim=dim, steps=steps, hidden=hidden, cond_dim=cond_dim)
    linear_init = linear_init or ("reverse" if dim == 2 else "rotation")
    base = StandardNormal(dim) if df is None else StudentT(dim, df)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        layers = [
            FlowStep(dim, cond_dim, hidden, coupling=coupling, linear_init=linear_init)
            for _ in range(steps)
        ]
    return Flow(layers, base)
