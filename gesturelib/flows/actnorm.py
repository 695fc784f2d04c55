"""ActNorm: a per-feature affine map, initialised so that the first batch comes out standardised.

Glow (Kingma & Dhariwal, 2018) replaces batch normalisation by *activation normalisation*: one
learned scale and bias per feature,

    y = (x - loc) * exp(log_scale),          log|det dy/dx| = sum_d log_scale_d (per frame),

which is invertible, batch-independent after training, and has a log-determinant that does not
depend on ``x``. Its parameters are set from the data once: on the first call of :meth:`forward`
``loc`` becomes the batch mean and ``exp(-log_scale)`` the batch standard deviation of each
feature, so every step of a fresh flow sees standardised inputs, which makes deep flows train
from the first step.

Whether that initialisation has happened is stored in the buffer ``initialized``, so it is part of
the ``state_dict``: a flow saved after training and loaded into a fresh module does *not*
re-initialise from the next batch (a pitfall of reference implementations that keep the flag as a
plain Python attribute).
"""

from __future__ import annotations

import torch
from torch import nn


class ActNorm(nn.Module):
    """Per-feature scale and bias with data-dependent initialisation.

    Direction: :meth:`forward` maps data to noise, ``y = (x - loc) * exp(log_scale)``;
    :meth:`inverse` maps back. Inputs are ``(B, D)`` or ``(B, T, D)``; the log-determinant is per
    sample, ``(B,)``, summed over its ``T`` frames.

    Args:
        dim: number of features ``D``.
        eps: added to the standard deviation at initialisation, so that a constant feature gets a
            large but finite scale.
    """

    def __init__(self, dim: int, eps: float = 1e-6):
        super().__init__()
        if dim < 1:
            raise ValueError(f"dim must be a positive number of features, got {dim}")
        self.dim, self.eps = dim, eps
        self.loc = nn.Parameter(torch.zeros(dim))
        self.log_scale = nn.Parameter(torch.zeros(dim))
        # A buffer, not a Python bool, so that it is saved and restored with the state_dict.
        self.register_buffer("initialized", torch.tensor(False))

    @torch.no_grad()
    def initialize(self, x: torch.Tensor) -> None:
        """Set ``loc`` and ``log_scale`` so that ``x`` ``(..., D)`` maps to zero mean and unit
        variance per feature; statistics over all its frames, which must be at least 2 and
        finite."""
        frames = x.reshape(-1, self.dim)
        if frames.shape[0] < 2:
            raise ValueError(
                "ActNorm initialises its scale from the spread of the first batch, which needs "
                f"at least 2 samples (frames); got x of shape {tuple(x.shape)}"
            )
        if not bool(torch.isfinite(frames).all()):
            raise ValueError("ActNorm cannot initialise from a batch with NaN or infinite values")
        self.loc.copy_(frames.mean(dim=0))
        self.log_scale.copy_(-torch.log(frames.std(dim=0, unbiased=False) + self.eps))
        self.initialized.fill_(True)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Data -> noise; initialises from ``x`` on the first call. Returns ``(y, logdet (B,))``."""
        if not self.initialized:
            self.initialize(x)
        return (x - self.loc) * torch.exp(self.log_scale), self._logdet(x, 1.0)

    def inverse(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Noise -> data: ``x = y * exp(-log_scale) + loc``. Returns ``(x, logdet (B,))``, the
        negative of the forward log-determinant."""
        return y * torch.exp(-self.log_scale) + self.loc, self._logdet(y, -1.0)

    def _logdet(self, x: torch.Tensor, sign: float) -> torch.Tensor:
        frames = x.shape[1] if x.dim() == 3 else 1
        return (sign * frames * self.log_scale.sum()).expand(x.shape[0])

    def extra_repr(self) -> str:
        return f"dim={self.dim}, initialized={bool(self.initialized)}"
