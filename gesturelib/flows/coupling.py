"""Coupling layers: an invertible map built around an arbitrary neural network.

Split the features of each frame in two, ``x = [x_a, x_b]`` with ``x_a`` the first ``D // 2``.
Keep ``x_a``; transform ``x_b`` elementwise with parameters that a conditioner network computes
from ``x_a`` and the condition:

    affine:    y_b = x_b * exp(s) + t,    (t, raw) = NN([x_a, cond]),  s = soft_clamp(raw)
    additive:  y_b = x_b + t,             t = NN([x_a, cond])

The inverse needs the same parameters, and it has them, because ``x_a`` passes through
unchanged: ``x_b = (y_b - t) * exp(-s)``. The Jacobian is triangular, so
``log|det dy/dx| = sum(s)`` (zero for the additive coupling) however complex the network.

**Scale function.** ``s = c * tanh(raw / c)`` with ``c = clamp`` (2 by default), a soft clamp:

* the zero-initialised last layer gives ``raw = 0``, hence ``s = 0`` and a coupling that starts as
  the exact identity (Glow's ``sigmoid(raw + 2)`` starts at a scale of 0.88 instead);
* the scale can grow or shrink symmetrically (``exp(s)`` in ``[e^-c, e^c]``), where the sigmoid
  only contracts in the data -> noise direction;
* it is bounded, so one coupling cannot blow activations up by more than ``e^c``, which keeps
  training stable and outputs finite for large inputs;
* its slope is 1 at 0, so small scales are learned as fast as with a plain ``exp``.

:class:`AffineCoupling` and :class:`AdditiveCoupling` have an MLP conditioner and act on every
frame alone; :class:`RecurrentCoupling` has an LSTM or GRU conditioner and works on sequences
``(B, T, D)``: the network at frame ``t`` sees ``[x_a, cond]`` of frames ``1..t`` through its state.
The Jacobian over a whole sequence is then block lower-triangular, and its log-determinant is still
the sum of the per-frame ``sum(s)``.
"""

from __future__ import annotations

import torch
from torch import nn

from gesturelib.flows.checks import sum_per_sample
from gesturelib.flows.conditioners import ConditionerState, MLPConditioner, RecurrentConditioner


class _Split(nn.Module):
    """What every coupling shares: the split into halves and the elementwise transform."""

    def __init__(self, dim: int, cond_dim: int, additive: bool, clamp: float):
        super().__init__()
        if dim < 2:
            raise ValueError(
                f"a coupling splits the features in two, so it needs dim >= 2, got {dim}"
            )
        if not clamp > 0:
            raise ValueError(f"clamp must be positive, got {clamp}")
        self.dim, self.cond_dim, self.split = dim, cond_dim, dim // 2
        self.additive, self.clamp = additive, float(clamp)
        self.in_features = self.split + cond_dim
        self.out_features = (1 if additive else 2) * (dim - self.split)

    def log_scale(self, raw: torch.Tensor) -> torch.Tensor:
        """The bounded log-scale ``s = clamp * tanh(raw / clamp)``, in ``(-clamp, clamp)``."""
        return self.clamp * torch.tanh(raw / self.clamp)

    def conditioner_inputs(self, x: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor:
        """``[x_a, cond]`` ``(..., D // 2 + C)``."""
        untouched = x[..., : self.split]
        return untouched if cond is None else torch.cat([untouched, cond], dim=-1)

    def transform(self, x: torch.Tensor, params: torch.Tensor, inverse: bool):
        """Transform the second half of ``x`` ``(..., D)`` with the conditioner's ``params``;
        returns the whole ``y`` and ``logdet`` ``(B,)``."""
        untouched, changed = x[..., : self.split], x[..., self.split :]
        if self.additive:
            changed = changed - params if inverse else changed + params
            logdet = x.new_zeros(x.shape[0])
        else:
            shift, raw = params.chunk(2, dim=-1)
            log_scale = self.log_scale(raw)
            if inverse:
                changed, logdet = (changed - shift) * torch.exp(-log_scale), -log_scale
            else:
                changed, logdet = changed * torch.exp(log_scale) + shift, log_scale
            logdet = sum_per_sample(logdet)
        return torch.cat([untouched, changed], dim=-1), logdet

    def extra_repr(self) -> str:
        kind = "additive" if self.additive else f"affine, clamp={self.clamp}"
        return f"dim={self.dim}, cond_dim={self.cond_dim}, {kind}"


class AffineCoupling(_Split):
    """Affine coupling ``y_b = x_b * exp(s) + t`` with an MLP conditioner, frame by frame.

    Direction: :meth:`forward` maps data to noise; :meth:`inverse` maps back. Inputs ``(B, D)``
    or ``(B, T, D)`` with a condition ``(B, C)`` / ``(B, T, C)`` (or None); the log-determinant is
    per sample, ``(B,)``, summed over frames.

    Args:
        dim: number of features ``D`` (at least 2).
        cond_dim: number of condition features ``C`` (0 for none).
        hidden: width of the conditioner's hidden layers.
        num_layers: hidden layers of the conditioner.
        clamp: bound of the log-scale (see the module docstring).
    """

    additive = False

    def __init__(
        self, dim: int, cond_dim: int = 0, hidden: int = 64, num_layers: int = 2, clamp=2.0
    ):
        super().__init__(dim, cond_dim, self.additive, clamp)
        self.conditioner = MLPConditioner(self.in_features, self.out_features, hidden, num_layers)

    def forward(self, x: torch.Tensor, cond: torch.Tensor | None = None):
        """Data -> noise: ``(y, logdet)``."""
        return self.transform(x, self.conditioner(self.conditioner_inputs(x, cond)), False)

    def inverse(self, y: torch.Tensor, cond: torch.Tensor | None = None):
        """Noise -> data: ``(x, logdet)``, the log-determinant of the inverse map."""
        return self.transform(y, self.conditioner(self.conditioner_inputs(y, cond)), True)


class AdditiveCoupling(AffineCoupling):
    """Additive coupling ``y_b = x_b + t`` (volume-preserving: logdet 0), as in NICE.

    Args: as :class:`AffineCoupling` (``clamp`` is unused).
    """

    additive = True


class RecurrentCoupling(_Split):
    """Affine or additive coupling whose conditioner is an LSTM or GRU: sequences ``(B, T, D)``.

    Direction: :meth:`forward` maps data to noise; :meth:`inverse` maps back. Both take the
    conditioner's state after the previous frame (None at the start of a sequence) and return
    ``(y, logdet (B,), state)``.

    Args:
        dim, cond_dim, hidden, clamp: as :class:`AffineCoupling` (``hidden``: the state's width).
        cell: ``"lstm"`` or ``"gru"``.
        num_layers: stacked recurrent layers.
        additive: an additive coupling instead of an affine one.
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
        clamp: float = 2.0,
    ):
        super().__init__(dim, cond_dim, additive, clamp)
        self.conditioner = RecurrentConditioner(
            self.in_features, self.out_features, hidden, cell, num_layers
        )

    def forward(self, x: torch.Tensor, cond=None, state: ConditionerState = None):
        """Data -> noise: ``(y, logdet, state)``."""
        params, state = self.conditioner(self.conditioner_inputs(x, cond), state)
        return (*self.transform(x, params, False), state)

    def inverse(self, y: torch.Tensor, cond=None, state: ConditionerState = None):
        """Noise -> data: ``(x, logdet, state)``."""
        params, state = self.conditioner(self.conditioner_inputs(y, cond), state)
        return (*self.transform(y, params, True), state)
