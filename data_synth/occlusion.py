"""A tracker that loses keypoints: which of the agent's limbs a camera fails to see, and when.

Motion estimated from video has gaps: a wrist passes behind the body or out of the picture, an
elbow hides behind the other arm. The Flow-VAE paper's data had such gaps and filled them with a
denoising autoencoder before any model saw them (notebook 06). :func:`occlude` gives our motion
gaps of the same kind, so that a fill can be measured against the truth the generator keeps.

* A lost keypoint hides the rotation of its limb, the limb that ends at it (a lost wrist hides
  the forearm).
* Gaps come in bursts: each keypoint is lost at a rate per second (:data:`LOSS_RATE_PER_S`: the
  wrists most often, since they move most and furthest from the body), for 0.1 to 0.8 s.
* The result marks hidden limbs in a ``visible (T, 9)`` mask and holds the T-pose's rotation there
  (a valid rotation: never NaN), with positions by forward kinematics, as a tracker that returns
  a default for what it lost.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from data_synth.config import check_value
from gesturelib.skeleton import KEYPOINTS, forward_kinematics

#: How often each keypoint is lost, per second of motion, at ``rate_scale=1``.
LOSS_RATE_PER_S = {
    "sternum": 0.02,
    "left_shoulder": 0.03,
    "left_elbow": 0.08,
    "left_wrist": 0.25,
    "right_shoulder": 0.03,
    "right_elbow": 0.08,
    "right_wrist": 0.25,
    "head": 0.02,
    "nose": 0.05,
}
#: Shortest and longest gap, seconds.
GAP_S = (0.1, 0.8)
#: The 6D rotation of a limb as in the T-pose (the identity): what a hidden limb holds.
T_POSE_ROTATION = np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], dtype=np.float32)


def occlusion_mask(num_frames: int, fps: int, seed: int, rate_scale: float = 1.0) -> np.ndarray:
    """Which limbs are seen in each frame: ``visible (num_frames, 9)``, False in the gaps.

    Args:
        num_frames: ``T``.
        fps: frames per second.
        seed: draws the gaps.
        rate_scale: multiplies every rate of :data:`LOSS_RATE_PER_S`, 0 (nothing is lost) to
            100.
    """
    num_frames = check_value(num_frames, "num_frames", 1, integer=True)
    fps = check_value(fps, "fps", 1, integer=True)
    seed = check_value(seed, "seed (a non-negative integer)", 0, integer=True)
    rate_scale = check_value(rate_scale, "rate_scale", 0.0, 100.0)
    rng = np.random.default_rng([seed, 0x0CC1])
    visible = np.ones((num_frames, len(KEYPOINTS)), dtype=bool)
    seconds = num_frames / fps
    for joint, name in enumerate(KEYPOINTS):
        for _ in range(rng.poisson(LOSS_RATE_PER_S[name] * rate_scale * seconds)):
            start = rng.uniform(0.0, seconds)
            length = rng.uniform(*GAP_S)
            first, last = int(start * fps), int(np.ceil((start + length) * fps))
            visible[first:last, joint] = False
    return visible


def occlude(conversation, seed: int, rate_scale: float = 1.0):
    """A copy of ``conversation`` whose agent a tracker saw with gaps (module docstring).

    Returns:
        The conversation with ``visible (T, 9)`` set (limbs it had lost already stay lost), the
        T-pose's rotation at every hidden limb and positions recomputed from the rotations;
        audio, activity and events unchanged.
    """
    for name in ("num_frames", "fps", "rotations", "positions"):
        if not hasattr(conversation, name):
            raise TypeError(
                f"occlude needs a data_synth.Conversation; a {type(conversation).__name__} has no "
                f"{name}"
            )
    visible = occlusion_mask(conversation.num_frames, conversation.fps, seed, rate_scale)
    if getattr(conversation, "visible", None) is not None:
        visible &= conversation.visible
    rotations = np.where(visible[..., None], conversation.rotations, T_POSE_ROTATION)
    rotations = rotations.astype(conversation.rotations.dtype)
    positions = forward_kinematics(rotations).astype(conversation.positions.dtype)
    return replace(conversation, rotations=rotations, positions=positions, visible=visible)
