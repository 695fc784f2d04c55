"""Normalising flows: Glow's bijections and conditional, recurrent flows built from them.

A normalising flow is an invertible map ``f`` from data ``x`` to noise ``z`` with a tractable
Jacobian. By the change of variables,

    log p(x | c) = log p_Z(f(x; c)) + log|det df/dx|,

so a flow is trained by maximising the exact log-likelihood and sampled by drawing ``z`` from
the base distribution ``p_Z`` and inverting: ``x = f^-1(z; c)``.

Building blocks (each usable alone, each with ``forward`` = data -> noise and ``inverse`` =
noise -> data, both returning the output and its log-determinant per sample ``(B,)``):

* :class:`ActNorm` (:mod:`~gesturelib.flows.actnorm`): per-feature scale and bias, initialised
  from the first batch.
* :class:`InvertibleLinear` (:mod:`~gesturelib.flows.linear`): Glow's invertible 1x1 convolution
  on vectors, LU-decomposed.
* :class:`AffineCoupling`, :class:`AdditiveCoupling` (:mod:`~gesturelib.flows.coupling`) with
  :class:`MLPConditioner`, :class:`LSTMConditioner` or :class:`GRUConditioner`, each ending in
  a :class:`ZeroLinear` layer (:mod:`~gesturelib.flows.conditioners`).
* :class:`StandardNormal`, :class:`StudentT` (:mod:`~gesturelib.flows.base`): base distributions.
* :class:`FlowStep` (ActNorm -> linear -> coupling), :class:`Flow` and the factory :func:`glow`
  (:mod:`~gesturelib.flows.flow`), which also documents the conventions for conditions,
  sequences ``(B, T, D)`` and the explicit recurrent state used by MoGlow.

Example::

    flow = glow(dim=2, steps=8, hidden=64)
    loss = -flow.log_prob(x).mean()          # x (B, 2)
    samples = flow.sample(1000, temperature=0.8, generator=torch.Generator().manual_seed(0))
"""

from gesturelib.flows.actnorm import ActNorm
from gesturelib.flows.base import StandardNormal, StudentT
from gesturelib.flows.conditioners import (
    ConditionerState,
    GRUConditioner,
    LSTMConditioner,
    MLPConditioner,
    ZeroLinear,
    make_conditioner,
)
from gesturelib.flows.coupling import AdditiveCoupling, AffineCoupling
from gesturelib.flows.flow import Flow, FlowState, FlowStep, glow
from gesturelib.flows.linear import InvertibleLinear, random_rotation

__all__ = [
    "ActNorm",
    "AdditiveCoupling",
    "AffineCoupling",
    "ConditionerState",
    "Flow",
    "FlowState",
    "FlowStep",
    "GRUConditioner",
    "InvertibleLinear",
    "LSTMConditioner",
    "MLPConditioner",
    "StandardNormal",
    "StudentT",
    "ZeroLinear",
    "glow",
    "make_conditioner",
    "random_rotation",
]
