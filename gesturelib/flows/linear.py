"""The invertible linear layer: Glow's invertible 1x1 convolution, applied to vectors.

A coupling layer only transforms half of the features given the other half, so between couplings
the features must be mixed. Glow learns the mixing: ``y = W x`` with an invertible ``D x D``
matrix ``W``, whose log-determinant is ``log|det W|`` per frame.

Two parametrisations:

* **LU** (default): ``W = P L (U + diag(sign_s * exp(log_abs_s)))`` with ``P`` a fixed
  permutation, ``L`` unit lower-triangular and ``U`` strictly upper-triangular. Then
  ``log|det W| = sum(log_abs_s)`` costs O(D), ``W`` can never become singular (its diagonal
  factor is ``exp(.)`` times a fixed sign), and the inverse needs only two triangular solves.
* **plain**: ``W`` is a free matrix; ``log|det W|`` comes from ``torch.linalg.slogdet`` (O(D^3)).

Both start from an orthogonal matrix, so at initialisation the layer only mixes and its
log-determinant is zero:

* ``init="rotation"``: a random rotation (Glow's choice), which mixes every feature with every
  other: the right start in the dozens of dimensions of a pose;
* ``init="reverse"``: the permutation that reverses the feature order. With the coupling's fixed
  split into halves, consecutive couplings then alternate which half they transform, as the
  alternating masks of RealNVP. In two dimensions this is the better start: a random rotation
  can leave two consecutive couplings transforming nearly the same direction, which wastes a
  step (:func:`~gesturelib.flows.glow` uses it for ``dim == 2``; ``docs/benchmarks.md`` measures
  both).

The inverse matrix is computed in float64 from the current parameters on every call, so it cannot
go stale after an optimiser step (:meth:`~gesturelib.flows.Flow.fixed_weights` computes it once
where the weights are promised not to change, for frame-by-frame sampling).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

#: The initial matrices :class:`InvertibleLinear` can start from.
INITS = ("rotation", "reverse")


def random_rotation(dim: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """A rotation matrix ``(dim, dim)`` drawn uniformly (Haar measure), in float64."""
    gaussian = torch.randn(dim, dim, generator=generator, dtype=torch.float64)
    q, r = torch.linalg.qr(gaussian)
    q = q * torch.sign(torch.diagonal(r))  # makes the draw uniform over orthogonal matrices
    if torch.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


class InvertibleLinear(nn.Module):
    """``y = W x`` with an invertible ``W`` ``(D, D)``, LU-decomposed by default.

    Direction: :meth:`forward` maps data to noise (``y = W x``); :meth:`inverse` maps back.
    Inputs are ``(B, D)`` or ``(B, T, D)``; the log-determinant is per sample, ``(B,)``.

    Args:
        dim: number of features ``D``.
        lu: LU parametrisation (True) or a plain matrix (False); see the module docstring.
        generator: torch generator for the random initial rotation (the global one if None).
        init: the initial matrix, ``"rotation"`` or ``"reverse"``; see the module docstring.
    """

    def __init__(
        self,
        dim: int,
        lu: bool = True,
        generator: torch.Generator | None = None,
        *,
        init: str = "rotation",
    ):
        super().__init__()
        if dim < 1:
            raise ValueError(f"dim must be a positive number of features, got {dim}")
        if init not in INITS:
            raise ValueError(f"unknown init {init!r}; choose one of {list(INITS)}")
        self.dim, self.lu, self.init = dim, lu, init
        if init == "rotation":
            start = random_rotation(dim, generator)
        else:
            start = torch.eye(dim, dtype=torch.float64).flip(0)
        dtype = torch.get_default_dtype()
        if not lu:
            self.weight = nn.Parameter(start.to(dtype))
            return
        permutation, lower, upper = torch.linalg.lu(start)
        diagonal = torch.diagonal(upper)
        self.register_buffer("permutation", permutation.to(dtype))
        self.register_buffer("sign_s", torch.sign(diagonal).to(dtype))
        self.register_buffer("eye", torch.eye(dim, dtype=dtype), persistent=False)
        self.lower = nn.Parameter(torch.tril(lower, -1).to(dtype))
        self.upper = nn.Parameter(torch.triu(upper, 1).to(dtype))
        self.log_abs_s = nn.Parameter(torch.log(diagonal.abs()).to(dtype))

    def _lu_factors(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``L`` (unit lower-triangular) and ``U`` (upper-triangular with diagonal ``s``)."""
        lower = torch.tril(self.lower, -1) + self.eye
        upper = torch.triu(self.upper, 1) + torch.diag(self.sign_s * torch.exp(self.log_abs_s))
        return lower, upper

    def weight_matrix(self) -> torch.Tensor:
        """The current matrix ``W`` ``(D, D)``."""
        if not self.lu:
            return self.weight
        lower, upper = self._lu_factors()
        return self.permutation @ (lower @ upper)

    def inverse_matrix(self) -> torch.Tensor:
        """``W^-1`` ``(D, D)``, computed in float64 from the current parameters."""
        if not self.lu:
            return torch.linalg.inv(self.weight.double()).to(self.weight.dtype)
        lower, upper = (factor.double() for factor in self._lu_factors())
        eye = self.eye.double()
        # W^-1 = U^-1 L^-1 P^T, each triangular inverse by a triangular solve.
        lower_inv = torch.linalg.solve_triangular(lower, eye, upper=False, unitriangular=True)
        upper_inv = torch.linalg.solve_triangular(upper, eye, upper=True)
        return (upper_inv @ lower_inv @ self.permutation.double().T).to(self.lower.dtype)

    def log_abs_det(self) -> torch.Tensor:
        """``log|det W|``, a scalar (per frame)."""
        if self.lu:
            return self.log_abs_s.sum()
        return torch.linalg.slogdet(self.weight)[1]

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Data -> noise: ``y = W x`` for every frame. Returns ``(y, logdet (B,))``."""
        return F.linear(x, self.weight_matrix()), self._logdet(x, 1.0)

    def inverse(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Noise -> data: ``x = W^-1 y`` for every frame. Returns ``(x, logdet (B,))``."""
        return F.linear(y, self.inverse_matrix()), self._logdet(y, -1.0)

    def _logdet(self, x: torch.Tensor, sign: float) -> torch.Tensor:
        frames = x.shape[1] if x.dim() == 3 else 1
        return (sign * frames * self.log_abs_det()).expand(x.shape[0])

    def extra_repr(self) -> str:
        return f"dim={self.dim}, lu={self.lu}, init={self.init!r}"
