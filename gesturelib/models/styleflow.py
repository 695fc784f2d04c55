"""Ye et al. (2022): MoGlow with GRU couplings and a global encoder, trained to reconstruct, whose
global feature of a reference motion transfers that motion's style without any style label.

The flow is MoGlow's (:mod:`gesturelib.models.moglow`: residual, with pose noise off the surface),
with GRUs in its couplings (the paper: as good as LSTMs, fewer parameters, and less inclined to
continue the past than to follow the speech). Every coupling reads two things next to the
untouched half of the pose:

    x_t --ActNorm--linear--coupling(GRU)--> ... (K steps) -->  z_t ~ N(0, I)
                                ^
                    [local control c_t ; global feature g_t]

* **The local control** ``c_t``: MoGlow's, from the last ``LOCAL_POSES`` = 5 poses and the speech
  and activity window (:class:`~gesturelib.models.control.ControlEncoder`).
* **The global feature** ``g_t`` (:class:`GlobalEncoder`): two temporal convolution networks
  (TCNs), one over ``past_poses`` = 100 poses (4 s) and one over the speech and activity window,
  each averaged over its window, joined by an MLP. The pose TCN's output, the **style code**, is
  computed from the poses *before the excerpt* and held for all of its frames while training, so
  it cannot tell the flow what happens next, only what stays: where the hands hover, how wide
  and how fast they move, the conversation's style, which the generator draws and the model is
  never told. (First tried with each frame's own last 2 s: the flow used the code for the next
  move, and a reference's code moved no style; ``docs/benchmarks.md``.) Generating, the code
  comes from the last 4 s of the model's own motion, at every frame.
* **The loss** (the paper's eq. 11): ``NLL + reconstruction * L1(x, x') + perceptual * L_gp``,
  where ``x' = f^-1(z'; c, g)`` decodes a fresh draw ``z'`` of the base with the same control
  (the paper's "backward pass": it trains the global encoder to carry what the sample needs), and
  ``L_gp`` is the mean absolute difference of the feature maps that the fourth convolution of a
  motion autoencoder, trained first on the training motion (:class:`GestureFeatureNetwork`),
  computes from ``x`` and ``x'``. ``global_size = 0`` or ``perceptual = 0`` are the paper's
  ablations.
* **Style transfer.** The paper's: the reference's motion read through the flow with its own
  speech gives base codes ``z_t`` (:meth:`~gesturelib.models.MoGlow.latents`), replayed with the
  new speech (``Stream(style_from=...)``, ``generate --style-from``). The global encoder's own
  route, :meth:`StyleFlow.reference_code` held at every frame (``Stream(style_code=...)``),
  is measured to move no style: the couplings' GRUs learn the style from the real past poses
  within an excerpt, so the flow ignores a code that says it again (``docs/benchmarks.md``).

Deliberately not the paper's: a Gaussian base (the paper's Student's t makes training robust to
outliers that our synthetic motion does not have), TCN blocks without batch normalisation (a
frame at a time, generation would run on its running averages), and one local control encoder as
in the course's MoGlow rather than the raw 1.2k control numbers in every coupling.

Logged scalars (``loss(batch)``): ``loss``; ``nll`` per frame (nats) of the noisy poses;
``reconstruction`` and ``perceptual``, the two terms before their weights.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

import torch
from torch import nn
from torch.nn import functional

from gesturelib.configs import check_fields
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.flows import RecurrentFlow, recurrent_glow
from gesturelib.models.common import batch_parts, check_config_type, mlp
from gesturelib.models.control import ControlConfig, ControlEncoder
from gesturelib.models.moglow import MoGlow, MoGlowConfig
from gesturelib.pose_surface import SurfaceNoise
from gesturelib.skeleton import POSE_DIM

#: Poses of the local control (MoGlow's tau); the global encoder reads all ``past_poses``.
LOCAL_POSES = 5
#: Frames each output of the global encoder's TCNs sees: a window must hold more.
TCN_VIEW = 17


@dataclass(frozen=True)
class GestureFeatureConfig:
    """Sizes of the perceptual loss's motion autoencoder.

    Attributes:
        channels: width of its convolutions.
        features: channels of the fourth convolution, whose maps the loss compares.
    """

    channels: int = 64
    features: int = 32

    def __post_init__(self):
        check_fields(self, positive=("channels", "features"))

    @classmethod
    def quick(cls, **changes) -> GestureFeatureConfig:
        """A narrow network for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(channels=24, features=12), **changes)


