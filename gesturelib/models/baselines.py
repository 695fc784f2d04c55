"""Deterministic speech-to-gesture regressors of Kucherenko et al. (2021): Aud2Pose, Aud2Repr2Pose.

Both map the speech around a frame to *one* pose, trained on the mean squared error. Under MSE the
best prediction is the conditional mean ``E[x | speech]``: where speech allows many gestures, the
regressor averages them ("regression to the mean"): its gestures are smaller than real ones, and
an average of strokes and holds neither strikes fast nor holds still (notebook 03 measures it at
the wrists). The probabilistic models of the course exist to avoid exactly that.

Aud2Pose (Hasegawa et al. 2018, as used by Kucherenko et al.)
-------------------------------------------------------------
A window of speech frames around frame ``t`` -> three fully connected layers applied to each
frame of the window -> a bidirectional GRU over the window -> a linear layer -> the pose ``x_t``
and, as a multi-task regulariser, its velocity ``x_t - x_{t-1}`` (the paper found that it helps
the network learn motion dynamics; ``velocity_weight=0`` turns it off). Sliding the window over
a sequence gives a pose sequence. :class:`SpeechWindowNet` is that network.

==================  =================================  =====================================
                    the paper                          here (:class:`Aud2PoseConfig`)
==================  =================================  =====================================
speech window       30 frames before and after         ``speech_past``=5, ``speech_future``=25
                                                       (the Flow-VAE control window)
input per frame     26 MFCCs                           27 log-mels + the activity one-hot
FC and GRU width    256                                64
dropout             0.1 (and batch norm)               0.1 (no batch norm)
output              pose and velocity                  pose and velocity
==================  =================================  =====================================

The activity one-hot is added (``use_activity``) because in our dyadic data the speech track mixes
both speakers: without it the network has to tell from the voice alone who is talking, while the
probabilistic models of the course are told.

Aud2Repr2Pose: two stages, two models, one training loop
--------------------------------------------------------
1. :class:`MotionDenoisingAutoencoder` (MotionE + MotionD) learns a compact motion representation
   ``r = MotionE(x)`` by reconstructing poses from noisy copies: Gaussian noise of standard
   deviation ``noise_std`` (0.05 of each feature's standard deviation in the paper; the poses are
   standardised, so 0.05) is added to the input, the loss is the MSE to the clean pose. As in the
   paper the only hidden layer is the representation itself (pose -> r -> pose);
   ``hidden_sizes`` adds layers on either side.
2. :class:`Aud2Repr2Pose` holds a copy of that trained autoencoder, frozen, and a
   :class:`SpeechWindowNet` (SpeechE, the Aud2Pose network) trained to predict the representation
   of the true pose from speech: MSE in representation space. At test time
   ``MotionD(SpeechE(speech))`` gives the pose.

Each stage is an ordinary model of :mod:`gesturelib.train`, so both train with the same loop::

    autoencoder = MotionDenoisingAutoencoder(MotionDAEConfig())
    train(autoencoder, datasets["train"], datasets["val"], TrainConfig())          # stage 1
    model = Aud2Repr2Pose.from_autoencoder(autoencoder, Aud2Repr2PoseConfig())
    train(model, datasets["train"], datasets["val"], TrainConfig())                # stage 2

The stage-2 checkpoint contains the frozen autoencoder's weights, so
:func:`gesturelib.checkpoints.load_model` restores the whole chain. Because stage 2 needs trained
weights that its config cannot carry, an :class:`Aud2Repr2Pose` built from its config alone (as
:func:`gesturelib.train.load_or_train` builds models) refuses to train: build it with
:meth:`Aud2Repr2Pose.from_autoencoder` (stage 1 itself can come from ``load_or_train``).

The paper's autoencoder also encodes velocities (384 inputs: 192 coordinates and their
derivatives, representation 325); on its second dataset it used positions alone, as we do (54
inputs, representation 24).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import torch
from torch import nn

from gesturelib.configs import SpeechContext, check_fields
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.models.common import batch_parts, eval_mode, mlp
from gesturelib.skeleton import POSE_DIM

# ---------------------------------------------------------------------------------------------
# The speech network shared by Aud2Pose and Aud2Repr2Pose (SpeechE)
# ---------------------------------------------------------------------------------------------


class SpeechWindowNet(nn.Module):
    """One speech window -> one output vector: 3 FC layers per frame, a bidirectional GRU, linear.

    Args:
        frame_features: numbers per window frame (27 mels, + 4 with the activity one-hot).
        hidden_size: width of the FC layers and of each GRU direction.
        output_size: numbers out.
        dropout: after each FC layer and before the output layer.
    """

    def __init__(self, frame_features: int, hidden_size: int, output_size: int, dropout: float):
        super().__init__()
        layers = []
        for size_in in (frame_features, hidden_size, hidden_size):
            layers += [nn.Linear(size_in, hidden_size), nn.ReLU(), nn.Dropout(dropout)]
        self.frame_layers = nn.Sequential(*layers)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.dropout = nn.Dropout(dropout)
        self.output = nn.Linear(2 * hidden_size, output_size)

    def forward(self, windows: torch.Tensor) -> torch.Tensor:
        """``(N, W, frame_features)`` windows -> ``(N, output_size)``."""
        _, final = self.gru(self.frame_layers(windows))  # final: (2, N, hidden), both directions
        summary = torch.cat([final[0], final[1]], dim=-1)  # (N, 2 * hidden): all of the window
        return self.output(self.dropout(summary))


@dataclass(frozen=True)
class SpeechEncoderConfig(SpeechContext):
    """What the speech network reads and how big it is (shared by Aud2Pose and Aud2Repr2Pose).

    Attributes:
        n_mels: log-mel bands per frame (27).
        n_activities: speech-activity classes (4).
        speech_past, speech_future: the window around each frame
            (:class:`~gesturelib.configs.SpeechContext`).
        use_activity: also read the activity one-hot of each window frame.
        hidden_size: width of the FC and GRU layers (the paper: 256).
        dropout: dropout probability (the paper: 0.1).
    """

    n_mels: int = N_MELS
    n_activities: int = NUM_ACTIVITIES
    use_activity: bool = True
    hidden_size: int = 64
    dropout: float = 0.1

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            positive=("n_mels", "n_activities", "hidden_size"),
            fractions=("dropout",),
            flags=("use_activity",),
        )

    @property
    def frame_features(self) -> int:
        """Numbers per window frame that the network reads."""
        return self.n_mels + (self.n_activities if self.use_activity else 0)


def speech_windows(batch: dict, config: SpeechEncoderConfig, owner: str) -> torch.Tensor:
    """The windows of every frame of ``batch`` as one batch: ``(B * L, W, frame_features)``."""
    expected = {"speech": (config.speech_window, config.n_mels)}
    if config.use_activity:
        expected["activity"] = (config.speech_window, config.n_activities)
    parts = batch_parts(batch, expected, owner)
    return torch.cat(parts, dim=-1).flatten(0, 1)


def _frames(batch: dict) -> tuple[int, int]:
    """``(B, L)`` of a batch (already checked)."""
    return tuple(batch["speech"].shape[:2])


# ---------------------------------------------------------------------------------------------
# Aud2Pose
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Aud2PoseConfig(SpeechEncoderConfig):
    """:class:`SpeechEncoderConfig` plus the output.

    Attributes:
        pose_dim: numbers per pose (54).
        velocity_weight: weight of the velocity MSE in the loss; 0 = predict the pose alone.
            The velocity target needs ``past_pose`` in the batch (``WindowConfig.past_poses >= 1``).
    """

    pose_dim: int = POSE_DIM
    velocity_weight: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        check_fields(self, positive=("pose_dim",), non_negative=("velocity_weight",))

    @classmethod
    def quick(cls, **changes) -> Aud2PoseConfig:
        """Narrow layers for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(hidden_size=16), **changes)


