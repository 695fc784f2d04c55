"""Rotation representations: the continuous 6D representation and rotation matrices.

Why 6D?  Euler angles jump by 360 degrees and suffer gimbal lock; quaternions double-cover
rotations (q and -q are the same rotation), so any continuous network output must "choose" a sign
and jumps somewhere. Zhou et al. (2019) showed that the first two rows of the rotation matrix are a
continuous representation: a network can output any 6 numbers and Gram-Schmidt turns them into a
valid rotation. The Flow-VAE paper (Taylor et al. 2021) represents each limb this way.

Conventions
-----------
* A rotation matrix ``R`` acts on column vectors: ``v_rotated = R @ v``.
* The 6D representation is the first two *rows* of ``R``, flattened: ``[R00 R01 R02 R10 R11 R12]``.
  The third row is their cross product (rows of a rotation are orthonormal and right-handed).
* Every function accepts any leading batch shape, ``(..., 6)`` or ``(..., 3, 3)`` or ``(..., 3)``,
  and either a ``numpy.ndarray`` or a ``torch.Tensor``; it returns the same kind it was given
  (dtype preserved). Torch inputs keep their autograd graph.
"""

from __future__ import annotations

import functools

import numpy as np
import torch

#: Added to norms before dividing, so that degenerate inputs give finite (if meaningless) output.
EPS = 1e-8


