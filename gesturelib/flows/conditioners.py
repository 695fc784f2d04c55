"""Conditioner networks: the neural networks inside a coupling layer.

A coupling layer keeps half of the features, ``x_a``, and transforms the other half with
parameters computed by a conditioner from ``[x_a, cond]``. Any network works (the coupling stays
invertible whatever it computes), so there are two:

* :class:`MLPConditioner` acts on every frame independently: ``(..., I) -> (..., O)``.
* :class:`RecurrentConditioner` (an LSTM, as in MoGlow, or a GRU, as in Ye et al.) runs along
  time: ``(B, T, I) -> (B, T, O)``, so that a flow over the next pose can remember the whole past,
  not only the few frames in its condition. It is *stateless*: the hidden state is an argument and
  a result, never an attribute, so running a whole sequence at once and running it one frame at a
  time, passing the state along, give the same outputs. One frame is stepped with the recurrent
  cell itself (``torch.lstm_cell``), several times faster than a length-1 pass of ``nn.LSTM``.

Both end with a :class:`ZeroLinear` layer, so a new coupling outputs zero shift and zero
log-scale: it starts as the identity, and a flow starts as its ActNorm and linear layers. From that
start a coupling first learns by reweighting the hidden features it begins with, so their scale
matters: the MLP scales each hidden layer's weights on the first batch it sees so that every unit
starts at unit mean square before its ReLU, whatever the scale of the inputs (a data-dependent
initialisation, like ActNorm's, that costs nothing afterwards). It scales without centring: a
centred unit would switch at the mean of the first batch, and in a 2D flow, whose conditioner sees
one coordinate, all of them would switch at the same point.
"""

from __future__ import annotations

import torch
from torch import nn

#: The state of a recurrent conditioner: ``(h, c)`` for an LSTM, ``h`` for a GRU, each
#: ``(num_layers, B, hidden)``; None for a zero initial state.
ConditionerState = torch.Tensor | tuple[torch.Tensor, torch.Tensor] | None

CELLS = ("lstm", "gru")


class ZeroLinear(nn.Linear):
    """A linear layer that starts at zero, with a learned gain per output: ``(..., I) -> (..., O)``.

    ``output = (x @ W.T + b) * exp(3 * log_gain)``, with ``W``, ``b`` and ``log_gain`` all zero at
    first, so the layer first outputs exactly zero (the coupling starts as the identity). The gain
    is Glow's ``logs``: it learns the size of each output on a log scale, and once it has grown it
    amplifies every later update of the weights feeding that output, like a learning rate that
    each output tunes for itself; the factor 3 (Glow's) makes it act three times faster.
    """

    gain_factor = 3.0

    def __init__(self, in_features: int, out_features: int, device=None, dtype=None):
        super().__init__(in_features, out_features, device=device, dtype=dtype)
        self.log_gain = nn.Parameter(torch.zeros(out_features, device=device, dtype=dtype))

    def reset_parameters(self) -> None:
        """Back to the zero start: weight, bias and log-gain all zero."""
        nn.init.zeros_(self.weight)
        nn.init.zeros_(self.bias)
        if hasattr(self, "log_gain"):  # nn.Linear.__init__ calls this before log_gain exists
            nn.init.zeros_(self.log_gain)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(x) * torch.exp(self.gain_factor * self.log_gain)