class Aud2Pose(nn.Module):
    """Speech window -> pose (and velocity), trained on MSE; deterministic.

    ``loss(batch)`` needs ``pose (B, L, 54)``, ``speech (B, L, W, 27)``, ``activity (B, L, W, 4)``
    (if ``use_activity``) and ``past_pose (B, L, tau, 54)`` (if ``velocity_weight > 0``); it logs
    ``loss``, ``mse`` (pose, per number) and ``velocity_mse`` (if ``velocity_weight > 0``).
    """

    config_class = Aud2PoseConfig

    def __init__(self, config: Aud2PoseConfig):
        super().__init__()
        self.config = config
        outputs = config.pose_dim * (2 if config.velocity_weight > 0 else 1)
        self.net = SpeechWindowNet(
            config.frame_features, config.hidden_size, outputs, config.dropout
        )

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Pose ``(B, L, 54)`` and velocity ``(B, L, 54)`` of every frame (velocity None if
        ``velocity_weight == 0``)."""
        windows = speech_windows(batch, self.config, "Aud2Pose")
        output = self.net(windows).unflatten(0, _frames(batch))  # (B, L, 54 or 108)
        if self.config.velocity_weight > 0:
            pose, velocity = output.chunk(2, dim=-1)
            return pose, velocity
        return output, None

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """MSE of the pose (+ ``velocity_weight`` x MSE of the velocity ``x_t - x_{t-1}``)."""
        dim = self.config.pose_dim
        (pose,) = batch_parts(batch, {"pose": (dim,)}, "Aud2Pose.loss")
        predicted_pose, predicted_velocity = self(batch)
        mse = (predicted_pose - pose).pow(2).mean()
        if predicted_velocity is None:
            return {"loss": mse, "mse": mse.detach()}
        (past_pose,) = batch_parts(batch, {"past_pose": ("tau", dim)}, "Aud2Pose.loss")
        if past_pose.shape[2] == 0:
            raise ValueError(
                "Aud2Pose.loss: the velocity target needs the previous pose, but "
                "batch['past_pose'] has tau = 0 frames; use WindowConfig(past_poses >= 1) or "
                "velocity_weight=0"
            )
        velocity = pose - past_pose[:, :, -1]
        velocity_mse = (predicted_velocity - velocity).pow(2).mean()
        loss = mse + self.config.velocity_weight * velocity_mse
        return {"loss": loss, "mse": mse.detach(), "velocity_mse": velocity_mse.detach()}

    @torch.no_grad()
    def predict(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """The pose of every frame, ``(B, L, 54)`` (normalised), in eval mode: no randomness."""
        with eval_mode(self):
            return self(batch)[0]

    #: Deterministic: no noise per generated frame.
    noise_dim = 0

    def step(self, frame: dict[str, torch.Tensor], state, noise: torch.Tensor):
        """One frame of generation (:mod:`gesturelib.sampling`): the pose ``(B, 54)`` of a frame
        from its speech window (``L = 1``); no state, no noise."""
        return self.predict(frame)[:, 0], None


# ---------------------------------------------------------------------------------------------
# Aud2Repr2Pose, stage 1: the motion representation
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionDAEConfig:
    """Sizes and corruption of the denoising autoencoder of motion (MotionE + MotionD).

    Two papers use one: Kucherenko et al. on single poses with Gaussian noise (the defaults), and
    the Flow-VAE paper on windows of 5 poses with 10 % of the limb rotations zeroed, to fill the
    limbs a tracker lost (:meth:`taylor`).

    Attributes:
        pose_dim: numbers per pose (54).
        hidden_sizes: layers between the input and the representation (mirrored in the decoder);
            () is Kucherenko et al.'s one layer each way.
        representation_dim: size of the representation ``r`` (Kucherenko et al.: 325 of 384
            inputs; the Flow-VAE paper: 30).
        noise_std: standard deviation of the Gaussian noise added to the (standardised) input
            while training.
        window: consecutive poses in one input (1: frames independent).
        mask_rate: share of limb rotations zeroed in the input while training (zero is the mean
            pose, in normalised units).
        batch_norm: batch normalisation after the first layer (the Flow-VAE paper's).
    """

    pose_dim: int = POSE_DIM
    hidden_sizes: tuple[int, ...] = ()
    representation_dim: int = 24
    noise_std: float = 0.05
    window: int = 1
    mask_rate: float = 0.0
    batch_norm: bool = False

    def __post_init__(self):
        check_fields(
            self,
            positive=("pose_dim", "representation_dim", "window"),
            sizes=("hidden_sizes",),
            non_negative=("noise_std",),
            fractions=("mask_rate",),
            flags=("batch_norm",),
        )
        if self.pose_dim % 6:
            raise ValueError(f"MotionDAEConfig.pose_dim must be 6 per limb, got {self.pose_dim}")

    @classmethod
    def quick(cls, **changes) -> MotionDAEConfig:
        """A small representation for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(representation_dim=8), **changes)

    @classmethod
    def taylor(cls, **changes) -> MotionDAEConfig:
        """The Flow-VAE paper's (section 4.2): windows of 5 poses, 10 % of the limb rotations
        zeroed, a 70-50-30 encoder with batch normalisation after the first layer."""
        paper = cls(
            hidden_sizes=(70, 50),
            representation_dim=30,
            noise_std=0.0,
            window=5,
            mask_rate=0.1,
            batch_norm=True,
        )
        return dataclasses.replace(paper, **changes)


