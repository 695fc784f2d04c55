"""The conditional Flow-VAE (Taylor et al. 2021), and a variational variant whose loss is an ELBO.

An autoencoder compresses each pose to a small latent, ``x_t -> h_t -> x_t'``, frame by frame and
without any conditioning; a MoGlow-style flow (LSTM couplings, :mod:`gesturelib.flows.recurrent`)
models the latents of a motion given the control of each frame (past poses, speech and activity
windows: :mod:`gesturelib.models.control`):

    training:    x_t --encoder--> h_t --flow(c_t)--> z_t ~ N(0, I)
    generation:  z_t ~ N(0, I) --flow^-1(c_t)--> h'_t --decoder--> x'_t,  fed back as the past

Every part is trained together. The flow works on ``latent_dim`` numbers instead of 54, which is
why the paper's model is smaller and faster to train than MoGlow.

:class:`FlowVAE` is the paper's model, and its config's defaults are the course's recipe, which
differs from the paper in four settings explained below (``detach_prior``, ``residual``,
``leak`` and ``transition_weight``; the paper's: ``FlowVAEConfig(detach_prior=False,
residual=False, leak=0, transition_weight=1)``). The recipe
(:mod:`gesturelib.recipes`) also lowers the data dropout on the past poses from the paper's 0.4
(the default) to 0.2: measured over six seeds, every run then keeps its drift and wrist speeds;
and it takes MoGlow's longer window of past speech (0.6 s) and shifted voices (``voice_shift``),
for voices it was not trained on (``docs/benchmarks.md``).
Its loss (eq. 4) is

    alpha * NLL(h) + MSE(x, d(h)) + MSE(x, d(h')),     h = e(x),  h' = f^-1(z'; c), z' ~ N(0, I)

where the last term, the paper's novelty, decodes a latent *drawn from the flow* for the same
control and asks it to be the real pose. ``sample_weight`` weighs it (0: the ablation), and the
recipe weighs it ``transition_weight`` = 3 times more on the frames where the agent is silent
with its own speech in the control's window: where the generator's hands retract after a phrase
and rise before the next, moments the flows otherwise move through too slowly
(``docs/benchmarks.md``; the paper's weight is 1 everywhere). The
encoder is deterministic, so NLL(h) is not a likelihood of ``x``: the encoder can lower it
without end by shrinking ``h``, and the decoder can undo the shrinking. Two remedies. The
recipe's is ``detach_prior``: the NLL's gradient stops at ``h``, so it trains the flow (and the
control encoder) to model the latents the autoencoder makes, and never the encoder to make
latents that are easy to model; the encoder has no reason to shrink, and no noise is needed
(``latent_noise=0``). The other is ``latent_noise``: the flow and the decoder see
``h + sigma * eps`` with a fixed ``sigma``, so a shrunken latent drowns in the noise and can no
longer be decoded. That makes the encoder a Gaussian with fixed variance, and the loss a
weighted, beta-VAE-like objective; but the flow learns the latents *with* their noise, so every
generated frame carries a fresh draw of it, which the decoder turns into jitter.

:class:`VariationalFlowVAE` makes it a true ELBO on ``log p(x | c)``: a Gaussian encoder
``q(h | x)``, the flow as the conditional prior ``p(h | c)``, and a Gaussian decoder with a
variance per pose number (the running mean of its squared error, fixed in evaluation),

    log p(x | c) >= E_q[log p(x | h)] - E_q[log q(h | x) - log p_flow(h | c)],

estimated with one draw of ``h``. Like MoGlow it models poses with a little noise off the pose
surface (:mod:`gesturelib.pose_surface`), so its bound and MoGlow's likelihood are in the same
nats. Generation decodes the decoder's mean.

The flow models the latent itself given the control, as in the paper; each frame's latent is a
new draw, and the motion jitters even without noise. Both models can model instead the change of
the latent from the encoding of the last pose, ``h_t - e(x_{t-1})``, as MoGlow models the change
of the pose (``residual=True``; a shift by a known vector, log-determinant 0), adding each
generated change to the last generated latent. Its motion is smooth, but over long generations it
drifts away from any plausible pose: the small errors of each change add up, and nothing pulls
the latent back (notebook 06 measures it; with ``latent_noise`` the noise itself adds up, a
random walk). ``leak`` is the pull: the change is measured from the last latent moved a fraction
``leak`` of the way towards the rest pose's latent ``e(r)``, ``h_t - (e(x_{t-1}) - leak *
(e(x_{t-1}) - e(r)))``, still a known shift. The flow can learn to undo the pull where the data
moves away from rest (its control shows the last poses), while the errors it cannot fit now
decay instead of adding up. The rest pose ``r`` (``rest_pose``) is the pose the agent holds
while still: the running mean, over the training batches, of the quarter of their frames that
moved least since the last frame. (On the course's data it lies within 2 cm of the mean pose in
posture, but its latent lies nearer the latents of real poses than ``e(0)`` does: the mean pose's
numbers are an average of rotations, not a rotation. Runs pulled towards ``e(0)``,
``pull_to_rest=False``, as runs saved before the rest pose existed were, drifted more.)
(Re-encoding each decoded pose as the origin, ``e(d(h'_{t-1}))``, is no remedy: encoder and
decoder do not quite undo each other, and the errors grow.)

Logged scalars (``loss(batch)``), all per frame: :class:`FlowVAE`: ``loss``, ``nll`` (of the
latent, nats), ``mse`` (of ``d(h)``, per number), ``sample_mse`` (of ``d(h')``; always on the
validation data, in training only if it is in the loss) and ``latent_scale`` (of ``h``:
:func:`latent_scale`); :class:`VariationalFlowVAE`: ``loss`` (= -ELBO, nats), ``reconstruction``
(-E log p(x | h)), ``kl`` and ``latent_scale`` (of the posterior means).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import torch
import torch.nn.functional as F
from torch import nn

from gesturelib.configs import check_fields
from gesturelib.conventions import Activity
from gesturelib.flows import RecurrentFlow, recurrent_glow
from gesturelib.models.common import batch_parts, check_config_type, mlp
from gesturelib.models.control import ControlConfig, ControlEncoder
from gesturelib.pose_surface import SurfaceNoise
from gesturelib.runtime import standard_normal
from gesturelib.skeleton import POSE_DIM

LOG_2PI = math.log(2 * math.pi)


def latent_scale(latent: torch.Tensor) -> torch.Tensor:
    """The spread of latents ``(..., D)``: the geometric mean of their standard deviations along
    their principal axes, ``det(Cov)^(1 / 2D)``.

    A flow's log-likelihood of the latents rises by ``log`` of this for every number it models
    when the latents shrink, or collapse onto fewer dimensions (then it tends to 0), so it is
    the scale a deterministic encoder is tempted to reduce.
    """
    frames = latent.reshape(-1, latent.shape[-1]).double()
    variances = torch.linalg.eigvalsh(torch.cov(frames.T)).clamp_min(1e-30)
    return variances.log().mean().mul(0.5).exp().to(latent.dtype)


@dataclass(frozen=True)
class LatentFlowConfig(ControlConfig):
    """What both Flow-VAEs share: the control, the autoencoder and the flow over its latent.

    Attributes:
        speech_past, speech_future, past_poses, style, control_size, dropout, voice_shift: the
            control (:class:`~gesturelib.models.control.ControlConfig`).
        latent_dim: numbers per latent ``h_t`` (the paper: 35).
        autoencoder_hidden: units of the encoder's and the decoder's hidden layer (the paper: 105).
        steps: Glow steps ``K`` of the flow (the paper: 8).
        hidden: units of each coupling's LSTM and of the control encoder (the paper: 400).
        residual: the flow models ``h_t - e(x_{t-1})`` (needs ``past_poses >= 1``), not ``h_t``
            as the paper does; see the module docstring.
        leak: with ``residual``, the fraction of the way from the last latent to the rest pose's
            that the change is measured from (0: none; see the module docstring).
        pull_to_rest: ``leak`` pulls towards the rest pose's latent (the model tracks the rest
            pose while training), not the mean pose's.
    """

    #: Fields added after runs were saved, with the value those runs were trained with, so that
    #: their checkpoints load as they were trained (:func:`gesturelib.configs.config_from_dict`).
    FIELDS_ADDED: ClassVar[dict] = {
        **ControlConfig.FIELDS_ADDED,
        "leak": 0.0,
        "pull_to_rest": False,
    }

    latent_dim: int = 16
    autoencoder_hidden: int = 105
    steps: int = 4
    hidden: int = 64
    residual: bool = True
    leak: float = 0.02
    pull_to_rest: bool = True

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            positive=("latent_dim", "autoencoder_hidden", "steps", "hidden"),
            fractions=("leak",),
            flags=("residual", "pull_to_rest"),
        )
        if not 2 <= self.latent_dim < POSE_DIM:
            raise ValueError(
                f"{type(self).__name__}.latent_dim must be between 2 and {POSE_DIM - 1} (a "
                f"latent smaller than the pose, and a flow needs 2 numbers), got {self.latent_dim}"
            )
        if self.residual and self.past_poses < 1:
            raise ValueError("residual=True needs the last pose in the control: past_poses >= 1")
        if self.leak and not self.residual:
            raise ValueError(
                "leak pulls the latent of a residual model: it needs residual=True "
                "(for a model of the latent itself, set leak=0 too)"
            )

    @classmethod
    def quick(cls, **changes):
        """A small model for tests and quick mode; ``changes`` override any field."""
        small = cls(latent_dim=8, autoencoder_hidden=32, steps=2, hidden=32, control_size=16)
        return dataclasses.replace(small, **changes)


@dataclass(frozen=True)
class FlowVAEConfig(LatentFlowConfig):
    """The paper's Flow-VAE: :class:`LatentFlowConfig` and the weights of its loss.

    Attributes:
        alpha: weight of the latent's NLL (the paper's 5e-4).
        sample_weight: weight of ``MSE(x, d(h'))``, the term with a latent drawn from the flow
            (the paper: 1; 0 leaves it out).
        transition_weight: that term's weight, relative to the other frames', on the frames
            where the agent is silent with its own speech in the control's window (the last
            ``speech_past`` frames or the next ``speech_future``): where its hands retract
            after a phrase and rise before the next (the paper: 1).
        latent_noise: standard deviation of the noise added to ``h`` (0: none, and the encoder
            can shrink its latent without end unless ``detach_prior``; see the module docstring).
        detach_prior: the NLL trains the flow alone: its gradient does not reach the encoder
            (the paper's does).
    """

    FIELDS_ADDED: ClassVar[dict] = {
        **LatentFlowConfig.FIELDS_ADDED,
        "detach_prior": False,
        "transition_weight": 1.0,
    }

    alpha: float = 5e-4
    sample_weight: float = 1.0
    transition_weight: float = 3.0
    latent_noise: float = 0.0
    detach_prior: bool = True

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            non_negative=("alpha", "sample_weight", "transition_weight", "latent_noise"),
            flags=("detach_prior",),
        )


@dataclass(frozen=True)
class VariationalFlowVAEConfig(LatentFlowConfig):
    """The variational Flow-VAE: :class:`LatentFlowConfig` and MoGlow's pose noise.

    Attributes:
        pose_noise: standard deviation of the noise off the pose surface, normalised units (as
            :class:`~gesturelib.models.MoGlowConfig`, so that the two are measured in the same
            nats).
    """

    pose_noise: float = 0.05

    def __post_init__(self):
        super().__post_init__()
        check_fields(self, non_negative=("pose_noise",))


class _LatentFlowModel(nn.Module):
    """The control encoder, the flow over the latent, the decoder, and generation.

    Subclasses add the encoder, :meth:`encode` (the latent, or its mean, of poses ``(..., 54)``)
    and ``loss``.
    """

    #: The temperature generation uses unless told otherwise.
    default_temperature = 1.0
    #: The share of a training batch's frames, those that moved least, whose mean pose is taken
    #: as the rest pose, and how far each batch moves the tracked rest pose towards it.
    still_share = 0.25
    rest_momentum = 0.05

    def __init__(self, config: LatentFlowConfig):
        super().__init__()
        check_config_type(self, config)
        self.config = config
        self.control = ControlEncoder(config, config.hidden)
        self.flow: RecurrentFlow = recurrent_glow(
            config.latent_dim,
            config.steps,
            config.hidden,
            config.encoded_size,
            cell="lstm",
            seed=int(torch.randint(2**31, ())),  # from the global generator, like every weight
        )
        self.decoder = mlp([config.latent_dim, config.autoencoder_hidden, POSE_DIM])
        if config.leak and config.pull_to_rest:
            # The pose the pull aims at, normalised (the mean pose, zero, until training sees
            # data), and whether a batch has set it yet.
            self.register_buffer("rest_pose", torch.zeros(POSE_DIM))
            self.register_buffer("rest_seen", torch.tensor(False))

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def decode(self, latent: torch.Tensor) -> torch.Tensor:
        """Poses ``(..., 54)`` (normalised) from latents ``(..., latent_dim)``."""
        return self.decoder(latent)

    @property
    def noise_dim(self) -> int:
        """Numbers of base noise per generated frame: the latent's."""
        return self.config.latent_dim

    def generating(self):
        """``with model.generating():`` fixes the flow's weights for frame-by-frame generation."""
        return self.flow.fixed_weights()

    @torch.no_grad()
    def step(self, frame: dict[str, torch.Tensor], state, noise: torch.Tensor):
        """One frame of generation (:mod:`gesturelib.sampling`): ``z_t -> h'_t -> x'_t``.

        Args:
            frame: the control of one frame, as a batch with ``L = 1`` (``past_pose
                (B, 1, tau, 54)``, the model's own recent output; ``speech``, ``activity``).
            state: ``(the flow's state, the last latent)`` after the previous frame (None at
                the start). A residual model adds its latent change to the last latent itself,
                not to the encoding of the pose decoded from it.
            noise: ``z_t`` ``(B, latent_dim)``, already scaled by the temperature.
        Returns:
            ``(pose (B, 54), state)``, the pose normalised.
        """
        flow_state, last = (None, None) if state is None else state
        latent, _, flow_state = self.flow.inverse(noise[:, None], self.control(frame), flow_state)
        if self.config.residual:
            last = self.encode(frame["past_pose"][:, :, -1]) if last is None else last
            latent = latent + self._toward_rest(last)
        return self.decode(latent)[:, 0], (flow_state, latent)

    def _toward_rest(self, last: torch.Tensor) -> torch.Tensor:
        """A residual model's origin: the last latent ``(..., latent_dim)``, moved ``leak`` of
        the way towards the rest pose's latent (the mean pose's without ``pull_to_rest``)."""
        if not self.config.leak:
            return last
        rest = self.rest_pose if hasattr(self, "rest_pose") else last.new_zeros(POSE_DIM)
        # A copy: training moves the buffer in place, which would break this loss's graph if a
        # second loss came before its backward (gradient accumulation).
        return last - self.config.leak * (last - self.encode(rest.to(last, copy=True)))

    @torch.no_grad()
    def _track_rest(self, pose: torch.Tensor, last: torch.Tensor) -> None:
        """Move ``rest_pose`` towards the mean of the poses ``(B, L, 54)`` that moved least from
        their last poses ``(B, L, 54)`` (the first batch sets it)."""
        change = (pose - last).norm(dim=-1).flatten()
        still = pose.flatten(0, 1)[change <= change.quantile(self.still_share)].mean(0)
        if self.rest_seen:
            self.rest_pose.lerp_(still, self.rest_momentum)
        else:
            self.rest_pose.copy_(still)
            self.rest_seen.fill_(True)

    def _origin(self, batch) -> torch.Tensor | float:
        """What the flow's latents are measured from: for a residual model the encoding of the
        last pose ``(B, L, latent_dim)`` (:meth:`_toward_rest`), else 0."""
        if not self.config.residual:
            return 0.0
        return self._toward_rest(self.encode(batch["past_pose"][:, :, -1]))

    def _pose_and_control(self, batch):
        """``pose (B, L, 54)``, the encoded control, and a generator for evaluation's draws
        (fixed, so that the validation loss is the same every time; None in training). In
        training, the rest pose follows the batch."""
        (pose,) = batch_parts(batch, {"pose": (POSE_DIM,)}, f"{type(self).__name__}.loss")
        if self.training and hasattr(self, "rest_pose"):
            self._track_rest(pose, batch["past_pose"][:, :, -1])
        control = self.control(batch, training=self.training)
        generator = None if self.training else torch.Generator(pose.device).manual_seed(0)
        return pose, control, generator


class FlowVAE(_LatentFlowModel):
    """The paper's Flow-VAE: a deterministic autoencoder and a flow over its latent.

    ``loss(batch)`` needs the items of :class:`gesturelib.data.WindowDataset` with
    ``sequence_length = L``: ``pose (B, L, 54)``, ``past_pose (B, L, tau, 54)``, ``speech
    (B, L, W, 27)``, ``activity (B, L, W, 4)`` (and ``style``). See the module docstring.
    """

    config_class = FlowVAEConfig

    def __init__(self, config: FlowVAEConfig):
        super().__init__(config)
        self.encoder = mlp([POSE_DIM, config.autoencoder_hidden, config.latent_dim])

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        """The latent ``h = e(x)`` ``(..., latent_dim)`` of poses ``(..., 54)`` (normalised)."""
        return self.encoder(pose)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The paper's loss per frame (eq. 4), with the remedies the config asks for (see the
        module docstring)."""
        config = self.config
        pose, control, generator = self._pose_and_control(batch)
        latent = noisy = self.encode(pose)
        if config.latent_noise > 0:
            draw = standard_normal(latent.shape, generator, pose.device, pose.dtype)
            noisy = latent + config.latent_noise * draw
        origin = self._origin(batch)
        modelled = noisy - origin
        if config.detach_prior:  # the NLL then trains the flow alone, and cannot shrink h
            modelled = modelled.detach()
        log_prob, _ = self.flow.log_prob(modelled, control)
        nll = -log_prob.mean() / pose.shape[1]
        mse = F.mse_loss(self.decode(noisy), pose)
        terms = {
            "nll": nll.detach(),
            "mse": mse.detach(),
            "latent_scale": latent_scale(latent.detach()),
        }
        loss = config.alpha * nll + mse
        if config.sample_weight > 0 or not self.training:
            z = standard_normal(latent.shape, generator, pose.device, pose.dtype)
            drawn, _, _ = self.flow.inverse(z, control)
            per_frame = (self.decode(drawn + origin) - pose).pow(2).mean(-1)  # (B, L)
            weighted = (self._sample_weights(batch) * per_frame).mean()
            loss = loss + config.sample_weight * weighted
            terms["sample_mse"] = per_frame.mean().detach()
        return {"loss": loss, **terms}

    def _sample_weights(self, batch) -> torch.Tensor | float:
        """The decoded-sample term's weight per frame ``(B, L)``: ``transition_weight`` where the
        agent is silent with its own speech in the control's window, 1 elsewhere."""
        if self.config.transition_weight == 1:
            return 1.0
        speaks = batch["activity"][..., [Activity.A_SPEAKS, Activity.BOTH]].sum(-1) > 0.5
        between = ~speaks[..., self.config.speech_past] & speaks.any(-1)  # (B, L)
        return torch.where(between, self.config.transition_weight, 1.0)


class VariationalFlowVAE(_LatentFlowModel):
    """The Flow-VAE as a variational autoencoder with the flow as its conditional prior.

    ``loss(batch)`` is the negative ELBO per frame, in nats, of the poses with noise off the
    pose surface; it needs the items :class:`FlowVAE` needs.

    Args:
        config: the sizes.
        normaliser: the statistics the poses are normalised with (the pose noise needs them);
            a model rebuilt from a checkpoint gets them back with its weights.
    """

    config_class = VariationalFlowVAEConfig
    #: How far each training batch moves the decoder's variance towards its squared error.
    variance_momentum = 0.05

    def __init__(self, config: VariationalFlowVAEConfig, normaliser=None):
        super().__init__(config)
        self.encoder = mlp([POSE_DIM, config.autoencoder_hidden, 2 * config.latent_dim])
        # The decoder's variance per pose number, set to the running mean of its squared error
        # while training (the variance that maximises the likelihood, as a calibrated decoder's),
        # and fixed in evaluation. Learned by gradient instead, it lags far behind the error.
        self.register_buffer("decoder_variance", torch.ones(POSE_DIM))
        self.noise = SurfaceNoise(config.pose_noise)
        if normaliser is not None:
            self.noise.set_statistics(normaliser)

    def posterior(self, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``q(h | x)``: its mean and log-variance, each ``(..., latent_dim)``."""
        mean, log_var = self.encoder(pose).chunk(2, dim=-1)
        return mean, log_var

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        """The mean of ``q(h | x)`` ``(..., latent_dim)`` for poses ``(..., 54)``."""
        return self.posterior(pose)[0]

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The negative ELBO per frame (nats), from one draw of ``h ~ q(h | x)``."""
        pose, control, generator = self._pose_and_control(batch)
        length = pose.shape[1]
        noisy_pose = pose + self.noise(pose, generator)
        mean, log_var = self.posterior(noisy_pose)
        eps = standard_normal(mean.shape, generator, pose.device, pose.dtype)
        latent = mean + torch.exp(0.5 * log_var) * eps
        log_posterior = -0.5 * (eps.square() + log_var + LOG_2PI).sum(-1)  # log q(h | x), (B, L)
        log_prior, _ = self.flow.log_prob(latent - self._origin(batch), control)  # (B,)
        error = (noisy_pose - self.decode(latent)).square()
        if self.training:
            with torch.no_grad():
                batch_variance = error.flatten(0, 1).mean(0)
                self.decoder_variance.lerp_(batch_variance, self.variance_momentum)
        variance = self.decoder_variance.clone()  # a copy, as the rest pose (_toward_rest)
        log_likelihood = -0.5 * (error / variance + variance.log() + LOG_2PI).sum(-1)
        kl = (log_posterior.sum(1) - log_prior).mean() / length
        reconstruction = -log_likelihood.mean()
        return {
            "loss": reconstruction + kl,
            "reconstruction": reconstruction.detach(),
            "kl": kl.detach(),
            "latent_scale": latent_scale(mean.detach()),
        }
