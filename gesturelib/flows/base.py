"""Base distributions of a flow: the simple density that the data is mapped onto.

A flow's log-likelihood is ``log p(x) = log p_Z(f(x)) + log|det df/dx|``; ``p_Z`` is the base.

* :class:`StandardNormal`: ``N(0, I)``, Glow's and MoGlow's choice.
* :class:`StudentT`: the multivariate Student's t with ``df`` degrees of freedom, location 0 and
  scale matrix ``I``, as in "studentising flows" (Alexanderson & Henter, 2020), which Ye et al.
  (2022) adopt for a more robust training. Its heavier tails make the log-likelihood of an outlier
  grow only logarithmically with its distance (quadratically for the Gaussian), so one bad frame
  cannot dominate a gradient step. As ``df -> inf`` it tends to ``N(0, I)``; for ``D = 1`` it is
  the univariate Student's t.

Both act on the last axis, the ``D`` features of one frame: ``log_prob`` maps ``(B, D)`` to
``(B,)`` and ``(B, T, D)`` to ``(B, T)``; a sequence's frames are independent under the base. ``sample(shape)`` returns
``(*shape, D)``.

**Temperature** scales a base sample: ``z = temperature * eps`` with ``eps`` a draw from the
base, i.e. it multiplies the standard deviation. ``temperature = 0`` returns the mode ``z = 0``
exactly (and draws nothing); it never means "use the default".
"""

from __future__ import annotations

import math

import torch
from torch import nn

from gesturelib.flows.checks import check_features


def _check_temperature(temperature: float) -> float:
    temperature = float(temperature)
    if not (math.isfinite(temperature) and temperature >= 0):
        raise ValueError(
            f"temperature must be a finite number >= 0 (0 gives the mode), got {temperature}"
        )
    return temperature


def _check_shape(shape) -> tuple[int, ...]:
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    if not all(isinstance(s, int) and s >= 0 for s in shape):
        raise ValueError(
            f"shape must be a tuple of non-negative ints such as (B,) or (B, T), got {shape}"
        )
    return shape


def sample_standard_gamma(
    concentration: float,
    shape: tuple[int, ...],
    generator: torch.Generator | None = None,
    device=None,
) -> torch.Tensor:
    """Draws from Gamma(concentration, rate 1), float64, shape ``shape``, from a torch generator.

    ``torch.distributions`` cannot take a ``torch.Generator``, so this is the rejection sampler of
    Marsaglia & Tsang (2000), vectorised: propose ``d * (1 + c * n)^3`` with ``n ~ N(0, 1)`` and
    accept with their squeeze test; rejected entries (a few percent) are drawn again. For a
    concentration ``a < 1`` it samples Gamma(a + 1) and multiplies by ``U^(1/a)``.
    """
    if not concentration > 0:
        raise ValueError(
            f"the concentration of a Gamma distribution must be positive, got {concentration}"
        )
    boosted = concentration < 1
    a = concentration + 1 if boosted else concentration
    d = a - 1 / 3
    c = 1 / math.sqrt(9 * d)
    count = math.prod(shape)
    out = torch.empty(count, dtype=torch.float64, device=device)
    pending = torch.arange(count, device=device)
    while pending.numel() > 0:
        n = torch.randn(pending.numel(), generator=generator, dtype=torch.float64, device=device)
        u = torch.rand(pending.numel(), generator=generator, dtype=torch.float64, device=device)
        v = (1 + c * n) ** 3
        log_v = torch.log(v.clamp_min(torch.finfo(torch.float64).tiny))
        accept = (v > 0) & (torch.log(u) < 0.5 * n**2 + d - d * v + d * log_v)
        out[pending[accept]] = d * v[accept]
        pending = pending[~accept]
    if boosted:
        u = torch.rand(count, generator=generator, dtype=torch.float64, device=device)
        out = out * u ** (1 / concentration)
    return out.reshape(shape)


class StandardNormal(nn.Module):
    """The standard normal ``N(0, I)`` over ``D`` features.

    Args:
        dim: number of features ``D``.
    """

    def __init__(self, dim: int):
        super().__init__()
        if dim < 1:
            raise ValueError(f"dim must be a positive number of features, got {dim}")
        self.dim = dim

    def log_prob(self, z: torch.Tensor) -> torch.Tensor:
        """``log N(z; 0, I)`` per frame: ``(B, D)`` -> ``(B,)``, ``(B, T, D)`` -> ``(B, T)``."""
        check_features(z, self.dim, name="z", sequence=None)
        return -0.5 * (z**2).sum(dim=-1) - 0.5 * self.dim * math.log(2 * math.pi)

    def sample(
        self,
        shape,
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        device=None,
        dtype=None,
    ) -> torch.Tensor:
        """``temperature * eps``, ``eps ~ N(0, I)``, of shape ``(*shape, D)``; zeros if
        ``temperature == 0``."""
        shape, temperature = _check_shape(shape), _check_temperature(temperature)
        if temperature == 0:
            return torch.zeros(*shape, self.dim, device=device, dtype=dtype)
        eps = torch.randn(*shape, self.dim, generator=generator, device=device, dtype=dtype)
        return temperature * eps

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
            The covariance is ``df / (df - 2) * I`` for ``df > 2``.
    """

    def __init__(self, dim: int, df: float):
        super().__init__()
        if dim < 1:
            raise ValueError(f"dim must be a positive number of features, got {dim}")
        if not (math.isfinite(df) and df > 0):
            raise ValueError(f"df (degrees of freedom) must be a finite positive number, got {df}")
        self.dim, self.df = dim, float(df)
        self._log_normaliser = (
            math.lgamma((self.df + dim) / 2)
            - math.lgamma(self.df / 2)
            - 0.5 * dim * math.log(self.df * math.pi)
        )

    def log_prob(self, z: torch.Tensor) -> torch.Tensor:
        """Log-density per frame: ``(B, D)`` -> ``(B,)``, ``(B, T, D)`` -> ``(B, T)``."""
        check_features(z, self.dim, name="z", sequence=None)
        squared_norm = (z**2).sum(dim=-1)
        return self._log_normaliser - 0.5 * (self.df + self.dim) * torch.log1p(
            squared_norm / self.df
        )

    def sample(
        self,
        shape,
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
        device=None,
        dtype=None,
    ) -> torch.Tensor:
        """``temperature * t``, ``t`` a draw of this distribution, of shape ``(*shape, D)``; zeros
        if ``temperature == 0``."""
        shape, temperature = _check_shape(shape), _check_temperature(temperature)
        if temperature == 0:
            return torch.zeros(*shape, self.dim, device=device, dtype=dtype)
        eps = torch.randn(*shape, self.dim, generator=generator, device=device, dtype=torch.float64)
        chi_square = 2 * sample_standard_gamma(self.df / 2, shape, generator, device)
        t = eps * torch.sqrt(self.df / chi_square)[..., None]
        return (temperature * t).to(dtype or torch.get_default_dtype())

    def extra_repr(self) -> str:
        return f"dim={self.dim}, df={self.df}"


BASES: dict[str, type[nn.Module]] = {"normal": StandardNormal, "student_t": StudentT}
