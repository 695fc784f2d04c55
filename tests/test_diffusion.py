"""The diffusion model: its schedule and sampler against known answers, its network's inputs, and
chunked generation through the streaming protocol."""

import dataclasses

import numpy as np
import pytest
import torch

from gesturelib.data import ConversationFeatures, WindowConfig, WindowDataset
from gesturelib.features import speech_features
from gesturelib.models import DiffusionConfig, GestureDiffusion, Sampling
from gesturelib.models.diffusion import (
    PREDICTIONS,
    alpha_sigma,
    clean_and_noise,
    denoise,
    target_of,
)
from gesturelib.pose_surface import project
from gesturelib.sampling import Stream, generate

SMALL = DiffusionConfig.quick(speech_past=4, speech_future=6, past_poses=3, chunk=5, width=16)


@pytest.fixture(scope="module")
def data(short_windows):
    """The short conversation, its normaliser and a batch of chunk-long windows."""
    conversation, normaliser = short_windows[:2]
    features = ConversationFeatures.from_conversation(conversation)
    windows = WindowConfig(
        speech_past=SMALL.speech_past,
        speech_future=SMALL.speech_future,
        past_poses=SMALL.past_poses,
        sequence_length=SMALL.chunk,
        stride=7,
    )
    dataset = WindowDataset([features], windows, normaliser)
    batch = {name: torch.stack([dataset[i][name] for i in range(8)]) for name in dataset[0]}
    return conversation, normaliser, batch


def random_model(config=SMALL, seed=0) -> GestureDiffusion:
    """A model whose every weight is random (none of its blocks is the identity it starts as)."""
    torch.manual_seed(seed)
    model = GestureDiffusion(config)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(0.2 * torch.randn(parameter.shape, generator=generator))
    return model.eval()


def test_the_schedule_runs_from_clean_to_pure_noise_preserving_the_variance():
    levels = torch.linspace(0, 1, 101, dtype=torch.float64)
    alpha, sigma = alpha_sigma(levels)
    torch.testing.assert_close(alpha**2 + sigma**2, torch.ones_like(alpha))
    assert alpha[0] > 0.99999 and sigma[-1] > 0.99999  # log SNR +20 and -20
    torch.testing.assert_close(
        torch.log(alpha[0] ** 2 / sigma[0] ** 2), torch.tensor(20.0).double()
    )
    assert (alpha.diff() < 0).all()


@pytest.mark.parametrize("kind", PREDICTIONS)
def test_each_prediction_gives_back_the_clean_sample_and_the_noise(kind):
    generator = torch.Generator().manual_seed(0)
    clean, noise = torch.randn(2, 4, 3, generator=generator, dtype=torch.float64)
    alpha, sigma = alpha_sigma(torch.tensor([0.1, 0.4, 0.7, 0.95], dtype=torch.float64))
    alpha, sigma = alpha[:, None], sigma[:, None]
    noisy = alpha * clean + sigma * noise
    target = target_of(clean, noise, alpha, sigma, kind)
    back_clean, back_noise = clean_and_noise(target, noisy, alpha, sigma, kind)
    torch.testing.assert_close(back_clean, clean)
    torch.testing.assert_close(back_noise, noise)


def gaussian_predictor(mean: float, std: float, kind: str):
    """The exact prediction of ``kind`` for data ``N(mean, std^2)``: the clean sample's posterior
    mean given ``x_s``, in the form ``kind`` asks for."""

    def predict(noisy, level):
        alpha, sigma = (v[:, None] for v in alpha_sigma(level.double()))
        clean = mean + alpha * std**2 / (alpha**2 * std**2 + sigma**2) * (noisy - alpha * mean)
        noise = (noisy - alpha * clean) / sigma
        return target_of(clean, noise, alpha, sigma, kind)

    return predict


@pytest.mark.parametrize("method", ["ddim", "ddpm"])
@pytest.mark.parametrize("kind", PREDICTIONS)
def test_the_sampler_with_the_exact_denoiser_converges_to_the_data_distribution(method, kind):
    """Data N(3, 0.5^2): the exact denoiser is known in closed form. Few steps shrink the spread
    (each step a straight line along a curved path); with more it comes to the data's."""
    spreads = []
    for steps in (10, 200):
        draws = steps if method == "ddpm" else 1
        generator = torch.Generator().manual_seed(1)
        noise = torch.randn(draws, 20000, 1, generator=generator, dtype=torch.float64)
        samples = denoise(gaussian_predictor(3.0, 0.5, kind), noise, steps, method, kind)
        assert abs(samples.mean().item() - 3.0) < 0.02
        spreads.append(samples.std().item())
    assert spreads[0] < 0.47 and abs(spreads[1] - 0.5) < 0.01


