"""Gaps in motion, where a tracker lost a limb: a simple fill, and the error of any fill.

A tracker that loses a keypoint loses the rotation of the limb that ends at it
(:mod:`data_synth.occlusion` makes such gaps, marked in a ``visible (T, 9)`` mask). The Flow-VAE
paper fills them with a denoising autoencoder before training
(:meth:`gesturelib.models.MotionDenoisingAutoencoder.fill`); the simpler fills it must beat are the
mean pose and :func:`interpolate_gaps`. :func:`limb_angle_error` scores a fill against the truth.
"""

from __future__ import annotations

import numpy as np
import torch

from gesturelib.pose_surface import limb_directions, project
from gesturelib.skeleton import NUM_JOINTS


def _checked(rotations, visible) -> tuple[np.ndarray, np.ndarray]:
    rotations = np.asarray(rotations, dtype=np.float64)
    visible = np.asarray(visible)
    if rotations.ndim != 3 or rotations.shape[1:] != (NUM_JOINTS, 6):
        raise ValueError(f"rotations must have shape (T, {NUM_JOINTS}, 6), got {rotations.shape}")
    if visible.shape != rotations.shape[:2] or visible.dtype != bool:
        raise ValueError(
            f"visible must be a bool mask of shape {rotations.shape[:2]}, got "
            f"{visible.dtype} {visible.shape}"
        )
    return rotations, visible


def interpolate_gaps(rotations, visible) -> np.ndarray:
    """Fill each hidden limb by linear interpolation in time, then return it to the pose surface.

    Each limb's 6 numbers are interpolated between the last frame that saw it and the next one
    (held at the value of the nearest seen frame before the first or after the last), and
    :func:`~gesturelib.pose_surface.project` makes them a rotation of that limb again.

    Args:
        rotations: ``(T, 9, 6)`` limb rotations; the values at hidden limbs are ignored.
        visible: ``(T, 9)`` bool, False where a limb was not seen.
    Returns:
        ``(T, 9, 6)``: the seen limbs as they were, the hidden ones filled (a limb never seen
        keeps its values, put back on the surface).
    """
    rotations, visible = _checked(rotations, visible)
    filled = rotations.copy()
    frames = np.arange(len(rotations))
    for limb in range(NUM_JOINTS):
        seen = visible[:, limb]
        if seen.all() or not seen.any():
            continue
        for number in range(6):
            filled[~seen, limb, number] = np.interp(
                frames[~seen], frames[seen], rotations[seen, limb, number]
            )
    on_surface = project(torch.from_numpy(filled)).numpy()
    return np.where(visible[..., None], rotations, on_surface)


def limb_angle_error(rotations, truth) -> np.ndarray:
    """Degrees between each limb's direction in ``rotations`` and in ``truth``, both
    ``(..., 9, 6)``: ``(..., 9)``."""
    directions = [
        limb_directions(torch.as_tensor(np.asarray(r, np.float64))) for r in (rotations, truth)
    ]
    cosine = (directions[0] * directions[1]).sum(-1).clamp(-1.0, 1.0)
    return torch.rad2deg(torch.arccos(cosine)).numpy()
