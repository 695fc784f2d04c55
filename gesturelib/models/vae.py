"""Pose autoencoders, the variational autoencoder (VAE) and the CVAE baseline of the Flow-VAE paper.

From autoencoder to VAE
-----------------------
A :class:`PoseAutoencoder` squeezes a pose ``x`` (54 numbers) through a small latent ``z`` and
back, ``x -> e(x) = z -> d(z) = x'``, trained on the mean squared error. It compresses well but
is no generative model: nothing says which ``z`` a new pose should come from.

A :class:`PoseVAE` makes the latent random. The encoder outputs a Gaussian posterior
``q(z | x) = N(mu(x), diag(sigma(x)^2))`` (as a mean and a log-variance), the prior is
``p(z) = N(0, I)`` and the decoder a Gaussian likelihood ``p(x | z) = N(d(z), s^2 I)``. Training
maximises the evidence lower bound (ELBO) of ``log p(x)``::

    log p(x) >= E_q[log p(x | z)] - KL(q(z | x) || p(z))                      (ELBO)

and we minimise its negative per frame, ``loss = reconstruction + beta * KL``:

* **reconstruction** = ``sum_d (x_d - d(z)_d)^2``, the squared error summed over the 54 numbers,
  which is ``-log N(x; d(z), s^2 I)`` for ``s^2 = 1/2`` up to a constant. So "MSE" means a
  Gaussian likelihood with variance 1/2 per (standardised) number; ``beta < 1`` is the same as a
  narrower likelihood, ``s^2 = beta / 2``: sharper reconstructions, a latent less like the prior.
  ``beta = 1`` is the ELBO; ``beta > 1`` is the beta-VAE.
* **KL** of two Gaussians in closed form (:func:`gaussian_kl`), in nats: ``>= 0``, and 0 exactly
  when the posterior is the prior (``mu = 0, sigma = 1``).
* The expectation is estimated with one sample drawn by the **reparameterisation trick**
  (:func:`reparameterise`): ``z = mu + sigma * eps`` with ``eps ~ N(0, I)``, so the gradient flows
  through ``mu`` and ``sigma``.

Sampling draws ``z = temperature * eps`` from the prior and decodes it; temperature 0 gives
``d(0)``, the decoder of the prior's mode. Both models work on single frames: a batch's
``pose (B, L, 54)`` is ``B * L`` independent poses.

The CVAE baseline (Taylor et al. 2021, after Greenwood et al. 2017)
-------------------------------------------------------------------
The Flow-VAE paper compares against a conditional VAE with recurrent (LSTM) encoder and decoder,
conditioned on the speech features and the speech-activity one-hot, trained on MSE + KL.
:class:`CVAE` is that model, sized for this data:

==================  =========================  ==========================================
                    the paper                  here (:class:`CVAEConfig` defaults)
==================  =========================  ==========================================
LSTM layers         5 (encoder and decoder)    2
units per layer     200                        64
dropout             0.2                        0.2
latent              not stated                 8 numbers per frame
learning rate       1e-4, patience 10          the shared Noam schedule (``TrainConfig``)
parameters          3M                         about 0.33M
==================  =========================  ==========================================

What it conditions on, per frame ``t``: the whole speech and activity window of that frame
(``speech_past`` frames before, ``speech_future`` after: the same control window as MoGlow and the
Flow-VAE), flattened and compressed by one linear layer into a ``control_size`` vector ``c_t``.
The look-ahead matters because gestures anticipate the speech they go with, and the decoder runs
forwards in time. Past *poses* are not given: the paper conditions the CVAE on speech and activity
only, so its sense of motion comes from the recurrent state.

One latent vector ``z_t`` per frame (a sequence of latents, as in a variational RNN):

* encoder ``q(z_t | x_{1:L}, c_{1:L})``: a bidirectional LSTM over ``[x_t, c_t]`` (it only runs
  in training, so it may look at the whole excerpt), then a linear layer to mean and log-variance;
* decoder: a forward LSTM over ``[z_t, c_t]``, then a linear layer to the pose ``x'_t``;
* prior ``p(z_t) = N(0, I)``, independent per frame.

Sampling (:meth:`CVAE.sample`) draws ``z_t = temperature * eps_t`` for every frame and runs the
decoder over the given control sequence, giving a whole pose sequence ``(B, L, 54)``; different
generators give different motions for the same speech. The prior is independent from frame to
frame, whereas the latents the encoder gives real motion are correlated in time: at temperature 1
the decoder smooths the difference only in part, and samples jitter more than real motion does.
MoGlow and the Flow-VAE replace this prior by an autoregressive one, ``p(z_t | past, c_t)``.

KL and posterior collapse
~~~~~~~~~~~~~~~~~~~~~~~~~
The KL term is the price, in nats per frame, of the information ``z`` carries about the pose
beyond what the speech already tells. A decoder that sees the speech window and has its own
recurrent memory can predict a plausible *average* pose from ``c`` alone; where that is nearly as
good, it pays less by ignoring ``z``, and the posterior collapses onto the prior (``kl`` near 0 in
the logged scalars, :meth:`CVAE.kl_per_dimension` showing dimensions near 0): every sample is then
nearly the same motion. Whether it happens depends on ``beta`` and on the data. With the defaults
on the course's data (notebook 03, full mode) every latent dimension stays in use and decoding the
posterior reconstructs far better than sampling the prior: what sets the samples apart from real
motion is the independent per-frame prior (above), not a collapse. Raising ``beta`` makes the code
dearer and pushes dimensions towards collapse; lowering it buys more latent information, at the
cost of a posterior further from the prior, so that prior samples are no closer to real motion
and jitter more. The Flow-VAE paper found its CVAE baseline less active than the real speaker.

Logged scalars (``loss(batch)``): ``loss``; ``mse``, the squared error per number (comparable
across models); ``kl`` (VAE and CVAE), nats per frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import nn

from gesturelib.configs import SpeechContext, check_fields, check_temperature
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.models.common import batch_parts, eval_mode, first_parameter, mlp
from gesturelib.skeleton import POSE_DIM

# ---------------------------------------------------------------------------------------------
# Gaussian latents
# ---------------------------------------------------------------------------------------------


def gaussian_kl(mean: torch.Tensor, log_var: torch.Tensor) -> torch.Tensor:
    """``KL(N(mean, diag(exp(log_var))) || N(0, I))`` in nats, summed over the last axis.

    ``0.5 * sum(mean^2 + var - 1 - log var)``: each term is >= 0 and 0 only at mean = 0, var = 1.

    Args:
        mean, log_var: ``(..., D)``.
    Returns:
        ``(...)``.
    """
    return 0.5 * (mean.pow(2) + log_var.exp() - 1.0 - log_var).sum(-1)


def reparameterise(
    mean: torch.Tensor, log_var: torch.Tensor, generator: torch.Generator | None = None
) -> torch.Tensor:
    """A draw ``z = mean + exp(log_var / 2) * eps``, ``eps ~ N(0, I)``, differentiable in both.

    Args:
        mean, log_var: ``(..., D)``.
        generator: for ``eps``; None uses PyTorch's global generator (which
            :func:`gesturelib.train.train` seeds).
    Returns:
        ``(..., D)``.
    """
    return mean + (0.5 * log_var).exp() * standard_normal(mean.shape, generator, mean)


def standard_normal(
    shape: tuple, generator: torch.Generator | None, like: torch.Tensor
) -> torch.Tensor:
    """``N(0, I)`` noise of ``shape`` on ``like``'s device and dtype, drawn from ``generator``.

    Drawn on the generator's own device, then moved, so that a CPU generator drives a GPU model.
    """
    device = generator.device if generator is not None else like.device
    noise = torch.randn(shape, generator=generator, device=device, dtype=like.dtype)
    return noise.to(like.device)


def prior_sample(
    shape: tuple, temperature: float, generator: torch.Generator | None, like: torch.Tensor
) -> torch.Tensor:
    """``temperature * eps``, ``eps ~ N(0, I)`` of ``shape``; exactly zeros (the mode) at 0."""
    temperature = check_temperature(temperature)
    if temperature == 0:
        return like.new_zeros(shape)
    return temperature * standard_normal(shape, generator, like)


# ---------------------------------------------------------------------------------------------
# Frame-wise autoencoder and VAE
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PoseAutoencoderConfig:
    """Sizes of a frame-wise pose autoencoder.

    Attributes:
        pose_dim: numbers per pose (9 limbs x 6D rotation = 54).
        hidden_sizes: hidden layers of the encoder (the decoder mirrors them).
        latent_dim: size of ``z``; 2 so that the latent space can be plotted as it is (a larger
            latent reconstructs better: on held-out conversations of the quick dataset, 8
            numbers gave a third of the error of 2).
    """

    pose_dim: int = POSE_DIM
    hidden_sizes: tuple[int, ...] = (128, 64)
    latent_dim: int = 2

    def __post_init__(self):
        check_fields(self, positive=("pose_dim", "latent_dim"), sizes=("hidden_sizes",))

    @classmethod
    def quick(cls, **changes) -> PoseAutoencoderConfig:
        """Small layers for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(hidden_sizes=(32,)), **changes)


