"""Style control, measured: held at a low, a middle and a high level, how much of the change asked
does a model's motion realise? (Alexanderson et al. 2020, §5.2.)

A model trained with MoGlow's style inputs (:mod:`gesturelib.style`) is given one feature held
at the 15th, 50th and 85th percentile of its training values (the others at their median), and
the style of what comes out is measured back with the same function, averaged over each clip.
**share**: the realised change from the low to the high level as a share of the change asked
(1: obeyed in full; 0: ignored).

The levels are percentiles of *frames*, each averaged over 4 s, and most of that spread lies
within conversations (a speaking agent's hands move faster than a listening one's): a clip held
at the 15th percentile of hand speed asks for 4 s windows of listening throughout, whatever the
speech. :func:`conversation_span` measures how much of the change asked whole recorded clips
span: a model that answers each level with motion like a real conversation's realises about that
share, and one that realises more makes motion more extreme than most recorded clips.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gesturelib.evaluation.headline import generate_for
from gesturelib.evaluation.transfer import clip_style
from gesturelib.metrics import rank_correlation
from gesturelib.style import STYLE_FEATURES

#: The levels asked, as percentiles of the training values (the paper's low, mid and high).
LEVELS = (15, 50, 85)


@dataclass(frozen=True)
class StyleResponse:
    """How one style feature's realised value follows the value asked.

    Attributes:
        asked: ``(3,)`` the feature's value at each of :data:`LEVELS`.
        realised: ``(3,)`` the mean over clips and samples of the value realised at each level.
        share: ``(realised[-1] - realised[0]) / (asked[-1] - asked[0])``.
        rank_correlation: of asked and realised over every clip and sample (NaN where the
            realised value never changes).
    """

    asked: np.ndarray
    realised: np.ndarray
    share: float
    rank_correlation: float


def style_response(
    model,
    normaliser,
    conversations: Sequence,
    samples: int = 2,
    seed: int = 0,
    temperature: float | None = None,
) -> dict[str, StyleResponse]:
    """Each style feature held at each of :data:`LEVELS` in turn, for the speech (and who is
    talking) of ``conversations``: ``{feature: StyleResponse}``.

    Args:
        model, normaliser: a model trained with style inputs (``config.style``) and its
            normaliser, whose ``style_percentiles`` give the levels.
        conversations: with ``audio``, ``sample_rate`` and ``activity``; their motion is not used.
        samples, seed: draws per conversation and level, and their seed.
        temperature: of the draws; the model's own if None.
    Raises:
        ValueError: for a model without style inputs.
    """
    if not getattr(model.config, "style", False):
        raise ValueError(
            f"this {type(model).__name__} has no style inputs: train it with style=True"
        )
    responses = {}
    for index, name in enumerate(STYLE_FEATURES):
        asked, realised = [], []
        for level in LEVELS:
            value = normaliser.style_at_percentiles({name: level})[index]
            motions = generate_for(
                conversations,
                model,
                normaliser,
                samples=samples,
                seed=seed,
                temperature=temperature,
                style={name: level},
            )
            for draws in motions:
                for motion in draws:
                    asked.append(value)
                    realised.append(clip_style(motion)[index])
        levels = np.array(asked).reshape(len(LEVELS), -1)[:, 0]
        means = np.array(realised).reshape(len(LEVELS), -1).mean(axis=1)
        responses[name] = StyleResponse(
            asked=levels,
            realised=means,
            share=float((means[-1] - means[0]) / (levels[-1] - levels[0])),
            rank_correlation=rank_correlation(asked, realised) if np.ptp(realised) else np.nan,
        )
    return responses


def conversation_span(normaliser, clips: np.ndarray) -> dict[str, float]:
    """The share of the change asked (from the 15th to the 85th percentile of the training
    frames) that recorded clips span (from the 15th to the 85th percentile of their styles), per
    style feature.

    Args:
        normaliser: whose ``style_percentiles`` give the change asked.
        clips: ``(N, 4)`` the styles of recorded clips
            (:func:`~gesturelib.evaluation.transfer.clip_style`), e.g. of the training
            conversations and their mirror images, as the normaliser was fitted on.
    """
    low, high = LEVELS[0], LEVELS[-1]
    asked = normaliser.style_percentiles[high] - normaliser.style_percentiles[low]
    spanned = np.percentile(clips, high, axis=0) - np.percentile(clips, low, axis=0)
    return {name: float(s / a) for name, s, a in zip(STYLE_FEATURES, spanned, asked, strict=True)}
