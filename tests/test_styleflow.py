"""Ye et al.'s flow: the global encoder, the loss's terms, generation frame by frame against the
whole sequence, the style code of a reference motion, a reference's latent codes replayed, and
its front doors."""

import dataclasses

import numpy as np
import pytest
import torch
from torch.autograd.functional import jacobian

from gesturelib.cli import main
from gesturelib.models import GestureFeatureConfig, GestureFeatureNetwork, StyleFlow
from gesturelib.models import StyleFlowConfig as Config
from gesturelib.sampling import Stream

SMALL = Config.quick(
    speech_past=8, speech_future=9, past_poses=18, steps=2, hidden=8, global_size=4
)


@pytest.fixture(scope="module")
def data():
    """A short conversation, its normaliser and a batch of three 8-frame windows with 18 past
    poses (float64)."""
    from data_synth import generate_conversation
    from gesturelib.data import ConversationFeatures, Normaliser, WindowConfig, WindowDataset

    conversation = generate_conversation(8.0, seed=5)
    features = ConversationFeatures.from_conversation(conversation)
    normaliser = Normaliser.fit([features])
    windows = WindowConfig(speech_past=8, speech_future=9, past_poses=18, sequence_length=8)
    dataset = WindowDataset([features], dataclasses.replace(windows, stride=8), normaliser)
    batch = {n: torch.stack([dataset[i][n] for i in range(3)]).double() for n in dataset[0]}
    return conversation, normaliser, batch


def random_model(config, normaliser, batch, seed=0) -> StyleFlow:
    """A StyleFlow whose every weight is random (no identity layer) and whose ActNorm layers
    have seen ``batch``, in double precision and eval mode."""
    torch.manual_seed(seed)
    model = StyleFlow(config, normaliser).double()
    model.loss(batch)  # initialises ActNorm
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(0.2 * torch.randn(parameter.shape, generator=generator).double())
    return model.eval()


def test_the_flow_inverts_and_its_logdet_is_the_jacobians(data):
    _, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch)
    short = {name: part[:1, :3] for name, part in batch.items()}
    condition = model.conditioning(short)
    assert condition.shape == (1, 3, SMALL.control_size + SMALL.global_size)
    z, logdet, _ = model.flow(short["pose"], condition)
    x, inverse_logdet, _ = model.flow.inverse(z, condition)
    torch.testing.assert_close(x, short["pose"])
    torch.testing.assert_close(inverse_logdet, -logdet)
    matrix = jacobian(
        lambda v: model.flow(v.reshape(1, 3, 54), condition)[0].flatten(), short["pose"].flatten()
    )
    torch.testing.assert_close(torch.linalg.slogdet(matrix)[1], logdet[0])


def test_generating_frame_by_frame_gives_the_decoded_sequence(data, step_through):
    """step() on each frame's control, with the style code of the first frame's history, gives
    f^-1(z; c, g) + the last pose, as the loss decodes the whole excerpt."""
    _, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch)
    z = torch.randn(batch["pose"].shape, dtype=torch.float64, generator=torch.Generator())
    whole = model.flow.inverse(z, model.conditioning(batch))[0] + batch["past_pose"][:, :, -1]
    code = torch.cat([model.reference_code(history) for history in batch["past_pose"][:, 0]])
    stepped = step_through(model, batch, z, reference_code=code)
    torch.testing.assert_close(stepped, whole)


def test_the_style_code_comes_from_the_first_frames_history_and_the_control_from_five_poses(
    data,
):
    _, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch)
    size = SMALL.control_size
    local = dict(batch, past_pose=batch["past_pose"][:, :, -5:])
    conditioning = model.conditioning(batch)
    assert torch.equal(model.control(local), conditioning[..., :size])
    oldest = dict(batch, past_pose=batch["past_pose"].clone())
    oldest["past_pose"][:, 0, 0] += 1.0  # the first frame's oldest pose: only the style code's
    changed = model.conditioning(oldest)
    assert torch.equal(changed[..., :size], conditioning[..., :size])
    assert not torch.isclose(changed[..., size:], conditioning[..., size:]).any(dim=-1).all()
    later = dict(batch, past_pose=batch["past_pose"].clone())
    later["past_pose"][:, 1:, :-5] += 1.0  # later frames' histories: held code, nothing changes
    assert torch.equal(model.conditioning(later), conditioning)
    ablated = random_model(dataclasses.replace(SMALL, global_size=0), normaliser, batch)
    assert ablated.conditioning(batch).shape[-1] == size


