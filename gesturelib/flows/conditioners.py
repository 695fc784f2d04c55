"""Conditioner networks: the neural networks inside a coupling layer.

A coupling layer keeps half of the features, ``x_a``, and transforms the other half with
parameters computed by a conditioner from ``[x_a, cond]``. Any network works (the coupling stays
invertible whatever it computes), so the conditioner is pluggable:

* :class:`MLPConditioner` acts on every frame independently: inputs ``(..., I)``.
* :class:`LSTMConditioner` and :class:`GRUConditioner` run along time: inputs ``(B, T, I)``. This
  is what MoGlow (LSTM) and Ye et al. (GRU) use, so that a flow over the next pose can remember the
  whole past, not only the few frames in its condition.

All three share one interface, ``conditioner(inputs, state=None) -> (outputs, state)``, and are
*stateless* modules: a recurrent conditioner's hidden state is an argument and a result, never an
attribute. Running a whole sequence at once and running it one frame at a time, passing the state
along, therefore give the same outputs. A feed-forward conditioner takes and returns
``state=None``.

Every conditioner ends with a :class:`ZeroLinear` layer, so a new coupling outputs zero shift and
zero log-scale: it starts as the identity and the flow starts as its ActNorm and linear layers.
Three details help a flow learn from that start, the first two taken from Glow. Their effect on
the held-out NLL of the 2D toy flows of ``benchmarks/flows_vs_reference.py`` after 10 000 steps
(nats, mean ± sd over 4 seeds unless stated), each measured with the one before already in place:

* A coupling first learns by reweighting the hidden features it starts with, so their scale
  matters. The MLP therefore puts an ActNorm after each hidden linear layer, initialised from the
  first batch so that every hidden unit starts at a common scale before its ReLU, whatever the
  scale of the inputs. Eight Gaussians: 1.842 ± 0.009 without it, 1.809 ± 0.012 with it (measured
  with the earlier, centring version; see the last point).
* The zero layer learns a gain per output (:class:`ZeroLinear`), which lets the size of each
  output be learned on a log scale. Eight Gaussians: 1.809 ± 0.012 -> 1.795 ± 0.012; on two moons
  (1.708 -> 1.703) and the checkerboard (2.221 -> 2.216) the gain is within the seeds' spread.
* That ActNorm scales each hidden unit to unit mean square but does not centre it
  (:class:`HiddenActNorm`). Centring put every first-layer ReLU's threshold at the mean of the
  first batch, so in 2D, where a conditioner sees one coordinate, its 64 first-layer units started
  as two features. Over 16 seeds, with the linear layers starting as swaps: two moons
  1.715 ± 0.020 -> 1.706 ± 0.012, eight Gaussians 1.797 ± 0.009 -> 1.784 ± 0.009, checkerboard
  2.194 ± 0.023 -> 2.180 ± 0.022. It makes no difference to notebook 04's pose flow.

A custom conditioner can be passed to a coupling if it has the same interface and the attributes
``in_features``, ``out_features`` and ``recurrent``.
"""

from __future__ import annotations

import torch
from torch import nn

from gesturelib.flows.actnorm import ActNorm

#: The state of one recurrent conditioner: ``(h, c)`` for an LSTM, ``h`` for a GRU, each
#: ``(num_layers, B, hidden)``; ``None`` for a feed-forward conditioner or a zero initial state.
ConditionerState = torch.Tensor | tuple[torch.Tensor, torch.Tensor] | None


