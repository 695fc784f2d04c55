"""How each model of the course is trained: its data windows and configs, in full and quick mode.

One recipe per trainable model, used by ``python -m gesturelib train MODEL`` and by the chapters
that train the same model, so that a model is the same wherever it is trained:

==================  ======================  ==========================================================
name                model                   trained on
==================  ======================  ==========================================================
``moglow``          :class:`MoGlow`         4 s excerpts (teacher forcing), built with the normaliser
``flowvae``         :class:`FlowVAE`        4 s excerpts, as MoGlow
``flowvae_elbo``    the variational         4 s excerpts, built with the normaliser
                    Flow-VAE
``cvae``            :class:`CVAE`           2 s excerpts
``aud2pose``        :class:`Aud2Pose`       single frames with their speech windows
``motion_dae``      the denoising            excerpts of 1 s (its frames independent); stage 1 of
                    autoencoder             ``aud2repr2pose``
``aud2repr2pose``   :class:`Aud2Repr2Pose`  single frames; built around a trained ``motion_dae``
``imputation_dae``  the denoising            excerpts of 1 s, cut into windows of 5 poses: the
                    autoencoder of the      Flow-VAE paper's filler of lost limbs
                    Flow-VAE paper
==================  ======================  ==========================================================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from torch import nn

from gesturelib.data import WindowConfig
from gesturelib.models import (
    CVAE,
    Aud2Pose,
    Aud2PoseConfig,
    Aud2Repr2Pose,
    Aud2Repr2PoseConfig,
    CVAEConfig,
    FlowVAE,
    FlowVAEConfig,
    MoGlow,
    MoGlowConfig,
    MotionDAEConfig,
    MotionDenoisingAutoencoder,
    VariationalFlowVAE,
    VariationalFlowVAEConfig,
)
from gesturelib.train import TrainConfig


@dataclass(frozen=True)
class Recipe:
    """The windows and configs of one model; ``quick_*`` are the quick-mode variants.

    Attributes:
        model_class: the model.
        windows, quick_windows: the :class:`~gesturelib.data.WindowConfig` of its training items.
        model_config, quick_model_config: its config.
        train_config, quick_train_config: its :class:`~gesturelib.train.TrainConfig`.
        stage_one: the recipe of a model trained first and built into this one, or None.
        build: ``build(config, normaliser, stage_one_model) -> model``; by default
            ``model_class(config)``.
    """

    model_class: type[nn.Module]
    windows: WindowConfig
    quick_windows: WindowConfig
    model_config: Any
    quick_model_config: Any
    train_config: TrainConfig
    quick_train_config: TrainConfig
    stage_one: str | None = None
    build: Callable | None = None

    def settings(self, quick: bool, **train_changes) -> tuple[WindowConfig, Any, TrainConfig]:
        """``(windows, model_config, train_config)`` for full or quick mode; ``train_changes``
        override training fields (the seed, the device)."""
        train = self.quick_train_config if quick else self.train_config
        return (
            self.quick_windows if quick else self.windows,
            self.quick_model_config if quick else self.model_config,
            dataclasses.replace(train, **train_changes),
        )

    def make(self, config, normaliser, stage_one_model=None) -> nn.Module:
        """The untrained model."""
        if self.build is None:
            return self.model_class(config)
        return self.build(config, normaliser, stage_one_model)


_EXCERPTS = WindowConfig(sequence_length=100, stride=50)
_QUICK_EXCERPTS = WindowConfig(sequence_length=50, stride=25)
_FLOW_TRAINING = TrainConfig(epochs=30, batch_size=16, warmup_steps=500, patience=8)
_QUICK_FLOW_TRAINING = TrainConfig.quick(epochs=3, batch_size=8, warmup_steps=50)
_REGRESSOR_TRAINING = TrainConfig(epochs=10, batch_size=64, warmup_steps=200, patience=4)
_QUICK_REGRESSOR_TRAINING = TrainConfig.quick(epochs=4, batch_size=32, warmup_steps=100)
_FRAMES = WindowConfig(sequence_length=1, stride=8)
_QUICK_FRAMES = WindowConfig(sequence_length=1, stride=6)

RECIPES: dict[str, Recipe] = {
    "moglow": Recipe(
        MoGlow,
        _EXCERPTS,
        _QUICK_EXCERPTS,
        MoGlowConfig(),
        MoGlowConfig.quick(),
        _FLOW_TRAINING,
        _QUICK_FLOW_TRAINING,
        build=lambda config, normaliser, _: MoGlow(config, normaliser),
    ),
    "flowvae": Recipe(
        FlowVAE,
        _EXCERPTS,
        _QUICK_EXCERPTS,
        FlowVAEConfig(),
        FlowVAEConfig.quick(),
        _FLOW_TRAINING,
        _QUICK_FLOW_TRAINING,
    ),
    "flowvae_elbo": Recipe(
        VariationalFlowVAE,
        _EXCERPTS,
        _QUICK_EXCERPTS,
        VariationalFlowVAEConfig(),
        VariationalFlowVAEConfig.quick(),
        _FLOW_TRAINING,
        _QUICK_FLOW_TRAINING,
        build=lambda config, normaliser, _: VariationalFlowVAE(config, normaliser),
    ),
    "cvae": Recipe(
        CVAE,
        WindowConfig(sequence_length=50, stride=25),
        WindowConfig(sequence_length=50, stride=10),
        CVAEConfig(),
        CVAEConfig.quick(),
        TrainConfig(epochs=20, batch_size=32, warmup_steps=200, patience=5),
        TrainConfig.quick(epochs=5, batch_size=16, warmup_steps=100),
    ),
    "aud2pose": Recipe(
        Aud2Pose,
        _FRAMES,
        _QUICK_FRAMES,
        Aud2PoseConfig(),
        Aud2PoseConfig.quick(),
        _REGRESSOR_TRAINING,
        _QUICK_REGRESSOR_TRAINING,
    ),
    "motion_dae": Recipe(
        MotionDenoisingAutoencoder,
        WindowConfig(sequence_length=25, stride=10),
        WindowConfig(sequence_length=25, stride=10),
        MotionDAEConfig(),
        MotionDAEConfig.quick(),
        TrainConfig(epochs=15, batch_size=32, warmup_steps=200, patience=5),
        TrainConfig.quick(epochs=8, batch_size=16, warmup_steps=100),
    ),
    "imputation_dae": Recipe(
        MotionDenoisingAutoencoder,
        WindowConfig(sequence_length=25, stride=5, past_poses=0),
        WindowConfig(sequence_length=25, stride=5, past_poses=0),
        MotionDAEConfig.taylor(),
        MotionDAEConfig.taylor(hidden_sizes=(32, 16), representation_dim=12),
        TrainConfig(epochs=15, batch_size=32, warmup_steps=200, patience=5, drop_last=True),
        TrainConfig.quick(epochs=5, batch_size=16, warmup_steps=50, drop_last=True),
    ),
    "aud2repr2pose": Recipe(
        Aud2Repr2Pose,
        _FRAMES,
        _QUICK_FRAMES,
        Aud2Repr2PoseConfig(),
        Aud2Repr2PoseConfig.quick(),
        _REGRESSOR_TRAINING,
        _QUICK_REGRESSOR_TRAINING,
        stage_one="motion_dae",
        build=lambda config, _, autoencoder: Aud2Repr2Pose.from_autoencoder(autoencoder, config),
    ),
}

#: The models a run folder can hold, by class name (what ``generate`` and ``info`` load).
MODEL_CLASSES: dict[str, type[nn.Module]] = {
    r.model_class.__name__: r.model_class for r in RECIPES.values()
}


def trained(name: str, splits, quick: bool, cache_dir, seed: int = 0, progress: bool = False):
    """The model of recipe ``name`` trained on ``splits`` (a dataset's ``{"train": [...],
    "val": [...], ...}`` conversations) from ``seed``, through the shared load-or-train cache in
    ``cache_dir`` (a stage-one model first, where the recipe has one).

    Returns:
        ``(model, history, normaliser)``.
    """
    from gesturelib.data import make_datasets
    from gesturelib.train import load_or_train

    recipe = RECIPES[name]
    inner = None
    if recipe.stage_one is not None:
        inner = trained(recipe.stage_one, splits, quick, cache_dir, seed, progress)[0]
    windows, config, training = recipe.settings(quick, seed=seed)
    datasets, normaliser = make_datasets(splits, windows)
    model, history = load_or_train(
        recipe.model_class,
        config,
        datasets["train"],
        datasets["val"],
        training,
        cache_dir,
        normaliser,
        build=lambda c: recipe.make(c, normaliser, inner),
        progress=progress,
    )
    return model, history, normaliser