def test_a_reference_code_is_the_mean_pose_code_over_the_references_windows(data):
    conversation, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch)
    reference = torch.tensor(
        normaliser.normalise_pose(conversation.rotations[:30].reshape(30, 54)), dtype=torch.float64
    )
    windows = torch.stack([reference[i : i + 18] for i in range(13)])  # every 18 frames
    expected = model.global_encoder.poses(windows, 18)[:, 0].mean(dim=0)
    code = model.reference_code(reference)
    assert code.shape == (1, 1, SMALL.global_size)
    torch.testing.assert_close(code[0, 0], expected)
    # A frame's own history given as the reference: the same conditioning as without one.
    frame = {name: part[:1, :1] for name, part in batch.items()}
    own = model.reference_code(frame["past_pose"][0, 0])
    torch.testing.assert_close(
        model.conditioning({**frame, "reference_code": own}), model.conditioning(frame)
    )
    with pytest.raises(ValueError, match="T >= 18"):
        model.reference_code(reference[:17])


def test_a_tcn_over_a_sequence_gives_each_windows_feature_as_alone(data):
    _, normaliser, batch = data
    encoder = random_model(SMALL, normaliser, batch).global_encoder.speech
    sequence = torch.randn(2, 30, 31, dtype=torch.float64)
    whole = encoder(sequence, 20)  # (2, 11, size)
    alone = torch.cat([encoder(sequence[:, i : i + 20], 20) for i in range(11)], dim=1)
    torch.testing.assert_close(whole, alone)


def test_the_loss_adds_the_weighted_reconstruction_and_perceptual_terms(data):
    _, normaliser, batch = data
    features = GestureFeatureNetwork(GestureFeatureConfig.quick()).double()
    torch.manual_seed(0)
    model = StyleFlow(SMALL, normaliser, features).double().eval()
    terms = model.loss(batch)
    expected = terms["nll"] + SMALL.reconstruction * terms["reconstruction"]
    expected = expected + SMALL.perceptual * terms["perceptual"]
    torch.testing.assert_close(terms["loss"], expected)
    assert terms["reconstruction"] > 0 and terms["perceptual"] > 0
    for name, parameter in model.feature_encoder.named_parameters():  # copied and frozen
        assert not parameter.requires_grad
        assert torch.equal(parameter, dict(features.encoder.named_parameters())[name])
    # The same draws as the loss in eval mode: the pose noise, then the latent, from seed 0.
    generator = torch.Generator().manual_seed(0)
    model.noise(batch["pose"], generator)
    latent = model.flow.noise(batch["pose"].shape[:2], 1.0, generator)
    decoded = (
        model.flow.inverse(latent, model.conditioning(batch))[0] + batch["past_pose"][:, :, -1]
    )
    torch.testing.assert_close(terms["reconstruction"], (decoded - batch["pose"]).abs().mean())
    difference = features.encode(decoded) - features.encode(batch["pose"])
    torch.testing.assert_close(terms["perceptual"], difference.abs().mean())
    plain = StyleFlow(dataclasses.replace(SMALL, reconstruction=0.0, perceptual=0.0), normaliser)
    plain.double().eval()
    plain_terms = plain.loss(batch)
    assert plain.feature_encoder is None and torch.equal(plain_terms["loss"], plain_terms["nll"])


def test_the_feature_network_halves_time_twice_and_reconstructs():
    network = GestureFeatureNetwork(GestureFeatureConfig.quick())
    pose = torch.randn(2, 32, 54)
    assert network.encode(pose).shape == (2, 12, 8)
    assert network.loss({"pose": pose})["mse"] > 0
    with pytest.raises(ValueError, match="multiple of 4"):
        network.loss({"pose": pose[:, :30]})


def test_configs_refuse_labels_and_too_short_a_history():
    with pytest.raises(ValueError, match="without labels"):
        Config(style=True)
    with pytest.raises(ValueError, match="past_poses must be >= 5"):
        Config(past_poses=4)
    with pytest.raises(ValueError, match="longer than its TCNs' view"):
        Config(past_poses=17)
    Config(past_poses=5, global_size=0)  # the ablation reads no window
    with pytest.raises(TypeError, match="GestureFeatureConfig"):
        Config(features=3)
    assert Config(features={"channels": 8, "features": 4}).features == GestureFeatureConfig(8, 4)


def test_stepping_a_references_latents_gives_back_its_poses(data, step_through):
    """latents() is what step() inverts: with the reference's own control (and the style code
    of its first frame's history, held as in training), frame by frame, its base codes give back
    its poses (Ye et al.'s transfer replays them with other speech)."""
    _, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch)
    z = model.latents(batch)
    assert z.shape == batch["pose"].shape
    code = torch.cat([model.reference_code(history) for history in batch["past_pose"][:, 0]])
    stepped = step_through(model, batch, z, reference_code=code)
    torch.testing.assert_close(stepped, batch["pose"])


