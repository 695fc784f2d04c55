"""MoGlow, the pose surface and generation: likelihoods, sequence vs frame by frame, seeds."""

import dataclasses

import numpy as np
import pytest
import torch
from torch.autograd.functional import jacobian

from gesturelib.features import speech_features
from gesturelib.models import MoGlow, MoGlowConfig
from gesturelib.pose_surface import T_POSE_DIRECTIONS, SurfaceNoise, limb_directions, project
from gesturelib.rotations import shortest_arc
from gesturelib.sampling import Stream, generate
from gesturelib.skeleton import forward_kinematics

SMALL = MoGlowConfig.quick(speech_past=2, speech_future=3, past_poses=2, steps=2, hidden=8)


@pytest.fixture(scope="module")
def data(short_windows):
    return short_windows[:3]


def test_a_whole_sequence_inverts_and_its_logdet_is_the_jacobians(data, trained_looking):
    _, normaliser, batch = data
    model = trained_looking(SMALL, normaliser, batch).double()
    short = {name: part[:1, :3].double() for name, part in batch.items()}  # (1, 3, ...)
    cond = model.control(short)
    z, logdet, _ = model.flow(short["pose"], cond)
    x, inverse_logdet, _ = model.flow.inverse(z, cond)
    torch.testing.assert_close(x, short["pose"])
    torch.testing.assert_close(inverse_logdet, -logdet)
    matrix = jacobian(
        lambda v: model.flow(v.reshape(1, 3, 54), cond)[0].flatten(), short["pose"].flatten()
    )
    torch.testing.assert_close(torch.linalg.slogdet(matrix)[1], logdet[0], atol=1e-8, rtol=1e-8)


def test_teacher_forcing_and_frame_by_frame_agree_on_likelihood_and_samples(
    data, trained_looking, step_through
):
    _, normaliser, batch = data
    model = trained_looking(SMALL, normaliser, batch).double()
    batch = {name: part.double() for name, part in batch.items()}
    cond = model.control(batch)
    log_prob, _ = model.flow.log_prob(batch["pose"], cond)
    state, total = None, torch.zeros(3, dtype=torch.float64)
    for t in range(batch["pose"].shape[1]):
        frame_log_prob, state = model.flow.log_prob(
            batch["pose"][:, t : t + 1], cond[:, t : t + 1], state
        )
        total = total + frame_log_prob
    torch.testing.assert_close(total, log_prob)
    z = torch.randn(
        batch["pose"].shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1)
    )
    whole, _, _ = model.flow.inverse(z, cond)
    stepped = step_through(model, batch, z)
    last = batch["past_pose"][:, :, -1]  # a residual MoGlow's poses are changes from the last one
    torch.testing.assert_close(stepped, whole + last)


def test_a_sequences_latents_step_back_to_its_poses(data, trained_looking, step_through):
    """latents() inverts step(): the base codes of poses, read with their control, give them back
    frame by frame (what a style reference's replayed codes rest on)."""
    _, normaliser, batch = data
    model = trained_looking(SMALL, normaliser, batch).double()
    batch = {name: part.double() for name, part in batch.items()}
    z = model.latents(batch)
    stepped = step_through(model, batch, z)
    torch.testing.assert_close(stepped, batch["pose"])