class GestureFeatureNetwork(nn.Module):
    """Ye et al.'s feature extractor: a convolutional autoencoder of normalised pose excerpts.

    ``encode(pose (B, L, 54)) -> (B, features, ceil(L / 4))``: the maps of its fourth convolution
    (two of them halve the time axis). ``loss(batch)`` needs ``pose (B, L, 54)`` with ``L`` a
    multiple of 4 and returns the reconstruction MSE as ``loss`` and ``mse``.
    """

    config_class = GestureFeatureConfig

    def __init__(self, config: GestureFeatureConfig):
        super().__init__()
        check_config_type(self, config)
        self.config = config
        width = config.channels
        self.encoder = nn.Sequential(
            nn.Conv1d(POSE_DIM, width, 3, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv1d(width, width, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv1d(width, width, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv1d(width, config.features, 3, padding=1),  # the fourth: the compared maps
        )
        self.decoder = nn.Sequential(
            nn.LeakyReLU(0.2),
            nn.ConvTranspose1d(config.features, width, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.ConvTranspose1d(width, width, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv1d(width, POSE_DIM, 3, padding=1),
        )

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        """Normalised poses ``(B, L, 54)`` -> feature maps ``(B, features, ceil(L / 4))``."""
        return self.encoder(pose.transpose(1, 2))

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Reconstruction MSE of ``batch["pose"] (B, L, 54)`` (``L`` a multiple of 4)."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, "GestureFeatureNetwork.loss")
        if pose.shape[1] % 4:
            raise ValueError(
                f"GestureFeatureNetwork.loss needs excerpts of a multiple of 4 frames, got "
                f"{pose.shape[1]}"
            )
        mse = functional.mse_loss(self.decoder(self.encode(pose)).transpose(1, 2), pose)
        return {"loss": mse, "mse": mse.detach()}


@dataclass(frozen=True)
class StyleFlowConfig(MoGlowConfig):
    """Ye et al.'s flow: MoGlow's fields (with GRUs), the global encoder and the loss weights.

    Attributes:
        past_poses: poses the style code is computed from, 100 (4 s: the style features'
            window); the local control reads the last ``LOCAL_POSES`` of them.
        global_size: numbers of the style code, the speech code and the global feature; 0
            leaves the global encoder out (the paper's ablation: MoGlow with GRUs).
        reconstruction: weight of the L1 distance between the poses and a decoded sample (the
            paper's lambda_1 = 1).
        perceptual: weight of the gesture perceptual loss (lambda_2 = 0.1); 0 trains without the
            feature network.
        features: the perceptual loss's feature network.
        voice_shift: 0: the voices as recorded, as Ye et al. train (MoGlow's recipe moves them,
            for chapter 08's recordings; on this flow that changed what chapter 09 measures:
            ``docs/benchmarks.md``).
        steps, hidden, pose_noise, noise_moves_limbs, residual, speech_past, speech_future,
            control_size, dropout: as :class:`~gesturelib.models.moglow.MoGlowConfig`.
    """

    past_poses: int = 100
    voice_shift: int = 0
    global_size: int = 16
    reconstruction: float = 1.0
    perceptual: float = 0.1
    features: GestureFeatureConfig = GestureFeatureConfig()

    def __post_init__(self):
        super().__post_init__()
        check_fields(self, counts=("global_size",), non_negative=("reconstruction", "perceptual"))
        if self.past_poses < LOCAL_POSES:
            raise ValueError(
                f"StyleFlowConfig.past_poses must be >= {LOCAL_POSES} (the local control's "
                f"poses), got {self.past_poses}"
            )
        if self.style:
            raise ValueError("StyleFlowConfig learns style without labels: style must be False")
        if self.global_size and min(self.past_poses, self.speech_window) <= TCN_VIEW:
            raise ValueError(
                f"the global encoder's windows must be longer than its TCNs' view of {TCN_VIEW} "
                f"frames: past_poses = {self.past_poses}, speech window = {self.speech_window}"
            )
        if isinstance(self.features, dict):  # read back from JSON
            object.__setattr__(self, "features", GestureFeatureConfig(**self.features))
        if not isinstance(self.features, GestureFeatureConfig):
            raise TypeError(
                f"StyleFlowConfig.features must be a GestureFeatureConfig, got "
                f"{type(self.features).__name__}"
            )

    @classmethod
    def quick(cls, **changes) -> StyleFlowConfig:
        """A small model for tests and quick mode; ``changes`` override any field."""
        small = cls(
            steps=4,
            hidden=32,
            control_size=16,
            past_poses=25,
            global_size=8,
            features=GestureFeatureConfig.quick(),
        )
        return dataclasses.replace(small, **changes)


class TemporalEncoder(nn.Module):
    """A TCN averaged over sliding windows: ``(N, S, C)`` and a window of ``W`` frames ->
    ``(N, S - W + 1, size)``, the feature of every window of ``W`` consecutive frames.

    A convolution to ``width`` channels, then three residual blocks of dilated convolutions
    (dilation 1, 2, 4: each output sees ``TCN_VIEW`` = 17 frames, enough for a stroke's speed),
    all without padding, then the mean over each window's outputs and a linear map. Without
    padding, a window's feature depends on its own frames only, so encoding a whole sequence at
    once (training: every frame's window in one pass) gives what encoding each window alone gives
    (generation), at a fraction of the cost.
    """

    def __init__(self, channels: int, width: int, size: int):
        super().__init__()
        self.input = nn.Conv1d(channels, width, 3)
        self.blocks = nn.ModuleList(nn.Conv1d(width, width, 3, dilation=d) for d in (1, 2, 4))
        self.output = nn.Linear(width, size)
        self.reach = TCN_VIEW // 2  # frames an output sees on each side

    def forward(self, sequence: torch.Tensor, window: int) -> torch.Tensor:
        assert window > 2 * self.reach, "a window must be longer than a TCN output's view"
        hidden = functional.relu(self.input(sequence.transpose(1, 2)))  # (N, width, S - 2)
        for block in self.blocks:
            trim = block.dilation[0]
            hidden = functional.relu(hidden[..., trim:-trim] + block(hidden))
        # Each window of W frames holds W - 2 * reach outputs: their mean, for every window.
        pooled = functional.avg_pool1d(hidden, window - 2 * self.reach, stride=1)
        return self.output(pooled.transpose(1, 2))


class GlobalEncoder(nn.Module):
    """The global feature of every frame: ``g = MLP([style code, TCN(speech, activity)])``, the
    style code ``TCN(poses)`` from the history of an excerpt's first frame, held for the excerpt.

    Args:
        config: the model's sizes; the TCNs are ``hidden // 4`` wide and each gives
            ``global_size`` numbers.
    """

    def __init__(self, config: StyleFlowConfig):
        super().__init__()
        width, size = config.hidden // 4, config.global_size
        self.poses = TemporalEncoder(POSE_DIM, width, size)
        self.speech = TemporalEncoder(N_MELS + NUM_ACTIVITIES, width, size)
        self.join = mlp([2 * size, config.hidden, size])

    def forward(self, batch: dict[str, torch.Tensor], pose_code=None) -> torch.Tensor:
        """``(B, L, global_size)`` from ``past_pose (B, L, H, 54)`` (the history of the first
        frame only), ``speech`` and ``activity`` ``(B, L, W, .)``; ``pose_code``
        ``(B, global_size)`` replaces the history's (transfer)."""
        speech = torch.cat([batch["speech"], batch["activity"]], dim=-1)  # (B, L, W, 31)
        window = speech.shape[2]
        speech_code = self.speech(_sequence(speech), window)  # (B, L, size)
        if pose_code is None:
            history = batch["past_pose"][:, 0]  # (B, H, 54): the poses before the first frame
            pose_code = self.poses(history, history.shape[1])[:, 0]
        pose_code = pose_code[:, None].expand(-1, speech.shape[1], -1)
        return self.join(torch.cat([pose_code, speech_code], dim=-1))


def _sequence(windows: torch.Tensor) -> torch.Tensor:
    """The frames that the windows of consecutive frames ``(B, L, W, C)`` are cut from,
    ``(B, W + L - 1, C)``: the first window and the newest frame of each later one."""
    return torch.cat([windows[:, 0], windows[:, 1:, -1]], dim=1)


class StyleFlow(MoGlow):
    """Ye et al.'s flow; see the module docstring.

    ``loss(batch)`` needs MoGlow's batch (``pose (B, L, 54)``, ``past_pose (B, L, H, 54)`` with
    ``H = past_poses``, ``speech (B, L, W, 27)``, ``activity (B, L, W, 4)``). Generation follows
    :mod:`gesturelib.sampling`; a frame may carry ``reference_code (B, 1, global_size)`` from
    :meth:`reference_code` to take the style of a reference motion.

    Args:
        config: the sizes and loss weights.
        normaliser: the statistics the poses are normalised with (for the pose noise).
        features: the trained perceptual feature network (its encoder's weights are copied and
            frozen); None for a model rebuilt from a checkpoint, which restores them.
    """

    config_class = StyleFlowConfig

    def __init__(
        self,
        config: StyleFlowConfig,
        normaliser=None,
        features: GestureFeatureNetwork | None = None,
    ):
        nn.Module.__init__(self)
        check_config_type(self, config)
        self.config = config
        shared = {field.name: getattr(config, field.name) for field in fields(ControlConfig)}
        self.control = ControlEncoder(
            ControlConfig(**{**shared, "past_poses": LOCAL_POSES}), config.hidden
        )
        self.global_encoder = GlobalEncoder(config) if config.global_size else None
        self.flow: RecurrentFlow = recurrent_glow(
            POSE_DIM,
            config.steps,
            config.hidden,
            config.encoded_size + config.global_size,
            cell="gru",
        )
        self.noise = SurfaceNoise(config.pose_noise, across_only=not config.noise_moves_limbs)
        if normaliser is not None:
            self.noise.set_statistics(normaliser)
        # The feature network's encoder alone, frozen (its weights travel in the checkpoint).
        self.feature_encoder = None
        if config.perceptual:
            network = GestureFeatureNetwork(config.features)
            if features is not None:
                network.load_state_dict(features.state_dict())
            self.feature_encoder = network.encoder.requires_grad_(False)

    def conditioning(self, batch, training: bool = False) -> torch.Tensor:
        """What every coupling reads: ``[c_t ; g_t]``, ``(B, L, control + global_size)``; the
        global part from ``batch["reference_code"] (B, 1, global_size)`` where the batch has
        one."""
        local = dict(batch, past_pose=batch["past_pose"][:, :, -LOCAL_POSES:])
        control = self.control(local, training=training)
        if self.global_encoder is None:
            return control
        reference = batch.get("reference_code")
        code = None if reference is None else reference[:, 0]
        return torch.cat([control, self.global_encoder(batch, code)], dim=-1)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The NLL per frame of the noisy poses, plus the weighted reconstruction and perceptual
        terms of a decoded sample (teacher forcing)."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, "StyleFlow.loss")
        generator = None if self.training else torch.Generator(pose.device).manual_seed(0)
        origin = self._origin(batch)
        condition = self.conditioning(batch, training=self.training)
        log_prob, _ = self.flow.log_prob(pose + self.noise(pose, generator) - origin, condition)
        nll = -log_prob.mean() / pose.shape[1]
        terms = {"nll": nll, "reconstruction": nll.new_zeros(()), "perceptual": nll.new_zeros(())}
        loss = nll
        if self.config.reconstruction or self.config.perceptual:
            latent = self.flow.noise(pose.shape[:2], 1.0, generator)
            decoded = self.flow.inverse(latent, condition)[0] + origin  # (B, L, 54)
            terms["reconstruction"] = (decoded - pose).abs().mean()
            loss = loss + self.config.reconstruction * terms["reconstruction"]
            if self.feature_encoder is not None:
                maps = self.feature_encoder(torch.stack([decoded, pose]).flatten(0, 1).mT)
                decoded_maps, pose_maps = maps.unflatten(0, (2, len(pose)))
                terms["perceptual"] = (decoded_maps - pose_maps).abs().mean()
                loss = loss + self.config.perceptual * terms["perceptual"]
        return {"loss": loss, **{name: value.detach() for name, value in terms.items()}}

    @torch.no_grad()
    def reference_code(self, reference: torch.Tensor) -> torch.Tensor:
        """The style code of a reference motion averaged over its every window of ``past_poses``
        frames: ``(1, 1, global_size)`` from normalised poses ``(T, 54)``, ``T >= past_poses``,
        to put in each generated frame as ``reference_code``."""
        if self.global_encoder is None:
            raise ValueError("this StyleFlow has no global encoder (global_size=0): no style code")
        history = self.config.past_poses
        if reference.ndim != 2 or reference.shape[1] != POSE_DIM or len(reference) < history:
            raise ValueError(
                f"a reference motion must be normalised poses (T, {POSE_DIM}) with T >= "
                f"{history} frames, got {tuple(reference.shape)}"
            )
        codes = self.global_encoder.poses(reference[None], history)  # (1, T - H + 1, size)
        return codes.mean(dim=1, keepdim=True)
