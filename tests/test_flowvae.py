"""The Flow-VAEs: the latent flow's likelihood and generation, each loss term on a known answer,
the shrinking latent and its remedy, the ELBO's KL against a closed form, bad configs."""

import dataclasses
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from gesturelib.checkpoints import CheckpointMismatchError, load_model
from gesturelib.configs import config_from_dict, config_to_dict
from gesturelib.conventions import Activity
from gesturelib.features import speech_features
from gesturelib.models import (
    CVAE,
    CVAEConfig,
    FlowVAE,
    FlowVAEConfig,
    MoGlow,
    MoGlowConfig,
    VariationalFlowVAE,
    VariationalFlowVAEConfig,
)
from gesturelib.models.flowvae import latent_scale
from gesturelib.pose_surface import project
from gesturelib.sampling import generate
from gesturelib.train import TrainConfig, train

SIZES = dict(
    speech_past=2,
    speech_future=3,
    past_poses=2,
    latent_dim=4,
    autoencoder_hidden=8,
    steps=2,
    hidden=8,
    control_size=8,
)
#: The paper's model (frame by frame, its NLL training the encoder) with noise on the latent.
PAPER = FlowVAEConfig(
    **SIZES, residual=False, leak=0.0, detach_prior=False, latent_noise=0.1, transition_weight=1.0
)
ELBO = VariationalFlowVAEConfig(**SIZES, residual=False, leak=0.0)


@pytest.fixture(scope="module")
def data(short_windows):
    return short_windows


def build(config, normaliser, batch, seed=0, perturb=True):
    """A model whose flow has seen ``batch`` (ActNorm initialised); with ``perturb`` every weight
    is moved at random, so that no coupling is an identity."""
    torch.manual_seed(seed)
    model = (
        FlowVAE(config)
        if isinstance(config, FlowVAEConfig)
        else VariationalFlowVAE(config, normaliser)
    )
    model.loss(batch)
    if perturb:
        generator = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for parameter in model.parameters():
                parameter.add_(0.2 * torch.randn(parameter.shape, generator=generator))
    return model.eval()


def rest_pose(model):
    """The pose ``(54,)`` a model's pull aims at: the tracked rest pose, or the mean pose (zero)
    for a model pulled towards the mean (or not pulled: then it does not matter)."""
    if model.config.leak and model.config.pull_to_rest:
        assert model.rest_seen  # set by the training batch `build` showed it
        return model.rest_pose
    assert not hasattr(model, "rest_pose")
    return torch.zeros(54, dtype=torch.float64)


def identity_flow(model):
    """Make the flow a rotation: ActNorm at the identity, couplings at their zero start."""
    with torch.no_grad():
        for step in model.flow.steps:
            step.actnorm.loc.zero_()
            step.actnorm.log_scale.zero_()
            step.actnorm.initialized.fill_(True)
            output = step.coupling.conditioner.output
            for parameter in (output.weight, output.bias, output.log_gain):
                parameter.zero_()
    return model


