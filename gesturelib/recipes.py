"""How each model of the course is trained: its data windows and configs, in full and quick mode.

One recipe per trainable model, used by ``python -m gesturelib train MODEL`` and by the chapters
that train the same model, so that a model is the same wherever it is trained:

====================  ======================  ==========================================================
name                  model                   trained on
====================  ======================  ==========================================================
``moglow``            :class:`MoGlow`         4 s excerpts (teacher forcing), built with the normaliser
``flowvae``           :class:`FlowVAE`        4 s excerpts, as MoGlow
``flowvae_elbo``      the variational         4 s excerpts, built with the normaliser
                      Flow-VAE
``cvae``              :class:`CVAE`           2 s excerpts
``aud2pose``          :class:`Aud2Pose`       single frames with their speech windows
``motion_dae``        the denoising           excerpts of 1 s (its frames independent); stage 1 of
                      autoencoder             ``aud2repr2pose``
``aud2repr2pose``     :class:`Aud2Repr2Pose`  single frames; built around a trained ``motion_dae``
``imputation_dae``    the denoising           excerpts of 1 s, cut into windows of 5 poses: the
                      autoencoder of the      Flow-VAE paper's filler of lost limbs
                      Flow-VAE paper
``gesture_features``  the perceptual loss's   excerpts of 1.28 s; stage 1 of ``styleflow``
                      motion autoencoder
``styleflow``         :class:`StyleFlow`      4 s excerpts with 4 s of past poses, built around a
                                              trained ``gesture_features``
``diffusion``         the diffusion model     chunks of 0.4 s, with the poses before and the speech
                                              around them
====================  ======================  ==========================================================
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
    DiffusionConfig,
    FlowVAE,
    FlowVAEConfig,
    GestureDiffusion,
    GestureFeatureConfig,
    GestureFeatureNetwork,
    MoGlow,
    MoGlowConfig,
    MotionDAEConfig,
    MotionDenoisingAutoencoder,
    StyleFlow,
    StyleFlowConfig,
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

    def settings(
        self, quick: bool, model_changes: dict | None = None, **train_changes
    ) -> tuple[WindowConfig, Any, TrainConfig]:
        """``(windows, model_config, train_config)`` for full or quick mode.

        ``model_changes`` override model-config fields (a chapter's variant); the window fields
        the model config shares (past poses, speech context) follow the changed config, so the
        data always fits the model. ``train_changes`` override training fields (the seed, the
        device, the epochs)."""
        config = self.quick_model_config if quick else self.model_config
        config = dataclasses.replace(config, **(model_changes or {}))
        windows = self.quick_windows if quick else self.windows
        shared = {
            w: getattr(config, f) for f, w in _SHARED_WINDOW_FIELDS.items() if hasattr(config, f)
        }
        train = self.quick_train_config if quick else self.train_config
        return (
            dataclasses.replace(windows, **shared),
            config,
            dataclasses.replace(train, **train_changes),
        )

    def make(self, config, normaliser, stage_one_model=None) -> nn.Module:
        """The untrained model."""
        if self.build is None:
            return self.model_class(config)
        return self.build(config, normaliser, stage_one_model)


#: Model-config fields that set a field of the training window: the config's value wins.
_SHARED_WINDOW_FIELDS = {
    "past_poses": "past_poses",
    "speech_past": "speech_past",
    "speech_future": "speech_future",
    "chunk": "sequence_length",  # the diffusion model trains on windows of one chunk
}
_EXCERPTS = WindowConfig(sequence_length=100, stride=50)
_QUICK_EXCERPTS = WindowConfig(sequence_length=50, stride=25)
_FLOW_TRAINING = TrainConfig(epochs=30, batch_size=16, warmup_steps=500, patience=8)
_QUICK_FLOW_TRAINING = TrainConfig.quick(epochs=3, batch_size=8, warmup_steps=50)
_REGRESSOR_TRAINING = TrainConfig(epochs=10, batch_size=64, warmup_steps=200, patience=4)
_QUICK_REGRESSOR_TRAINING = TrainConfig.quick(epochs=4, batch_size=32, warmup_steps=100)
_FRAMES = WindowConfig(sequence_length=1, stride=8)
_QUICK_FRAMES = WindowConfig(sequence_length=1, stride=6)
_FLOWVAE_CONTROL = {"dropout": 0.2, "speech_past": 15, "voice_shift": 3}

#: Every trainable model of the course, in the order of the chapters.
RECIPES: dict[str, Recipe] = {
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
    "cvae": Recipe(
        CVAE,
        WindowConfig(sequence_length=50, stride=25),
        WindowConfig(sequence_length=50, stride=10),
        CVAEConfig(),
        CVAEConfig.quick(),
        TrainConfig(epochs=20, batch_size=32, warmup_steps=200, patience=5),
        TrainConfig.quick(epochs=5, batch_size=16, warmup_steps=100),
    ),
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
        # Less data dropout than the paper's 0.4 (the config's default): over six seeds, every
        # run keeps its drift and its wrist speeds. MoGlow's 0.6 s of past speech, and voices
        # moved by up to three mel bands while training, for voices it was not trained on
        # (chapter 08; both in docs/benchmarks.md).
        FlowVAEConfig(**_FLOWVAE_CONTROL),
        FlowVAEConfig.quick(**_FLOWVAE_CONTROL),
        # Its validation loss falls every epoch while its generated motion does not improve with
        # it: the epoch of the last five whose generated validation motion has the lowest FGD is
        # kept, which lowers its test FGD and that FGD's spread over seeds (docs/benchmarks.md).
        dataclasses.replace(_FLOW_TRAINING, judged_epochs=5),
        dataclasses.replace(_QUICK_FLOW_TRAINING, judged_epochs=2),
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
    "imputation_dae": Recipe(
        MotionDenoisingAutoencoder,
        WindowConfig(sequence_length=25, stride=5, past_poses=0),
        WindowConfig(sequence_length=25, stride=5, past_poses=0),
        MotionDAEConfig.taylor(),
        MotionDAEConfig.taylor(hidden_sizes=(32, 16), representation_dim=12),
        TrainConfig(epochs=15, batch_size=32, warmup_steps=200, patience=5, drop_last=True),
        TrainConfig.quick(epochs=5, batch_size=16, warmup_steps=50, drop_last=True),
    ),
    "gesture_features": Recipe(
        GestureFeatureNetwork,
        WindowConfig(sequence_length=32, stride=8, past_poses=0),
        WindowConfig(sequence_length=32, stride=8, past_poses=0),
        GestureFeatureConfig(),
        GestureFeatureConfig.quick(),
        TrainConfig(epochs=15, batch_size=32, warmup_steps=200, patience=5),
        TrainConfig.quick(epochs=5, batch_size=16, warmup_steps=50),
    ),
    "styleflow": Recipe(
        StyleFlow,
        _EXCERPTS,
        _QUICK_EXCERPTS,
        StyleFlowConfig(),
        StyleFlowConfig.quick(),
        # A sixth of MoGlow's steps (a third of its epochs): its GRUs and decoded sample make a
        # step several times dearer.
        TrainConfig(epochs=10, batch_size=32, warmup_steps=250, patience=4),
        _QUICK_FLOW_TRAINING,
        stage_one="gesture_features",
        build=lambda config, normaliser, features: StyleFlow(config, normaliser, features),
    ),
    "diffusion": Recipe(
        GestureDiffusion,
        WindowConfig(stride=3),  # of one chunk each
        WindowConfig(stride=5),
        DiffusionConfig(),
        DiffusionConfig.quick(),
        TrainConfig(epochs=10, batch_size=64, warmup_steps=500, patience=4),  # 15 min
        TrainConfig.quick(epochs=3, batch_size=32, warmup_steps=50),
    ),
}

#: The recipes whose models generate motion (:mod:`gesturelib.sampling`'s protocol), in order.
GENERATORS: tuple[str, ...] = tuple(n for n, r in RECIPES.items() if hasattr(r.model_class, "step"))

#: The models a run folder can hold, by class name (what ``generate`` and ``info`` load).
MODEL_CLASSES: dict[str, type[nn.Module]] = {
    r.model_class.__name__: r.model_class for r in RECIPES.values()
}
