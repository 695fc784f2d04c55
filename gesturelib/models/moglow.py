"""MoGlow (Alexanderson et al. 2020): an autoregressive, speech-conditioned flow over poses.

MoGlow models the next pose given its context, ``p(x_t | x_{t-tau..t-1}, c_t)``, as a Glow flow
over the 54 pose numbers whose couplings hold LSTMs:

    x_t  --ActNorm--linear--coupling(LSTM)--> ... (K steps) -->  z_t ~ N(0, I)

* **The control** ``c_t`` of frame ``t`` (:mod:`gesturelib.models.control`): the previous
  ``tau = 5`` poses (with data dropout while training), the speech window with 1 s of
  look-ahead (moved up or down a few mel bands while training) and the same window of who is
  talking, encoded by one small network into
  ``control_size`` numbers that every coupling reads next to the untouched half of the pose, and
  optionally the style, read beside them as it is.
* **Memory**: each coupling's LSTM runs along the frames, so the flow at frame ``t`` depends on
  everything before it, not only on ``tau`` poses. The likelihood of a sequence is exact:
  ``log p(x_{1:T} | c) = sum_t log p(x_t | x_{<t}, c_t)``.
* **Pose noise**: poses lie on an 18-dimensional surface inside their 54 numbers, where a density
  is infinite, so the flow is trained on poses plus noise off the surface
  (:mod:`gesturelib.pose_surface`), which moves no limb.
* **Residual** (``residual=True``): the flow models the change from the last pose,
  ``x_t - x_{t-1}``, a shift by a known vector (log-determinant 0), so the likelihood is still
  that of ``x_t``. Motion is smooth, so the next pose lies very close to the last one; modelled
  directly, the flow must learn that sharp a conditional from the past poses in its control,
  which takes long training, and until then its samples jitter from frame to frame. The shift uses
  the true last pose, which data dropout never hides.

Training is teacher-forced on excerpts (4 s by default) from a zero state; one ``loss`` call
evaluates a whole excerpt in one pass. Generation (:mod:`gesturelib.sampling`) runs frame by frame
through :meth:`MoGlow.step`, starting from the mean pose and feeding back its own output.

Logged scalars (``loss(batch)``): ``loss`` = ``nll``, the negative log-likelihood per frame
(nats) of the noisy poses.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import nn

from gesturelib.configs import check_fields
from gesturelib.flows import RecurrentFlow, recurrent_glow
from gesturelib.models.common import batch_parts, check_config_type
from gesturelib.models.control import ControlConfig, ControlEncoder
from gesturelib.pose_surface import SurfaceNoise
from gesturelib.skeleton import POSE_DIM


@dataclass(frozen=True)
class MoGlowConfig(ControlConfig):
    """MoGlow's sizes (the paper: K = 16 steps, LSTMs of 800 units; here sized for a CPU).

    Attributes:
        speech_past: frames of past speech and activity, 15 (0.6 s; the paper: 5): a listener's
            nod comes up to half a second after the partner's phrase ends, which the control must
            still show when the head moves.
        voice_shift: 2: while training, each excerpt's speech is moved by up to two of the 27
            mel bands, so that a voice higher or lower than the course's drives the model as
            theirs do (chapter 08); runs saved before the field existed had 0.
        speech_future, past_poses, style, control_size, dropout: the control
            (:class:`~gesturelib.models.control.ControlConfig`).
        steps: Glow steps ``K``.
        hidden: units of each coupling's LSTM, and of the control encoder's hidden layer.
        pose_noise: standard deviation of the noise added to the poses, normalised units.
        noise_moves_limbs: noise in all 54 directions (True), not only in those that move no limb.
        residual: the flow models the change from the last pose, ``x_t - x_{t-1}`` (needs
            ``past_poses >= 1``); see the module docstring.
    """

    speech_past: int = 15
    voice_shift: int = 2
    steps: int = 8
    hidden: int = 128
    pose_noise: float = 0.05
    noise_moves_limbs: bool = False
    residual: bool = True

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            positive=("steps", "hidden"),
            non_negative=("pose_noise",),
            flags=("noise_moves_limbs", "residual"),
        )
        if self.residual and self.past_poses < 1:
            raise ValueError("residual=True models the change from the last pose: past_poses >= 1")

    @classmethod
    def quick(cls, **changes) -> MoGlowConfig:
        """A small MoGlow for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(steps=4, hidden=32, control_size=16), **changes)


