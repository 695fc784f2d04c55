"""Style transfer, measured against the style the motion shows: does a model take a reference's?

Ye et al. (2022) transfer the style of a reference motion to new speech and judge it by eye: on real
data nobody knows what the right result is. Here every conversation's style was drawn by the
generator, and :func:`gesturelib.style.style_features` reads it back from any motion. For a pair
of conversations ``(A, B)``, the model speaks A's speech with B's motion as the reference; the
style the generated motion shows (each feature averaged over the clip) is compared with the style
of B's motion (what was asked) and of A's (what the speech came with):

* **follows**: the slope of the realised style against the reference's, fitted over the pairs by
  least squares, per feature: 1 when the motion takes the reference's style in full, 0 when it
  ignores the reference (the style realised is then the model's own, whatever B's);
* **nearer**: the share of pairs whose realised style lies nearer B's than A's, per feature.

A model that copies nothing and moves in one style scores a slope near 0 and a share near a half;
choose references that span each feature's range, or its slope says little.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gesturelib.conventions import FPS
from gesturelib.style import STYLE_FEATURES, style_features


def clip_style(positions: np.ndarray) -> np.ndarray:
    """The style a motion shows: each of :data:`~gesturelib.style.STYLE_FEATURES` averaged over
    the frames of ``positions`` ``(T, 9, 3)`` cm, ``(4,)``."""
    return style_features(positions).mean(axis=0)


def transfer_scores(
    speakers: np.ndarray, references: np.ndarray, realised: np.ndarray
) -> dict[str, dict[str, float]]:
    """**follows** and **nearer** (module docstring) for each style feature.

    Args:
        speakers, references, realised: ``(P, 4)`` styles of the pairs' speech conversations, of
            their references and of the generated motion (:func:`clip_style`), one row per pair.
    Returns:
        ``{feature: {"follows": slope, "nearer": share}}``.
    Raises:
        ValueError: for arrays of other shapes, fewer than two pairs, or references of one style
            in some feature (no slope can be fitted).
    """
    arrays = [np.asarray(a, dtype=np.float64) for a in (speakers, references, realised)]
    shape = arrays[0].shape
    if len(shape) != 2 or shape[1] != len(STYLE_FEATURES) or shape[0] < 2:
        raise ValueError(f"styles must be (P, {len(STYLE_FEATURES)}) with P >= 2, got {shape}")
    if any(a.shape != shape for a in arrays):
        raise ValueError(f"styles of one shape needed, got {[a.shape for a in arrays]}")
    speakers, references, realised = arrays
    scores = {}
    for k, name in enumerate(STYLE_FEATURES):
        asked = references[:, k] - references[:, k].mean()
        if not np.any(asked):
            raise ValueError(f"the references all have the same {name}: choose ones that differ")
        slope = np.sum(asked * (realised[:, k] - realised[:, k].mean())) / np.sum(asked**2)
        nearer = np.abs(realised[:, k] - references[:, k]) < np.abs(realised[:, k] - speakers[:, k])
        scores[name] = {"follows": float(slope), "nearer": float(nearer.mean())}
    return scores


def transfer_pairs(
    model, normaliser, speakers: Sequence, references: Sequence, seconds: float = 20.0, seed=0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Generate every pair: the first ``seconds`` of each speaker conversation's speech (and who
    is talking) with each reference conversation's whole motion as ``style_from``.

    Args:
        model, normaliser: a model that takes a reference motion
            (:class:`~gesturelib.models.StyleFlow`) and its normaliser.
        speakers, references: conversations (``audio``, ``sample_rate``, ``activity``,
            ``positions``, ``rotations``), e.g. held-out ones and training ones spanning the
            styles.
        seconds: of each speaker's speech.
        seed: of every sample (one per pair).
    Returns:
        ``(speaker styles, reference styles, realised styles)``, each ``(P, 4)`` in the order
        speaker by speaker, reference by reference, for :func:`transfer_scores`.
    """
    from gesturelib.pipeline import speech_to_motion

    reference_styles = [clip_style(b.positions) for b in references]
    rows = []
    for a in speakers:
        frames = min(len(a.activity), round(seconds * FPS))
        audio = a.audio[: frames * a.sample_rate // FPS]
        own = clip_style(a.positions)
        for b, asked in zip(references, reference_styles, strict=True):
            motion = speech_to_motion(
                model,
                normaliser,
                audio,
                a.sample_rate,
                activity=a.activity[:frames],
                style_from=b.rotations,
                seed=seed,
            )
            rows.append((own, asked, clip_style(motion.positions[0])))
    return tuple(np.array(column) for column in zip(*rows, strict=True))