class PoseAutoencoder(nn.Module):
    """Deterministic autoencoder of single poses: ``(..., 54) -> (..., latent) -> (..., 54)``.

    ``loss(batch)`` logs ``loss`` = ``mse``, the squared reconstruction error per number.
    """

    config_class = PoseAutoencoderConfig

    def __init__(self, config: PoseAutoencoderConfig):
        super().__init__()
        self.config = config
        sizes = [config.pose_dim, *config.hidden_sizes, config.latent_dim]
        self.encoder = mlp(sizes)
        self.decoder = mlp(sizes[::-1])

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        """``(..., 54)`` poses -> ``(..., latent_dim)`` codes."""
        return self.encoder(pose)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """``(..., latent_dim)`` codes -> ``(..., 54)`` poses."""
        return self.decoder(z)

    def forward(self, pose: torch.Tensor) -> torch.Tensor:
        """``(..., 54)`` -> its reconstruction ``(..., 54)``."""
        return self.decode(self.encode(pose))

    @torch.no_grad()
    def latent(self, pose: torch.Tensor) -> torch.Tensor:
        """The code of each pose, for plotting: ``(..., 54) -> (..., latent_dim)``."""
        return self.encode(pose)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Reconstruction MSE of ``batch["pose"] (B, L, 54)``, frame by frame."""
        (pose,) = batch_parts(batch, {"pose": (self.config.pose_dim,)}, "PoseAutoencoder.loss")
        mse = (self(pose) - pose).pow(2).mean()
        return {"loss": mse, "mse": mse.detach()}


@dataclass(frozen=True)
class PoseVAEConfig(PoseAutoencoderConfig):
    """A :class:`PoseAutoencoderConfig` plus the weight of the KL term.

    Attributes:
        beta: weight of KL in ``loss = reconstruction + beta * KL``; 1 is the ELBO of a Gaussian
            likelihood with variance 1/2 (module docstring).
    """

    beta: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        check_fields(self, non_negative=("beta",))


class PoseVAE(nn.Module):
    """Variational autoencoder of single poses with a standard normal prior on ``z``.

    ``loss(batch)`` logs ``loss`` (negative ELBO per frame, beta-weighted), ``mse`` (squared error
    per number) and ``kl`` (nats per frame).
    """

    config_class = PoseVAEConfig

    def __init__(self, config: PoseVAEConfig):
        super().__init__()
        self.config = config
        sizes = [config.pose_dim, *config.hidden_sizes]
        # one network outputs mean and log-variance side by side
        self.encoder = mlp([*sizes, 2 * config.latent_dim])
        self.decoder = mlp([config.latent_dim, *sizes[::-1]])

    def encode(self, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The posterior ``q(z | x)``: ``(..., 54)`` -> mean and log-variance, each
        ``(..., latent_dim)``."""
        mean, log_var = self.encoder(pose).chunk(2, dim=-1)
        return mean, log_var

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """The likelihood's mean ``d(z)``: ``(..., latent_dim)`` -> ``(..., 54)``."""
        return self.decoder(z)

    def forward(self, pose: torch.Tensor, generator: torch.Generator | None = None):
        """One reparameterised pass: ``(..., 54)`` -> (reconstruction, mean, log_var)."""
        mean, log_var = self.encode(pose)
        return self.decode(reparameterise(mean, log_var, generator)), mean, log_var

    @torch.no_grad()
    def latent(self, pose: torch.Tensor) -> torch.Tensor:
        """The posterior mean of each pose, for plotting: ``(..., 54) -> (..., latent_dim)``."""
        return self.encode(pose)[0]

    @torch.no_grad()
    def sample(
        self, n: int, temperature: float = 1.0, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """``n`` poses decoded from ``z = temperature * eps``, ``eps ~ N(0, I)``: ``(n, 54)``.

        Temperature 0 gives ``n`` copies of ``d(0)``; the same generator state, the same poses.
        """
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n must be an integer >= 1, got {n!r}")
        z = prior_sample((n, self.config.latent_dim), temperature, generator, first_parameter(self))
        return self.decode(z)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Negative ELBO of ``batch["pose"] (B, L, 54)`` per frame, with one sample of ``z``."""
        (pose,) = batch_parts(batch, {"pose": (self.config.pose_dim,)}, "PoseVAE.loss")
        reconstruction, mean, log_var = self(pose)
        squared_error = (reconstruction - pose).pow(2)
        kl = gaussian_kl(mean, log_var).mean()
        loss = squared_error.sum(-1).mean() + self.config.beta * kl
        return {"loss": loss, "mse": squared_error.mean().detach(), "kl": kl.detach()}


# ---------------------------------------------------------------------------------------------
# The recurrent CVAE baseline
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CVAEConfig(SpeechContext):
    """Sizes of the CVAE baseline; the paper's values are in the module docstring.

    Attributes:
        pose_dim: numbers per pose (54).
        n_mels: log-mel bands per frame (27).
        n_activities: speech-activity classes (4).
        speech_past, speech_future: the control window around each frame
            (:class:`~gesturelib.configs.SpeechContext`).
        control_size: the window of each frame is compressed to this many numbers.
        hidden_size: units per LSTM layer (the paper: 200).
        num_layers: LSTM layers in the encoder and in the decoder (the paper: 5).
        latent_dim: size of ``z_t``, one per frame.
        dropout: between LSTM layers and on the control features (the paper: 0.2).
        beta: weight of the KL term (1 = the ELBO).
    """

    pose_dim: int = POSE_DIM
    n_mels: int = N_MELS
    n_activities: int = NUM_ACTIVITIES
    control_size: int = 64
    hidden_size: int = 64
    num_layers: int = 2
    latent_dim: int = 8
    dropout: float = 0.2
    beta: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            positive=(
                "pose_dim",
                "n_mels",
                "n_activities",
                "control_size",
                "hidden_size",
                "num_layers",
                "latent_dim",
            ),
            fractions=("dropout",),
            non_negative=("beta",),
        )

    @classmethod
    def quick(cls, **changes) -> CVAEConfig:
        """One small layer each way, for tests and quick mode; ``changes`` override any field."""
        small = cls(control_size=16, hidden_size=32, num_layers=1, latent_dim=4)
        return dataclasses.replace(small, **changes)


class CVAE(nn.Module):
    """Recurrent conditional VAE: poses ``(B, L, 54)`` given speech and activity windows.

    ``loss(batch)`` needs ``pose (B, L, 54)``, ``speech (B, L, W, 27)`` and ``activity
    (B, L, W, 4)`` (``W = speech_past + 1 + speech_future``) and logs ``loss`` (negative ELBO
    per frame, beta-weighted), ``mse`` (per number) and ``kl`` (nats per frame). Train it on
    excerpts of several frames (``WindowConfig(sequence_length=...)``, e.g. 50).
    """

    config_class = CVAEConfig

    def __init__(self, config: CVAEConfig):
        super().__init__()
        self.config = config
        window_features = config.speech_window * (config.n_mels + config.n_activities)
        self.control = nn.Sequential(
            nn.Linear(window_features, config.control_size), nn.ReLU(), nn.Dropout(config.dropout)
        )
        between_layers = config.dropout if config.num_layers > 1 else 0.0  # torch warns otherwise
        self.encoder = nn.LSTM(
            config.pose_dim + config.control_size,
            config.hidden_size,
            config.num_layers,
            batch_first=True,
            dropout=between_layers,
            bidirectional=True,
        )
        self.posterior = nn.Linear(2 * config.hidden_size, 2 * config.latent_dim)
        self.decoder = nn.LSTM(
            config.latent_dim + config.control_size,
            config.hidden_size,
            config.num_layers,
            batch_first=True,
            dropout=between_layers,
        )
        self.output = nn.Linear(config.hidden_size, config.pose_dim)

    def control_features(self, batch: dict[str, torch.Tensor], owner: str = "CVAE") -> torch.Tensor:
        """``c_t`` of every frame: speech ``(B, L, W, 27)`` and activity ``(B, L, W, 4)`` ->
        ``(B, L, control_size)``."""
        config = self.config
        expected = {
            "speech": (config.speech_window, config.n_mels),
            "activity": (config.speech_window, config.n_activities),
        }
        speech, activity = batch_parts(batch, expected, owner)
        window = torch.cat([speech, activity], dim=-1).flatten(2)  # (B, L, W * 31)
        return self.control(window)

    def encode(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The posterior of every frame: mean and log-variance, ``(B, L, latent_dim)`` each."""
        (pose,) = batch_parts(batch, {"pose": (self.config.pose_dim,)}, "CVAE.encode")
        control = self.control_features(batch, "CVAE.encode")
        states, _ = self.encoder(torch.cat([pose, control], dim=-1))  # (B, L, 2 * hidden)
        mean, log_var = self.posterior(states).chunk(2, dim=-1)
        return mean, log_var

    def decode(self, z: torch.Tensor, batch_control: dict[str, torch.Tensor]) -> torch.Tensor:
        """Poses from latents and the control: ``z (B, L, latent_dim)`` -> ``(B, L, 54)``."""
        return self._decode(z, self.control_features(batch_control, "CVAE.decode"))

    def _decode(self, z: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        if z.shape != (*control.shape[:2], self.config.latent_dim):
            raise ValueError(
                f"z must have shape (B, L, {self.config.latent_dim}) = "
                f"{(*control.shape[:2], self.config.latent_dim)} to match the control, "
                f"got {tuple(z.shape)}"
            )
        states, _ = self.decoder(torch.cat([z, control], dim=-1))  # (B, L, hidden)
        return self.output(states)

    def loss(self, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Negative ELBO per frame (squared error summed over the pose + beta * KL)."""
        (pose,) = batch_parts(batch, {"pose": (self.config.pose_dim,)}, "CVAE.loss")
        control = self.control_features(batch, "CVAE.loss")
        states, _ = self.encoder(torch.cat([pose, control], dim=-1))
        mean, log_var = self.posterior(states).chunk(2, dim=-1)
        reconstruction = self._decode(reparameterise(mean, log_var), control)
        squared_error = (reconstruction - pose).pow(2)
        kl = gaussian_kl(mean, log_var).mean()
        loss = squared_error.sum(-1).mean() + self.config.beta * kl
        return {"loss": loss, "mse": squared_error.mean().detach(), "kl": kl.detach()}

    @torch.no_grad()
    def sample(
        self,
        batch_control: dict[str, torch.Tensor],
        temperature: float = 1.0,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """A pose sequence for each control sequence, with latents from the prior.

        Args:
            batch_control: ``speech (B, L, W, 27)`` and ``activity (B, L, W, 4)`` (a whole batch
                will do: other parts are ignored).
            temperature: ``z_t = temperature * eps_t``; 0 decodes ``z = 0`` (deterministic).
            generator: for ``eps``; the same generator state gives the same motion.
        Returns:
            ``(B, L, 54)`` normalised poses. Computed in eval mode (no dropout); the model's mode
            is restored afterwards.
        """
        with eval_mode(self):
            control = self.control_features(batch_control, "CVAE.sample")
            shape = (*control.shape[:2], self.config.latent_dim)
            return self._decode(prior_sample(shape, temperature, generator, control), control)

    #: The temperature generation (:mod:`gesturelib.sampling`) uses unless told otherwise.
    default_temperature = 1.0

    @property
    def noise_dim(self) -> int:
        """Numbers of prior noise per generated frame: ``z_t``."""
        return self.config.latent_dim

    @torch.no_grad()
    def step(self, frame: dict[str, torch.Tensor], state, noise: torch.Tensor):
        """One frame of generation (:mod:`gesturelib.sampling`): the pose ``(B, 54)`` decoded from
        ``z_t = noise`` ``(B, latent_dim)`` and the control of one frame (``speech (B, 1, W, 27)``,
        ``activity (B, 1, W, 4)``), carrying the decoder's state (None at the start)."""
        with eval_mode(self):
            control = self.control_features(frame, "CVAE.step")
            states, state = self.decoder(torch.cat([noise[:, None], control], dim=-1), state)
            return self.output(states)[:, 0], state

    @torch.no_grad()
    def reconstruct(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """Decoded posterior means of ``batch`` (poses and control): ``(B, L, 54)``, eval mode."""
        with eval_mode(self):
            mean, _ = self.encode(batch)
            return self.decode(mean, batch)

    @torch.no_grad()
    def kl_per_dimension(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """Mean KL of each latent dimension over the frames of ``batch``: ``(latent_dim,)`` nats.

        Dimensions near 0 are unused (collapsed onto the prior); the sum is the logged ``kl``.
        """
        with eval_mode(self):
            mean, log_var = self.encode(batch)
            per_dimension = 0.5 * (mean.pow(2) + log_var.exp() - 1.0 - log_var)
            return per_dimension.flatten(0, 1).mean(0)