class MoGlow(nn.Module):
    """The next-pose flow given past poses, speech, activity (and style); see the module docstring.

    ``loss(batch)`` needs ``pose (B, L, 54)``, ``past_pose (B, L, tau, 54)``, ``speech
    (B, L, W, 27)``, ``activity (B, L, W, 4)`` and, with ``style``, ``style (B, L, 4)``: the items
    of :class:`gesturelib.data.WindowDataset` with ``sequence_length = L``.

    Args:
        config: the sizes.
        normaliser: the statistics the poses are normalised with (the pose noise needs them);
            a model rebuilt from a checkpoint gets them back with its weights.
    """

    config_class = MoGlowConfig
    #: The temperature generation uses unless told otherwise.
    default_temperature = 1.0

    def __init__(self, config: MoGlowConfig, normaliser=None):
        super().__init__()
        check_config_type(self, config)
        self.config = config
        self.control = ControlEncoder(config, config.hidden)
        self.flow: RecurrentFlow = recurrent_glow(
            POSE_DIM, config.steps, config.hidden, config.encoded_size, cell="lstm"
        )
        self.noise = SurfaceNoise(config.pose_noise, across_only=not config.noise_moves_limbs)
        if normaliser is not None:
            self.noise.set_statistics(normaliser)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Negative log-likelihood per frame of the noisy poses of ``batch`` (teacher forcing)."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, "MoGlow.loss")
        # Fixed noise in evaluation, so that the validation loss is the same every time.
        generator = None if self.training else torch.Generator(pose.device).manual_seed(0)
        noisy = pose + self.noise(pose, generator) - self._origin(batch)
        log_prob, _ = self.flow.log_prob(noisy, self.conditioning(batch, training=self.training))
        nll = -log_prob.mean() / pose.shape[1]
        return {"loss": nll, "nll": nll.detach()}

    def conditioning(self, batch, training: bool = False) -> torch.Tensor:
        """What every coupling reads: the encoded control ``(B, L, encoded_size)``."""
        return self.control(batch, training=training)

    @torch.no_grad()
    def latents(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """The base codes ``z`` ``(B, L, 54)`` of the poses of ``batch`` (teacher forcing, no pose
        noise): what :meth:`step` turns back into these poses with the same control."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, f"{type(self).__name__}.latents")
        z, _, _ = self.flow(pose - self._origin(batch), self.conditioning(batch))
        return z

    @property
    def noise_dim(self) -> int:
        """Numbers of base noise per generated frame (:mod:`gesturelib.sampling` draws them)."""
        return POSE_DIM

    def generating(self):
        """``with model.generating():`` fixes the weights for frame-by-frame generation (each
        linear layer's inverse is computed once, no gradients)."""
        return self.flow.fixed_weights()

    @torch.no_grad()
    def step(self, frame: dict[str, torch.Tensor], state, noise: torch.Tensor):
        """One frame of generation: the pose ``x_t`` for base noise ``z_t``, ``(B, 54)`` normalised.

        Args:
            frame: the control of one frame, as a batch with ``L = 1``: ``past_pose
                (B, 1, tau, 54)`` (the model's own recent output), ``speech (B, 1, W, 27)``,
                ``activity (B, 1, W, 4)`` (and ``style (B, 1, 4)``).
            state: the flow's state after the previous frame (None at the start).
            noise: ``z_t`` ``(B, 54)``, already scaled by the temperature (0: the base's mode).
        Returns:
            ``(pose (B, 54), state)``.
        """
        pose, _, state = self.flow.inverse(noise[:, None], self.conditioning(frame), state)
        return (pose + self._origin(frame))[:, 0], state

    def _origin(self, batch) -> torch.Tensor | float:
        """What the flow's poses are measured from: the last pose ``(B, L, 54)`` (never dropped
        out), or 0."""
        return batch["past_pose"][:, :, -1] if self.config.residual else 0.0
