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
* Every function accepts any leading batch shape, ``(..., 6)`` or ``(..., 3, 3)`` or ``(..., 3)``.
* Inputs may be ``numpy.ndarray``, ``torch.Tensor`` or anything NumPy reads as an array (lists,
  tuples). The result is a tensor if any input is one (on its device, keeping its autograd
  graph), a NumPy array otherwise. Its dtype is the promoted floating dtype of the inputs;
  integer and boolean inputs count as NumPy's float64 (as ``np.mean`` does), integer tensors as
  PyTorch's default float dtype. Anything else (strings, complex numbers) raises ``TypeError``.
* What is not a rotation raises :class:`RotationError` naming the first bad index: a matrix
  whose rows are not orthonormal with determinant +1 (within :data:`ROTATION_TOLERANCE`), 6D
  vectors whose two halves are zero or parallel (they define no rotation), a zero axis or
  direction, NaN or infinite values.
"""

from __future__ import annotations

import functools
import inspect

import numpy as np
import torch

#: A matrix counts as a rotation when ``R R^T`` is within this of the identity (entrywise) and
#: its determinant within this of +1: loose enough for float32 round-off, tight enough to catch
#: any scaled, sheared or reflected matrix.
ROTATION_TOLERANCE = 1e-3
#: Two 3-vectors are parallel when the sine of the angle between them is below this: Gram-Schmidt
#: then has no second direction to keep (float32 round-off of exactly parallel vectors is ~1e-7).
PARALLEL_TOLERANCE = 1e-6
#: Added to norms before dividing where a value is known not to vanish, against round-off.
EPS = 1e-8


class RotationError(ValueError):
    """An input that is not, or does not define, a rotation; ``index`` is the first bad one."""

    def __init__(self, message: str, index: tuple[int, ...] = ()):
        super().__init__(message)
        self.index = index


def as_real_array(value, name: str):
    """``value`` as a floating NumPy array or tensor (see the module docstring for the rules)."""
    if isinstance(value, torch.Tensor):
        if value.is_complex():
            raise TypeError(f"{name} must hold real numbers, got {value.dtype}")
        return value if value.is_floating_point() else value.to(torch.get_default_dtype())
    try:
        array = np.asarray(value)
    except ValueError as error:  # e.g. ragged nested lists
        raise TypeError(f"{name} must be an array of real numbers: {error}") from error
    if array.dtype.kind in "biu":
        return array.astype(np.float64)
    if array.dtype.kind != "f" or array.dtype.itemsize > 8:
        raise TypeError(f"{name} must hold real numbers, got dtype {array.dtype}")
    return array


def _array_function(fn):
    """Run a torch implementation on array-like arguments; return the kind it was given.

    The arguments become tensors of their promoted floating dtype, on the device of the first
    tensor among them; a Python number after the first argument takes that dtype, as in NumPy
    and PyTorch.
    """
    names = list(inspect.signature(fn).parameters)

    @functools.wraps(fn)
    def wrapper(*args):
        values = [
            value
            if position > 0 and isinstance(value, (int, float))
            else as_real_array(value, name)
            for position, (value, name) in enumerate(zip(args, names, strict=False))
        ]
        values = [
            torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v
            for v in values
        ]
        tensors = [v for v in values if isinstance(v, torch.Tensor)]
        dtype = functools.reduce(torch.promote_types, (t.dtype for t in tensors))
        given = [a for a in args if isinstance(a, torch.Tensor)]
        device = given[0].device if given else torch.device("cpu")
        result = fn(
            *(
                v.to(device=device, dtype=dtype) if isinstance(v, torch.Tensor) else v
                for v in values
            )
        )
        return result if given else result.numpy()

    return wrapper


def check_trailing_shape(x, trailing: tuple[int, ...], name: str) -> None:
    """Raise ``ValueError`` unless ``x.shape`` ends with ``trailing``.

    The message states the expected shape, e.g. ``rot6d must have shape (..., 9, 6), got (8, 6)``.
    """
    shape = tuple(x.shape)
    if len(shape) < len(trailing) or shape[len(shape) - len(trailing) :] != trailing:
        expected = "(..., " + ", ".join(str(d) for d in trailing) + ")"
        raise ValueError(f"{name} must have shape {expected}, got {shape}")


def _at(name: str, index: tuple[int, ...]) -> str:
    """``rot6d[3, 2]`` for an index into a batch, ``rot6d`` for an unbatched input."""
    return f"{name}[{', '.join(map(str, index))}]" if index else name


def _first_bad(bad: torch.Tensor) -> tuple[int, ...] | None:
    """Index of the first True of a boolean tensor, or None when there is none."""
    if not bool(bad.any()):
        return None
    return tuple(int(i) for i in np.unravel_index(int(bad.reshape(-1).nonzero()[0, 0]), bad.shape))


def _check_finite(x: torch.Tensor, name: str, item_dims: int) -> None:
    index = _first_bad(~torch.isfinite(x).flatten(-item_dims).all(-1))
    if index is not None:
        raise RotationError(f"{_at(name, index)} holds NaN or infinite values", index)


def check_rotation_matrix(matrix: torch.Tensor, name: str) -> None:
    """Refuse matrices ``(..., 3, 3)`` that are not rotations (see :data:`ROTATION_TOLERANCE`)."""
    _check_finite(matrix, name, 2)
    with torch.no_grad():
        eye = torch.eye(3, dtype=matrix.dtype, device=matrix.device)
        off = (matrix @ matrix.transpose(-1, -2) - eye).abs().amax(dim=(-1, -2))
        det = torch.linalg.det(matrix) if matrix.numel() else off
        index = _first_bad((off > ROTATION_TOLERANCE) | ((det - 1).abs() > ROTATION_TOLERANCE))
    if index is not None:
        raise RotationError(
            f"{_at(name, index)} is not a rotation: R R^T differs from the identity by "
            f"{float(off[index]):.3g} and its determinant is {float(det[index]):.3g} (a rotation "
            f"has orthonormal rows and determinant +1, within {ROTATION_TOLERANCE:g}); to turn "
            "any matrix into the nearest valid 6D rotation, use normalize_rot6d(matrix[..., :2, "
            ":].reshape(*matrix.shape[:-2], 6))",
            index,
        )


@_array_function
def rot6d_to_matrix(rot6d):
    """6D representation ``(..., 6)`` -> rotation matrix ``(..., 3, 3)`` by Gram-Schmidt.

    Any 6 numbers whose two 3-vectors are not parallel give a valid rotation (orthonormal rows,
    determinant +1): row 1 is the first vector normalised, row 2 the second with its component
    along row 1 removed and then normalised, row 3 their cross product.

    Raises:
        RotationError: where the two 3-vectors are zero or parallel (sine of their angle below
            :data:`PARALLEL_TOLERANCE`), or not finite; they define no rotation.
    """
    check_trailing_shape(rot6d, (6,), "rot6d")
    return _gram_schmidt(rot6d, "rot6d")


def _gram_schmidt(rot6d: torch.Tensor, name: str) -> torch.Tensor:
    """The rotation ``(..., 3, 3)`` of 6D vectors ``(..., 6)``; RotationError if they define none.

    The check costs little: what is left of the second vector once its part along the first is
    removed has length ``|a2| sin(angle)``, so zero, parallel and NaN inputs all show there.
    """
    a1, a2 = rot6d[..., :3], rot6d[..., 3:]
    b1 = a1 / a1.norm(dim=-1, keepdim=True)
    b2 = a2 - (b1 * a2).sum(dim=-1, keepdim=True) * b1
    b2_length = b2.norm(dim=-1, keepdim=True)
    with torch.no_grad():
        index = _first_bad(~(b2_length[..., 0] > PARALLEL_TOLERANCE * a2.norm(dim=-1)))
    if index is not None:
        _check_finite(rot6d, name, 1)
        raise RotationError(
            f"{_at(name, index)} = {rot6d[index].tolist()}: its two 3-vectors are zero or "
            "parallel, so they define no rotation; give two vectors that are not parallel, "
            "such as the first two rows of a rotation matrix",
            index,
        )
    b2 = b2 / b2_length
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-2)


@_array_function
def matrix_to_rot6d(matrix):
    """Rotation matrix ``(..., 3, 3)`` -> 6D representation ``(..., 6)`` (its first two rows).

    Raises:
        RotationError: naming the first matrix that is not a rotation (see
            :data:`ROTATION_TOLERANCE`): its first two rows would not be a rotation's.
    """
    check_trailing_shape(matrix, (3, 3), "matrix")
    check_rotation_matrix(matrix, "matrix")
    return _first_two_rows(matrix)


def _first_two_rows(matrix: torch.Tensor) -> torch.Tensor:
    return matrix[..., :2, :].reshape(*matrix.shape[:-2], 6)


@_array_function
def normalize_rot6d(rot6d):
    """Project arbitrary 6D vectors ``(..., 6)`` onto the valid ones (orthonormal first two rows).

    Raises:
        RotationError: as :func:`rot6d_to_matrix`.
    """
    check_trailing_shape(rot6d, (6,), "rot6d")
    return _first_two_rows(_gram_schmidt(rot6d, "rot6d"))


@_array_function
def shortest_arc(source, target):
    """The rotation of smallest angle that turns direction ``source`` into direction ``target``.

    Args:
        source: ``(..., 3)`` vectors (need not be unit length, but not zero).
        target: ``(..., 3)`` vectors, broadcastable against ``source``.
    Returns:
        ``(..., 3, 3)`` rotation matrices ``R`` with ``R @ source_hat == target_hat``. Its axis is
        ``source x target``; no twist about the limb is added. For opposite directions (a 180 degree
        turn, where the axis is not unique) it turns about an axis perpendicular to ``source``.
    Raises:
        RotationError: for a zero (or non-finite) vector, which has no direction.
    """
    check_trailing_shape(source, (3,), "source")
    check_trailing_shape(target, (3,), "target")
    source, target = torch.broadcast_tensors(source, target)
    u = source / _direction_norm(source, "source")
    v = target / _direction_norm(target, "target")
    cos = (u * v).sum(dim=-1)

    # Near-opposite directions: replace v by a unit vector perpendicular to u and compose two
    # 90 degree turns (u -> w -> -u), which is the 180 degree turn about u x w.
    opposite = cos < -1.0 + 1e-6
    if bool(opposite.any()):
        helper = torch.zeros_like(u)
        helper[..., 0] = 1.0
        # If u is (nearly) along x, use y as the helper axis instead.
        along_x = u[..., 0].abs() > 0.9
        helper[along_x] = torch.tensor([0.0, 1.0, 0.0], dtype=u.dtype, device=u.device)
        w = torch.linalg.cross(u, helper, dim=-1)
        w = w / w.norm(dim=-1, keepdim=True).clamp_min(EPS)
        eye = torch.eye(3, dtype=u.dtype, device=u.device)
        half_turn = 2.0 * w[..., :, None] * w[..., None, :] - eye
        regular = _rodrigues_from_unit_vectors(u, torch.where(opposite[..., None], w, v))
        return torch.where(opposite[..., None, None], half_turn, regular)
    return _rodrigues_from_unit_vectors(u, v)


def _direction_norm(vectors: torch.Tensor, name: str) -> torch.Tensor:
    """Norms ``(..., 1)`` of vectors ``(..., 3)``; RotationError where one is zero or not finite."""
    norm = vectors.norm(dim=-1, keepdim=True)
    with torch.no_grad():
        index = _first_bad(~((norm[..., 0] > 0) & (norm[..., 0] < float("inf"))))
    if index is not None:
        _check_finite(vectors, name, 1)
        raise RotationError(f"{_at(name, index)} is a zero vector: it has no direction", index)
    return norm


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


@_array_function
def axis_angle_to_matrix(axis, angle):
    """Rotation of ``angle`` radians about ``axis`` (Rodrigues' formula).

    Args:
        axis: ``(..., 3)`` rotation axes (normalised here; a zero axis raises RotationError).
        angle: ``(...)`` angles in radians, broadcastable against ``axis[..., 0]``.
    Returns:
        ``(..., 3, 3)`` rotation matrices.
    """
    check_trailing_shape(axis, (3,), "axis")
    angle = torch.as_tensor(angle, dtype=axis.dtype, device=axis.device)
    if not bool(torch.isfinite(angle).all()):
        raise RotationError("angle holds NaN or infinite values: no rotation has such an angle")
    try:
        axis, _ = torch.broadcast_tensors(axis, angle[..., None])
    except RuntimeError:
        raise ValueError(
            f"angle {tuple(angle.shape)} must broadcast against axis[..., 0] "
            f"{tuple(axis.shape[:-1])}"
        ) from None
    angle = angle.expand(axis.shape[:-1])
    k = axis / _direction_norm(axis, "axis")
    skew = _skew(k)
    sin, cos = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device).expand_as(skew)
    return eye + sin * skew + (1.0 - cos) * (skew @ skew)


@_array_function
def geodesic_angle(matrix_a, matrix_b):
    """Angle in radians of the rotation taking ``matrix_a`` to ``matrix_b``, both ``(..., 3, 3)``.

    Raises:
        RotationError: if either is not a rotation (see :data:`ROTATION_TOLERANCE`).
    """
    check_trailing_shape(matrix_a, (3, 3), "matrix_a")
    check_trailing_shape(matrix_b, (3, 3), "matrix_b")
    check_rotation_matrix(matrix_a, "matrix_a")
    check_rotation_matrix(matrix_b, "matrix_b")
    relative = matrix_a.transpose(-1, -2) @ matrix_b
    cos = (relative.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0
    return torch.arccos(cos.clamp(-1.0, 1.0))
