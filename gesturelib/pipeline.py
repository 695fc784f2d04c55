"""The course's two pipelines, each written once: a registered model trained from its recipe, and
speech turned into motion.

* :func:`train_model`: recipe -> configs (quick or full, with changes) -> training windows and
  normaliser -> the model built under its seed -> trained into a run folder, or loaded from the
  cache of trained runs (a model with a stage one trains that first; a recipe with judged epochs
  is judged by the FGD of the motion it generates for the validation conversations). The command line's
  ``train``, the chapters, ``make results`` and the benchmarks call it.
* :func:`speech_to_motion`: a recording (and a partner's) -> who is talking -> speech features ->
  frame-by-frame sampling -> limb rotations and keypoints. ``generate``, ``demo``, the explorer
  and the evaluation call it.

Both are thin: the work is done by :mod:`gesturelib.recipes`, :mod:`gesturelib.data`,
:mod:`gesturelib.train`, :mod:`gesturelib.features` and :mod:`gesturelib.sampling`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from torch import nn

from gesturelib import distributed
from gesturelib.data import ConversationLike, Normaliser, make_datasets
from gesturelib.evaluation.fgd import feature_network
from gesturelib.evaluation.judge import GeneratedMotionFGD
from gesturelib.features import mix_voices, speech_features, who_is_talking
from gesturelib.history import History
from gesturelib.recipes import RECIPES
from gesturelib.sampling import generate
from gesturelib.skeleton import forward_kinematics
from gesturelib.train import build_seeded, load_or_train, train

#: Where the chapters and tools cache trained runs, relative to the repository.
DEFAULT_CACHE = Path("checkpoints")


class Trained(NamedTuple):
    """A trained model with its training history and the normaliser it needs to generate:
    ``model, history, normaliser = train_model(...)``."""

    model: nn.Module
    history: History
    normaliser: Normaliser


def train_model(
    name: str,
    splits: Mapping[str, list],
    *,
    quick: bool,
    seed: int = 0,
    model_changes: Mapping | None = None,
    train_changes: Mapping | None = None,
    cache: str | Path = DEFAULT_CACHE,
    out: str | Path | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> Trained:
    """The model of recipe ``name`` trained on ``splits`` from ``seed``.

    The untrained model is built under ``seed`` (and nothing else), so the same recipe, changes,
    seed and data give the same weights, bit for bit, on one machine and torch build.

    Args:
        name: a key of :data:`gesturelib.recipes.RECIPES`.
        splits: a dataset's conversations, ``{"train": [...], "val": [...], ...}``.
        quick: the quick-mode recipe.
        model_changes: fields of the model config to change (a chapter's variant); window
            fields the model config sets (past poses, speech context, a diffusion chunk) follow
            it.
        train_changes: fields of the training config to change (``epochs``, ``device``, ...).
        cache: the folder of cached runs (:func:`gesturelib.train.load_or_train`): a finished
            run is loaded, an interrupted one resumed, when ``out`` is None. Also where the
            FGD's feature network is cached, for a recipe with judged epochs.
        out: a run folder to train into (the command line's ``train``); a run of this model,
            configs and data found there is resumed. A stage-one model goes into
            ``out/<stage one>``.
        overwrite: with ``out``: start afresh, replacing the checkpoints there.
        progress: show progress bars (or a line for each run loaded from the cache).
    Returns:
        The :class:`Trained` model with its best weights, in eval mode.
    """
    recipe = RECIPES[name]
    inner = None
    if recipe.stage_one is not None:
        inner = train_model(
            recipe.stage_one,
            splits,
            quick=quick,
            seed=seed,
            train_changes=train_changes,
            cache=cache,
            out=None if out is None else Path(out) / recipe.stage_one,
            overwrite=overwrite,
            progress=progress,
        ).model
    windows, config, training = recipe.settings(
        quick, model_changes or {}, **{"seed": seed, **(train_changes or {})}
    )
    datasets, normaliser = make_datasets(splits, windows)
    judge = None
    if training.judged_epochs:
        with distributed.alone():  # under torchrun: one process trains it, the others load it
            features = feature_network(
                [c.positions for c in splits["train"]],
                [c.positions for c in splits["val"]],
                cache,
                quick=quick,
                progress=progress,
            )
        judge = GeneratedMotionFGD(splits["val"], normaliser, features)

    def build(config):
        return recipe.make(config, normaliser, inner)

    if out is None:
        model, history = load_or_train(
            recipe.model_class,
            config,
            datasets["train"],
            datasets["val"],
            training,
            cache,
            normaliser,
            # A plain model(config) keeps the cache key of a chapter that trains it by hand.
            build=None if recipe.build is None else build,
            judge=judge,
            progress=progress,
        )
    else:
        model = build_seeded(build, config, training.seed)
        history = train(
            model,
            datasets["train"],
            datasets["val"],
            training,
            out,
            normaliser=normaliser,
            overwrite=overwrite,
            progress=progress,
            judge=judge,
        )
        model.eval()
    return Trained(model, history, normaliser)


@dataclass(frozen=True)
class Motion:
    """Generated motion for one recording.

    Attributes:
        rotations: ``(K, T, 9, 6)`` limb rotations of the ``K`` samples.
        positions: ``(K, T, 9, 3)`` their keypoints (cm; the root at the origin).
        activity: ``(T,)`` who-is-talking codes the model heard.
        audio: ``(n,)`` the sound heard: the agent's voice, mixed with the partner's if given.
        sample_rate: of ``audio``.
    """

    rotations: np.ndarray
    positions: np.ndarray
    activity: np.ndarray
    audio: np.ndarray
    sample_rate: int


def speech_to_motion(
    model: nn.Module,
    normaliser: Normaliser,
    audio: np.ndarray,
    sample_rate: int,
    *,
    partner: np.ndarray | None = None,
    activity: np.ndarray | None = None,
    style: Mapping[str, float] | None = None,
    style_from: ConversationLike | None = None,
    samples: int = 1,
    temperature: float | None = None,
    seed: int | None = 0,
    progress: bool = False,
) -> Motion:
    """The agent's motion for a recording of its speech.

    Args:
        model, normaliser: a model that generates (:mod:`gesturelib.sampling`'s protocol) and the
            normaliser it was trained with.
        audio: ``(n,)`` the agent's voice (or a conversation's mixed sound, with ``activity``).
        sample_rate: of ``audio`` (and ``partner``).
        partner: ``(n,)`` the partner's voice, as long as the agent's, or None.
        activity: ``(T,)`` who-is-talking codes, where they are known (a generated conversation);
            None: from voice activity in ``audio`` and ``partner``
            (:func:`~gesturelib.features.who_is_talking`).
        style: percentiles of the training values by style feature, e.g.
            ``{"hand_height": 85}`` (the others at their median), for a model with style inputs.
        style_from: a reference recording (a conversation: its motion and its speech) whose
            style to take, for MoGlow or Ye et al.'s flow (:class:`~gesturelib.sampling.Stream`).
        samples, temperature, seed, progress: as for :func:`gesturelib.sampling.generate`.
    Returns:
        The :class:`Motion`.
    Raises:
        ValueError: ``style`` for a model trained without style inputs, or bad percentiles.
        AudioError: a recording that cannot be heard (see ``who_is_talking``).
    """
    style_values = normaliser.style_at_percentiles(dict(style)) if style else None
    if activity is None:
        activity = who_is_talking(audio, sample_rate, partner)
    if partner is not None:
        audio = mix_voices(audio, partner)
    rotations = generate(
        model,
        normaliser,
        speech_features(audio, sample_rate),
        activity,
        samples=samples,
        temperature=temperature,
        seed=seed,
        style=style_values,
        style_from=style_from,
        progress=progress,
    )
    return Motion(rotations, forward_kinematics(rotations), activity, audio, sample_rate)