class MLPConditioner(nn.Module):
    """A multilayer perceptron applied to every frame: ``(..., I) -> (..., O)``.

    Args:
        in_features: ``I``, the size of ``[x_a, cond]``.
        out_features: ``O``, the number of coupling parameters.
        hidden: width of each hidden layer (Linear then ReLU).
        num_layers: number of hidden layers before the :class:`ZeroLinear` output.
    """

    def __init__(self, in_features: int, out_features: int, hidden: int = 64, num_layers: int = 2):
        super().__init__()
        widths = [in_features] + [hidden] * num_layers
        self.hidden_layers = nn.ModuleList(
            nn.Linear(a, b) for a, b in zip(widths[:-1], widths[1:], strict=True)
        )
        self.output = ZeroLinear(hidden, out_features)
        # A buffer, so that a loaded conditioner is not scaled again by its next batch.
        self.register_buffer("initialized", torch.tensor(False))

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        if not self.initialized:
            self.initialize(inputs)
        hidden = inputs
        for layer in self.hidden_layers:
            hidden = torch.relu(layer(hidden))
        return self.output(hidden)

    @torch.no_grad()
    def initialize(self, inputs: torch.Tensor) -> None:
        """Scale each hidden layer so that its units have unit mean square on ``inputs``."""
        hidden = inputs.reshape(-1, inputs.shape[-1])
        for layer in self.hidden_layers:
            root_mean_square = layer(hidden).square().mean(0).sqrt() + 1e-6
            layer.weight.div_(root_mean_square[:, None])
            layer.bias.div_(root_mean_square)
            hidden = torch.relu(layer(hidden))
        self.initialized.fill_(True)


class RecurrentConditioner(nn.Module):
    """A stacked LSTM or GRU along time, then a :class:`ZeroLinear` layer per frame.

    Args:
        in_features: ``I``, the size of ``[x_a, cond]`` per frame.
        out_features: ``O``, the number of coupling parameters per frame.
        hidden: the recurrent state's width.
        cell: ``"lstm"`` (MoGlow) or ``"gru"`` (Ye et al.).
        num_layers: stacked recurrent layers.
    """

    def __init__(
        self,
        in_features: int,
        out_features: int,
        hidden: int = 64,
        cell: str = "lstm",
        num_layers: int = 1,
    ):
        super().__init__()
        if cell not in CELLS:
            raise ValueError(f"unknown cell {cell!r}; choose one of {list(CELLS)}")
        self.cell, self.hidden, self.num_layers = cell, hidden, num_layers
        network = nn.LSTM if cell == "lstm" else nn.GRU
        self.rnn = network(in_features, hidden, num_layers, batch_first=True)
        self.output = ZeroLinear(hidden, out_features)

    def forward(self, inputs: torch.Tensor, state: ConditionerState = None):
        """``inputs`` ``(B, T, I)`` and the state after the previous frame (None: zeros) ->
        ``(outputs (B, T, O), state after the last frame)``."""
        if inputs.shape[1] == 1:
            hidden, state = self._step(inputs[:, 0], state)
            return self.output(hidden)[:, None], state
        hidden_sequence, state = self.rnn(inputs, state)
        return self.output(hidden_sequence), state

    def _step(self, x: torch.Tensor, state: ConditionerState):
        """One frame through the cells, sharing ``nn.LSTM``/``nn.GRU``'s weights: ``(B, I)`` ->
        ``(B, hidden)`` and the new state."""
        if state is None:
            state = self.initial_state(x.shape[0], device=x.device, dtype=x.dtype)
        lstm = self.cell == "lstm"
        h, c = state if lstm else (state, None)
        new_h, new_c = [], []
        for layer in range(self.num_layers):
            weights = [getattr(self.rnn, f"{name}_l{layer}") for name in _WEIGHT_NAMES]
            if lstm:
                x, cell_state = torch.lstm_cell(x, (h[layer], c[layer]), *weights)
                new_c.append(cell_state)
            else:
                x = torch.gru_cell(x, h[layer], *weights)
            new_h.append(x)
        h = torch.stack(new_h)
        return x, ((h, torch.stack(new_c)) if lstm else h)

    def initial_state(self, batch_size: int, device=None, dtype=None) -> ConditionerState:
        """The zero state for ``batch_size`` sequences (what ``state=None`` stands for)."""
        zeros = torch.zeros(self.num_layers, batch_size, self.hidden, device=device, dtype=dtype)
        return (zeros, zeros.clone()) if self.cell == "lstm" else zeros


_WEIGHT_NAMES = ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