class ZeroLinear(nn.Linear):
    """A linear layer that starts at zero, with a learned gain per output: ``(..., I)`` -> ``(..., O)``.

    ``output = (x @ W.T + b) * exp(gain_factor * log_gain)``, with ``W``, ``b`` and ``log_gain``
    all zero at first, so the layer first outputs exactly zero (the coupling starts as the
    identity). The gain is Glow's ``logs``: it learns the size of each output on a log scale, and
    once it has grown it amplifies every later update of the weights feeding that output, like a
    learning rate that each output tunes for itself. ``gain_factor`` (3 in Glow) makes ``log_gain``
    act that many times faster than an unscaled ``exp(log_gain)`` would under the same optimiser.

    Args:
        in_features: ``I``.
        out_features: ``O``.
        gain_factor: the scale of ``log_gain`` in the exponent (3 in Glow).
    """

    def __init__(
        self, in_features: int, out_features: int, gain_factor: float = 3.0, device=None, dtype=None
    ):
        super().__init__(in_features, out_features, device=device, dtype=dtype)
        self.log_gain = nn.Parameter(torch.zeros(out_features, device=device, dtype=dtype))
        self.gain_factor = float(gain_factor)

    def reset_parameters(self) -> None:
        """Back to the zero start: weight, bias and log-gain all zero."""
        # nn.Linear's random draw is kept, then overwritten, so that a seed builds the same flow
        # as the one the figures quoted in the docs and README were measured with.
        super().reset_parameters()
        nn.init.zeros_(self.weight)
        nn.init.zeros_(self.bias)
        if hasattr(self, "log_gain"):  # nn.Linear.__init__ calls this before log_gain exists
            nn.init.zeros_(self.log_gain)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(x) * torch.exp(self.gain_factor * self.log_gain)

    def extra_repr(self) -> str:
        return f"{super().extra_repr()}, gain_factor={self.gain_factor}"


def _check_sizes(in_features: int, out_features: int, hidden: int, num_layers: int) -> None:
    for name, value in [("out_features", out_features), ("hidden", hidden)]:
        if value < 1:
            raise ValueError(f"{name} must be at least 1, got {value}")
    if in_features < 0:
        raise ValueError(f"in_features must be non-negative, got {in_features}")
    if num_layers < 1:
        raise ValueError(f"num_layers must be at least 1, got {num_layers}")


