"""A flow over sequences whose couplings remember: the flow inside MoGlow and the Flow-VAE.

A :class:`RecurrentFlow` is a :class:`~gesturelib.flows.Flow` whose couplings have LSTM or GRU
conditioners (:class:`~gesturelib.flows.RecurrentCoupling`). It models sequences ``(B, T, D)``:
the flow at frame ``t`` depends on the frames before it through the recurrent state, so
``log p(x_{1:T} | c) = sum_t log p(x_t | x_{<t}, c_{<=t})`` exactly.

Every method takes the ``state`` after the previous frame (None: the start of a sequence) and
returns the new state as its last output; the state is a tuple with one entry per step. The
modules hold no state themselves, so a whole sequence at once (teacher-forced training) and one
frame at a time (autoregressive sampling) give the same result::

    z, logdet, state = flow(x, cond)                        # x (B, T, D), cond (B, T, C)
    state = None                                            # sampling frame by frame:
    with flow.fixed_weights():
        for t in range(T):
            x_t, state = flow.sample(cond[:, t : t + 1], state=state)     # x_t (B, 1, D)
"""

from __future__ import annotations

import torch
from torch import nn

from gesturelib.flows.actnorm import ActNorm
from gesturelib.flows.base import StandardNormal, StudentT
from gesturelib.flows.checks import check_sizes, sum_per_sample
from gesturelib.flows.conditioners import ConditionerState
from gesturelib.flows.coupling import RecurrentCoupling
from gesturelib.flows.flow import FlowBase, invert_linear_and_actnorm
from gesturelib.flows.linear import InvertibleLinear

#: A recurrent flow's state: one :data:`ConditionerState` per step.
FlowState = tuple[ConditionerState, ...]


class RecurrentFlowStep(nn.Module):
    """ActNorm -> invertible linear -> :class:`RecurrentCoupling`, on sequences ``(B, T, D)``.

    Args: as :class:`RecurrentCoupling`, plus ``linear_init`` and ``generator`` for the linear
    layer (as :class:`~gesturelib.flows.FlowStep`).
    """

    def __init__(
        self,
        dim: int,
        cond_dim: int = 0,
        hidden: int = 64,
        *,
        cell: str = "lstm",
        num_layers: int = 1,
        additive: bool = False,
        linear_init: str = "rotation",
        generator: torch.Generator | None = None,
    ):
        super().__init__()
        self.actnorm = ActNorm(dim)
        self.linear = InvertibleLinear(dim, generator=generator, init=linear_init)
        self.coupling = RecurrentCoupling(
            dim, cond_dim, hidden, cell=cell, num_layers=num_layers, additive=additive
        )
        self.fixed = None  # set only inside RecurrentFlow.fixed_weights()

    def forward(self, x, cond=None, state: ConditionerState = None):
        """Data -> noise: ``(y, logdet (B,), state)``."""
        x, logdet_actnorm = self.actnorm(x)
        x, logdet_linear = self.linear(x)
        x, logdet_coupling, state = self.coupling(x, cond, state)
        return x, logdet_actnorm + logdet_linear + logdet_coupling, state

    def inverse(self, z, cond=None, state: ConditionerState = None):
        """Noise -> data: ``(x, logdet (B,), state)``."""
        z, logdet_coupling, state = self.coupling.inverse(z, cond, state)
        z, logdet = invert_linear_and_actnorm(self, z)
        return z, logdet + logdet_coupling, state


