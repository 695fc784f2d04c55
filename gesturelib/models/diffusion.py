"""A denoising diffusion model of gesture: short chunks of poses denoised from noise, each
conditioned on the speech around it and on the poses just before it.

Where MoGlow writes one pose at a time, the diffusion model writes a **chunk** of ``C`` poses
(0.4 s) at once, by removing noise from them in a few steps (Ho et al. 2020; Song et al. 2021),
as "Listen, denoise, action!" and DiffuseStyleGesture do for whole clips. Each chunk is
conditioned on the last ``tau`` poses written before it, so motion of any length streams out
with the same :mod:`gesturelib.sampling` protocol as the flows, ``C`` frames per step; the stream
overlaps consecutive chunks by half a chunk and cross-fades them, for the seams.

**The timeline.** A chunk starting at frame ``t`` is denoised on a timeline of the frames
``t - speech_past .. t + speech_future`` (the speech window of frame ``t``, 1 s ahead), which
holds in its channels:

    speech (27) | who is talking (4) | style (4, optional) | "heard" flag
    pose (54): the clean past poses at t-tau..t-1, the noisy chunk at t..t+C-1, zero elsewhere
    "past" flag | "chunk" flag

A stack of dilated 1D convolutions (its receptive field covers the whole timeline), modulated by
the noise level, reads the timeline and predicts, at the chunk's frames, the clean chunk in the
form of ``prediction``. Every frame of the chunk thus sees all the speech of the window, which
ends ``speech_future - C + 1`` frames after the chunk's last frame.

**The forward process** (variance preserving, continuous time ``s`` in [0, 1]):
``x_s = alpha(s) x_0 + sigma(s) eps`` with ``alpha^2 + sigma^2 = 1`` and a cosine schedule of
the log signal-to-noise ratio ``log(alpha^2 / sigma^2)`` from +20 (clean) to -20 (pure noise).
Training draws ``s`` uniformly and regresses the target (mean squared error):

* ``"epsilon"``: the noise;  ``"x0"``: the clean chunk;  ``"v"``: ``alpha eps - sigma x_0``
  (Salimans & Ho 2022), which keeps the target's scale at every level.

The recipe predicts ``x0``, as most motion models do (MDM, DiffuseStyleGesture): predicting
``epsilon`` or ``v``, the clean chunk is what is left of ``x_s`` after the predicted noise is
taken away, and the noise the network fails to find at low levels stays in the motion as jitter;
predicting ``x0``, the network's output is the motion. It adds (``velocity_weight``) the squared
error of the clean estimate's velocities, from the last past pose on (MDM's "geometric" loss),
for the seams, where a chunk's first frame must continue the last pose. The measurements behind
both choices are in ``docs/benchmarks.md``.

**Sampling** (:func:`denoise`): from ``x_1 = noise`` down to ``s = 0`` in ``steps`` equal steps;
``method="ddim"`` is deterministic given ``x_1`` (Song et al.), ``"ddpm"`` draws fresh noise at
each step (the ancestral sampler, Ho et al.).

**Classifier-free guidance** (Ho & Salimans 2022): while training, the speech, activity and style
are hidden together with probability ``unconditioned`` (the "heard" flag tells the network), so
the same network also predicts unconditioned motion; sampling with ``guidance = w`` uses
``uncond + w (cond - uncond)``: 1 is the plain conditional model, above 1 follows the speech and
style more closely. The past poses are hidden with probability ``past_dropout`` (the first chunk
of a recording starts from the mean pose, and the model must not merely continue its past).

Logged scalars (``loss(batch)``): ``prediction``, the mean squared error of the prediction
(normalised pose units); ``velocity``, that of the clean estimate's frame-to-frame velocities
(from the last past pose on); ``loss = prediction + velocity_weight * velocity``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from gesturelib.configs import SpeechContext, check_fields
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.models.common import batch_parts, check_config_type
from gesturelib.models.control import control_shapes
from gesturelib.skeleton import POSE_DIM
from gesturelib.style import STYLE_FEATURES

#: What the network predicts, as the config names it.
PREDICTIONS = ("epsilon", "x0", "v")
#: The samplers of :func:`denoise`, with the share of fresh noise each draws per step (eta).
METHODS = {"ddim": 0.0, "ddpm": 1.0}
#: The log signal-to-noise ratio at s = 0 (clean) and s = 1 (pure noise).
LOGSNR_RANGE = (20.0, -20.0)


@dataclass(frozen=True)
class DiffusionConfig(SpeechContext):
    """The diffusion model's windows, network and training.

    Attributes:
        speech_past, speech_future: the speech window around a chunk's first frame (15 and 25
            frames); the timeline has ``speech_past + 1 + speech_future`` frames.
        past_poses: tau, the poses before the chunk it is conditioned on (``<= speech_past``).
        chunk: C, frames denoised at once (``<= speech_future + 1``, so that every frame of the
            chunk lies in the window).
        style: also condition on the style measured from the motion (:mod:`gesturelib.style`).
        width, layers: channels and residual blocks of the convolution stack.
        prediction: ``"epsilon"``, ``"x0"`` or ``"v"`` (module docstring).
        unconditioned: probability of hiding speech, activity and style while training (for
            classifier-free guidance).
        past_dropout: probability of hiding the past poses while training.
        velocity_weight: weight of the squared error of the clean estimate's velocities (frame
            to frame, from the last past pose on) in the loss.
    """

    speech_past: int = 15
    past_poses: int = 10
    chunk: int = 10
    style: bool = False
    width: int = 128
    layers: int = 8
    prediction: str = "x0"
    unconditioned: float = 0.1
    past_dropout: float = 0.1
    velocity_weight: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            counts=("past_poses",),
            positive=("chunk", "width", "layers"),
            fractions=("unconditioned", "past_dropout"),
            non_negative=("velocity_weight",),
            flags=("style",),
        )
        if self.past_poses > self.speech_past:
            raise ValueError(
                f"DiffusionConfig.past_poses ({self.past_poses}) must not exceed speech_past "
                f"({self.speech_past}): the past poses lie on the speech window's timeline"
            )
        if self.chunk > self.speech_future + 1:
            raise ValueError(
                f"DiffusionConfig.chunk ({self.chunk}) must not exceed speech_future + 1 "
                f"({self.speech_future + 1}): every frame of a chunk lies in the speech window"
            )
        if self.prediction not in PREDICTIONS:
            raise ValueError(
                f"DiffusionConfig.prediction must be one of {PREDICTIONS}, got {self.prediction!r}"
            )
        if self.prediction == "epsilon" and self.velocity_weight > 0:
            raise ValueError(
                "DiffusionConfig.velocity_weight needs prediction 'x0' or 'v': the clean estimate "
                "of an 'epsilon' prediction is unbounded at high noise (divided by alpha)"
            )

    @classmethod
    def quick(cls, **changes) -> DiffusionConfig:
        """A small model for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(width=32, layers=4), **changes)