class _FrameBatchNorm(nn.BatchNorm1d):
    """Batch normalisation of features ``(..., C)`` over every leading axis."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(x.reshape(-1, x.shape[-1])).reshape(x.shape)


class MotionDenoisingAutoencoder(nn.Module):
    """A window of poses ``(..., window * 54)`` -> representation ``(..., r)`` -> the window.

    Stage 1 of Aud2Repr2Pose (``window=1``), and the Flow-VAE paper's filler of lost limbs. The
    representation layer has a tanh, as the hidden layer of a classic denoising autoencoder;
    the decoder's output is linear. ``loss(batch)`` cuts ``batch["pose"] (B, L, 54)`` into
    windows, corrupts them (noise, zeroed limbs) and logs ``loss`` = ``mse``, the error to the
    clean windows per number.
    """

    config_class = MotionDAEConfig

    def __init__(self, config: MotionDAEConfig):
        super().__init__()
        self.config = config
        inputs = config.window * config.pose_dim
        sizes = [inputs, *config.hidden_sizes, config.representation_dim]
        layers = mlp(sizes)
        if config.batch_norm:
            layers.insert(1, _FrameBatchNorm(sizes[1]))
        self.encoder = nn.Sequential(layers, nn.Tanh())  # MotionE
        self.decoder = mlp(sizes[::-1])  # MotionD

    def encode(self, poses: torch.Tensor) -> torch.Tensor:
        """MotionE: ``(..., window * 54)`` -> ``(..., representation_dim)``, each in (-1, 1)."""
        return self.encoder(poses)

    def decode(self, representation: torch.Tensor) -> torch.Tensor:
        """MotionD: ``(..., representation_dim)`` -> ``(..., window * 54)``."""
        return self.decoder(representation)

    def forward(self, poses: torch.Tensor) -> torch.Tensor:
        """The reconstruction: ``(..., window * 54)`` -> ``(..., window * 54)``."""
        return self.decode(self.encode(poses))

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """MSE between clean windows of poses and the reconstruction of corrupted copies."""
        config = self.config
        (pose,) = batch_parts(
            batch, {"pose": (config.pose_dim,)}, "MotionDenoisingAutoencoder.loss"
        )
        if pose.shape[1] < config.window:
            raise ValueError(
                f"MotionDenoisingAutoencoder.loss needs excerpts of at least window = "
                f"{config.window} frames, got {pose.shape[1]}"
            )
        windows = pose.unfold(1, config.window, 1).transpose(-1, -2)  # (B, L - w + 1, w, 54)
        clean = windows.flatten(-2)
        corrupted = clean
        if config.mask_rate > 0:
            limbs = windows.unflatten(-1, (-1, 6))  # (B, L', w, 9, 6)
            kept = torch.rand(limbs.shape[:-1], device=pose.device) >= config.mask_rate
            corrupted = (limbs * kept[..., None]).flatten(-3)
        corrupted = corrupted + config.noise_std * torch.randn_like(clean)
        mse = (self(corrupted) - clean).pow(2).mean()
        return {"loss": mse, "mse": mse.detach()}

    @torch.no_grad()
    def fill(self, pose: torch.Tensor, visible: torch.Tensor) -> torch.Tensor:
        """Poses ``(T, 54)`` (normalised) whose limbs hidden in ``visible (T, 9)`` (bool) are
        replaced by the reconstruction of the window centred on their frame, its hidden limbs
        zeroed as in training and its ends padded with the first and last frame; the seen limbs
        are kept as they are. The filled numbers are the network's: project them onto the pose
        surface (:func:`gesturelib.pose_surface.project`) for rotations."""
        window, limbs = self.config.window, self.config.pose_dim // 6
        if pose.ndim != 2 or pose.shape[1] != self.config.pose_dim:
            raise ValueError(f"pose must be (T, {self.config.pose_dim}), got {tuple(pose.shape)}")
        if tuple(visible.shape) != (len(pose), limbs) or visible.dtype != torch.bool:
            raise ValueError(
                f"visible must be a bool mask (T, {limbs}) = {(len(pose), limbs)}, got "
                f"{visible.dtype} {tuple(visible.shape)}"
            )
        hidden = ~visible
        zeroed = (pose.unflatten(-1, (limbs, 6)) * (~hidden)[..., None]).flatten(-2)
        half = window // 2
        padded = torch.cat(
            [zeroed[:1].expand(half, -1), zeroed, zeroed[-1:].expand(window - 1 - half, -1)]
        )
        windows = padded.unfold(0, window, 1).transpose(-1, -2).flatten(-2)  # (T, w * 54)
        with eval_mode(self):  # batch norm with its running statistics
            centre = self(windows).unflatten(-1, (window, -1))[:, half]  # (T, 54)
        return torch.where(hidden.repeat_interleave(6, dim=-1), centre, pose)


# ---------------------------------------------------------------------------------------------
# Aud2Repr2Pose, stage 2: speech -> representation -> pose
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Aud2Repr2PoseConfig(SpeechEncoderConfig):
    """:class:`SpeechEncoderConfig` plus the autoencoder whose representation SpeechE predicts.

    Attributes:
        autoencoder: the config of the trained :class:`MotionDenoisingAutoencoder`
            (:meth:`Aud2Repr2Pose.from_autoencoder` fills it in).
    """

    autoencoder: MotionDAEConfig = field(default_factory=MotionDAEConfig)

    def __post_init__(self):
        super().__post_init__()
        if not isinstance(self.autoencoder, MotionDAEConfig):
            raise ValueError(
                "Aud2Repr2PoseConfig.autoencoder must be a MotionDAEConfig, got "
                f"{type(self.autoencoder).__name__}"
            )
        if self.autoencoder.window != 1 or self.autoencoder.batch_norm:
            raise ValueError(
                "Aud2Repr2Pose predicts the representation of one pose: its autoencoder needs "
                f"window=1 and no batch norm, got window={self.autoencoder.window}, "
                f"batch_norm={self.autoencoder.batch_norm}"
            )

    @classmethod
    def quick(cls, **changes) -> Aud2Repr2PoseConfig:
        """Narrow layers and the quick autoencoder; ``changes`` override any field."""
        return dataclasses.replace(
            cls(hidden_size=16, autoencoder=MotionDAEConfig.quick()), **changes
        )


class Aud2Repr2Pose(nn.Module):
    """Stage 2 of Aud2Repr2Pose: SpeechE predicts the frozen autoencoder's representation.

    Build it with :meth:`from_autoencoder`. ``loss(batch)`` needs ``pose (B, L, 54)``,
    ``speech (B, L, W, 27)`` and ``activity (B, L, W, 4)`` (if ``use_activity``); it logs
    ``loss`` (MSE of the representation, per number) and ``mse`` (of the decoded pose, per
    number: comparable with Aud2Pose's).
    """

    config_class = Aud2Repr2PoseConfig

    def __init__(self, config: Aud2Repr2PoseConfig):
        super().__init__()
        self.config = config
        self.autoencoder = MotionDenoisingAutoencoder(config.autoencoder)
        self.autoencoder.requires_grad_(False)
        self.speech_encoder = SpeechWindowNet(  # SpeechE
            config.frame_features,
            config.hidden_size,
            config.autoencoder.representation_dim,
            config.dropout,
        )
        # Saved with the weights: whether the autoencoder holds trained weights (from_autoencoder).
        self.register_buffer("autoencoder_loaded", torch.tensor(False))

    @classmethod
    def from_autoencoder(
        cls, autoencoder: MotionDenoisingAutoencoder, config: Aud2Repr2PoseConfig | None = None
    ) -> Aud2Repr2Pose:
        """A model holding a frozen copy of the trained ``autoencoder``.

        Args:
            autoencoder: stage 1, trained.
            config: the speech network's settings (its ``autoencoder`` field is replaced by
                ``autoencoder.config``); None for the defaults.
        Returns:
            The model, on the autoencoder's device, its speech network freshly initialised.
        """
        if not isinstance(autoencoder, MotionDenoisingAutoencoder):
            kind = type(autoencoder).__name__
            raise TypeError(f"autoencoder must be a MotionDenoisingAutoencoder, got {kind}")
        config = Aud2Repr2PoseConfig() if config is None else config
        model = cls(dataclasses.replace(config, autoencoder=autoencoder.config))
        model.autoencoder.load_state_dict(autoencoder.state_dict())
        model.autoencoder_loaded.fill_(True)
        return model.to(next(autoencoder.parameters()).device)

    def forward(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """The predicted representation of every frame: ``(B, L, representation_dim)``."""
        windows = speech_windows(batch, self.config, "Aud2Repr2Pose")
        return self.speech_encoder(windows).unflatten(0, _frames(batch))

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """MSE between SpeechE's output and MotionE of the true pose."""
        if not bool(self.autoencoder_loaded):
            raise RuntimeError(
                "this Aud2Repr2Pose holds an untrained autoencoder: build it with "
                "Aud2Repr2Pose.from_autoencoder(trained_autoencoder, config) after training a "
                "MotionDenoisingAutoencoder (stage 1)"
            )
        dim = self.config.autoencoder.pose_dim
        (pose,) = batch_parts(batch, {"pose": (dim,)}, "Aud2Repr2Pose.loss")
        predicted = self(batch)
        with torch.no_grad():
            target = self.autoencoder.encode(pose)
            pose_mse = (self.autoencoder.decode(predicted) - pose).pow(2).mean()
        loss = (predicted - target).pow(2).mean()
        return {"loss": loss, "mse": pose_mse}

    @torch.no_grad()
    def predict(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """``MotionD(SpeechE(speech))`` for every frame: ``(B, L, 54)`` (normalised), eval mode."""
        with eval_mode(self):
            return self.autoencoder.decode(self(batch))

    noise_dim = 0
    step = Aud2Pose.step
