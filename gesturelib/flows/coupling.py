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
* it is bounded, so one coupling cannot blow activations up by more than ``e^c`` per step, which
  keeps training stable and outputs finite for large inputs;
* its slope is 1 at 0, so small scales are learned as fast as with a plain ``exp``.

With a recurrent conditioner (LSTM, GRU) the coupling works on sequences ``(B, T, D)``: the
network at frame ``t`` sees ``[x_a, cond]`` of frames ``1..t`` through its state. The Jacobian
over a whole sequence is then block lower-triangular, and its log-determinant is still the sum of
the per-frame ``sum(s)``. Such a coupling takes the recurrent ``state`` as an argument and returns
the new state as a third output; a feed-forward coupling returns two outputs.
"""

from __future__ import annotations

import torch
from torch import nn

from gesturelib.flows.checks import check_cond, check_features, sum_per_sample
from gesturelib.flows.conditioners import ConditionerState, make_conditioner


class _Coupling(nn.Module):
    """What affine and additive couplings share: the split, the conditioner, the checks."""

    #: how many parameters the conditioner outputs per transformed feature
    params_per_feature: int

    def __init__(
        self,
        dim: int,
        cond_dim: int = 0,
        hidden: int = 64,
        conditioner: str | nn.Module = "mlp",
        num_layers: int = 2,
    ):
        super().__init__()
        if dim < 2:
            raise ValueError(
                f"a coupling splits the features in two, so it needs dim >= 2, got {dim}"
            )
        if cond_dim < 0:
            raise ValueError(f"cond_dim must be >= 0, got {cond_dim}")
        self.dim, self.cond_dim = dim, cond_dim
        self.split = dim // 2
        in_features = self.split + cond_dim
        out_features = self.params_per_feature * (dim - self.split)
        if isinstance(conditioner, str):
            conditioner = make_conditioner(
                conditioner, in_features, out_features, hidden, num_layers
            )
        else:
            sizes = (
                getattr(conditioner, "in_features", None),
                getattr(conditioner, "out_features", None),
            )
            if sizes != (in_features, out_features) or not hasattr(conditioner, "recurrent"):
                raise ValueError(
                    f"this coupling needs a conditioner with in_features={in_features}, "
                    f"out_features={out_features} and a `recurrent` attribute; got {sizes}"
                )
        self.conditioner = conditioner

    @property
    def recurrent(self) -> bool:
        """True if the conditioner is recurrent (then inputs are ``(B, T, D)`` and state flows)."""
        return bool(self.conditioner.recurrent)

    def forward(
        self, x: torch.Tensor, cond: torch.Tensor | None = None, state: ConditionerState = None
    ):
        """Data -> noise.

        Args:
            x: ``(B, D)`` or ``(B, T, D)``; ``(B, T, D)`` only for a recurrent conditioner.
            cond: ``(B, C)`` or ``(B, T, C)`` matching ``x``, or None if ``cond_dim == 0``.
            state: recurrent conditioners only: the conditioner state after the previous frame,
                or None for the start of a sequence.
        Returns:
            ``(y, logdet)``, or ``(y, logdet, state)`` for a recurrent conditioner: ``y`` of the
            shape of ``x``, ``logdet`` ``(B,)`` the log|det dy/dx| of each sample summed over its
            frames, ``state`` the conditioner state after the last frame.
        """
        return self._outputs(*self._run(x, cond, state, inverse=False))

    def inverse(
        self, y: torch.Tensor, cond: torch.Tensor | None = None, state: ConditionerState = None
    ):
        """Noise -> data; arguments and outputs as :meth:`forward`, with ``logdet`` the
        log|det dx/dy| of the inverse map (the negative of the forward one at ``x``)."""
        return self._outputs(*self._run(y, cond, state, inverse=True))

    def _outputs(self, y, logdet, state):
        return (y, logdet, state) if self.recurrent else (y, logdet)

    def _run(self, x, cond, state, inverse: bool):
        """Both directions, always returning ``(y, logdet, state)``; used by :class:`FlowStep`."""
        check_features(
            x, self.dim, name="y" if inverse else "x", sequence=True if self.recurrent else None
        )
        check_cond(cond, self.cond_dim, x)
        if state is not None and not self.recurrent:
            raise ValueError("this coupling's conditioner is feed-forward: it takes no state")
        untouched, changed = x[..., : self.split], x[..., self.split :]
        inputs = untouched if cond is None else torch.cat([untouched, cond], dim=-1)
        params, state = self.conditioner(inputs, state)
        changed, logdet = self._transform(changed, params, inverse)
        return torch.cat([untouched, changed], dim=-1), logdet, state

    def _transform(self, x_b, params, inverse: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """Transform the second half ``x_b`` ``(..., D - D//2)``; return it and logdet ``(B,)``."""
        raise NotImplementedError

    def extra_repr(self) -> str:
        return f"dim={self.dim}, cond_dim={self.cond_dim}, split={self.split}"


class AffineCoupling(_Coupling):
    """Affine coupling ``y_b = x_b * exp(s) + t`` with a soft-clamped log-scale ``s``.

    Direction: :meth:`forward` maps data to noise; :meth:`inverse` maps back.

    Args:
        dim: number of features ``D`` (at least 2).
        cond_dim: number of condition features ``C`` (0 for none).
        hidden: width of the conditioner's hidden layers (or recurrent state).
        conditioner: ``"mlp"``, ``"lstm"``, ``"gru"`` or a conditioner module (see
            :mod:`gesturelib.flows.conditioners`) with ``in_features = D//2 + C`` and
            ``out_features = 2 * (D - D//2)``.
        num_layers: hidden layers of the MLP, or stacked recurrent layers.
        clamp: bound ``c`` of the log-scale, ``s = c * tanh(raw / c)`` (see the module docstring).
    """

    params_per_feature = 2

    def __init__(
        self,
        dim: int,
        cond_dim: int = 0,
        hidden: int = 64,
        conditioner: str | nn.Module = "mlp",
        num_layers: int = 2,
        clamp: float = 2.0,
    ):
        super().__init__(dim, cond_dim, hidden, conditioner, num_layers)
        if not clamp > 0:
            raise ValueError(f"clamp must be positive, got {clamp}")
        self.clamp = float(clamp)

    def log_scale(self, raw: torch.Tensor) -> torch.Tensor:
        """The bounded log-scale ``s = clamp * tanh(raw / clamp)``, in ``(-clamp, clamp)``."""
        return self.clamp * torch.tanh(raw / self.clamp)

    def _transform(self, x_b, params, inverse):
        shift, raw = params.chunk(2, dim=-1)
        log_scale = self.log_scale(raw)
        if inverse:
            return (x_b - shift) * torch.exp(-log_scale), -sum_per_sample(log_scale)
        return x_b * torch.exp(log_scale) + shift, sum_per_sample(log_scale)

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, clamp={self.clamp}"


class AdditiveCoupling(_Coupling):
    """Additive coupling ``y_b = x_b + t`` (volume-preserving: logdet 0), as in NICE.

    Direction: :meth:`forward` maps data to noise; :meth:`inverse` maps back.

    Args: as :class:`AffineCoupling` without ``clamp``; a conditioner module needs
    ``out_features = D - D//2``.
    """

    params_per_feature = 1

    def _transform(self, x_b, params, inverse):
        logdet = x_b.new_zeros(x_b.shape[0])
        return (x_b - params if inverse else x_b + params), logdet


COUPLINGS: dict[str, type[_Coupling]] = {"affine": AffineCoupling, "additive": AdditiveCoupling}
