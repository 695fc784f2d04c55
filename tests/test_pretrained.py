"""The trained models that ship with the repository, and run folders as models: they load, they
generate, and they drive the agent from recordings of speech our generator did not make."""

from pathlib import Path

import numpy as np
import pytest
import torch

from gesturelib.checkpoints import CheckpointError, read_checkpoint, save_checkpoint
from gesturelib.evaluation.headline import speaking_listening_ratio, stroke_lead
from gesturelib.features import load_audio, speech_features, who_is_talking
from gesturelib.pretrained import NAMES, PRETRAINED_DIR, export_run, load_run, pretrained_folder
from gesturelib.sampling import generate
from gesturelib.skeleton import forward_kinematics

RECORDINGS = sorted((Path(__file__).parent / "data" / "voices").glob("*.flac"))


@pytest.fixture(scope="module", params=NAMES)
def shipped(request):
    model, normaliser, _ = load_run(pretrained_folder(request.param))
    return request.param, model, normaliser


def test_the_shipped_models_are_small_and_stored_at_half_precision():
    files = [PRETRAINED_DIR / name / "best.pt" for name in NAMES]
    assert sum(path.stat().st_size for path in files) < 10e6
    for path in files:
        weights = read_checkpoint(path, kind="best")["model"]  # weights_only=True
        assert all(w.dtype == torch.float16 for w in weights.values() if w.is_floating_point())


def test_a_shipped_model_loads_as_float32_and_generates(shipped):
    _, model, normaliser = shipped
    assert all(p.dtype == torch.float32 for p in model.parameters())
    audio, rate = load_audio(RECORDINGS[0])
    speech = speech_features(audio, rate)[:50]
    rotations = generate(model, normaliser, speech, np.zeros(50, np.int64), samples=2, seed=0)
    assert rotations.shape == (2, 50, 9, 6) and np.isfinite(rotations).all()


def voiced_motion(model, normaliser, recording, samples=2):
    """The agent's motion for a recording: it speaks where the recording holds speech."""
    audio, rate = load_audio(recording)
    activity = who_is_talking(audio, rate)
    rotations = generate(
        model, normaliser, speech_features(audio, rate), activity, samples=samples, seed=0
    )
    return audio, rate, activity, [forward_kinematics(r) for r in rotations]


@pytest.fixture(scope="module")
def moglow_on_recordings():
    """For each recording: the speaking/silence ratio of MoGlow's wrists (two samples), and the
    lead of its strokes over the speech's emphasis (one per sample)."""
    model, normaliser, _ = load_run(pretrained_folder("moglow"))
    measured = {}
    for recording in RECORDINGS:
        audio, rate, activity, motions = voiced_motion(model, normaliser, recording)
        ratio = speaking_listening_ratio(motions, [activity] * len(motions))
        measured[recording.stem] = (ratio, [stroke_lead(audio, rate, activity, m) for m in motions])
    return measured


def test_moglow_gestures_while_a_voice_speaks_and_rests_in_its_pauses(moglow_on_recordings):
    ratios = {name: ratio for name, (ratio, _) in moglow_on_recordings.items()}
    assert np.median(list(ratios.values())) > 2, ratios
    assert min(ratios.values()) > 1.5, ratios  # the reverberant room blurs the pauses most


def test_moglow_strikes_just_before_the_speech_s_emphasis(moglow_on_recordings):
    """In the data the strokes come 0.2 s before each stressed syllable."""
    leads = [lead for _, sample_leads in moglow_on_recordings.values() for lead in sample_leads]
    assert 0.1 < np.median(leads) < 0.35, leads


def test_load_run_names_what_it_cannot_load(tmp_path, moglow_run):
    with pytest.raises(CheckpointError, match="not a run folder"):
        load_run(tmp_path / "nowhere")
    with pytest.raises(CheckpointError, match="is a file; give the run folder"):
        load_run(moglow_run / "best.pt")
    checkpoint = read_checkpoint(moglow_run / "best.pt")
    checkpoint["model_class"] = "Banana"
    save_checkpoint(checkpoint, tmp_path / "banana" / "best.pt")
    with pytest.raises(CheckpointError, match="'Banana', a model this version cannot load"):
        load_run(tmp_path / "banana")
    with pytest.raises(ValueError, match="the shipped models are moglow, flowvae"):
        pretrained_folder("gpt")


def test_an_exported_run_generates_what_the_run_does(tmp_path, moglow_run, short_windows):
    path = export_run(moglow_run, tmp_path / "small")
    assert path.stat().st_size < 0.6 * (moglow_run / "best.pt").stat().st_size
    conversation = short_windows[0]
    speech = speech_features(conversation.audio, conversation.sample_rate)
    motions = [
        generate(*load_run(folder)[:2], speech, conversation.activity, seed=1, temperature=0)
        for folder in (moglow_run, tmp_path / "small")
    ]
    # float16 weights: the poses differ by rounding, a fraction of a degree at most
    np.testing.assert_allclose(motions[1], motions[0], atol=0.02)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        export_run(moglow_run, tmp_path / "small")
