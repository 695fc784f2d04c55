"""Glow steps chained into a complete, optionally conditional and recurrent, normalising flow.

One :class:`FlowStep` is Glow's step: ActNorm -> invertible linear -> coupling (in the data ->
noise direction). A :class:`Flow` chains ``K`` steps and a base distribution:

    forward:  x --step 1--> ... --step K--> z,   log p(x | c) = log p_Z(z) + sum_k logdet_k
    inverse:  z --step K^-1--> ... --step 1^-1--> x    (sampling)

Conventions (shared with every module of :mod:`gesturelib.flows`):

* ``forward(x, cond) -> (z, logdet)`` maps data to noise, ``logdet = log|det dz/dx|``;
  ``inverse(z, cond) -> (x, logdet)`` maps noise to data, ``logdet = log|det dx/dz|``, the
  negative of the forward log-determinant at that ``x``; so ``log p(x) = log p_Z(z) - logdet``.
* Vectors are ``(B, D)`` with conditions ``(B, C)``; sequences ``(B, T, D)`` with ``(B, T, C)``.
  Log-determinants and log-probabilities are per sample, ``(B,)``: for a sequence they are summed
  over its ``T`` frames (the log-likelihood of the whole sequence).
* ActNorm and the linear layer act on each frame alone. A feed-forward (MLP) flow accepts vectors
  or sequences and treats frames independently.
* With recurrent (LSTM/GRU) conditioners the flow models sequences ``(B, T, D)`` only, and every
  method takes a ``state`` and returns the new state as its *last* output. The state is a tuple
  with one entry per step (see :data:`FlowState`); ``state=None`` means "start of the sequence"
  (zeros). The modules hold no state themselves, so a whole sequence at once (teacher-forced
  training) and one frame at a time (autoregressive sampling) give the same result::

      z, logdet, state = flow(x, cond)                       # x (B, T, D), cond (B, T, C)
      state = None                                           # sampling frame by frame:
      for t in range(T):
          x_t, state = flow.sample(cond=cond[:, t : t + 1], state=state)    # x_t (B, 1, D)

Use :func:`glow` to build a flow in one call.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from gesturelib.flows.actnorm import ActNorm
from gesturelib.flows.base import BASES
from gesturelib.flows.checks import (
    check_cond,
    check_features,
    check_finite,
    sum_per_sample,
)
from gesturelib.flows.conditioners import ConditionerState
from gesturelib.flows.coupling import COUPLINGS
from gesturelib.flows.linear import InvertibleLinear

#: A flow's recurrent state: one :data:`ConditionerState` per step (None for feed-forward steps).
FlowState = tuple[ConditionerState, ...]


class FlowStep(nn.Module):
    """One Glow step: ActNorm -> invertible linear -> coupling (data -> noise).

    Args:
        dim: number of features ``D`` (at least 2).
        cond_dim: number of condition features ``C`` (0 for none).
        hidden: width of the coupling's conditioner.
        conditioner: ``"mlp"``, ``"lstm"``, ``"gru"`` or a conditioner module.
        coupling: ``"affine"`` or ``"additive"``.
        lu: LU-decomposed linear layer (True) or a plain matrix (False).
        num_layers: hidden layers of the MLP, or stacked recurrent layers.
        clamp: bound of the affine coupling's log-scale (default 2.0); affine only.
        generator: torch generator for the linear layer's initial rotation.
        linear_init: ``"rotation"`` (random, default) or ``"reverse"``: the linear layer's initial
            matrix (see :mod:`gesturelib.flows.linear`).
    """

    def __init__(
        self,
        dim: int,
        cond_dim: int = 0,
        hidden: int = 64,
        conditioner: str | nn.Module = "mlp",
        *,
        coupling: str = "affine",
        lu: bool = True,
        num_layers: int = 2,
        clamp: float | None = None,
        generator: torch.Generator | None = None,
        linear_init: str = "rotation",
    ):
        super().__init__()
        if coupling not in COUPLINGS:
            raise ValueError(f"unknown coupling {coupling!r}; choose one of {sorted(COUPLINGS)}")
        if coupling != "affine" and clamp is not None:
            raise ValueError(
                f"clamp bounds the scale of an affine coupling; a {coupling} coupling has none"
            )
        options = {"clamp": clamp} if clamp is not None else {}
        self.actnorm = ActNorm(dim)
        self.linear = InvertibleLinear(dim, lu=lu, generator=generator, init=linear_init)
        self.coupling = COUPLINGS[coupling](
            dim, cond_dim, hidden, conditioner, num_layers, **options
        )

    @property
    def dim(self) -> int:
        return self.coupling.dim

    @property
    def cond_dim(self) -> int:
        return self.coupling.cond_dim

    @property
    def recurrent(self) -> bool:
        return self.coupling.recurrent

    def initial_state(self, batch_size: int, device=None, dtype=None) -> ConditionerState:
        """The zero state of the coupling's conditioner (None if it is feed-forward)."""
        if not self.recurrent:
            return None
        return self.coupling.conditioner.initial_state(batch_size, device=device, dtype=dtype)

    def forward(
        self, x: torch.Tensor, cond: torch.Tensor | None = None, state: ConditionerState = None
    ):
        """Data -> noise. Arguments and outputs as :meth:`AffineCoupling.forward
        <gesturelib.flows.coupling.AffineCoupling.forward>`: ``(z, logdet)``, plus the new
        ``state`` for a recurrent conditioner; ``logdet`` ``(B,)`` sums the three layers."""
        y, logdet, state = self._run(x, cond, state, inverse=False)
        return (y, logdet, state) if self.recurrent else (y, logdet)

    def inverse(
        self, z: torch.Tensor, cond: torch.Tensor | None = None, state: ConditionerState = None
    ):
        """Noise -> data: coupling^-1, then linear^-1, then ActNorm^-1; ``logdet`` is
        log|det dx/dz|."""
        x, logdet, state = self._run(z, cond, state, inverse=True)
        return (x, logdet, state) if self.recurrent else (x, logdet)

    def _run(self, x, cond, state, inverse: bool):
        """Both directions, always returning ``(y, logdet, state)``; used by :class:`Flow`."""
        if inverse:
            x, logdet_coupling, state = self.coupling._run(x, cond, state, inverse=True)
            x, logdet_linear = self.linear.inverse(x)
            x, logdet_actnorm = self.actnorm.inverse(x)
        else:
            x, logdet_actnorm = self.actnorm(x)
            x, logdet_linear = self.linear(x)
            x, logdet_coupling, state = self.coupling._run(x, cond, state, inverse=False)
        return x, logdet_actnorm + logdet_linear + logdet_coupling, state