def _numpy_in_numpy_out(fn):
    """Run a torch implementation on numpy arrays too: convert in, convert the result back."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        given_numpy = any(isinstance(a, np.ndarray) for a in args)
        converted = [
            torch.from_numpy(np.ascontiguousarray(a)) if isinstance(a, np.ndarray) else a
            for a in args
        ]
        result = fn(*converted, **kwargs)
        return result.numpy() if given_numpy else result

    return wrapper


def check_trailing_shape(x, trailing: tuple[int, ...], name: str) -> None:
    """Raise ``ValueError`` unless ``x.shape`` ends with ``trailing``.

    The message states the expected shape, e.g. ``rot6d must have shape (..., 9, 6), got (8, 6)``.
    """
    shape = tuple(x.shape)
    if len(shape) < len(trailing) or shape[len(shape) - len(trailing) :] != trailing:
        expected = "(..., " + ", ".join(str(d) for d in trailing) + ")"
        raise ValueError(f"{name} must have shape {expected}, got {shape}")


@_numpy_in_numpy_out
def rot6d_to_matrix(rot6d):
    """6D representation ``(..., 6)`` -> rotation matrix ``(..., 3, 3)`` by Gram-Schmidt.

    Any 6 numbers whose two 3-vectors are not parallel give a valid rotation (orthonormal rows,
    determinant +1): row 1 is the first vector normalised, row 2 the second with its component
    along row 1 removed and then normalised, row 3 their cross product.
    """
    check_trailing_shape(rot6d, (6,), "rot6d")
    a1, a2 = rot6d[..., :3], rot6d[..., 3:]
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(EPS)
    b2 = a2 - (b1 * a2).sum(dim=-1, keepdim=True) * b1
    b2 = b2 / b2.norm(dim=-1, keepdim=True).clamp_min(EPS)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-2)


@_numpy_in_numpy_out
def matrix_to_rot6d(matrix):
    """Rotation matrix ``(..., 3, 3)`` -> 6D representation ``(..., 6)`` (its first two rows)."""
    check_trailing_shape(matrix, (3, 3), "matrix")
    return matrix[..., :2, :].reshape(*matrix.shape[:-2], 6)


@_numpy_in_numpy_out
def normalize_rot6d(rot6d):
    """Project arbitrary 6D vectors ``(..., 6)`` onto the valid ones (orthonormal first two rows)."""
    return matrix_to_rot6d(rot6d_to_matrix(rot6d))


@_numpy_in_numpy_out
def shortest_arc(source, target):
    """The rotation of smallest angle that turns direction ``source`` into direction ``target``.

    Args:
        source: ``(..., 3)`` vectors (need not be unit length).
        target: ``(..., 3)`` vectors, broadcastable against ``source``.
    Returns:
        ``(..., 3, 3)`` rotation matrices ``R`` with ``R @ source_hat == target_hat``. Its axis is
        ``source x target``; no twist about the limb is added. For opposite directions (a 180 degree
        turn, where the axis is not unique) it turns about an axis perpendicular to ``source``.
    """
    check_trailing_shape(source, (3,), "source")
    check_trailing_shape(target, (3,), "target")
    source, target = torch.broadcast_tensors(source, target)
    u = source / source.norm(dim=-1, keepdim=True).clamp_min(EPS)
    v = target / target.norm(dim=-1, keepdim=True).clamp_min(EPS)
    cos = (u * v).sum(dim=-1)

    # Near-opposite directions: replace v by a unit vector perpendicular to u and compose two
    # 90 degree turns (u -> w -> -u), which is the 180 degree turn about u x w.
    opposite = cos < -1.0 + 1e-6
    if bool(opposite.any()):
        helper = torch.zeros_like(u)
        helper[..., 0] = 1.0
        # If u is (nearly) along x, use y as the helper axis instead.
        along_x = u[..., 0].abs() > 0.9
        helper[along_x] = torch.tensor([0.0, 1.0, 0.0], dtype=u.dtype)
        w = torch.linalg.cross(u, helper, dim=-1)
        w = w / w.norm(dim=-1, keepdim=True).clamp_min(EPS)
        half_turn = 2.0 * w[..., :, None] * w[..., None, :] - torch.eye(3, dtype=u.dtype)
        regular = _rodrigues_from_unit_vectors(u, torch.where(opposite[..., None], w, v))
        return torch.where(opposite[..., None, None], half_turn, regular)
    return _rodrigues_from_unit_vectors(u, v)


def _skew(k):
    """Cross-product matrix ``(..., 3, 3)`` of ``k`` ``(..., 3)``: ``_skew(k) @ v == k x v``."""
    zero = torch.zeros_like(k[..., 0])
    return torch.stack(
        [
            torch.stack([zero, -k[..., 2], k[..., 1]], dim=-1),
            torch.stack([k[..., 2], zero, -k[..., 0]], dim=-1),
            torch.stack([-k[..., 1], k[..., 0], zero], dim=-1),
        ],
        dim=-2,
    )


def _rodrigues_from_unit_vectors(u, v):
    """``R = I + [k]x + [k]x^2 / (1 + cos)`` with ``k = u x v``: valid unless ``u = -v``."""
    k = torch.linalg.cross(u, v, dim=-1)
    cos = (u * v).sum(dim=-1)
    skew = _skew(k)
    eye = torch.eye(3, dtype=u.dtype, device=u.device).expand_as(skew)
    return eye + skew + (skew @ skew) / (1.0 + cos)[..., None, None].clamp_min(EPS)


@_numpy_in_numpy_out
def axis_angle_to_matrix(axis, angle):
    """Rotation of ``angle`` radians about ``axis`` (Rodrigues' formula).

    Args:
        axis: ``(..., 3)`` rotation axes (normalised here).
        angle: ``(...)`` angles in radians, broadcastable against ``axis[..., 0]``.
    Returns:
        ``(..., 3, 3)`` rotation matrices.
    """
    check_trailing_shape(axis, (3,), "axis")
    angle = torch.as_tensor(angle, dtype=axis.dtype)
    axis, _ = torch.broadcast_tensors(axis, angle[..., None])
    angle = angle.expand(axis.shape[:-1])
    k = axis / axis.norm(dim=-1, keepdim=True).clamp_min(EPS)
    skew = _skew(k)
    sin, cos = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    eye = torch.eye(3, dtype=axis.dtype).expand_as(skew)
    return eye + sin * skew + (1.0 - cos) * (skew @ skew)


@_numpy_in_numpy_out
def geodesic_angle(matrix_a, matrix_b):
    """Angle in radians of the rotation taking ``matrix_a`` to ``matrix_b``, both ``(..., 3, 3)``."""
    check_trailing_shape(matrix_a, (3, 3), "matrix_a")
    check_trailing_shape(matrix_b, (3, 3), "matrix_b")
    relative = matrix_a.transpose(-1, -2) @ matrix_b
    cos = (relative.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    return torch.arccos(cos.clamp(-1.0, 1.0))