@pytest.mark.parametrize(
    "config",
    [
        PAPER,
        ELBO,
        dataclasses.replace(PAPER, residual=True),
        dataclasses.replace(PAPER, residual=True, leak=0.2),
        dataclasses.replace(PAPER, residual=True, leak=0.2, pull_to_rest=False),
        dataclasses.replace(ELBO, residual=True, leak=0.2),
        FlowVAEConfig(**SIZES),
    ],
    ids=["paper", "elbo", "residual", "leak", "leak-to-mean", "elbo-leak", "recipe"],
)
def test_the_latent_flow_agrees_teacher_forced_and_frame_by_frame(data, config, step_through):
    _, normaliser, batch, _ = data
    model = build(config, normaliser, batch).double()
    batch = {name: part.double() for name, part in batch.items()}
    cond = model.control(batch)
    latent = model.encode(batch["pose"]) - model._origin(batch)
    log_prob, _ = model.flow.log_prob(latent, cond)
    state, total = None, torch.zeros(3, dtype=torch.float64)
    for t in range(latent.shape[1]):
        frame_log_prob, state = model.flow.log_prob(latent[:, t : t + 1], cond[:, t : t + 1], state)
        total = total + frame_log_prob
    torch.testing.assert_close(total, log_prob)
    z = torch.randn(latent.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    drawn, _, _ = model.flow.inverse(z, cond)
    stepped = step_through(model, batch, z)
    # A residual model adds each change to the last generated latent moved `leak` of the way
    # to the rest pose's, starting from the encoding of the past pose before the first frame.
    latents = drawn
    if config.residual:
        last = model.encode(batch["past_pose"][:, :1, -1])
        rest = model.encode(rest_pose(model))
        steps = []
        for t in range(drawn.shape[1]):
            last = drawn[:, t : t + 1] + last - config.leak * (last - rest)
            steps.append(last)
        latents = torch.cat(steps, dim=1)
    torch.testing.assert_close(stepped, model.decode(latents))


@pytest.mark.parametrize(
    "config", [FlowVAEConfig(**SIZES), PAPER, dataclasses.replace(ELBO, residual=True, leak=0.2)]
)
def test_one_step_ahead_decodes_teacher_forced_latent_draws(data, config, monkeypatch):
    """Given the base codes of the recording's own latents for noise, every one-step draw is the
    recorded pose through the autoencoder, ``d(e(x_t))``; given other noise at one frame, only
    that frame changes: the flow's memory and the origin move on with the recording, not with
    the draws. With random noise, the draws are seeded poses on the surface."""
    import gesturelib.sampling as sampling

    conversation, normaliser, batch, _ = data
    model = build(config, normaliser, batch)
    drawn = sampling.one_step_ahead(model, normaliser, conversation, seed=3)
    np.testing.assert_allclose(project(torch.as_tensor(drawn)).numpy(), drawn, atol=1e-6)
    np.testing.assert_array_equal(
        drawn, sampling.one_step_ahead(model, normaliser, conversation, 3)
    )
    assert not np.allclose(drawn, sampling.one_step_ahead(model, normaliser, conversation, 4))

    recording = sampling.recording_batch(model, normaliser, conversation)
    with torch.no_grad():
        latent = model.encode(recording["pose"])
        codes, _, _ = model.flow(latent - model._origin(recording), model.control(recording))
    first = max(config.past_poses, config.speech_past)
    recorded = conversation.rotations[first : first + codes.shape[1]]
    decoded = sampling.through_autoencoder(model, normaliser, recorded)

    def replay(changed_frame=None):
        rows = iter(codes[0].clone())
        frames = iter(range(codes.shape[1]))

        def noise(shape, *_):
            code = next(rows)
            return code + 100.0 if next(frames) == changed_frame else code

        monkeypatch.setattr(
            sampling, "standard_normal", lambda shape, *a: noise(shape).reshape(shape)
        )
        return sampling.one_step_ahead(model, normaliser, conversation)

    replayed = replay()
    assert replayed.shape == drawn.shape == (codes.shape[1], 9, 6)
    np.testing.assert_allclose(replayed, decoded, atol=1e-5)
    changed = replay(changed_frame=3)
    assert not np.allclose(changed[3], decoded[3], atol=1e-4)
    np.testing.assert_allclose(
        np.delete(changed, 3, axis=0), np.delete(decoded, 3, axis=0), atol=1e-5
    )
    with pytest.raises(ValueError, match="recurrent flow"):  # an autoencoder, but no flow
        sampling.one_step_ahead(CVAE(CVAEConfig.quick()), normaliser, conversation)
    with pytest.raises(ValueError, match="needs a Flow-VAE"):
        sampling.through_autoencoder(MoGlow(MoGlowConfig.quick()), normaliser, recorded)


@pytest.mark.parametrize("residual, leak", [(False, 0.0), (True, 0.0), (True, 0.3)])
def test_each_term_of_the_papers_loss_on_a_known_answer(data, residual, leak):
    _, normaliser, batch, _ = data
    config = dataclasses.replace(PAPER, latent_noise=0.0, alpha=0.3, residual=residual, leak=leak)
    model = identity_flow(build(config, normaliser, batch, perturb=False)).double()
    batch = {name: part.double() for name, part in batch.items()}
    pose, length = batch["pose"], batch["pose"].shape[1]
    terms = model.loss(batch)
    latent = model.encode(pose)
    origin = 0.0
    if residual:  # e(x_{t-1}), moved `leak` of the way to the rest pose's latent e(r)
        last = model.encode(batch["past_pose"][:, :, -1])
        origin = last - leak * (last - model.encode(rest_pose(model)))
    # A rotation keeps lengths and has log-determinant 0: NLL is the standard normal's.
    change = latent - origin
    nll = (0.5 * change.square().sum(-1) + 0.5 * 4 * math.log(2 * math.pi)).sum(1).mean() / length
    torch.testing.assert_close(terms["nll"], nll)
    torch.testing.assert_close(terms["mse"], (model.decode(latent) - pose).square().mean())
    # In evaluation the draw z' comes from a generator seeded 0; the flow maps it by a rotation.
    generator = torch.Generator().manual_seed(0)
    z = torch.randn(latent.shape, generator=generator, dtype=torch.float64)
    drawn, _, _ = model.flow.inverse(z, model.control(batch))
    torch.testing.assert_close(drawn.norm(dim=-1), z.norm(dim=-1))
    sample_mse = (model.decode(drawn + origin) - pose).square().mean()
    torch.testing.assert_close(terms["sample_mse"], sample_mse)
    torch.testing.assert_close(terms["loss"], 0.3 * nll + terms["mse"] + sample_mse)
    without = FlowVAE(dataclasses.replace(config, sample_weight=0.0)).double()
    without.load_state_dict(model.state_dict())
    torch.testing.assert_close(without.eval().loss(batch)["loss"], 0.3 * nll + terms["mse"])


def test_the_decoded_sample_term_weighs_the_agents_pauses_next_to_its_speech(data):
    """``transition_weight`` multiplies the decoded-sample error of the frames where the agent
    is silent with its own speech in the window; other frames keep weight 1."""
    _, normaliser, batch, _ = data
    config = dataclasses.replace(PAPER, latent_noise=0.0, transition_weight=4.0)
    model = build(config, normaliser, batch).double().eval()
    batch = {name: part.double() for name, part in batch.items()}
    codes = torch.full(batch["activity"].shape[:3], int(Activity.NONE))  # (B, L, W)
    now = config.speech_past
    codes[:, 1, now] = Activity.A_SPEAKS  # speaking: weight 1
    codes[:, 2, 0] = Activity.BOTH  # silent, the agent spoke at the window's start
    codes[:, 3, -1] = Activity.A_SPEAKS  # silent, the agent speaks at the window's end
    codes[:, 4, now] = Activity.B_SPEAKS  # listening, the agent silent all window: weight 1
    batch["activity"] = F.one_hot(codes, batch["activity"].shape[-1]).double()
    terms = model.loss(batch)
    paper = FlowVAE(dataclasses.replace(config, transition_weight=1.0)).double().eval()
    paper.load_state_dict(model.state_dict())
    reference = paper.loss(batch)
    # The same draw, so the per-frame errors are the same; only their weights differ.
    torch.testing.assert_close(terms["sample_mse"], reference["sample_mse"])
    z = torch.randn(
        batch["pose"].shape[:2] + (config.latent_dim,),
        generator=torch.Generator().manual_seed(0),
        dtype=torch.float64,
    )
    drawn, _, _ = model.flow.inverse(z, model.control(batch))
    per_frame = (model.decode(drawn) - batch["pose"]).square().mean(-1)
    weights = torch.ones_like(per_frame)
    weights[:, 2:4] = 4.0
    base = config.alpha * terms["nll"] + terms["mse"]
    torch.testing.assert_close(terms["loss"], base + (weights * per_frame).mean())
    torch.testing.assert_close(reference["loss"], base + per_frame.mean())


@pytest.mark.parametrize("residual", [False, True])
def test_a_detached_prior_trains_the_flow_alone(data, residual):
    """With detach_prior the NLL's gradient reaches the flow and the control encoder, never the
    autoencoder: the encoder's gradient is the reconstruction's alone."""
    _, normaliser, batch, _ = data
    config = dataclasses.replace(
        PAPER, latent_noise=0.0, sample_weight=0.0, alpha=1.0, residual=residual
    )
    gradients = {}
    for detach in (False, True):
        model = build(dataclasses.replace(config, detach_prior=detach), normaliser, batch).double()
        batch64 = {name: part.double() for name, part in batch.items()}
        terms = model.loss(batch64)
        model.zero_grad()
        terms["loss"].backward()
        encoder = [p.grad.clone() for p in model.encoder.parameters()]
        flow = [p.grad.clone() for p in model.flow.parameters() if p.grad is not None]
        model.zero_grad()
        mse = F.mse_loss(model.decode(model.encode(batch64["pose"])), batch64["pose"])
        mse.backward()
        reconstruction = [p.grad.clone() for p in model.encoder.parameters()]
        gradients[detach] = [
            torch.allclose(a, b) for a, b in zip(encoder, reconstruction, strict=True)
        ]
        assert flow and any(g.abs().sum() > 0 for g in flow)
    assert all(gradients[True]) and not all(gradients[False])


def test_a_shrunken_latent_buys_likelihood_for_nothing_unless_the_latent_is_noisy(data):
    _, normaliser, batch, _ = data
    batch = {name: part.double() for name, part in batch.items()}
    nll, clean, extra = {}, {}, {}
    for noise in (0.0, 0.1):
        for shrink in (1.0, 0.1):
            torch.manual_seed(0)
            model = FlowVAE(dataclasses.replace(PAPER, latent_noise=noise)).double()
            # The encoder's output times `shrink`, the decoder's input over it:
            with torch.no_grad():
                model.encoder[-1].weight.mul_(shrink)
                model.encoder[-1].bias.mul_(shrink)
                model.decoder[0].weight.div_(shrink)
            model.loss(batch)  # ActNorm initialises on the latents it is given
            terms = model.eval().loss(batch)
            reconstruction = model.decode(model.encode(batch["pose"]))
            clean[noise, shrink] = (reconstruction - batch["pose"]).square().mean().item()
            nll[noise, shrink] = terms["nll"].item()
            extra[noise, shrink] = terms["mse"].item() - clean[noise, shrink]
    # The decoder undoes the shrinking, and without noise so does the flow's first ActNorm: the
    # likelihood of each frame's latent gains exactly latent_dim * log 10 nats, for nothing.
    assert clean[0.0, 0.1] == pytest.approx(clean[0.0, 1.0], rel=1e-9)
    assert nll[0.0, 1.0] - nll[0.0, 0.1] == pytest.approx(4 * math.log(10), rel=1e-3)
    # With noise a shrunken latent drowns in it: the noise costs the decoder far more.
    assert extra[0.1, 0.1] > 10 * abs(extra[0.1, 1.0])


@pytest.mark.parametrize("residual", [False, True])
def test_the_elbos_kl_estimate_matches_the_closed_form_for_an_affine_flow(data, residual):
    _, normaliser, batch, _ = data
    config = dataclasses.replace(ELBO, residual=residual, pose_noise=0.0)
    model = identity_flow(build(config, normaliser, batch, perturb=False)).double()
    with torch.no_grad():  # a flow that is an affine map: ActNorm's scale and shift, rotations
        for step in model.flow.steps:
            step.actnorm.loc.copy_(torch.tensor([0.5, -1.0, 0.2, 0.0]))
            step.actnorm.log_scale.copy_(torch.tensor([0.3, -0.2, 0.1, 0.4]))
    many = {
        name: part.double().repeat(400, *[1] * (part.dim() - 1)) for name, part in batch.items()
    }
    model.train()  # a fresh draw of h for each of the 1200 copies
    torch.manual_seed(0)
    estimate = model.loss(many)["kl"].item()
    # The flow is z = A h + b: p(h) = N(mean, cov) with A^-1 and b from the composed map.
    with torch.no_grad():
        eye = torch.eye(4, dtype=torch.float64)
        matrix, shift = eye, torch.zeros(4, dtype=torch.float64)
        for step in model.flow.steps:
            scale = torch.diag(torch.exp(step.actnorm.log_scale))
            linear = step.linear.weight_matrix()
            matrix = linear @ scale @ matrix
            shift = linear @ (scale @ (shift - step.actnorm.loc))
        inverse = torch.linalg.inv(matrix)
        prior_mean, prior_cov = -inverse @ shift, inverse @ inverse.T
        mean, log_var = model.posterior(batch["pose"].double())
        if residual:  # the flow models h_t - mu(x_{t-1}): the prior moves with the last pose
            prior_mean = prior_mean + model.encode(batch["past_pose"][:, :, -1].double())
        prior = torch.distributions.MultivariateNormal(prior_mean, prior_cov)
        posterior = torch.distributions.MultivariateNormal(mean, torch.diag_embed(log_var.exp()))
        closed = torch.distributions.kl_divergence(posterior, prior).mean().item()
    assert estimate == pytest.approx(closed, abs=0.05 * abs(closed) + 0.05)


def test_the_elbo_reconstruction_is_a_gaussian_log_likelihood(data):
    _, normaliser, batch, _ = data
    model = build(ELBO, normaliser, batch).double()
    with torch.no_grad():
        model.decoder_variance.fill_(0.25)
        model.encoder[-1].weight[4:].zero_()  # log-variances of -30: h is the posterior's mean
        model.encoder[-1].bias[4:].fill_(-30.0)
        model.noise.std = 0.0
    batch = {name: part.double() for name, part in batch.items()}
    terms = model.loss(batch)
    decoded = model.decode(model.encode(batch["pose"]))
    expected = -torch.distributions.Normal(decoded, 0.5).log_prob(batch["pose"]).sum(-1).mean()
    torch.testing.assert_close(terms["reconstruction"], expected)
    torch.testing.assert_close(terms["loss"], terms["reconstruction"] + terms["kl"])


@pytest.mark.parametrize("config", [PAPER, ELBO], ids=["paper", "elbo"])
def test_generation_is_deterministic_at_temperature_zero_and_by_seed(data, config):
    conversation, normaliser, batch, _ = data
    model = build(config, normaliser, batch)
    speech = speech_features(conversation.audio, conversation.sample_rate)[:60]
    activity = conversation.activity[:60]
    cold = [generate(model, normaliser, speech, activity, temperature=0, seed=s) for s in (1, 2)]
    np.testing.assert_array_equal(*cold)
    same = [generate(model, normaliser, speech, activity, seed=3) for _ in range(2)]
    np.testing.assert_array_equal(*same)
    assert same[0].shape == (1, 60, 9, 6)
    assert not np.array_equal(same[0], generate(model, normaliser, speech, activity, seed=4))


def test_a_flowvae_trains_and_its_run_folder_is_no_moglows(data, tmp_path):
    _, normaliser, _, dataset = data
    model = FlowVAE(PAPER)
    history = train(model, dataset, dataset, TrainConfig.quick(epochs=2), tmp_path, progress=False)
    assert history.val["sample_mse"] and "sample_mse" in history.train
    assert isinstance(load_model(tmp_path / "best.pt", FlowVAE), FlowVAE)
    with pytest.raises(CheckpointMismatchError):
        load_model(tmp_path / "best.pt", MoGlow)


@pytest.mark.parametrize("config_class", [FlowVAEConfig, VariationalFlowVAEConfig])
@pytest.mark.parametrize("residual", [False, True])
def test_runs_saved_before_the_pull_and_the_detached_prior_load_as_they_were_trained(
    config_class, residual
):
    """A checkpoint's config without ``leak`` (and ``detach_prior``) comes from before they
    existed: it was trained without them, whatever the defaults are now."""
    stored = config_to_dict(config_class(**SIZES, residual=residual, leak=0.0))
    stored.pop("leak")
    stored.pop("pull_to_rest")
    stored.pop("detach_prior", None)
    config = config_from_dict(config_class, stored)
    assert config.residual == residual and config.leak == 0.0
    assert getattr(config, "detach_prior", False) is False
    assert config_from_dict(config_class, config_to_dict(config_class())) == config_class()


@pytest.mark.parametrize("config_class", [FlowVAEConfig, VariationalFlowVAEConfig])
def test_runs_pulled_towards_the_mean_pose_load_as_they_were_trained(config_class):
    """Runs saved before the rest pose existed were pulled towards the mean pose: without
    ``pull_to_rest`` in their config they load so, and their weights (no rest pose) fit."""
    stored = config_to_dict(config_class(**SIZES, leak=0.2))
    stored.pop("pull_to_rest")
    config = config_from_dict(config_class, stored)
    assert config.leak == 0.2 and not config.pull_to_rest
    model_class = FlowVAE if config_class is FlowVAEConfig else VariationalFlowVAE
    model = model_class(config)
    assert "rest_pose" not in model.state_dict()
    # The weights of such a run (saved by a model without the buffer) load strictly.
    saved = model_class(dataclasses.replace(config_class(**SIZES, leak=0.2), pull_to_rest=False))
    model.load_state_dict(saved.state_dict())


def test_two_losses_can_be_summed_before_one_backward(data):
    """Gradient accumulation: the statistics a model tracks in place while training (the rest
    pose, the decoder's variance) must not break the graph of a loss not yet differentiated."""
    _, normaliser, batch, _ = data
    torch.manual_seed(0)
    for model in (
        FlowVAE(FlowVAEConfig(**SIZES)),
        VariationalFlowVAE(VariationalFlowVAEConfig(**SIZES), normaliser),
    ):
        model.loss(batch)  # the first batch initialises ActNorm and sets the rest pose
        (model.loss(batch)["loss"] + model.loss(batch)["loss"]).backward()
        assert model.encoder[0].weight.grad.abs().sum() > 0


def test_the_rest_pose_is_the_running_mean_of_the_stillest_quarter_of_the_frames(data):
    """The first training batch sets the rest pose to the mean of the quarter of its frames that
    changed least from their last poses; each later batch moves it 5 % of the way to its own."""
    _, _, batch, _ = data
    torch.manual_seed(0)
    model = FlowVAE(FlowVAEConfig(**SIZES)).double()
    batch = {name: part.double() for name, part in batch.items()}
    pose, last = batch["pose"], batch["past_pose"][:, :, -1]

    def stillest_mean(pose, last):
        frames, changes = pose.flatten(0, 1), (pose - last).norm(dim=-1).flatten()
        order = changes.argsort()
        count = int(np.floor(0.25 * (len(order) - 1))) + 1  # the frames at or below the quantile
        return frames[order[:count]].mean(0)

    assert not model.rest_seen and not model.rest_pose.any()
    model.loss(batch)
    first = stillest_mean(pose, last)
    torch.testing.assert_close(model.rest_pose, first)
    moved = pose.flip(-1)  # another batch, whose still frames lie elsewhere
    model.loss({**batch, "pose": moved})
    torch.testing.assert_close(model.rest_pose, first + 0.05 * (stillest_mean(moved, last) - first))
    model.eval()
    model.loss(batch)  # evaluation leaves it
    torch.testing.assert_close(model.rest_pose, first + 0.05 * (stillest_mean(moved, last) - first))


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"alpha": -1.0}, "alpha must be a finite number >= 0"),
        ({"latent_dim": 54}, "latent_dim must be between 2 and 53"),
        ({"latent_dim": 1}, "latent_dim must be between 2 and 53"),
        ({"sample_weight": float("nan")}, "sample_weight must be a finite number >= 0"),
        ({"residual": True, "past_poses": 0}, "past_poses >= 1"),
        ({"residual": False}, r"it needs residual=True \(for a model of the latent itself, set"),
        ({"residual": True, "leak": 1.5}, "leak must be"),
        ({"detach_prior": 1}, "detach_prior"),
    ],
)
def test_bad_configs_get_named_errors(changes, message):
    with pytest.raises(ValueError, match=message):
        FlowVAEConfig(**changes)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"pose_noise": -0.1}, "pose_noise must be a finite number >= 0"),
        ({"latent_dim": 60}, "latent_dim must be between 2 and 53"),
        ({"residual": True, "past_poses": 0}, "past_poses >= 1"),
    ],
)
def test_bad_variational_configs_get_named_errors(changes, message):
    with pytest.raises(ValueError, match=message):
        VariationalFlowVAEConfig(**changes)


