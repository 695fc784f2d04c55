"""Base distributions of a flow: the simple density that the data is mapped onto.

A flow's log-likelihood is ``log p(x) = log p_Z(f(x)) + log|det df/dx|``; ``p_Z`` is the base.

* :class:`StandardNormal`: ``N(0, I)``, Glow's and MoGlow's choice.
* :class:`StudentT`: the multivariate Student's t with ``df`` degrees of freedom, location 0 and
  scale matrix ``I``, as in "studentising flows" (Alexanderson & Henter, 2020), which Ye et al.
  (2022) adopt for a more robust training. Its heavier tails make the log-likelihood of an outlier
  fall only logarithmically with its distance (quadratically for the Gaussian), so one bad frame
  cannot dominate a gradient step. As ``df -> inf`` it tends to ``N(0, I)``.

Both act on the last axis, the ``D`` features of one frame: ``log_prob`` maps ``(..., D)`` to
``(...)``; ``sample(shape)`` returns ``(*shape, D)``.

**Temperature** scales a base sample: ``z = temperature * eps`` with ``eps`` a draw from the
base, i.e. it multiplies the standard deviation. ``temperature = 0`` returns the mode ``z = 0``
exactly (and draws nothing); it never means "use the default".
"""

from __future__ import annotations

import math

import torch
from torch import nn

from gesturelib.configs import check_temperature
from gesturelib.runtime import standard_normal


def _as_shape(shape: int | tuple[int, ...]) -> tuple[int, ...]:
    return (shape,) if isinstance(shape, int) else tuple(shape)


class StandardNormal(nn.Module):
    """The standard normal ``N(0, I)`` over ``D`` features."""

    def __init__(self, dim: int):
        super().__init__()
        self.dim = dim

    def log_prob(self, z: torch.Tensor) -> torch.Tensor:
        """``log N(z; 0, I)`` per frame: ``(..., D)`` -> ``(...)``."""
        return -0.5 * (z**2).sum(dim=-1) - 0.5 * self.dim * math.log(2 * math.pi)

    def sample(self, shape, temperature=1.0, generator=None, device=None, dtype=None):
        """``temperature * eps``, ``eps ~ N(0, I)``, of shape ``(*shape, D)`` (``shape`` an int
        ``n`` or a tuple); zeros at 0."""
        temperature, shape = check_temperature(temperature), (*_as_shape(shape), self.dim)
        if temperature == 0:
            return torch.zeros(shape, device=device, dtype=dtype)
        return temperature * standard_normal(shape, generator, device, dtype)

    def extra_repr(self) -> str:
        return f"dim={self.dim}"


class StudentT(nn.Module):
    """The multivariate Student's t over ``D`` features: location 0, scale ``I``, ``df`` degrees
    of freedom.

    Density: ``Gamma((df + D)/2) / (Gamma(df/2) (df pi)^(D/2)) * (1 + |z|^2 / df)^(-(df + D)/2)``.
    A draw is ``eps * sqrt(df / w)`` with ``eps ~ N(0, I)`` and ``w ~ chi-square(df)``, one ``w``
    per frame (so the features of a frame share their tail, as in studentising flows).

    Args:
        dim: number of features ``D``.
        df: degrees of freedom, > 0; small values give heavy tails, large ones approach N(0, I).
    """

    def __init__(self, dim: int, df: float):
        super().__init__()
        if not (isinstance(df, int | float) and math.isfinite(df) and df > 0):
            raise ValueError(f"df (degrees of freedom) must be a finite positive number, got {df}")
        self.dim, self.df = dim, float(df)
        self._log_normaliser = (
            math.lgamma((self.df + dim) / 2)
            - math.lgamma(self.df / 2)
            - 0.5 * dim * math.log(self.df * math.pi)
        )

    def log_prob(self, z: torch.Tensor) -> torch.Tensor:
        """Log-density per frame: ``(..., D)`` -> ``(...)``."""
        exponent = -0.5 * (self.df + self.dim)
        return self._log_normaliser + exponent * torch.log1p((z**2).sum(dim=-1) / self.df)

    def sample(self, shape, temperature=1.0, generator=None, device=None, dtype=None):
        """``temperature * t``, ``t`` a draw of this distribution, of shape ``(*shape, D)``;
        zeros at temperature 0. Every number comes from ``generator``."""
        temperature, shape = check_temperature(temperature), _as_shape(shape)
        if temperature == 0:
            return torch.zeros(*shape, self.dim, device=device, dtype=dtype)
        eps = standard_normal((*shape, self.dim), generator, dtype=torch.float64)
        # torch.distributions draws from the global generator: seed a private copy of it from
        # ``generator``, so that the draw is reproducible and leaves the global stream alone.
        seed = int(torch.randint(2**62, (), generator=generator, device=eps.device))
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            chi_square = torch.distributions.Chi2(torch.tensor(self.df)).sample(shape)
        t = eps * torch.sqrt(self.df / chi_square.double().to(eps.device))[..., None]
        return (temperature * t).to(device=device, dtype=dtype or torch.get_default_dtype())

    def extra_repr(self) -> str:
        return f"dim={self.dim}, df={self.df}"