class RecurrentFlow(FlowBase):
    """``K`` recurrent steps and a base distribution, over sequences ``(B, T, D)``.

    Direction: :meth:`forward` maps data to noise, :meth:`inverse` noise to data; each takes the
    state after the previous frame and returns the new one (see the module docstring).

    Args:
        steps: :class:`RecurrentFlowStep` s sharing ``dim`` and ``cond_dim``.
        base: base distribution over ``dim`` features.
    """

    sequences_only = True

    def initial_state(self, batch_size: int, device=None, dtype=None) -> FlowState:
        """The zero state (what ``state=None`` stands for): one entry per step."""
        return tuple(
            step.coupling.conditioner.initial_state(batch_size, device, dtype)
            for step in self.steps
        )

    def forward(self, x: torch.Tensor, cond=None, state: FlowState | None = None):
        """Data -> noise. ``x`` ``(B, T, D)``, finite; ``cond`` ``(B, T, C)`` or None.

        Returns:
            ``(z, logdet, state)``: ``logdet`` ``(B,)`` summed over frames, and the state after
            the last frame.
        """
        states = self._states(state)
        self.check(x, cond, state=state)
        logdet = x.new_zeros(x.shape[0])
        for k, step in enumerate(self.steps):
            x, step_logdet, states[k] = step(x, cond, states[k])
            logdet = logdet + step_logdet
        return x, logdet, tuple(states)

    def inverse(self, z: torch.Tensor, cond=None, state: FlowState | None = None):
        """Noise -> data: ``(x, logdet, state)`` with ``logdet`` ``(B,)`` = log|det dx/dz|."""
        states = self._states(state)
        self.check(z, cond, name="z", state=state)
        self.check_initialised()
        logdet = z.new_zeros(z.shape[0])
        for k in reversed(range(len(self.steps))):
            z, step_logdet, states[k] = self.steps[k].inverse(z, cond, states[k])
            logdet = logdet + step_logdet
        return z, logdet, tuple(states)

    def log_prob(self, x: torch.Tensor, cond=None, state: FlowState | None = None):
        """``(log p(x | cond) (B,), state)``, the log-likelihood of each whole sequence."""
        z, logdet, state = self(x, cond, state)
        return sum_per_sample(self.base.log_prob(z)) + logdet, state

    def sample(
        self,
        cond: torch.Tensor | None = None,
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        state: FlowState | None = None,
        shape: tuple[int, int] | None = None,
    ):
        """Draw ``x = inverse(temperature * eps)`` (noise -> data).

        Args:
            cond: ``(B, T, C)``; None for an unconditional flow, which then needs ``shape``.
            temperature: scales the base sample; 0 gives ``inverse(0)``, deterministically.
            generator: torch generator for the base sample.
            state: the state after the previous frame, None at the start.
            shape: ``(B, T)``, only for an unconditional flow.
        Returns:
            ``(x (B, T, D), state)``.
        """
        if (cond is None) == (shape is None):
            raise ValueError("give cond (B, T, C), or shape (B, T) for an unconditional flow")
        shape = tuple(cond.shape[:-1]) if cond is not None else tuple(shape)
        x, _, state = self.inverse(self.noise(shape, temperature, generator), cond, state)
        return x, state

    def _states(self, state: FlowState | None) -> list:
        if state is None:
            return [None] * len(self.steps)
        if not isinstance(state, tuple | list) or len(state) != len(self.steps):
            raise ValueError(
                f"state must be a tuple with one entry per step ({len(self.steps)}), as the "
                "flow returns it or initial_state() makes it"
            )
        return list(state)

    def check(self, x, cond, name: str = "x", state: FlowState | None = None) -> None:
        """:meth:`FlowBase.check`, and a state (if any) of as many sequences as ``x``."""
        super().check(x, cond, name)
        if state is not None:
            first = state[0][0] if isinstance(state[0], tuple | list) else state[0]
            if isinstance(first, torch.Tensor) and first.shape[1] != x.shape[0]:
                raise ValueError(
                    f"the state is of {first.shape[1]} sequences but {name} of {x.shape[0]}: "
                    "carry the state of the same batch, or start afresh with state=None"
                )


def recurrent_glow(
    dim: int,
    steps: int,
    hidden: int,
    cond_dim: int = 0,
    *,
    cell: str = "lstm",
    num_layers: int = 1,
    coupling: str = "affine",
    df: float | None = None,
    seed: int = 0,
) -> RecurrentFlow:
    """Build a :class:`RecurrentFlow` of ``steps`` recurrent Glow steps (MoGlow's flow).

    Args:
        dim, steps, hidden, cond_dim, coupling, df, seed: as :func:`~gesturelib.flows.glow`;
            ``hidden`` is the width of each recurrent state.
        cell: ``"lstm"`` (MoGlow) or ``"gru"`` (Ye et al.).
        num_layers: stacked recurrent layers in each coupling.
    Returns:
        The :class:`RecurrentFlow`.
    """
    check_sizes(dim=dim, steps=steps, hidden=hidden, cond_dim=cond_dim, num_layers=num_layers)
    if coupling not in ("affine", "additive"):
        raise ValueError(f"unknown coupling {coupling!r}; choose 'affine' or 'additive'")
    base = StandardNormal(dim) if df is None else StudentT(dim, df)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        layers = [
            RecurrentFlowStep(
                dim,
                cond_dim,
                hidden,
                cell=cell,
                num_layers=num_layers,
                additive=coupling == "additive",
                linear_init="reverse" if dim == 2 else "rotation",
            )
            for _ in range(steps)
        ]
    return RecurrentFlow(layers, base)