class Flow(nn.Module):
    """A normalising flow: ``K`` steps and a base distribution, optionally conditional/recurrent.

    Direction: :meth:`forward` maps data to noise, :meth:`inverse` noise to data. See the module
    docstring for shapes, log-determinants and the recurrent state.

    Args:
        steps: the steps, all with the same ``dim`` and ``cond_dim``, applied in order by
            :meth:`forward`.
        base: base distribution with ``dim``, ``log_prob`` and ``sample`` (see
            :mod:`gesturelib.flows.base`).
    """

    def __init__(self, steps: Sequence[FlowStep], base: nn.Module):
        super().__init__()
        if len(steps) == 0:
            raise ValueError("a flow needs at least one step")
        sizes = {(step.dim, step.cond_dim) for step in steps}
        if len(sizes) != 1:
            raise ValueError(f"all steps must share (dim, cond_dim); got {sorted(sizes)}")
        if base.dim != steps[0].dim:
            raise ValueError(
                f"the base distribution has dim={base.dim}, the steps dim={steps[0].dim}"
            )
        self.steps = nn.ModuleList(steps)
        self.base = base

    @property
    def dim(self) -> int:
        """``D``, the number of data features (per frame)."""
        return self.steps[0].dim

    @property
    def cond_dim(self) -> int:
        """``C``, the number of condition features (0 for an unconditional flow)."""
        return self.steps[0].cond_dim

    @property
    def recurrent(self) -> bool:
        """True if any step has a recurrent conditioner: sequences only, state in and out."""
        return any(step.recurrent for step in self.steps)

    def initial_state(self, batch_size: int, device=None, dtype=None) -> FlowState:
        """The zero state (what ``state=None`` stands for): one entry per step."""
        return tuple(
            step.initial_state(batch_size, device=device, dtype=dtype) for step in self.steps
        )

    def forward(
        self, x: torch.Tensor, cond: torch.Tensor | None = None, state: FlowState | None = None
    ):
        """Data -> noise.

        Args:
            x: ``(B, D)`` or ``(B, T, D)`` (``(B, T, D)`` only for a recurrent flow); must be finite.
            cond: ``(B, C)`` or ``(B, T, C)`` matching ``x``; None for an unconditional flow.
            state: recurrent flows only: the state after the previous frame, None at the start.
        Returns:
            ``(z, logdet)``, or ``(z, logdet, state)`` for a recurrent flow: ``z`` of the shape of
            ``x``, ``logdet`` ``(B,)`` = log|det dz/dx| summed over frames, and the state after
            the last frame.
        """
        self._check_call(x, cond, state, name="x", finite=True)
        return self._outputs(*self._run(x, cond, state, inverse=False))

    def inverse(
        self, z: torch.Tensor, cond: torch.Tensor | None = None, state: FlowState | None = None
    ):
        """Noise -> data.

        Args: as :meth:`forward`, with ``z`` in place of ``x``.
        Returns:
            ``(x, logdet)``, or ``(x, logdet, state)`` for a recurrent flow, with ``logdet`` ``(B,)``
            = log|det dx/dz| summed over frames (so ``log p(x) = log p_Z(z) - logdet``).
        """
        self._check_call(z, cond, state, name="z")
        return self._outputs(*self._run(z, cond, state, inverse=True))

    def log_prob(
        self, x: torch.Tensor, cond: torch.Tensor | None = None, state: FlowState | None = None
    ):
        """``log p(x | cond)`` per sample, summed over frames for sequences.

        Args: as :meth:`forward`. A non-finite ``x`` or ``cond`` raises ``ValueError``.
        Returns:
            ``log_prob`` ``(B,)``, or ``(log_prob, state)`` for a recurrent flow.
        """
        self._check_call(x, cond, state, name="x", finite=True)
        z, logdet, state = self._run(x, cond, state, inverse=False)
        log_prob = sum_per_sample(self.base.log_prob(z)) + logdet
        return (log_prob, state) if self.recurrent else log_prob

    def sample(
        self,
        n_or_shape: int | Sequence[int] | None = None,
        cond: torch.Tensor | None = None,
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        state: FlowState | None = None,
    ):
        """Draw ``x = inverse(temperature * eps)``, ``eps`` from the base (noise -> data).

        Args:
            n_or_shape: ``n`` (gives ``(n, D)``), or the batch shape ``(B,)`` / ``(B, T)``. May be
                omitted when ``cond`` is given (its leading shape is used); a recurrent flow needs
                ``(B, T)``.
            cond: ``(B, C)`` or ``(B, T, C)``; None for an unconditional flow.
            temperature: multiplies the base sample's standard deviation; 0 gives the mode of the
                base pushed through the flow (``z = 0``), deterministically.
            generator: torch generator for the base sample.
            state: recurrent flows only: the state after the previous frame, None at the start.
        Returns:
            ``x`` ``(B, D)`` or ``(B, T, D)``, or ``(x, state)`` for a recurrent flow.
        """
        shape = self._sample_shape(n_or_shape, cond)
        parameter = next(self.parameters())
        z = self.base.sample(
            shape, temperature, generator, device=parameter.device, dtype=parameter.dtype
        )
        self._check_call(z, cond, state, name="z")
        x, _, state = self._run(z, cond, state, inverse=True)
        return (x, state) if self.recurrent else x

    def _outputs(self, y, logdet, state):
        return (y, logdet, state) if self.recurrent else (y, logdet)

    def _run(self, x, cond, state, inverse: bool):
        states = list(state) if state is not None else [None] * len(self.steps)
        order = range(len(self.steps) - 1, -1, -1) if inverse else range(len(self.steps))
        logdet = x.new_zeros(x.shape[0])
        for k in order:
            x, step_logdet, states[k] = self.steps[k]._run(x, cond, states[k], inverse)
            logdet = logdet + step_logdet
        return x, logdet, tuple(states)

    def _check_call(self, x, cond, state, name: str, finite: bool = False) -> None:
        check_features(x, self.dim, name=name, sequence=True if self.recurrent else None)
        check_cond(cond, self.cond_dim, x, x_name=name)
        if finite:  # a NaN here would silently turn a training step's loss and weights into NaN
            check_finite(x, name)
            if cond is not None:
                check_finite(cond, "cond")
        dtype = next(self.parameters()).dtype
        for tensor, label in ((x, name), (cond, "cond")):
            if tensor is not None and tensor.dtype != dtype:
                raise TypeError(
                    f"{label} has dtype {tensor.dtype} but the flow's parameters are {dtype}; "
                    "convert one of them (e.g. flow.double() or tensor.float())"
                )
        if state is None:
            return
        if not self.recurrent:
            raise ValueError("this flow has no recurrent conditioner: it takes no state")
        if not isinstance(state, tuple | list) or len(state) != len(self.steps):
            raise ValueError(
                f"state must be a tuple with one entry per step ({len(self.steps)}), as returned "
                f"by the flow or by initial_state(); got {type(state).__name__}"
                + (f" of length {len(state)}" if isinstance(state, tuple | list) else "")
            )

    def _sample_shape(self, n_or_shape, cond) -> tuple[int, ...]:
        if n_or_shape is None and cond is None:
            raise ValueError("give the number of samples n, a batch shape (B,) or (B, T), or cond")
        shape = None
        if n_or_shape is not None:
            shape = (n_or_shape,) if isinstance(n_or_shape, int) else tuple(n_or_shape)
        if cond is not None:
            cond_shape = tuple(cond.shape[:-1])
            if shape is not None and shape != cond_shape:
                raise ValueError(
                    f"the sample shape {shape} does not match cond's leading shape {cond_shape}"
                )
            shape = cond_shape
        allowed = (2,) if self.recurrent else (1, 2)
        if len(shape) not in allowed or not all(isinstance(s, int) and s > 0 for s in shape):
            wanted = "(B, T)" if self.recurrent else "n, (B,) or (B, T)"
            raise ValueError(
                f"{'a recurrent flow samples sequences: ' if self.recurrent else ''}"
                f"the sample shape must be {wanted} with positive sizes, got {shape}"
            )
        return shape