def test_a_residual_moglow_models_the_change_from_the_last_pose(
    data, trained_looking, step_through
):
    _, normaliser, batch = data
    config = dataclasses.replace(SMALL, residual=True, pose_noise=0.0)
    model = trained_looking(config, normaliser, batch).double()
    batch = {name: part.double() for name, part in batch.items()}
    cond, last = model.control(batch), batch["past_pose"][:, :, -1]
    log_prob, _ = model.flow.log_prob(batch["pose"] - last, cond)  # the shift has log-det 0
    torch.testing.assert_close(model.loss(batch)["nll"], -log_prob.mean() / last.shape[1])
    z = torch.randn(last.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    whole, _, _ = model.flow.inverse(z, cond)
    stepped = step_through(model, batch, z)
    torch.testing.assert_close(stepped, whole + last)
    with pytest.raises(ValueError, match="past_poses >= 1"):
        MoGlowConfig(residual=True, past_poses=0)


def test_data_dropout_changes_training_but_nothing_at_evaluation(data, trained_looking):
    _, normaliser, batch = data
    model = trained_looking(SMALL, normaliser, batch)
    no_dropout = MoGlow(dataclasses.replace(SMALL, dropout=0.0), normaliser)
    no_dropout.load_state_dict(model.state_dict())
    no_dropout.eval()
    evaluated = model.loss(batch)["loss"]
    assert torch.equal(evaluated, model.loss(batch)["loss"])  # fixed noise: the same every time
    assert torch.equal(evaluated, no_dropout.loss(batch)["loss"])
    # In double precision: a random model's loss is large, and float32 can round a change away.
    model, no_dropout = model.double().train(), no_dropout.double().train()
    batch = {name: part.double() for name, part in batch.items()}
    torch.manual_seed(0)
    with_dropout = model.loss(batch)["loss"]
    torch.manual_seed(0)
    assert not torch.equal(with_dropout, no_dropout.loss(batch)["loss"])


def test_shift_bands_moves_each_item_and_fills_from_the_nearest_band_kept():
    from gesturelib.models.control import shift_bands

    speech = torch.arange(5.0).expand(3, 2, 4, 5)  # (B, L, W, n_mels): band b holds b
    shifted = shift_bands(speech, torch.tensor([2, 0, -1]))
    torch.testing.assert_close(shifted[0, 1, 3], torch.tensor([0.0, 0, 0, 1, 2]))  # a higher voice
    torch.testing.assert_close(shifted[1], speech[1])
    torch.testing.assert_close(shifted[2, 0, 0], torch.tensor([1.0, 2, 3, 4, 4]))  # a lower one


def test_the_voice_shift_moves_the_speech_in_training_only(data):
    from gesturelib.models.control import ControlEncoder

    _, _, batch = data
    shifting = ControlEncoder(dataclasses.replace(SMALL, voice_shift=2, dropout=0.0), hidden=8)
    still = ControlEncoder(dataclasses.replace(SMALL, voice_shift=0, dropout=0.0), hidden=8)
    still.load_state_dict(shifting.state_dict())
    torch.testing.assert_close(shifting(batch), still(batch))  # generation hears the voice as it is
    torch.manual_seed(0)
    assert not torch.allclose(shifting(batch, training=True), still(batch, training=True))
    torch.manual_seed(0)
    again = shifting(batch, training=True)
    torch.manual_seed(0)
    torch.testing.assert_close(again, shifting(batch, training=True))  # seeded: reproducible
    with pytest.raises(ValueError, match="voice_shift"):
        MoGlowConfig(voice_shift=-1)


def test_noise_off_the_surface_moves_no_limb_and_isotropic_noise_does(data):
    conversation, normaliser, _ = data
    pose = torch.tensor(
        normaliser.normalise_pose(conversation.rotations.reshape(-1, 54)), dtype=torch.float64
    )

    def keypoints(normalised):
        raw = normaliser.denormalise_pose(normalised.numpy()).reshape(-1, 9, 6)
        return forward_kinematics(raw)

    moves = {}
    for across_only in (True, False):
        noise = SurfaceNoise(0.05, across_only).double()
        noise.set_statistics(normaliser)
        drawn = noise(pose, torch.Generator().manual_seed(0))
        assert 0.03 < drawn.pow(2).mean().sqrt() < 0.06
        moves[across_only] = np.linalg.norm(
            keypoints(pose + drawn) - keypoints(pose), axis=-1
        ).mean()
    assert moves[True] < 0.01 < 0.05 < moves[False]  # cm
    with pytest.raises(RuntimeError, match="normalisation"):
        SurfaceNoise(0.05)(pose)


def test_project_keeps_poses_on_the_surface_and_returns_others_to_it(data):
    conversation, _, _ = data
    rotations = torch.tensor(conversation.rotations, dtype=torch.float64)
    torch.testing.assert_close(project(rotations), rotations, atol=1e-6, rtol=0)
    off = rotations + 0.1 * torch.randn(rotations.shape, generator=torch.Generator().manual_seed(2))
    again = project(off)
    torch.testing.assert_close(project(again), again)
    np.testing.assert_allclose(forward_kinematics(again), forward_kinematics(off), atol=1e-6)


def test_project_turns_each_limb_by_its_shortest_arc_even_right_round():
    directions = torch.nn.functional.normalize(
        torch.randn(20, 9, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(3)),
        dim=-1,
    )
    directions[0, 1] = -torch.as_tensor(T_POSE_DIRECTIONS[1])  # the left shoulder reversed
    for poses in (directions[1:], directions):  # the closed form, and the fallback
        arcs = shortest_arc(torch.as_tensor(T_POSE_DIRECTIONS), poses)
        expected = arcs[..., :2, :].flatten(-2)
        torch.testing.assert_close(project(expected), expected)
        torch.testing.assert_close(limb_directions(project(expected)), poses)


def generation_setup(data, trained_looking):
    conversation, normaliser, batch = data
    model = trained_looking(SMALL, normaliser, batch)
    speech = speech_features(conversation.audio, conversation.sample_rate)
    return model, normaliser, speech, conversation.activity


def test_same_seed_same_motion_and_sample_k_does_not_depend_on_how_many(data, trained_looking):
    model, normaliser, speech, activity = generation_setup(data, trained_looking)
    three = generate(model, normaliser, speech, activity, samples=3, seed=4)
    one = generate(model, normaliser, speech, activity, samples=1, seed=4)
    assert three.shape == (3, len(speech), 9, 6)
    # Up to the rounding of batched float32 arithmetic, which a residual model integrates.
    np.testing.assert_allclose(three[0], one[0], atol=1e-2)
    assert np.abs(three[0] - three[1]).max() > 0.01
    other = generate(model, normaliser, speech, activity, seed=5)
    assert not np.array_equal(other[0], one[0])


def test_temperature_zero_is_deterministic_whatever_the_seed(data, trained_looking):
    model, normaliser, speech, activity = generation_setup(data, trained_looking)
    first = generate(model, normaliser, speech, activity, temperature=0, seed=1)
    np.testing.assert_array_equal(
        first, generate(model, normaliser, speech, activity, temperature=0, seed=2)
    )


def test_streaming_in_chunks_gives_the_motion_of_the_whole_recording(data, trained_looking):
    model, normaliser, speech, activity = generation_setup(data, trained_looking)
    whole = generate(model, normaliser, speech, activity, seed=3)
    stream, parts = Stream(model, normaliser, seed=3), []
    for start in range(0, len(speech), 7):  # 7 frames at a time, as a live caller would
        parts.append(stream.push(speech[start : start + 7], activity[start : start + 7]))
    parts.append(stream.finish())
    np.testing.assert_allclose(np.concatenate(parts, axis=1), whole, atol=1e-5)
    assert parts[0].shape[1] == 7 - SMALL.speech_future  # the look-ahead delays the first poses


def test_a_recording_of_one_frame_is_enough_and_bad_features_are_refused(data, trained_looking):
    model, normaliser, speech, activity = generation_setup(data, trained_looking)
    assert generate(model, normaliser, speech[:1], activity[:1]).shape == (1, 1, 9, 6)
    with pytest.raises(ValueError, match=r"speech must be \(n, 27\) frames"):
        generate(model, normaliser, speech[:, :20], activity)
    with pytest.raises(ValueError, match="activity must be"):
        generate(model, normaliser, speech, activity[:-1])
    with pytest.raises(ValueError, match="samples must be an integer >= 1"):
        generate(model, normaliser, speech, activity, samples=0)


def test_style_control_holds_the_asked_style_and_refuses_impossible_percentiles(
    data, trained_looking
):
    conversation, normaliser, batch = data
    batch = {**batch, "style": batch["style"]}
    model = trained_looking(dataclasses.replace(SMALL, style=True), normaliser, batch)
    speech = speech_features(conversation.audio, conversation.sample_rate)[:20]
    activity = conversation.activity[:20]
    high = normaliser.style_at_percentiles({"hand_height": 85})
    low = normaliser.style_at_percentiles({"hand_height": 15})
    assert high[0] > low[0]
    a = generate(model, normaliser, speech, activity, seed=0, style=high)
    b = generate(model, normaliser, speech, activity, seed=0, style=low)
    assert not np.array_equal(a, b)  # the style reaches the model
    with pytest.raises(ValueError, match=r"in \[0, 100\]"):
        normaliser.style_at_percentiles({"hand_height": 101})


def test_the_style_reaches_the_couplings_as_it_is_beside_the_encoded_control(data, trained_looking):
    from gesturelib.models.control import ControlEncoder

    _, normaliser, batch = data
    config = dataclasses.replace(SMALL, style=True)
    encoder = ControlEncoder(config, hidden=8)
    control = encoder(batch)
    assert control.shape[-1] == config.encoded_size == config.control_size + 4
    torch.testing.assert_close(control[..., -4:], batch["style"])
    plain = ControlEncoder(SMALL, hidden=8)
    assert plain(batch).shape[-1] == SMALL.encoded_size == SMALL.control_size
    model = trained_looking(config, normaliser, batch)  # the flow's density moves with the style
    change = batch["pose"] - batch["past_pose"][:, :, -1]
    with torch.no_grad():
        log_probs = [
            model.flow.log_prob(change, model.control({**batch, "style": batch["style"] + shift}))[
                0
            ]
            for shift in (0, 1)
        ]
    assert not torch.allclose(*log_probs)


def test_a_style_model_saved_before_the_style_passed_beside_the_encoder_is_refused(tmp_path):
    from gesturelib.checkpoints import CheckpointMismatchError, load_state

    model = MoGlow(dataclasses.replace(SMALL, style=True))
    state = model.state_dict()
    first = "control.encoder.0.weight"  # the old encoder read the style: 4 more inputs
    state[first] = torch.zeros(state[first].shape[0], state[first].shape[1] + 4)
    with pytest.raises(CheckpointMismatchError, match="(?s)control.encoder.0.weight.*retrain it"):
        load_state(model, state, tmp_path / "best.pt")


def test_generation_with_a_progress_bar_draws_the_same_motion(
    short_windows, trained_looking, monkeypatch
):
    import gesturelib.sampling as sampling

    conversation, normaliser, batch, _ = short_windows
    model = trained_looking(SMALL, normaliser, batch)
    speech = speech_features(conversation.audio, conversation.sample_rate)
    whole = generate(model, normaliser, speech, conversation.activity, samples=2, seed=4)
    monkeypatch.setattr(sampling, "_PROGRESS_STEP", 7)  # many pushes of a few frames
    pushed = generate(
        model, normaliser, speech, conversation.activity, samples=2, seed=4, progress=True
    )
    np.testing.assert_array_equal(whole, pushed)


def test_one_step_ahead_is_teacher_forced_draw_by_draw(data, trained_looking, monkeypatch):
    """Given the recording's own base codes for noise, every one-step draw is the recorded pose:
    the memory moves on with the recording, not with the draws; with random noise, the draws are
    seeded poses on the surface."""
    import gesturelib.sampling as sampling
    from gesturelib.models import Aud2Pose, Aud2PoseConfig

    conversation, normaliser, batch = data
    # Weights less random than elsewhere: float32 inverts the flow to within 1e-6.
    model = trained_looking(SMALL, normaliser, batch, spread=0.05)
    drawn = sampling.one_step_ahead(model, normaliser, conversation, seed=3)
    first = max(SMALL.past_poses, SMALL.speech_past)
    frames = len(conversation.rotations) - first - SMALL.speech_future
    assert drawn.shape == (frames, 9, 6)
    np.testing.assert_allclose(project(torch.as_tensor(drawn)).numpy(), drawn, atol=1e-6)
    np.testing.assert_array_equal(
        drawn, sampling.one_step_ahead(model, normaliser, conversation, 3)
    )
    assert not np.allclose(drawn, sampling.one_step_ahead(model, normaliser, conversation, 4))

    codes = iter(sampling.reference_latents(model, normaliser, conversation))
    monkeypatch.setattr(
        sampling, "standard_normal", lambda shape, *_: torch.as_tensor(next(codes)).reshape(shape)
    )
    recorded = conversation.rotations[first : first + frames]
    replayed = sampling.one_step_ahead(model, normaliser, conversation)
    np.testing.assert_allclose(replayed, recorded, atol=1e-5)
    with pytest.raises(ValueError, match="recurrent flow"):
        sampling.one_step_ahead(Aud2Pose(Aud2PoseConfig.quick()), normaliser, conversation)