@dataclass(frozen=True)
class Sampling:
    """How :meth:`GestureDiffusion.step` samples (set ``model.sampling``; not part of training).

    Attributes:
        steps: denoising steps per chunk.
        method: ``"ddim"`` (deterministic given the starting noise) or ``"ddpm"`` (fresh noise
            at every step).
        guidance: classifier-free guidance weight ``w``; 1 is the plain conditional model.
    """

    steps: int = 20
    method: str = "ddim"
    guidance: float = 1.0

    def __post_init__(self):
        check_fields(self, positive=("steps",), non_negative=("guidance",))
        if self.method not in METHODS:
            raise ValueError(
                f"Sampling.method must be one of {tuple(METHODS)}, got {self.method!r}"
            )

    @property
    def draws(self) -> int:
        """Noise tensors a chunk needs: the start, and one per later step for ``ddpm``."""
        return self.steps if METHODS[self.method] > 0 else 1


# ---------------------------------------------------------------------------------------------
# The noise schedule and the sampler, independent of the network
# ---------------------------------------------------------------------------------------------


def alpha_sigma(level: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(alpha, sigma)`` at noise levels ``level`` in [0, 1] (any shape): the cosine schedule
    of the log signal-to-noise ratio, from ``LOGSNR_RANGE[0]`` at 0 to ``LOGSNR_RANGE[1]`` at 1."""
    high, low = LOGSNR_RANGE
    start, end = math.atan(math.exp(-high / 2)), math.atan(math.exp(-low / 2))
    logsnr = -2 * torch.log(torch.tan(start + level * (end - start)))
    return torch.sigmoid(logsnr).sqrt(), torch.sigmoid(-logsnr).sqrt()


def clean_and_noise(
    output: torch.Tensor, noisy: torch.Tensor, alpha: torch.Tensor, sigma: torch.Tensor, kind: str
) -> tuple[torch.Tensor, torch.Tensor]:
    """The clean sample and the noise ``(x0, eps)`` that a prediction of ``kind`` stands for,
    given the noisy sample ``x_s = alpha x0 + sigma eps`` (``alpha``, ``sigma`` broadcast)."""
    if kind == "epsilon":
        return (noisy - sigma * output) / alpha, output
    if kind == "x0":
        return output, (noisy - alpha * output) / sigma
    assert kind == "v"
    return alpha * noisy - sigma * output, sigma * noisy + alpha * output


def target_of(clean: torch.Tensor, noise: torch.Tensor, alpha, sigma, kind: str) -> torch.Tensor:
    """What a network predicting ``kind`` should output for ``x_s = alpha clean + sigma noise``."""
    return {"epsilon": noise, "x0": clean, "v": alpha * noise - sigma * clean}[kind]


def denoise(
    predict: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    noise: torch.Tensor,
    steps: int,
    method: str,
    kind: str,
) -> torch.Tensor:
    """A sample ``x_0`` from the noise ``x_1`` by ``steps`` reverse steps (DDIM / DDPM).

    Args:
        predict: ``predict(x_s (B, ...), s (B,)) -> output (B, ...)``, the network's prediction
            of ``kind`` at level ``s``.
        noise: ``(draws, B, ...)``: ``noise[0]`` is ``x_1``; with ``method="ddpm"``,
            ``noise[1:]`` the fresh noise of the later steps (``draws = steps``).
        steps: reverse steps, from level 1 to 0 in equal strides.
        method: a key of :data:`METHODS`.
        kind: what ``predict`` outputs (:data:`PREDICTIONS`).
    Returns:
        ``(B, ...)`` the sample.
    """
    eta = METHODS[method]
    assert len(noise) == (steps if eta > 0 else 1)
    x = noise[0]
    levels = torch.linspace(1.0, 0.0, steps + 1, device=x.device)
    for number in range(steps):
        now, then = levels[number], levels[number + 1]
        alpha, sigma = alpha_sigma(now)
        clean, eps = clean_and_noise(predict(x, now.expand(len(x))), x, alpha, sigma, kind)
        if number + 1 < steps:
            alpha_then, sigma_then = alpha_sigma(then)
            # The share of the next level's noise drawn afresh (DDIM's sigma_t(eta)).
            fresh = eta * sigma_then / sigma * (1 - (alpha / alpha_then) ** 2).clamp(min=0).sqrt()
            x = alpha_then * clean + (sigma_then**2 - fresh**2).clamp(min=0).sqrt() * eps
            if eta > 0:
                x = x + fresh * noise[number + 1]
    return clean


# ---------------------------------------------------------------------------------------------
# The network
# ---------------------------------------------------------------------------------------------


class LevelEmbedding(nn.Module):
    """The noise level ``s`` ``(B,)`` as ``(B, width)`` features (sinusoids, then an MLP)."""

    def __init__(self, width: int, frequencies: int = 32):
        super().__init__()
        scales = torch.exp(-math.log(1000.0) * torch.arange(frequencies) / frequencies)
        self.register_buffer("scales", 1000.0 * scales, persistent=False)
        self.mlp = nn.Sequential(
            nn.Linear(2 * frequencies, width), nn.SiLU(), nn.Linear(width, width)
        )

    def forward(self, level: torch.Tensor) -> torch.Tensor:
        angles = level[:, None] * self.scales
        return self.mlp(torch.cat([angles.sin(), angles.cos()], dim=-1))


class ResidualBlock(nn.Module):
    """A dilated convolution over time, scaled and shifted by the noise level: ``(B, width, W)``."""

    def __init__(self, width: int, dilation: int):
        super().__init__()
        self.norm = nn.GroupNorm(min(8, width), width)
        self.modulation = nn.Linear(width, 2 * width)
        self.conv = nn.Conv1d(width, width, 3, padding=dilation, dilation=dilation)
        self.mix = nn.Conv1d(width, width, 1)
        nn.init.zeros_(self.mix.weight)  # each block starts as the identity
        nn.init.zeros_(self.mix.bias)

    def forward(self, h: torch.Tensor, level: torch.Tensor) -> torch.Tensor:
        scale, shift = self.modulation(level)[..., None].chunk(2, dim=1)
        inner = nn.functional.silu(self.norm(h) * (1 + scale) + shift)
        return h + self.mix(nn.functional.silu(self.conv(inner)))


class GestureDiffusion(nn.Module):
    """Chunks of poses denoised from noise given speech, activity, the past poses (and style);
    see the module docstring.

    ``loss(batch)`` needs the items of :class:`gesturelib.data.WindowDataset` with
    ``sequence_length = chunk``: ``pose (B, C, 54)``, ``past_pose (B, C, tau, 54)``, ``speech
    (B, C, W, 27)``, ``activity (B, C, W, 4)`` and, with ``style``, ``style (B, C, 4)``; only the
    first frame's windows are read (those of the chunk's start).
    """

    config_class = DiffusionConfig
    #: The temperature generation uses unless told otherwise (it scales every noise drawn).
    default_temperature = 1.0

    def __init__(self, config: DiffusionConfig):
        super().__init__()
        check_config_type(self, config)
        self.config = config
        self.sampling = Sampling()
        channels = N_MELS + NUM_ACTIVITIES + 1 + POSE_DIM + 2
        channels += len(STYLE_FEATURES) if config.style else 0
        self.inputs = nn.Conv1d(channels, config.width, 1)
        self.level = LevelEmbedding(config.width)
        self.blocks = nn.ModuleList(
            ResidualBlock(config.width, 2 ** (number % 4)) for number in range(config.layers)
        )
        self.outputs = nn.Conv1d(config.width, POSE_DIM, 1)

    @property
    def noise_dim(self) -> int:
        """Numbers of noise one :meth:`step` needs (:mod:`gesturelib.sampling` draws them)."""
        return self.sampling.draws * self.config.chunk * POSE_DIM

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The squared errors of the prediction and of its velocities at a random noise level
        per chunk (module docstring)."""
        pose, condition = self._parts(batch, "GestureDiffusion.loss")
        config = self.config
        if pose.shape[1] != config.chunk:
            raise ValueError(
                f"GestureDiffusion.loss needs windows of {config.chunk} frames (the chunk), got "
                f"{pose.shape[1]}: train it with WindowConfig(sequence_length={config.chunk})"
            )
        # Fixed draws in evaluation, so that the validation loss is the same every time.
        generator = None if self.training else torch.Generator(pose.device).manual_seed(0)

        def uniform(*shape):
            return torch.rand(shape, generator=generator, device=pose.device)

        level = uniform(len(pose))
        noise = torch.randn(pose.shape, generator=generator, device=pose.device)
        alpha, sigma = (value[:, None, None] for value in alpha_sigma(level))
        hide = {}
        if self.training:
            hide = {
                "condition_hidden": uniform(len(pose)) < config.unconditioned,
                "past_hidden": uniform(len(pose)) < config.past_dropout,
            }
        noisy = alpha * pose + sigma * noise
        output = self._network(noisy, level, condition, **hide)
        target = target_of(pose, noise, alpha, sigma, config.prediction)
        error = (output - target).pow(2).mean()
        # The velocities of the clean estimate, from the last past pose on (where it is shown):
        # the step into the chunk is where chunks meet.
        clean = clean_and_noise(output, noisy, alpha, sigma, config.prediction)[0]
        last = condition["past"][:, -1:] if config.past_poses else pose[:, :1]
        speed_error = (
            torch.cat([last, clean], 1).diff(dim=1) - torch.cat([last, pose], 1).diff(dim=1)
        ).pow(2)
        if "past_hidden" in hide:  # no step into a chunk whose past was hidden
            shown = torch.ones(speed_error.shape[:2], device=pose.device)
            shown[:, 0] = ~hide["past_hidden"]
            speed_error = speed_error * shown[..., None]
        velocity = speed_error.mean()
        loss = error + config.velocity_weight * velocity
        return {"loss": loss, "prediction": error.detach(), "velocity": velocity.detach()}

    @torch.no_grad()
    def step(self, frame: dict[str, torch.Tensor], state, noise: torch.Tensor):
        """The next chunk of poses, ``(B, C, 54)`` normalised, from the control of its first frame.

        Args:
            frame: as a batch with ``L = 1``: ``past_pose (B, 1, tau, 54)`` (the model's own
                recent output), ``speech (B, 1, W, 27)``, ``activity (B, 1, W, 4)`` (and
                ``style (B, 1, 4)``).
            state: unused (the past poses carry everything); returned as given.
            noise: ``(B, noise_dim)``, already scaled by the temperature.
        Returns:
            ``(poses (B, C, 54), state)``.
        """
        _, condition = self._parts(frame, "GestureDiffusion.step", with_pose=False)
        batch, sampling = len(noise), self.sampling
        draws = noise.reshape(batch, sampling.draws, self.config.chunk, POSE_DIM).transpose(0, 1)
        guided = sampling.guidance != 1

        def predict(x, level):
            if not guided:
                return self._network(x, level, condition)
            both = {key: torch.cat([value, value]) for key, value in condition.items()}
            hidden = torch.arange(2 * batch, device=x.device) >= batch
            output = self._network(torch.cat([x, x]), torch.cat([level, level]), both, hidden)
            heard, unheard = output.chunk(2)
            return unheard + sampling.guidance * (heard - unheard)

        poses = denoise(predict, draws, sampling.steps, sampling.method, self.config.prediction)
        return poses, state

    def _parts(self, batch, owner: str, with_pose: bool = True):
        """``(pose (B, C, 54) or None, condition)``: the condition of each item's first frame,
        ``past (B, tau, 54)``, ``speech (B, W, 27)``, ``activity (B, W, 4)`` (``style (B, 4)``)."""
        expected = control_shapes(self.config)
        if with_pose:
            expected = {"pose": (POSE_DIM,), **expected}
        parts = batch_parts(batch, expected, owner)
        pose = parts.pop(0) if with_pose else None
        names = ["past", "speech", "activity", "style"][: len(parts)]
        return pose, {name: part[:, 0] for name, part in zip(names, parts, strict=True)}

    def _network(
        self,
        noisy: torch.Tensor,
        level: torch.Tensor,
        condition: dict[str, torch.Tensor],
        condition_hidden: torch.Tensor | None = None,
        past_hidden: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The prediction ``(B, C, 54)`` for the noisy chunk ``(B, C, 54)`` at levels ``(B,)``;
        ``*_hidden`` ``(B,)`` booleans hide the condition or the past poses of some items."""
        config = self.config
        batch, window = len(noisy), config.speech_window
        heard = torch.ones(batch, device=noisy.device)
        if condition_hidden is not None:
            heard = heard * ~condition_hidden
        seen = torch.ones(batch, device=noisy.device)
        if past_hidden is not None:
            seen = seen * ~past_hidden
        start = config.speech_past  # the chunk's first frame on the timeline
        timeline = noisy.new_zeros(batch, window, POSE_DIM + 2)
        tau = config.past_poses
        timeline[:, start - tau : start, :POSE_DIM] = condition["past"] * seen[:, None, None]
        timeline[:, start - tau : start, POSE_DIM] = seen[:, None]
        timeline[:, start : start + config.chunk, :POSE_DIM] = noisy
        timeline[:, start : start + config.chunk, POSE_DIM + 1] = 1.0
        heard_ = heard[:, None, None]
        heard_parts = [condition["speech"] * heard_, condition["activity"] * heard_]
        if config.style:
            heard_parts.append(
                (condition["style"] * heard[:, None])[:, None].expand(-1, window, -1)
            )
        heard_parts.append(heard_.expand(-1, window, 1))
        channels = torch.cat([*heard_parts, timeline], dim=-1).transpose(1, 2)
        h = self.inputs(channels)
        embedded = self.level(level)
        for block in self.blocks:
            h = block(h, embedded)
        return self.outputs(h).transpose(1, 2)[:, start : start + config.chunk]