def test_ddim_is_deterministic_given_its_starting_noise_and_ddpm_is_not():
    predict = gaussian_predictor(0.0, 1.0, "v")
    start = torch.randn(1, 5, 2, dtype=torch.float64)
    first = denoise(predict, start, 10, "ddim", "v")
    torch.testing.assert_close(denoise(predict, start.clone(), 10, "ddim", "v"), first)
    fresh = torch.randn(10, 5, 2, dtype=torch.float64)
    again = fresh.clone()
    again[1:] = torch.randn(9, 5, 2, dtype=torch.float64)
    assert not torch.allclose(
        denoise(predict, fresh, 10, "ddpm", "v"), denoise(predict, again, 10, "ddpm", "v")
    )


def test_the_loss_falls_when_the_model_fits_a_small_batch(data):
    _, _, batch = data
    torch.manual_seed(0)
    model = GestureDiffusion(SMALL)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    model.eval()
    before = model.loss(batch)["loss"].item()
    model.train()
    for _ in range(150):
        optimiser.zero_grad()
        model.loss(batch)["loss"].backward()
        optimiser.step()
    model.eval()
    assert model.loss(batch)["loss"].item() < 0.6 * before
    # Evaluation draws the same levels and noise each time: a validation loss that can be compared.
    assert model.loss(batch)["loss"].item() == model.loss(batch)["loss"].item()


def test_each_input_reaches_the_chunk_and_the_hidden_condition_is_ignored(data):
    _, _, batch = data
    model = random_model()
    _, condition = model._parts(batch, "test")
    noisy, level = batch["pose"], torch.full((8,), 0.5)
    base = model._network(noisy, level, condition)
    for name in ("past", "speech", "activity"):
        changed = {**condition, name: condition[name] + 1.0}
        assert not torch.allclose(model._network(noisy, level, changed), base), name
        everything = torch.ones(8, dtype=torch.bool)
        hidden = "past_hidden" if name == "past" else "condition_hidden"
        torch.testing.assert_close(
            model._network(noisy, level, changed, **{hidden: everything}),
            model._network(noisy, level, condition, **{hidden: everything}),
        )


def test_guidance_zero_gives_motion_that_does_not_hear_the_speech(data):
    _, _, batch = data
    model = random_model()
    model.sampling = Sampling(steps=4, guidance=0.0)
    frame = {name: batch[name][:, :1] for name in ("past_pose", "speech", "activity")}
    noise = torch.randn(8, model.noise_dim)
    poses, _ = model.step(frame, None, noise)
    assert poses.shape == (8, SMALL.chunk, 54)
    louder = {**frame, "speech": frame["speech"] + 2.0}
    torch.testing.assert_close(model.step(louder, None, noise)[0], poses)
    model.sampling = Sampling(steps=4, guidance=2.0)
    assert not torch.allclose(model.step(louder, None, noise)[0], model.step(frame, None, noise)[0])


def test_ddpm_needs_noise_for_every_step():
    model = GestureDiffusion(SMALL)
    chunk = SMALL.chunk * 54
    assert model.noise_dim == chunk
    model.sampling = Sampling(steps=7, method="ddpm")
    assert model.noise_dim == 7 * chunk


@pytest.mark.parametrize("overlap", [0, 2])
@pytest.mark.parametrize("frames", [1, 4, 5, 6, 23])
def test_chunks_stream_exactly_the_recording_whatever_the_pieces_pushed(data, frames, overlap):
    conversation, normaliser, _ = data
    model = random_model()
    model.sampling = Sampling(steps=3)
    speech = speech_features(conversation.audio, conversation.sample_rate)[:frames]
    activity = conversation.activity[:frames]
    options = {"samples": 2, "seed": 3, "overlap": overlap}
    whole = generate(model, normaliser, speech, activity, **options)
    assert whole.shape == (2, frames, 9, 6) and np.isfinite(whole).all()
    stream, parts = Stream(model, normaliser, **options), []
    for start in range(0, frames, 3):
        parts.append(stream.push(speech[start : start + 3], activity[start : start + 3]))
    parts.append(stream.finish())
    np.testing.assert_allclose(np.concatenate(parts, axis=1), whole, atol=1e-5)


