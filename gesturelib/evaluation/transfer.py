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


#: How a model may take a reference's style: its base codes replayed (any recurrent flow), Ye et
#: al.'s global style code held (their flow only), or the reference's measured style given as
#: labels (a model trained with style inputs).
MECHANISMS = ("latents", "style code", "labels")


def transfer_pairs(
    model,
    normaliser,
    speakers: Sequence,
    references: Sequence,
    seconds: float = 15.0,
    seed=0,
    by: str = "latents",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Generate every pair: the first ``seconds`` of each speaker conversation's speech (and who
    is talking) with each reference conversation's style.

    Args:
        model, normaliser: a model that takes a reference's style (MoGlow, Ye et al.'s flow)
            and its normaliser.
        speakers, references: conversations (``audio``, ``sample_rate``, ``activity``,
            ``positions``, ``rotations``), e.g. held-out ones and training ones spanning the
            styles (:func:`spanning_references`).
        seconds: of each speaker's speech.
        seed: of every sample (one per pair).
        by: ``"latents"``: the reference's base codes replayed
            (:class:`~gesturelib.sampling.Stream`'s ``style_from``); ``"style code"``: the global
            encoder's code of the reference's poses held at every frame (``style_code``);
            ``"labels"``: the reference's style (:func:`clip_style`) held as the style inputs.
    Returns:
        ``(speaker styles, reference styles, realised styles)``, each ``(P, 4)`` in the order
        speaker by speaker, reference by reference, for :func:`transfer_scores`.
    """
    import torch

    from gesturelib.features import speech_features
    from gesturelib.sampling import generate
    from gesturelib.skeleton import forward_kinematics

    if by not in MECHANISMS:
        raise ValueError(f"by must be one of {MECHANISMS}, got {by!r}")
    options = []
    for b in references:
        if by == "latents":
            options.append({"style_from": b})
        elif by == "labels":
            options.append({"style": clip_style(b.positions)})
        else:
            poses = normaliser.normalise_pose(b.rotations.reshape(len(b.rotations), -1))
            code = model.reference_code(torch.as_tensor(poses, dtype=torch.float32))
            options.append({"style_code": code})
    reference_styles = [clip_style(b.positions) for b in references]
    rows = []
    for a in speakers:
        speech = speech_features(a.audio, a.sample_rate)[: round(seconds * FPS)]
        own = clip_style(a.positions)
        for asked, option in zip(reference_styles, options, strict=True):
            rotations = generate(
                model, normaliser, speech, a.activity[: len(speech)], seed=seed, **option
            )
            rows.append((own, asked, clip_style(forward_kinematics(rotations[0]))))
    return tuple(np.array(column) for column in zip(*rows, strict=True))


def style_transfer(model, normaliser, splits, seconds: float = 15.0) -> float:
    """The evaluation table's ``transfer``: **follows** by latent codes, averaged over the style
    features, for the held-out conversations' speech with the training conversations of
    :func:`spanning_references` (among those long enough to read a reference from); NaN where
    fewer than two remain, as in a dataset of one training recording: no slope can be fitted.

    Args:
        model, normaliser: a model whose stream replays a reference's latent codes (one with
            ``latents``: MoGlow, Ye et al.'s flow).
        splits: the dataset's ``{"train", "test", ...}`` conversations.
        seconds: of each held-out conversation's speech.
    """
    from gesturelib.sampling import shortest_reference

    long_enough = [c for c in splits["train"] if len(c.rotations) >= shortest_reference(model)]
    references = spanning_references(long_enough)
    if len(references) < 2:
        return float("nan")
    scores = transfer_scores(
        *transfer_pairs(model, normaliser, splits["test"], references, seconds, by="latents")
    )
    return float(np.mean([score["follows"] for score in scores.values()]))


def spanning_references(conversations: Sequence) -> list:
    """The conversations at the two ends of each style feature's range (each once, in the order
    of :data:`~gesturelib.style.STYLE_FEATURES`, lowest first): references whose styles span
    every feature, so that a slope can be fitted to each."""
    styles = np.array([clip_style(c.positions) for c in conversations])
    chosen = []
    for k in range(len(STYLE_FEATURES)):
        for index in (int(np.argmin(styles[:, k])), int(np.argmax(styles[:, k]))):
            if index not in chosen:
                chosen.append(index)
    return [conversations[i] for i in chosen]
