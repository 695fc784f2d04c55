"""Two-dimensional toy densities: data a person can picture, to watch a flow learn.

Each sampler draws ``n`` independent points ``(n, 2)`` (float32 torch tensors) and takes a
``generator``: a ``torch.Generator``, an int seed, or None for torch's global generator. The same
seed gives the same points.

* :func:`two_moons`: two interleaved half circles with Gaussian noise (curved, two components).
* :func:`eight_gaussians`: a ring of 8 narrow Gaussians (well-separated modes).
* :func:`checkerboard`: uniform on 8 of the 16 unit squares of ``[-2, 2]^2`` (sharp edges).
* :func:`rotated_crescent`: a *conditional* density: a crescent whose direction is the condition.

The ring and the checkerboard have closed-form log-densities (:func:`eight_gaussians_log_prob`,
:func:`checkerboard_log_prob`), so the best achievable negative log-likelihood (the entropy) is
known. All densities have a spread of order 1 so that no model needs to normalise its input.
"""

from __future__ import annotations

import math

import torch


def as_generator(generator: torch.Generator | int | None) -> torch.Generator | None:
    """Turn an int seed into a fresh ``torch.Generator``; pass a generator or None through."""
    if generator is None or isinstance(generator, torch.Generator):
        return generator
    if isinstance(generator, int):
        return torch.Generator().manual_seed(generator)
    raise TypeError(f"generator must be a torch.Generator, an int seed or None, got {generator!r}")


def _check_n(n: int) -> None:
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n must be a positive number of samples, got {n!r}")


def two_moons(n: int, noise: float = 0.1, generator: torch.Generator | int | None = None):
    """Two interleaving half circles of radius 2, with isotropic Gaussian noise.

    Each point picks a moon with probability 1/2 and an angle uniformly along it; the moons are
    those of scikit-learn's ``make_moons``, scaled by 2 and centred at the origin.

    Args:
        n: number of points.
        noise: standard deviation of the Gaussian noise added to every coordinate.
        generator: torch generator or int seed.
    Returns:
        ``(n, 2)`` float32.
    """
    _check_n(n)
    g = as_generator(generator)
    angle = math.pi * torch.rand(n, generator=g)
    lower = torch.rand(n, generator=g) < 0.5
    upper_moon = torch.stack([torch.cos(angle), torch.sin(angle)], dim=1)
    lower_moon = torch.stack([1 - torch.cos(angle), 0.5 - torch.sin(angle)], dim=1)
    points = torch.where(lower[:, None], lower_moon, upper_moon)
    points = 2 * (points - torch.tensor([0.5, 0.25]))
    return points + noise * torch.randn(n, 2, generator=g)


def eight_gaussians(
    n: int, radius: float = 2.0, std: float = 0.2, generator: torch.Generator | int | None = None
):
    """A mixture of 8 equally likely Gaussians ``N(c_k, std^2 I)`` with centres on a circle.

    Args:
        n: number of points.
        radius: radius of the circle of centres ``c_k = radius * (cos(k pi/4), sin(k pi/4))``.
        std: standard deviation of each component.
        generator: torch generator or int seed.
    Returns:
        ``(n, 2)`` float32.
    """
    _check_n(n)
    g = as_generator(generator)
    component = torch.randint(0, 8, (n,), generator=g)
    return _ring_centres(radius)[component] + std * torch.randn(n, 2, generator=g)


def eight_gaussians_log_prob(
    x: torch.Tensor, radius: float = 2.0, std: float = 0.2
) -> torch.Tensor:
    """Exact log-density of :func:`eight_gaussians`: ``(N, 2)`` -> ``(N,)``."""
    _check_points(x)
    centres = _ring_centres(radius).to(x)
    squared = ((x[:, None, :] - centres) ** 2).sum(dim=-1)  # (N, 8)
    log_component = -squared / (2 * std**2) - math.log(2 * math.pi * std**2)
    return torch.logsumexp(log_component, dim=1) - math.log(8)


def checkerboard(n: int, generator: torch.Generator | int | None = None):
    """Uniform on the 8 "black" unit squares of a 4 x 4 board on ``[-2, 2]^2``.

    A square ``[i, i+1) x [j, j+1)`` is black when ``i + j`` is even. The density is 1/8 there and
    0 elsewhere: its edges are discontinuities that a smooth flow can only approximate.

    Args:
        n: number of points.
        generator: torch generator or int seed.
    Returns:
        ``(n, 2)`` float32.
    """
    _check_n(n)
    g = as_generator(generator)
    first = 4 * torch.rand(n, generator=g) - 2
    column = torch.floor(first)
    # Of the 4 squares in this column, pick one of the 2 black ones: j = -2 + 2k + (i mod 2).
    row = -2 + 2 * torch.randint(0, 2, (n,), generator=g) + torch.remainder(column, 2)
    second = row + torch.rand(n, generator=g)
    return torch.stack([first, second], dim=1)


def checkerboard_log_prob(x: torch.Tensor) -> torch.Tensor:
    """Exact log-density of :func:`checkerboard`: ``(N, 2)`` -> ``(N,)``; ``-inf`` off the board."""
    _check_points(x)
    inside = ((x >= -2) & (x < 2)).all(dim=1)
    black = torch.remainder(torch.floor(x[:, 0]) + torch.floor(x[:, 1]), 2) == 0
    log_density = torch.full_like(x[:, 0], -math.log(8))
    return torch.where(inside & black, log_density, torch.full_like(log_density, -math.inf))


def rotated_crescent(
    n: int,
    angle: float | torch.Tensor | None = None,
    generator: torch.Generator | int | None = None,
):
    """A conditional density: a crescent (an arc of a ring) pointing in the direction ``angle``.

    Given the angle ``a``, a point lies at polar angle ``a + u``, ``u ~ U(-1, 1)`` radian, and
    radius ``2 + 0.15 e``, ``e ~ N(0, 1)``. The condition given to a model is
    ``(cos a, sin a)``, which is continuous in ``a``. Marginally over uniform angles the points
    fill a ring; a conditional flow must learn to put each crescent where its condition says.

    Args:
        n: number of points.
        angle: the direction in radians: a float (the same for all points), a tensor ``(n,)``,
            or None to draw each uniformly in ``[0, 2 pi)``.
        generator: torch generator or int seed.
    Returns:
        ``(points, cond)``: points ``(n, 2)`` and conditions ``(n, 2)``, float32.
    """
    _check_n(n)
    g = as_generator(generator)
    if angle is None:
        angle = 2 * math.pi * torch.rand(n, generator=g)
    angle = torch.as_tensor(angle, dtype=torch.float32).expand(n)
    polar = angle + (2 * torch.rand(n, generator=g) - 1)
    radius = 2 + 0.15 * torch.randn(n, generator=g)
    points = radius[:, None] * torch.stack([torch.cos(polar), torch.sin(polar)], dim=1)
    cond = torch.stack([torch.cos(angle), torch.sin(angle)], dim=1)
    return points, cond


#: The unconditional samplers by name, each ``sampler(n, generator=...) -> (n, 2)``.
TOY_DENSITIES = {
    "two_moons": two_moons,
    "eight_gaussians": eight_gaussians,
    "checkerboard": checkerboard,
}


def _ring_centres(radius: float) -> torch.Tensor:
    angles = torch.arange(8) * (math.pi / 4)
    return radius * torch.stack([torch.cos(angles), torch.sin(angles)], dim=1)


def _check_points(x) -> None:
    if not isinstance(x, torch.Tensor) or x.dim() != 2 or x.shape[1] != 2:
        shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"x must be a tensor of 2D points of shape (N, 2), got {shape}")
