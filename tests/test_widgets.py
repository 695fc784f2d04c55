"""The sampling explorer, headless: build it, set its controls, and check what it would show."""

import base64
import datetime
import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
import soundfile

from gesturelib.conventions import FPS, Activity
from gesturelib.features import AudioError
from gesturelib.pretrained import load_run
from gesturelib.widgets import Clip, Explorer, PoseViewer, Take, wav_data_url

VOICES = Path(__file__).parent / "data" / "voices"


@pytest.fixture(scope="module")
def explorer(moglow_run, short_windows):
    conversation = short_windows[0]
    model, normaliser, _ = load_run(moglow_run)
    clips = {
        "held-out": Clip.from_conversation(conversation, start_s=1.0, seconds=4.0),
        "a voice": Clip.from_file(VOICES / "us_clean.flac"),
    }
    return Explorer({"moglow": (model, normaliser)}, clips)


def decoded(viewer: PoseViewer) -> np.ndarray:
    return np.frombuffer(viewer.motions, dtype="<f4").reshape(viewer.count, -1, 9, 3)


def test_the_explorer_shows_the_recorded_motion_beside_a_sample(explorer):
    explorer.clip.value, explorer.truth.value = "held-out", True
    take = explorer.update()
    assert take.titles == ("recorded motion", "moglow")
    assert take.motions.shape == (2, 4 * FPS, 9, 3)
    np.testing.assert_array_equal(take.motions[0], explorer.clips["held-out"].truth)
    np.testing.assert_array_equal(decoded(explorer.viewer), take.motions)
    assert explorer.viewer.titles == list(take.titles)
    assert "sampled 4.0 s of motion" in explorer.status.value
    explorer.truth.value = False  # an observer samples again
    assert decoded(explorer.viewer).shape[0] == 1


def test_a_seed_gives_its_motion_again_and_another_seed_another(explorer):
    explorer.clip.value, explorer.truth.value, explorer.temperature.value = "held-out", False, 1.0
    explorer.seed.value = 3
    first = explorer.render().motions
    np.testing.assert_array_equal(explorer.render().motions, first)
    explorer.seed.value = 4
    assert np.abs(explorer.render().motions - first).max() > 0.1
    explorer.temperature.value = 0.0
    still = explorer.render().motions
    explorer.seed.value = 5
    np.testing.assert_array_equal(explorer.render().motions, still)


def test_samples_side_by_side_are_the_first_draws_of_the_seed(explorer):
    explorer.clip.value, explorer.truth.value, explorer.temperature.value = "held-out", True, 1.0
    explorer.seed.value = 3
    one = explorer.render().motions[1]
    explorer.samples.value = 3  # an observer samples again
    try:
        take = explorer.render()
        shown = decoded(explorer.viewer)
    finally:
        explorer.samples.value = 1
    assert take.titles == (
        "recorded motion",
        "moglow, sample 1",
        "moglow, sample 2",
        "moglow, sample 3",
    )
    assert shown.shape[0] == 4
    # Sample 1 of three is sample 1 of one (up to the rounding of batched float32 arithmetic).
    np.testing.assert_allclose(take.motions[1], one, atol=0.01)
    assert np.abs(take.motions[2] - take.motions[1]).max() > 0.1


def test_who_talks_can_be_forced(explorer):
    explorer.clip.value = "held-out"
    for label, code in (("the agent speaks", Activity.A_SPEAKS), ("nobody speaks", Activity.NONE)):
        explorer.talking.value = label
        np.testing.assert_array_equal(explorer.render().activity, code)
    explorer.talking.value = "as recorded"
    np.testing.assert_array_equal(explorer.render().activity, explorer.clips["held-out"].activity)


