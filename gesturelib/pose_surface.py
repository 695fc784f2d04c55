"""The surface poses lie on inside their 54 numbers, and noise that gives it thickness.

A pose is 9 limb rotations in the 6D representation. Each of our limb rotations is the shortest
arc from the T-pose limb to the limb (no twist about it), so it is fixed by the limb's direction:
a point on a sphere, 2 degrees of freedom. The 54 numbers of a pose therefore lie on an
18-dimensional surface; at every pose the other 36 directions leave it.

A density over 54 numbers is infinite on such a surface: a flow trained on exact poses lowers its
loss without end by squeezing the surface thinner, and learns nothing about poses. It needs data
with thickness, i.e. noise, and the question is which noise:

* noise in all 54 directions (as image flows dequantise pixels) also moves the poses *along* the
  surface: the limbs jitter, and so do the samples of a model trained on it;
* noise only in the directions that change no limb's direction (:class:`SurfaceNoise`, the
  default: 4 of each limb's 6 numbers, 36 in all) leaves the surface just as well, and moves no
  keypoint, because forward kinematics reads only each limb's direction. Returning a sample to
  the surface (:func:`project`, which keeps every limb's direction) removes such noise.

Both are measured in normalised pose units (the models' inputs), so the noise module holds the
pose statistics it was trained with. Which directions move a limb is found by finite differences
(:func:`direction_jacobian`).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from gesturelib.rotations import rot6d_to_matrix, shortest_arc
from gesturelib.runtime import standard_normal
from gesturelib.skeleton import NUM_JOINTS, POSE_DIM, T_POSE_OFFSETS

#: The unit direction of each T-pose limb, ``(9, 3)``.
T_POSE_DIRECTIONS = T_POSE_OFFSETS / np.linalg.norm(T_POSE_OFFSETS, axis=1, keepdims=True)


def _rot6d_of_directions(directions: torch.Tensor) -> torch.Tensor:
    """The 6D rotations ``(..., 9, 6)`` of limbs pointing along unit ``directions``
    ``(..., 9, 3)``: the first two rows of the shortest arc from each T-pose limb.

    Generation calls this every frame, so it is the closed form of Rodrigues' formula for unit
    vectors, ``R = c I + [k]x + k k^T / (1 + c)`` with ``k = s x d`` and ``c = s . d``, a handful
    of operations; a limb turned right round (``c = -1``, no unique axis) goes to
    :func:`~gesturelib.rotations.shortest_arc`.
    """
    source = torch.as_tensor(T_POSE_DIRECTIONS, dtype=directions.dtype, device=directions.device)
    cos = (source * directions).sum(-1, keepdim=True)  # (..., 9, 1)
    if bool((cos < -1.0 + 1e-6).any()):
        return shortest_arc(source, directions)[..., :2, :].flatten(-2)
    k = torch.linalg.cross(source.expand_as(directions), directions, dim=-1)
    kx, ky, kz = k.unbind(-1)
    # Rows 0 and 1 of c I + [k]x, then + (k_0, k_1)^T k / (1 + c).
    rows = torch.cat([cos, -kz[..., None], ky[..., None], kz[..., None], cos, -kx[..., None]], -1)
    rows = rows + (k[..., :2, None] * k[..., None, :]).flatten(-2) / (1.0 + cos)
    return rows


def limb_directions(rot6d: torch.Tensor) -> torch.Tensor:
    """The unit direction of every limb, ``(..., 9, 3)``, from rotations ``(..., 9, 6)``."""
    source = torch.as_tensor(T_POSE_DIRECTIONS, dtype=rot6d.dtype, device=rot6d.device)
    return (rot6d_to_matrix(rot6d) @ source[:, :, None])[..., 0]


def project(rot6d: torch.Tensor) -> torch.Tensor:
    """The pose on the surface ``(..., 9, 6)`` whose limbs point where those of ``rot6d`` do:
    any 6 numbers per limb become the shortest-arc rotation of their limb's direction."""
    return _rot6d_of_directions(limb_directions(rot6d))