def glow(
    dim: int,
    steps: int,
    hidden: int,
    cond_dim: int = 0,
    conditioner: str = "mlp",
    *,
    coupling: str = "affine",
    lu: bool = True,
    linear_init: str = "rotation",
    num_layers: int = 2,
    clamp: float | None = None,
    base: str = "normal",
    df: float | None = None,
    seed: int = 0,
) -> Flow:
    """Build a Glow-style flow of ``steps`` x (ActNorm -> invertible linear -> coupling).

    Args:
        dim: number of data features ``D`` (at least 2).
        steps: number of steps ``K``.
        hidden: width of each coupling's conditioner (MLP hidden layers or recurrent state).
        cond_dim: number of condition features ``C`` (0: unconditional).
        conditioner: ``"mlp"`` (frames independent), ``"lstm"`` (MoGlow) or ``"gru"``
            (Ye et al.); recurrent conditioners make a flow over sequences ``(B, T, D)``.
        coupling: ``"affine"`` or ``"additive"``.
        lu: LU-decomposed (True) or plain (False) invertible linear layers.
        linear_init: ``"rotation"`` (random, Glow's choice and the default) or ``"reverse"``
            (alternating halves, as RealNVP; how the two compare in 2D is in
            :mod:`gesturelib.flows.linear`).
        num_layers: hidden layers of each MLP, or stacked layers of each LSTM/GRU.
        clamp: bound of the affine log-scale (default 2.0, see :mod:`gesturelib.flows.coupling`).
        base: ``"normal"`` (N(0, I)) or ``"student_t"`` (multivariate Student's t, needs ``df``).
        df: degrees of freedom of the Student's t base.
        seed: seeds every initial weight, so the same arguments build the same flow. The global
            random state is left untouched.
    Returns:
        The :class:`Flow`.
    """
    if steps < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    if base not in BASES:
        raise ValueError(f"unknown base {base!r}; choose one of {sorted(BASES)}")
    if (base == "student_t") != (df is not None):
        raise ValueError(
            "df (degrees of freedom) must be given for base='student_t', and only for it"
        )
    base_distribution = BASES[base](dim, df) if df is not None else BASES[base](dim)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        flow_steps = [
            FlowStep(
                dim,
                cond_dim,
                hidden,
                conditioner,
                coupling=coupling,
                lu=lu,
                num_layers=num_layers,
                clamp=clamp,
                linear_init=linear_init,
            )
            for _ in range(steps)
        ]
    return Flow(flow_steps, base_distribution)