def test_a_recording_speaks_where_it_has_speech_and_has_no_recorded_motion(explorer):
    explorer.clip.value = "a voice"
    take = explorer.update()
    assert explorer.truth.disabled and take.titles == ("moglow",)
    clip = explorer.clips["a voice"]
    assert take.motions.shape[1] == len(clip.activity)
    speaking = clip.activity == Activity.A_SPEAKS
    assert 0.3 < speaking.mean() < 0.7  # three sentences between pauses of 3-4 s
    assert not speaking[: FPS + FPS // 2].any()  # the voice starts at 2 s (voices.csv)


def test_the_browser_gets_the_sound_as_a_wav_it_can_play(explorer):
    explorer.clip.value = "held-out"
    explorer.update()
    url = explorer.viewer.audio
    assert url.startswith("data:audio/wav;base64,")
    audio, rate = soundfile.read(io.BytesIO(base64.b64decode(url.split(",", 1)[1])))
    clip = explorer.clips["held-out"]
    assert rate == clip.sample_rate
    np.testing.assert_allclose(audio, clip.audio, atol=1 / 2**15)


def uploaded(name: str, content: bytes) -> tuple[dict]:
    """What a FileUpload holds after a person picks a file in the browser."""
    return (
        {
            "name": name,
            "type": "audio/flac",
            "size": len(content),
            "content": memoryview(content),
            "last_modified": datetime.datetime(2026, 1, 1, tzinfo=datetime.UTC),
        },
    )


def test_an_upload_joins_the_clips_and_a_bad_one_says_why(explorer):
    explorer.upload.value = uploaded("mine.flac", (VOICES / "scottish_phone.flac").read_bytes())
    assert explorer.clip.value == "mine.flac" and "mine.flac" in explorer.clips
    assert explorer.clips["mine.flac"].sample_rate == 16000  # read at the models' rate
    explorer.upload.value = uploaded("<notes>.wav", b"not audio")
    status = explorer.status.value
    assert "&lt;notes&gt;.wav" in status and "could not be read" in status  # escaped HTML
    assert tempfile.gettempdir() not in status  # the upload's name, never the temporary file's
    assert explorer.clip.value == "mine.flac"
    # The same name again with another recording: the new one is sampled and heard.
    heard = explorer.viewer.audio
    explorer.upload.value = uploaded("mine.flac", (VOICES / "us_clean.flac").read_bytes())
    assert explorer.viewer.audio != heard
    assert explorer.viewer.count == 1 and len(explorer.viewer.activity) > 500  # us_clean: 22 s


def test_a_new_clip_is_sampled_once_and_no_other(explorer, monkeypatch):
    explorer.clip.value = "a voice"  # not the first clip, to which new options reset a dropdown
    sampled = []
    render = explorer.render
    monkeypatch.setattr(explorer, "render", lambda: sampled.append(explorer.clip.value) or render())
    explorer.add_clip("the same again", explorer.clips["held-out"])
    assert sampled == ["the same again"] and explorer.clip.value == "the same again"


def test_style_sliders_are_off_for_a_model_without_style(explorer):
    explorer.update()
    assert all(slider.disabled for slider in explorer.style.values())


def test_style_sliders_steer_a_model_with_style_inputs(short_windows, trained_looking):
    import dataclasses

    from gesturelib.models import MoGlowConfig

    conversation, normaliser, batch, _ = short_windows
    config = MoGlowConfig.quick(speech_past=2, speech_future=3, past_poses=2, steps=2, hidden=8)
    model = trained_looking(dataclasses.replace(config, style=True), normaliser, batch)
    clip = Clip.from_conversation(conversation, seconds=4.0)
    styled = Explorer({"styled": (model, normaliser)}, {"clip": clip})
    assert not any(slider.disabled for slider in styled.style.values())
    before = styled.render().motions
    styled.style["hand_height"].value = 90
    after = decoded(styled.viewer)  # the observer sampled again and showed it
    np.testing.assert_array_equal(after[0], before[0])  # the recorded motion
    assert np.abs(after[1] - before[1]).max() > 0.1  # cm: the sample follows the slider


def test_clips_refuse_what_they_cannot_use(short_windows):
    conversation = short_windows[0]
    with pytest.raises(ValueError, match="does not fit"):
        Clip.from_conversation(conversation, start_s=60.0)
    with pytest.raises(AudioError, match="no speech"):
        Clip.from_recording(np.zeros(32000, np.float32), 16000)


def test_the_viewer_takes_several_motions():
    motions = np.random.default_rng(0).normal(size=(3, 5, 9, 3)).astype(np.float32)
    viewer = PoseViewer()
    take = Take(motions, ("a", "b", "c"), np.zeros(5, np.int64), np.zeros(3200), 16000, 0.0)
    viewer.show(take)
    np.testing.assert_array_equal(decoded(viewer), motions)
    assert viewer.activity == [0] * 5 and viewer.count == 3
    assert viewer.audio == wav_data_url(np.zeros(3200), 16000)
    assert len(viewer.bones) == len(viewer.colours) == 9  # a bone ends at each keypoint


def test_the_explorer_takes_a_diffusion_model_beside_a_flow(moglow_run, short_windows):
    import torch

    from gesturelib.models import DiffusionConfig, GestureDiffusion

    flow, normaliser, _ = load_run(moglow_run)
    torch.manual_seed(0)
    diffusion = GestureDiffusion(DiffusionConfig.quick()).eval()
    clips = {"held-out": Clip.from_conversation(short_windows[0], start_s=1.0, seconds=4.0)}
    both = Explorer({"moglow": (flow, normaliser), "diffusion": (diffusion, normaliser)}, clips)
    both.model.value, both.truth.value, both.seed.value = "diffusion", False, 2
    take = both.render()
    assert take.titles == ("diffusion",) and take.motions.shape == (1, 4 * FPS, 9, 3)
    assert np.isfinite(take.motions).all()
    np.testing.assert_array_equal(both.render().motions, take.motions)
