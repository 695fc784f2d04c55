"""MoGlow (Alexanderson et al. 2020): an autoregressive, speech-conditioned flow over poses.

MoGlow models the next pose given its context, ``p(x_t | x_{t-tau..t-1}, c_t)``, as a Glow flow
over the 54 pose numbers whose couplings hold LSTMs:

    x_t  --ActNorm--linear--coupling(LSTM)--> ... (K steps) -->  z_t ~ N(0, I)

* **The control** ``c_t`` of frame ``t``: the previous ``tau = 5`` poses, the speech window
  (5 past, the current and 25 future log-mel frames: 1 s of look-ahead, because gestures lead the
  speech they go with), the same window of the who-is-talking one-hot, and optionally the style
  (:mod:`gesturelib.style`). Every coupling reads it, next to the untouched half of the pose.
* **Memory**: each coupling's LSTM runs along the frames, so the flow at frame ``t`` depends on
  everything before it, not only on ``tau`` poses. The likelihood of a sequence is exact:
  ``log p(x_{1:T} | c) = sum_t log p(x_t | x_{<t}, c_t)``.
* **A shared control encoder**: the raw control is about 1.2k numbers a frame. Given to each of
  the ``K`` LSTMs it would dominate the cost, so one small network (as Ye et al.'s global
  encoder) turns it into ``control_size`` numbers that all couplings read
  (``control_size=0`` feeds the raw control to every coupling, as the reference code does;
  ``benchmarks/bench_moglow.py`` measures the two).
* **Data dropout** (training only): each past pose in the control is replaced by the mean pose
  (zero, in normalised units) with probability ``dropout`` (0.4, the paper's), independently.
  Without it the model can predict the next pose from the last ones alone and ignore the speech.
  Validation never drops (the reference code validates with dropout on: a bug we avoid).
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

from gesturelib.configs import SpeechContext, check_fields
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.flows import RecurrentFlow, recurrent_glow
from gesturelib.models.common import batch_parts
from gesturelib.pose_surface import SurfaceNoise
from gesturelib.skeleton import POSE_DIM
from gesturelib.style import STYLE_FEATURES


@dataclass(frozen=True)
class MoGlowConfig(SpeechContext):
    """MoGlow's sizes (the paper: K = 16 steps, LSTMs of 800 units; here sized for a CPU).

    Attributes:
        speech_past, speech_future: the speech and activity window (5 and 25 frames).
        past_poses: tau, the previous poses in the control.
        style: also condition on the style measured from the motion (:mod:`gesturelib.style`).
        steps: Glow steps ``K``.
        hidden: units of each coupling's LSTM, and of the control encoder's hidden layer.
        control_size: numbers the shared control encoder outputs; 0 feeds the raw control to
            every coupling.
        dropout: probability of replacing each past pose by the mean pose while training.
        pose_noise: standard deviation of the noise added to the poses, normalised units.
        noise_moves_limbs: noise in all 54 directions (True), not only in those that move no limb.
        residual: the flow models the change from the last pose, ``x_t - x_{t-1}`` (needs
            ``past_poses >= 1``); see the module docstring.
    """

    past_poses: int = 5
    style: bool = False
    steps: int = 8
    hidden: int = 128
    control_size: int = 64
    dropout: float = 0.4
    pose_noise: float = 0.05
    noise_moves_limbs: bool = False
    residual: bool = True

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            positive=("steps", "hidden"),
            counts=("past_poses", "control_size"),
            fractions=("dropout",),
            non_negative=("pose_noise",),
            flags=("style", "noise_moves_limbs", "residual"),
        )
        if self.residual and self.past_poses < 1:
            raise ValueError("residual=True models the change from the last pose: past_poses >= 1")

    @property
    def raw_control_size(self) -> int:
        """Numbers in the control of one frame before encoding."""
        window = self.speech_window * (N_MELS + NUM_ACTIVITIES)
        return self.past_poses * POSE_DIM + window + (len(STYLE_FEATURES) if self.style else 0)

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
        self.config = config
        raw = config.raw_control_size
        if config.control_size:
            self.encoder = nn.Sequential(
                nn.Linear(raw, config.hidden),
                nn.ReLU(),
                nn.Linear(config.hidden, config.control_size),
            )
        else:
            self.encoder = nn.Identity()
        self.flow: RecurrentFlow = recurrent_glow(
            POSE_DIM, config.steps, config.hidden, config.control_size or raw, cell="lstm"
        )
        self.noise = SurfaceNoise(config.pose_noise, across_only=not config.noise_moves_limbs)
        if normaliser is not None:
            self.noise.set_statistics(normaliser)

    def control(self, batch: dict[str, torch.Tensor], drop_past: bool = False) -> torch.Tensor:
        """The encoded control of every frame, ``(B, L, control_size)`` (raw: ``(B, L, 1231)``).

        Args:
            batch: ``past_pose``, ``speech``, ``activity`` (and ``style``), as for :meth:`loss`.
            drop_past: apply data dropout to the past poses (training only).
        """
        config = self.config
        expected = {
            "past_pose": (config.past_poses, POSE_DIM),
            "speech": (config.speech_window, N_MELS),
            "activity": (config.speech_window, NUM_ACTIVITIES),
        }
        if config.style:
            expected["style"] = (len(STYLE_FEATURES),)
        parts = batch_parts(batch, expected, "MoGlow")
        past = parts[0]
        if drop_past and config.dropout > 0:
            kept = torch.rand(past.shape[:3], device=past.device) >= config.dropout
            past = past * kept[..., None]  # a dropped pose becomes the mean pose, zero
        flat = [part.flatten(2) for part in (past, *parts[1:])]
        return self.encoder(torch.cat(flat, dim=-1))

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Negative log-likelihood per frame of the noisy poses of ``batch`` (teacher forcing)."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, "MoGlow.loss")
        # Fixed noise in evaluation, so that the validation loss is the same every time.
        generator = None if self.training else torch.Generator(pose.device).manual_seed(0)
        noisy = pose + self.noise(pose, generator) - self._origin(batch)
        log_prob, _ = self.flow.log_prob(noisy, self.control(batch, drop_past=self.training))
        nll = -log_prob.mean() / pose.shape[1]
        return {"loss": nll, "nll": nll.detach()}

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
        pose, _, state = self.flow.inverse(noise[:, None], self.control(frame), state)
        return (pose + self._origin(frame))[:, 0], state

    def _origin(self, batch) -> torch.Tensor | float:
        """What the flow's poses are measured from: the last pose ``(B, L, 54)`` (never dropped
        out), or 0."""
        return batch["past_pose"][:, :, -1] if self.config.residual else 0.0