def test_a_stream_replays_a_references_latents_and_refuses_what_cannot(data):
    from gesturelib.models import Aud2Pose, Aud2PoseConfig
    from gesturelib.sampling import reference_latents

    conversation, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch).float()
    latents = reference_latents(model, normaliser, conversation)
    assert latents.shape == (len(conversation.rotations) - 18 - 9, 54)
    speech = np.zeros((30, 27), dtype=np.float32)
    activity = np.zeros(30, dtype=np.int64)

    def motion(**options):
        stream = Stream(model, normaliser, seed=0, samples=2, **options)
        return np.concatenate([stream.push(speech, activity), stream.finish()], axis=1)

    own, replayed = motion(), motion(style_from=conversation)
    assert not np.allclose(own, replayed)
    np.testing.assert_array_equal(replayed, motion(style_from=conversation))  # no draws
    assert not np.allclose(replayed[0], replayed[1])  # each sample from its own offset
    np.testing.assert_allclose(
        motion(style_from=conversation, temperature=0), motion(temperature=0)
    )
    short = dataclasses.replace(
        conversation,
        rotations=conversation.rotations[:20],
        activity=conversation.activity[:20],
        audio=conversation.audio[: 20 * conversation.sample_rate // conversation.fps],
    )
    with pytest.raises(ValueError, match="at least 28 frames"):
        reference_latents(model, normaliser, short)
    regressor = Aud2Pose(Aud2PoseConfig.quick())
    with pytest.raises(ValueError, match="no base codes"):
        reference_latents(regressor, normaliser, conversation)


def test_a_stream_holds_a_style_code_and_refuses_a_wrong_one(data):
    conversation, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch).float()
    speech = np.zeros((30, 27), dtype=np.float32)
    activity = np.zeros(30, dtype=np.int64)
    outputs = {}
    for name, frames in (("own", None), ("first", slice(0, 50)), ("last", slice(-50, None))):
        code = None
        if frames is not None:
            poses = normaliser.normalise_pose(conversation.rotations[frames].reshape(50, 54))
            code = model.reference_code(torch.tensor(poses, dtype=torch.float32))
        stream = Stream(model, normaliser, seed=0, style_code=code)
        outputs[name] = np.concatenate([stream.push(speech, activity), stream.finish()], axis=1)
    assert not np.allclose(outputs["first"], outputs["own"])
    assert not np.allclose(outputs["first"], outputs["last"])
    with pytest.raises(ValueError, match="style_code must be 4 finite numbers"):
        Stream(model, normaliser, style_code=np.zeros(3))
    with pytest.raises(ValueError, match="style_code must be 4 finite numbers"):
        Stream(model, normaliser, style_code=np.full(4, np.nan))


def test_generate_style_from_takes_a_conversation_for_both_flows_and_refuses_the_rest(
    tmp_path, tiny_data, moglow_run, capsys
):
    run = tmp_path / "styleflow"
    assert main(["train", "styleflow", "--out", str(run), "--quick", "--data", str(tiny_data)]) == 0
    reference = next((tiny_data / "train").glob("*.wav")).with_suffix("")
    speech = next((tiny_data / "test").glob("*.wav")).with_suffix("")
    common = ["--conversation", str(speech), "--no-video"]
    for name, trained in (("styleflow", run), ("moglow", moglow_run)):
        out = tmp_path / f"{name}-styled"
        args = ["generate", str(trained), *common, "--out", str(out)]
        assert main([*args, "--style-from", str(reference)]) == 0
        plain = tmp_path / f"{name}-plain"
        assert main(["generate", str(trained), *common, "--out", str(plain)]) == 0
        with np.load(out / "motion.npz") as styled, np.load(plain / "motion.npz") as own:
            assert styled["rotations"].shape == own["rotations"].shape
            assert not np.allclose(styled["rotations"], own["rotations"])
    capsys.readouterr()
    for source, message in (
        (tmp_path / "nowhere", "not a conversation's path stem"),
        (tmp_path / "styleflow-styled" / "motion.npz", "without .npz"),
    ):
        args = ["generate", str(run), *common, "--out", str(tmp_path / "x"), "--style-from"]
        assert main([*args, str(source)]) == 2
        assert message in capsys.readouterr().err


def grid_pairs():
    """Every pair of 3 speaker styles with 4 reference styles: the speakers' style is the same
    on average for every reference, so a motion that keeps the speaker's style has slope 0."""
    rng = np.random.default_rng(0)
    speakers, references = rng.normal(size=(3, 4)) * 10, rng.normal(size=(4, 4)) * 10
    a = np.repeat(speakers, 4, axis=0)
    b = np.tile(references, (3, 1))
    return a, b


