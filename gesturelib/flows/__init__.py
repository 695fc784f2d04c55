"""Normalising flows: Glow's bijections, and flows over vectors and over sequences.

A normalising flow is an invertible map ``f`` from data ``x`` to noise ``z`` with a tractable
Jacobian. By the change of variables,

    log p(x | c) = log p_Z(f(x; c)) + log|det df/dx|,

so a flow is trained by maximising the exact log-likelihood and sampled by drawing ``z`` from
the base distribution ``p_Z`` and inverting: ``x = f^-1(z; c)``.

Building blocks, each usable alone, each with ``forward`` = data -> noise and ``inverse`` = noise ->
data, returning the output and its log-determinant per sample ``(B,)``:

* :class:`ActNorm` (:mod:`~gesturelib.flows.actnorm`): per-feature scale and bias, initialised
  from the first batch;
* :class:`InvertibleLinear` (:mod:`~gesturelib.flows.linear`): Glow's invertible 1x1 convolution
  on vectors, LU-decomposed;
* :class:`AffineCoupling`, :class:`AdditiveCoupling` (MLP conditioner) and
  :class:`RecurrentCoupling` (LSTM or GRU conditioner, which also takes and returns a state)
  (:mod:`~gesturelib.flows.coupling`, :mod:`~gesturelib.flows.conditioners`);
* :class:`StandardNormal`, :class:`StudentT` (:mod:`~gesturelib.flows.base`): base distributions.

Flows: :class:`Flow` (frames independent; built by :func:`glow`) returns ``(z, logdet)``;
:class:`RecurrentFlow` (MoGlow's; built by :func:`recurrent_glow`) works on sequences and returns
``(z, logdet, state)``. Example::

    flow = glow(dim=2, steps=8, hidden=64)
    loss = -flow.log_prob(x).mean()          # x (B, 2)
    samples = flow.sample(1000, temperature=0.8, generator=torch.Generator().manual_seed(0))
"""

from gesturelib.flows.actnorm import ActNorm
from gesturelib.flows.base import StandardNormal, StudentT
from gesturelib.flows.conditioners import MLPConditioner, RecurrentConditioner, ZeroLinear
from gesturelib.flows.coupling import AdditiveCoupling, AffineCoupling, RecurrentCoupling
from gesturelib.flows.flow import Flow, FlowStep, UninitialisedFlowError, glow
from gesturelib.flows.linear import InvertibleLinear, random_rotation
from gesturelib.flows.recurrent import FlowState, RecurrentFlow, RecurrentFlowStep, recurrent_glow

__all__ = [
    "ActNorm",
    "AdditiveCoupling",
    "AffineCoupling",
    "Flow",
    "FlowState",
    "FlowStep",
    "InvertibleLinear",
    "MLPConditioner",
    "RecurrentConditioner",
    "RecurrentCoupling",
    "RecurrentFlow",
    "RecurrentFlowStep",
    "StandardNormal",
    "StudentT",
    "UninitialisedFlowError",
    "ZeroLinear",
    "glow",
    "random_rotation",
    "recurrent_glow",
]