@pytest.mark.parametrize("overlap", [0, 2])
def test_a_chunk_continues_from_the_poses_the_stream_fed_back(data, overlap):
    """The second chunk, asked for ``chunk - overlap`` frames after the first, is given the
    poses written before it as its past."""
    conversation, normaliser, _ = data
    model = random_model()
    model.sampling = Sampling(steps=3)
    speech = speech_features(conversation.audio, conversation.sample_rate)[: 2 * SMALL.chunk]
    activity = conversation.activity[: 2 * SMALL.chunk]
    seen = []
    original = model.step

    def recording_step(frame, state, noise):
        seen.append(frame["past_pose"][:, 0].clone())
        return original(frame, state, noise)

    model.step = recording_step
    poses = generate(model, normaliser, speech, activity, seed=0, overlap=overlap)
    stride = SMALL.chunk - overlap
    assert len(seen) == -(-len(speech) // stride)
    written = torch.as_tensor(normaliser.normalise_pose(poses[0, :stride].reshape(-1, 54)))
    torch.testing.assert_close(seen[1][0], written[-SMALL.past_poses :].float(), atol=1e-4, rtol=0)


class AlternatingChunks(torch.nn.Module):
    """A chunk model that writes ``pose_a`` for its even calls and ``pose_b`` for its odd ones."""

    def __init__(self, pose_a, pose_b):
        super().__init__()
        self.config, self.noise_dim, self.calls = SMALL, 0, 0
        self.poses = (pose_a, pose_b)

    def step(self, frame, state, noise):
        pose = self.poses[self.calls % 2]
        self.calls += 1
        return pose.expand(len(noise), SMALL.chunk, -1), state


def test_overlapping_chunks_are_cross_faded_linearly_and_put_back_on_the_surface(data):
    conversation, normaliser, _ = data
    raw_a, raw_b = conversation.rotations[[0, 150]].reshape(2, 54)
    pose_a, pose_b = (torch.as_tensor(normaliser.normalise_pose(p)).float() for p in (raw_a, raw_b))
    speech = speech_features(conversation.audio, conversation.sample_rate)[:12]
    model = AlternatingChunks(pose_a, pose_b)
    poses = generate(model, normaliser, speech, conversation.activity[:12], overlap=2)[0]
    # Chunks of 5 asked for every 3 frames: a at 0-4, b at 3-7, a at 6-10, b at 9-13.
    fade = np.array([1 / 3, 2 / 3])[:, None]
    a_to_b = project(torch.as_tensor(raw_a * (1 - fade) + raw_b * fade).reshape(2, 9, 6))
    np.testing.assert_allclose(
        poses[:3], np.broadcast_to(raw_a.reshape(9, 6), (3, 9, 6)), atol=1e-5
    )
    np.testing.assert_allclose(poses[3:5], a_to_b.numpy(), atol=1e-5)
    np.testing.assert_allclose(poses[5], raw_b.reshape(9, 6), atol=1e-5)
    np.testing.assert_allclose(poses[6:8], a_to_b.numpy()[::-1], atol=1e-5)  # b to a
    np.testing.assert_allclose(poses[8], raw_a.reshape(9, 6), atol=1e-5)
    assert poses.shape == (12, 9, 6)  # the last chunk's held frames cut at the end
    without = generate(model, normaliser, speech, conversation.activity[:12], overlap=0)[0]
    np.testing.assert_allclose(without[5], raw_b.reshape(9, 6), atol=1e-5)  # laid end to end
    assert np.abs(np.diff(poses, axis=0)).max() < np.abs(np.diff(without, axis=0)).max() / 2


def test_an_overlap_a_chunk_cannot_hold_is_refused(data):
    _, normaliser, _ = data
    model = random_model()
    for overlap in (-1, SMALL.chunk):
        with pytest.raises(ValueError, match="overlap must lie in 0..4"):
            Stream(model, normaliser, overlap=overlap)
    with pytest.raises(TypeError, match="overlap must be an int"):
        Stream(model, normaliser, overlap=2.5)


def test_bad_configs_and_batches_are_refused_with_what_to_do(data):
    with pytest.raises(ValueError, match="chunk .* must not exceed speech_future"):
        DiffusionConfig(chunk=30)
    with pytest.raises(ValueError, match="past_poses .* must not exceed speech_past"):
        DiffusionConfig(past_poses=20)
    with pytest.raises(ValueError, match="prediction must be one of"):
        DiffusionConfig(prediction="score")
    with pytest.raises(ValueError, match="method must be one of"):
        Sampling(method="euler")
    _, _, batch = data
    short = {name: value[:, :3] for name, value in batch.items()}
    with pytest.raises(ValueError, match="sequence_length=5"):
        GestureDiffusion(SMALL).loss(short)
    styled = GestureDiffusion(dataclasses.replace(SMALL, style=True))
    with pytest.raises(ValueError, match=r"batch\['style'\]"):
        styled.loss({name: value for name, value in batch.items() if name != "style"})