def test_transfer_scores_on_known_answers():
    from gesturelib.evaluation.transfer import transfer_scores
    from gesturelib.style import STYLE_FEATURES

    a, b = grid_pairs()
    for realised, follows, nearer in (
        (b, 1.0, 1.0),  # takes the reference's style in full
        (a, 0.0, 0.0),  # keeps the speech's
        (a + 0.75 * (b - a), 0.75, 1.0),  # three quarters of the way
        (a + 0.25 * (b - a), 0.25, 0.0),
        (2 * b + 3, 2.0, None),  # overshoots: slope 2
    ):
        scores = transfer_scores(a, b, realised)
        assert list(scores) == list(STYLE_FEATURES)
        for score in scores.values():
            assert score["follows"] == pytest.approx(follows)
            if nearer is not None:
                assert score["nearer"] == nearer
    with pytest.raises(ValueError, match="same hand_height"):
        transfer_scores(a, np.ones_like(b), b)
    with pytest.raises(ValueError, match=r"\(P, 4\)"):
        transfer_scores(a[:, :3], b[:, :3], b[:, :3])


def test_clip_style_averages_the_style_features_over_the_clip(data):
    from gesturelib.evaluation.transfer import clip_style
    from gesturelib.style import style_features

    conversation = data[0]
    expected = style_features(conversation.positions).mean(axis=0)
    np.testing.assert_allclose(clip_style(conversation.positions), expected)
    raised = conversation.positions + np.array([0.0, 5.0, 0.0])  # every keypoint 5 cm higher
    assert clip_style(raised)[0] == pytest.approx(expected[0] + 5.0)


def test_spanning_references_are_the_ends_of_each_features_range():
    from types import SimpleNamespace

    from gesturelib.evaluation.transfer import spanning_references
    from gesturelib.skeleton import JOINT_INDEX

    base = np.zeros((100, 9, 3))
    base[:, :, 1] = 100.0
    clips = []
    for height in (0.0, 10.0, 20.0, 30.0):  # the right wrist's height alone differs
        positions = base.copy()
        positions[:, JOINT_INDEX["right_wrist"], 1] += height
        clips.append(SimpleNamespace(positions=positions, height=height))
    chosen = spanning_references(clips)
    assert [c.height for c in chosen[:2]] == [0.0, 30.0]  # hand height: the lowest, the highest
    assert len(chosen) == len({id(c) for c in chosen})  # each once


def test_style_transfer_averages_the_slopes_by_latent_codes(data, monkeypatch):
    from dataclasses import replace

    from gesturelib.evaluation import transfer
    from gesturelib.sampling import shortest_reference

    conversation, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch).float()
    short = replace(conversation, rotations=conversation.rotations[: shortest_reference(model) - 1])
    speakers = [object()]  # never read by the stand-in below
    for train in ([conversation], [conversation, short]):  # the short one cannot be a reference
        splits = {"train": train, "test": speakers}
        assert np.isnan(transfer.style_transfer(model, normaliser, splits))  # no slope to fit
    a, b = grid_pairs()
    asked = {}

    def halfway(model, normaliser, speakers, references, seconds, by):
        asked.update(speakers=speakers, references=references, seconds=seconds, by=by)
        return a, b, a + np.array([0.2, 0.4, 0.6, 0.8]) * (b - a)  # slopes 0.2 .. 0.8

    def ends(train):
        asked["candidates"] = train
        return train * 2

    monkeypatch.setattr(transfer, "transfer_pairs", halfway)
    monkeypatch.setattr(transfer, "spanning_references", ends)
    splits = {"train": [conversation, short], "test": speakers}
    assert transfer.style_transfer(model, normaliser, splits, 10) == pytest.approx(0.5)
    assert asked["candidates"] == [conversation] and asked["references"] == [conversation] * 2
    assert asked["speakers"] is speakers and (asked["seconds"], asked["by"]) == (10, "latents")


def test_transfer_pairs_generate_every_pair_by_each_mechanism(data):
    from gesturelib.evaluation.transfer import transfer_pairs

    conversation, normaliser, batch = data
    model = random_model(SMALL, normaliser, batch).float()
    for by in ("latents", "style code"):
        speakers, references, realised = transfer_pairs(
            model, normaliser, [conversation], [conversation, conversation], seconds=2, by=by
        )
        assert speakers.shape == references.shape == realised.shape == (2, 4)
        assert np.isfinite(realised).all()
    from gesturelib.models import MoGlow, MoGlowConfig

    config = MoGlowConfig.quick(speech_past=8, speech_future=9, steps=2, hidden=8, style=True)
    torch.manual_seed(0)
    labelled = MoGlow(config, normaliser)
    window = {name: part.float() for name, part in batch.items()}
    window["past_pose"] = window["past_pose"][:, :, -config.past_poses :]
    labelled.loss(window)  # initialises ActNorm
    pairs = transfer_pairs(
        labelled.eval(), normaliser, [conversation], [conversation], 2, by="labels"
    )
    assert np.isfinite(pairs[2]).all()
    with pytest.raises(ValueError, match="by must be one of"):
        transfer_pairs(model, normaliser, [conversation], [conversation], by="copy")
