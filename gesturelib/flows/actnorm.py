"""ActNorm: a per-feature affine map, initialised so that the first batch comes out standardised.

Glow (Kingma & Dhariwal, 2018) replaces batch normalisation by *activation normalisation*: one
learned scale and bias per feature,

    y = (x - loc) * exp(log_scale),          log|det dy/dx| = sum_d log_scale_d (per frame),

which is invertible, batch-independent after training, and has a log-determinant that does not
depend on ``x``. Its parameters are set from the data once: on the first call of :meth:`forward`
``loc`` becomes the batch mean and ``exp(-log_scale)`` the batch standard deviation of each
feature, so every step of a fresh flow sees standardised inputs, which makes deep flows train
from the first step. With ``centre=False`` it only scales (``loc`` stays zero, ``exp(-log_scale)``
is the root mean square), the variant used inside conditioner networks.

Whether that initialisation has happened is stored in the buffer ``initialized``, so it is part of
the ``state_dict``: a flow saved after training and loaded into a fresh module does *not*
re-initialise from the next batch (a pitfall of reference implementations that keep the flag as a
plain Python attribute).
"""

from __future__ import annotations

import torch
from torch import nn

from gesturelib.flows.checks import check_features, frames_per_sample


class ActNorm(nn.Module):
    """Per-feature scale and bias with data-dependent initialisation.

    Direction: :meth:`forward` maps data to noise, ``y = (x - loc) * exp(log_scale)``;
    :meth:`inverse` maps back.

    Args:
        dim: number of features ``D``.
        eps: added to the standard deviation (root mean square) at initialisation, so a
            constant feature gives a large but finite scale.
        centre: whether initialisation also centres each feature (``loc`` = batch mean). With
            ``centre=False`` ``loc`` starts at zero and ``exp(-log_scale)`` is the root mean
            square of the feature, so the batch comes out with unit mean square but keeps its
            offsets: the choice inside a conditioner, where centring would put every hidden
            unit's ReLU threshold at the same point (see ``conditioners.HiddenActNorm``).
    """

    def __init__(self, dim: int, eps: float = 1e-6, centre: bool = True):
        super().__init__()
        if dim < 1:
            raise ValueError(f"dim must be a positive number of features, got {dim}")
        self.dim = dim
        self.eps = eps
        self.centre = centre
        self.loc = nn.Parameter(torch.zeros(dim))
        self.log_scale = nn.Parameter(torch.zeros(dim))
        # A buffer, not a Python bool, so that it is saved and restored with the state_dict.
        self.register_buffer("initialized", torch.tensor(False))

    @torch.no_grad()
    def initialize(self, x: torch.Tensor) -> None:
        """Set ``loc`` and ``log_scale`` so that ``x`` maps to zero mean, unit variance per feature
        (with ``centre=False``: ``loc`` zero and unit mean square per feature).

        Args:
            x: ``(B, D)`` or ``(B, T, D)``; statistics are taken over all ``B * T`` frames, which
                must number at least 2.
        """
        check_features(x, self.dim)
        frames = x.reshape(-1, self.dim)
        if frames.shape[0] < 2:
            raise ValueError(
                "ActNorm initialises its scale from the spread of the first batch (its standard "
                "deviation, or root mean square with centre=False), which needs at least 2 "
                f"samples (frames); got x of shape {tuple(x.shape)}"
            )
        if self.centre:
            spread = frames.std(dim=0, unbiased=False)
            self.loc.copy_(frames.mean(dim=0))
        else:
            spread = frames.square().mean(dim=0).sqrt()
            self.loc.zero_()
        self.log_scale.copy_(-torch.log(spread + self.eps))
        self.initialized.fill_(True)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Data -> noise. Initialises from ``x`` on the first call (see :meth:`initialize`).

        Args:
            x: ``(B, D)`` or ``(B, T, D)``.
        Returns:
            ``y`` of the shape of ``x`` and ``logdet`` ``(B,)``, the log|det dy/dx| of each sample
            (summed over its ``T`` frames).
        """
        check_features(x, self.dim)
        return self.normalise(x), self._logdet(x, sign=1.0)

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """``y = (x - loc) * exp(log_scale)`` alone, for ``x`` ``(..., D)``: no shape check and no
        log-determinant (for use inside a network). Initialises from ``x`` on the first call."""
        if not bool(self.initialized):
            self.initialize(x.reshape(-1, self.dim))
        return (x - self.loc) * torch.exp(self.log_scale)

    def inverse(self, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Noise -> data: ``x = y * exp(-log_scale) + loc``.

        Args:
            y: ``(B, D)`` or ``(B, T, D)``.
        Returns:
            ``x`` of the shape of ``y`` and ``logdet`` ``(B,)``, the log|det dx/dy| of each sample
            (the negative of the forward one).
        """
        check_features(y, self.dim, name="y")
        x = y * torch.exp(-self.log_scale) + self.loc
        return x, self._logdet(y, sign=-1.0)

    def _logdet(self, x: torch.Tensor, sign: float) -> torch.Tensor:
        per_frame = sign * self.log_scale.sum()
        return (per_frame * frames_per_sample(x)).expand(x.shape[0])

    def extra_repr(self) -> str:
        centre = "" if self.centre else ", centre=False"
        return f"dim={self.dim}{centre}, initialized={bool(self.initialized)}"