class HiddenActNorm(nn.Module):
    """:class:`ActNorm` used as a normalisation layer inside a network: ``(..., H)`` -> same.

    Initialised from the first batch it sees so that every unit has unit mean square, then a
    learned per-unit affine map. Inside a conditioner its log-determinant is irrelevant and
    dropped.

    It scales but does not centre (``ActNorm(centre=False)``). Centring would move every unit's
    ReLU threshold to the mean of the first batch: in a 2D flow a coupling's conditioner sees a
    single coordinate, so all its first-layer units would switch at the same point and span only
    two features, ``relu(x - m)`` and ``relu(m - x)``, until training pulls them apart. Without
    centring each unit keeps the threshold of its random initialisation.
    """

    def __init__(self, features: int):
        super().__init__()
        self.actnorm = ActNorm(features, centre=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.actnorm.normalise(x)  # no checks or log-determinant on this hot path


class MLPConditioner(nn.Module):
    """A multilayer perceptron applied to every frame: ``(..., I)`` -> ``(..., O)``.

    Args:
        in_features: ``I``, the size of ``[x_a, cond]``.
        out_features: ``O``, the number of coupling parameters.
        hidden: width of each hidden layer.
        num_layers: number of hidden layers (each Linear, :class:`HiddenActNorm`, ReLU), before
            the :class:`ZeroLinear` output layer.
    """

    recurrent = False

    def __init__(self, in_features: int, out_features: int, hidden: int = 64, num_layers: int = 2):
        super().__init__()
        _check_sizes(in_features, out_features, hidden, num_layers)
        self.in_features, self.out_features = in_features, out_features
        layers: list[nn.Module] = []
        width = in_features
        for _ in range(num_layers):
            layers += [nn.Linear(width, hidden), HiddenActNorm(hidden), nn.ReLU()]
            width = hidden
        self.hidden_layers = nn.Sequential(*layers)
        self.output = ZeroLinear(hidden, out_features)

    def forward(self, inputs: torch.Tensor, state: ConditionerState = None):
        """``inputs`` ``(..., I)`` -> ``(outputs (..., O), None)``; ``state`` must be None."""
        if state is not None:
            raise ValueError("an MLP conditioner has no recurrent state; pass state=None")
        return self.output(self.hidden_layers(inputs)), None


class _RecurrentConditioner(nn.Module):
    """A stacked LSTM or GRU along time, then a :class:`ZeroLinear` layer per frame."""

    recurrent = True
    rnn_class: type[nn.RNNBase]

    def __init__(self, in_features: int, out_features: int, hidden: int = 64, num_layers: int = 2):
        super().__init__()
        _check_sizes(in_features, out_features, hidden, num_layers)
        if in_features < 1:
            raise ValueError(f"a recurrent conditioner needs in_features >= 1, got {in_features}")
        self.in_features, self.out_features = in_features, out_features
        self.hidden, self.num_layers = hidden, num_layers
        self.rnn = self.rnn_class(in_features, hidden, num_layers, batch_first=True)
        self.output = ZeroLinear(hidden, out_features)

    def forward(self, inputs: torch.Tensor, state: ConditionerState = None):
        """Run along time.

        Args:
            inputs: ``(B, T, I)``.
            state: the state after the previous frame (see :data:`ConditionerState`), or None
                for a zero state (the start of a sequence).
        Returns:
            ``outputs`` ``(B, T, O)`` and the state after the last frame.
        """
        if inputs.dim() != 3 or inputs.shape[-1] != self.in_features:
            raise ValueError(
                f"a recurrent conditioner takes inputs of shape (B, T, I) = "
                f"(B, T, {self.in_features}), got {tuple(inputs.shape)}"
            )
        if state is not None:
            self._check_state(state, inputs.shape[0])
        hidden_sequence, state = self.rnn(inputs, state)
        return self.output(hidden_sequence), state

    def initial_state(self, batch_size: int, device=None, dtype=None) -> ConditionerState:
        """The zero state for ``batch_size`` sequences (what ``state=None`` stands for)."""
        zeros = torch.zeros(self.num_layers, batch_size, self.hidden, device=device, dtype=dtype)
        return (zeros, zeros.clone()) if self._is_lstm else zeros

    @property
    def _is_lstm(self) -> bool:
        return self.rnn_class is nn.LSTM

    def _check_state(self, state, batch_size: int) -> None:
        wanted = (self.num_layers, batch_size, self.hidden)
        form = "a tuple (h, c) of two tensors" if self._is_lstm else "one tensor h"
        if self._is_lstm:
            tensors = tuple(state) if isinstance(state, tuple | list) and len(state) == 2 else None
        else:
            tensors = (state,) if isinstance(state, torch.Tensor) else None
        if tensors is None or any(
            not isinstance(t, torch.Tensor) or tuple(t.shape) != wanted for t in tensors
        ):
            got = (
                [
                    tuple(t.shape) if isinstance(t, torch.Tensor) else type(t).__name__
                    for t in tensors
                ]
                if tensors is not None
                else type(state).__name__
            )
            raise ValueError(
                f"the state of this {self.rnn_class.__name__} conditioner must be {form} of shape "
                f"(num_layers, B, hidden) = {wanted}, got {got}"
            )


class LSTMConditioner(_RecurrentConditioner):
    """An LSTM conditioner (as in MoGlow); its state is ``(h, c)``, each ``(num_layers, B, H)``.

    Args: as :class:`MLPConditioner`, with ``num_layers`` the number of stacked LSTM layers.
    """

    rnn_class = nn.LSTM


class GRUConditioner(_RecurrentConditioner):
    """A GRU conditioner (as in Ye et al.); its state is ``h`` ``(num_layers, B, H)``.

    Args: as :class:`MLPConditioner`, with ``num_layers`` the number of stacked GRU layers.
    """

    rnn_class = nn.GRU


CONDITIONERS: dict[str, type[nn.Module]] = {
    "mlp": MLPConditioner,
    "lstm": LSTMConditioner,
    "gru": GRUConditioner,
}


def make_conditioner(
    kind: str, in_features: int, out_features: int, hidden: int = 64, num_layers: int = 2
) -> nn.Module:
    """Build a conditioner by name: ``"mlp"``, ``"lstm"`` or ``"gru"``."""
    if kind not in CONDITIONERS:
        raise ValueError(f"unknown conditioner {kind!r}; choose one of {sorted(CONDITIONERS)}")
    return CONDITIONERS[kind](in_features, out_features, hidden=hidden, num_layers=num_layers)