def test_a_model_refuses_a_config_of_another_model():
    with pytest.raises(
        TypeError, match="FlowVAE needs a FlowVAEConfig, got VariationalFlowVAEConfig"
    ):
        FlowVAE(ELBO)
    with pytest.raises(
        TypeError, match="VariationalFlowVAE needs a VariationalFlowVAEConfig, got dict"
    ):
        VariationalFlowVAE({"latent_dim": 8})
    with pytest.raises(TypeError, match="MoGlow needs a MoGlowConfig, got FlowVAEConfig"):
        MoGlow(PAPER)


def test_latent_scale_is_the_geometric_mean_spread_along_the_principal_axes():
    generator = torch.Generator().manual_seed(0)
    white = torch.randn(20_000, 3, generator=generator, dtype=torch.float64)
    rotation = torch.linalg.qr(torch.randn(3, 3, generator=generator, dtype=torch.float64))[0]
    stretched = white * torch.tensor([4.0, 1.0, 0.25], dtype=torch.float64) @ rotation.T
    assert latent_scale(stretched).item() == pytest.approx(1.0, rel=0.02)  # (4 * 1 / 4)^(1/3)
    assert latent_scale(0.1 * stretched).item() == pytest.approx(0.1, rel=0.02)
    collapsed = torch.cat([white[:, :2], white[:, :1]], dim=1)  # a copy: one dimension fewer
    assert latent_scale(collapsed).item() < 0.01  # 0 but for rounding


def test_the_decoders_variance_follows_its_squared_error_in_training_only(data):
    _, normaliser, batch, _ = data
    model = build(ELBO, normaliser, batch)
    before = model.decoder_variance.clone()
    model.loss(batch)  # evaluation: fixed
    assert torch.equal(model.decoder_variance, before)
    model.train()
    for _ in range(200):
        model.loss(batch)
    with torch.no_grad():
        mean, _ = model.posterior(batch["pose"])
        error = (model.decode(mean) - batch["pose"]).square().flatten(0, 1).mean(0)
    ratio = model.decoder_variance / error
    assert 0.5 < ratio.median() < 2  # near the squared error, up to the draws of h and noise