def direction_jacobian(rot6d: torch.Tensor, step: float = 1e-4) -> torch.Tensor:
    """How each limb's direction moves with its 6 numbers, ``(..., 9, 2, 6)``, in float64.

    Row ``k`` is the derivative of the limb direction along the ``k``-th of two orthogonal
    tangents of the sphere at it (central differences). The 6 numbers of a limb move it in only
    these 2 ways; the other 4 directions of its 6 numbers change no limb at all.
    """
    rot6d = rot6d.double()
    directions = limb_directions(rot6d)
    helper = torch.zeros_like(directions)
    along_x = directions[..., 0].abs() > 0.9
    helper[..., 0], helper[..., 1] = (~along_x).double(), along_x.double()
    first = torch.linalg.cross(directions, helper, dim=-1)
    first = first / first.norm(dim=-1, keepdim=True)
    tangents = torch.stack([first, torch.linalg.cross(directions, first, dim=-1)], dim=-2)
    columns = []
    for number in range(6):
        change = torch.zeros(6, dtype=torch.float64, device=rot6d.device)
        change[number] = step
        moved = limb_directions(rot6d + change) - limb_directions(rot6d - change)
        columns.append((tangents @ moved[..., None])[..., 0] / (2 * step))  # (..., 9, 2)
    return torch.stack(columns, dim=-1)


class SurfaceNoise(nn.Module):
    """Gaussian noise for normalised poses ``(..., 54)``: off the surface only, or everywhere.

    Args:
        std: standard deviation in normalised pose units (0 turns the noise off).
        across_only: noise only in the 36 directions that move no limb (True), or in all 54.
    Buffers ``pose_mean`` and ``pose_std`` (54,) hold the normalisation of the poses it is given;
    set them with :meth:`set_statistics` (they are saved with the model).
    """

    def __init__(self, std: float, across_only: bool = True):
        super().__init__()
        self.std, self.across_only = float(std), across_only
        self.register_buffer("pose_mean", torch.zeros(POSE_DIM))
        self.register_buffer("pose_std", torch.ones(POSE_DIM))
        self.register_buffer("calibrated", torch.tensor(False))

    def set_statistics(self, normaliser) -> None:
        """Take the pose normalisation of a :class:`~gesturelib.data.Normaliser`."""
        self.pose_mean.copy_(torch.as_tensor(normaliser.pose_mean, dtype=self.pose_mean.dtype))
        self.pose_std.copy_(torch.as_tensor(normaliser.pose_std, dtype=self.pose_std.dtype))
        self.calibrated.fill_(True)

    @torch.no_grad()
    def forward(self, pose: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """Noise of the shape of ``pose`` (normalised, ``(..., 54)``), to add to it."""
        noise = standard_normal(pose.shape, generator, pose.device, torch.float64) * self.std
        if not self.across_only or self.std == 0:
            return noise.to(pose.dtype)
        if not self.calibrated:
            raise RuntimeError(
                "noise off the pose surface needs the poses' normalisation: build the model with "
                "the Normaliser of its training data (e.g. MoGlow(config, normaliser))"
            )
        scale = self.pose_std.double().reshape(NUM_JOINTS, 6)
        raw = (pose.double() * self.pose_std + self.pose_mean).unflatten(-1, (NUM_JOINTS, 6))
        # The 2 directions (per limb, in normalised units) in which the numbers move the limb:
        moving = (direction_jacobian(raw) * scale[..., None, :]).transpose(-1, -2)
        basis, _ = torch.linalg.qr(moving)  # (..., 9, 6, 2), orthonormal columns
        noise = noise.unflatten(-1, (NUM_JOINTS, 6))
        along = basis @ (basis.transpose(-1, -2) @ noise[..., None])
        return (noise - along[..., 0]).flatten(-2).to(pose.dtype)

    def extra_repr(self) -> str:
        return f"std={self.std}, across_only={self.across_only}"
