"""The cases of a bad-input probe that lost files, answered silently wrong, hung or answered
unclearly, each reproduced: the command line and the public API now refuse them in one line that
names the file or option, and change nothing on disk before every check has passed."""

import errno
import json
import shutil
import wave

import numpy as np
import pytest
import soundfile
import torch

from gesturelib.cli import main
from gesturelib.features import AudioError, load_audio, save_audio, who_is_talking

RATE = 16_000


def one_line_error(capsys, command: str) -> str:
    error = capsys.readouterr().err
    assert error.startswith(f"gesturelib {command}: error:") and error.count("\n") == 1, error
    return error


def speech(seconds: float = 3.0, seed: int = 2) -> np.ndarray:
    from data_synth import generate_conversation

    conversation = generate_conversation(max(seconds, 5.0), seed=seed)
    return conversation.audio[: int(seconds * conversation.sample_rate)]


# --------------------------------------------------------------------------- losses of files


@pytest.fixture
def finished_run(moglow_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(moglow_run, run)
    return run


@pytest.mark.parametrize(
    "bad", [["--data", "/nonexistent"], ["--device", "cuda"], ["--device", "meta"]]
)
def test_train_overwrite_with_a_bad_option_keeps_the_run(finished_run, tiny_data, bad, capsys):
    if bad == ["--device", "cuda"] and torch.cuda.is_available():
        pytest.skip("a CUDA GPU is here")
    before = {p.name: p.read_bytes() for p in finished_run.iterdir() if p.is_file()}
    command = ["train", "moglow", "--out", str(finished_run), "--quick", "--overwrite"]
    data = [] if bad[0] == "--data" else ["--data", str(tiny_data)]
    assert main([*command, *data, *bad]) == 2
    one_line_error(capsys, "train")
    assert {p.name: p.read_bytes() for p in finished_run.iterdir() if p.is_file()} == before


def test_train_overwrite_leaves_a_folder_of_the_users_alone(tiny_data, tmp_path):
    run = tmp_path / "dae"
    (run / "autoencoder").mkdir(parents=True)
    (run / "autoencoder" / "my_notes.txt").write_text("mine")
    command = ["train", "motion_dae", "--out", str(run), "--quick", "--data", str(tiny_data)]
    assert main([*command, "--overwrite"]) == 0
    assert (run / "autoencoder" / "my_notes.txt").read_text() == "mine"


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "speech.wav"
    save_audio(path, speech(2.0), RATE)
    return path


def generate(run, recording, out, *extra) -> int:
    return main(["generate", str(run), "--audio", str(recording), "--out", str(out), *extra])


def test_generate_never_replaces_a_file_a_person_changed(moglow_run, recording, tmp_path, capsys):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--no-video") == 0
    (out / "agent.bvh").write_text("my edit")
    assert generate(moglow_run, recording, out, "--no-video", "--seed", "2") == 2
    assert "agent.bvh" in one_line_error(capsys, "generate")
    assert (out / "agent.bvh").read_text() == "my edit"
    assert generate(moglow_run, recording, out, "--no-video", "--overwrite") == 0
    assert (out / "agent.bvh").read_text().startswith("HIERARCHY")


def test_generate_refuses_a_users_file_inside_a_sample_folder(
    moglow_run, recording, tmp_path, capsys
):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--no-video", "--samples", "2") == 0
    np.savez(out / "sample-1" / "motion.npz", mine=np.ones(3))
    assert generate(moglow_run, recording, out, "--no-video", "--samples", "2") == 2
    assert "sample-1/motion.npz" in one_line_error(capsys, "generate")
    assert "mine" in np.load(out / "sample-1" / "motion.npz")


def test_generate_replaces_its_earlier_output_as_one_set(moglow_run, recording, tmp_path):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--samples", "3") == 0
    assert (out / "sample-3" / "agent.mp4").exists()
    assert generate(moglow_run, recording, out, "--no-video") == 0
    names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert names == [".gesturelib-output", "agent.bvh", "motion.npz"]  # no stale video or samples


def test_a_full_disk_names_the_file_and_changes_nothing(
    moglow_run, recording, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--no-video") == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("gesturelib.bvh.os.replace", full)
    assert generate(moglow_run, recording, out, "--no-video", "--seed", "5") == 2
    error = one_line_error(capsys, "generate")
    assert "agent.bvh" in error and "disk is full" in error
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing partial left


def test_write_bvh_refuses_to_replace_a_file_and_an_impossible_frame_rate(tmp_path):
    from gesturelib.bvh import write_bvh

    rest = np.tile(np.array([1.0, 0, 0, 0, 1, 0]), (3, 9, 1))
    mine = tmp_path / "mine.bvh"
    mine.write_text("my file")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_bvh(mine, rest)
    assert mine.read_text() == "my file"
    for fps in (float("nan"), float("inf"), "25", 0.5):
        with pytest.raises(ValueError, match="fps must be a finite number"):
            write_bvh(tmp_path / "x.bvh", rest, fps=fps)
    with pytest.raises(ValueError, match="rotations must be numbers"):
        write_bvh(tmp_path / "x.bvh", np.full((3, 9, 6), "a"))
    assert not (tmp_path / "x.bvh").exists()


# --------------------------------------------------------------------------- audio


def tone(kind: str, seconds: float = 5.0) -> np.ndarray:
    t = np.arange(int(seconds * RATE)) / RATE
    rng = np.random.default_rng(0)
    signals = {
        "white noise": 0.1 * rng.standard_normal(t.size),
        "a 440 Hz sine": 0.5 * np.sin(2 * np.pi * 440 * t),
        "a square wave": np.clip(3 * np.sin(2 * np.pi * 200 * t), -0.5, 0.5),
        "a DC offset": np.full(t.size, 0.5),
    }
    return signals[kind].astype(np.float32)


@pytest.mark.parametrize("kind", ["white noise", "a 440 Hz sine", "a square wave", "a DC offset"])
def test_a_steady_sound_is_not_speech(kind, moglow_run, tmp_path, capsys):
    with pytest.raises(AudioError, match="steady sound|holds no speech"):
        who_is_talking(tone(kind), RATE)
    save_audio(tmp_path / "steady.wav", tone(kind), RATE)
    assert generate(moglow_run, tmp_path / "steady.wav", tmp_path / "out") == 2
    assert "steady.wav" in one_line_error(capsys, "generate")
    assert not (tmp_path / "out").exists()


def test_speech_is_still_speech_with_a_dc_offset_and_in_every_committed_voice(pytestconfig):
    voiced = who_is_talking(speech(5.0) + np.float32(0.2), RATE)
    assert 0.2 < np.mean(voiced != 0) < 1.0
    for path in sorted((pytestconfig.rootpath / "tests" / "data" / "voices").glob("*.flac")):
        audio, rate = load_audio(path)
        assert np.mean(who_is_talking(audio, rate) != 0) > 0.2, path.name


def test_a_clip_too_short_to_hear_says_so():
    with pytest.raises(AudioError, match="lasts 40 ms, too short"):
        who_is_talking(speech(1.0)[: int(0.04 * RATE)], RATE)


def test_a_header_claiming_an_impossible_rate_is_refused_before_resampling(tmp_path):
    path = tmp_path / "one_hertz.wav"
    with wave.open(str(path), "wb") as file:
        file.setnchannels(1)
        file.setsampwidth(2)
        file.setframerate(1)
        file.writeframes(np.zeros(16_000, np.int16).tobytes())
    with pytest.raises(AudioError, match="sample rate of 1 Hz"):
        load_audio(path)


def test_channels_that_cancel_out_are_named(tmp_path):
    voice = speech(2.0)
    path = tmp_path / "antiphase.wav"
    soundfile.write(path, np.stack([voice, -voice], axis=1), RATE, subtype="FLOAT")
    with pytest.raises(AudioError, match="channels cancel out"):
        load_audio(path)


@pytest.mark.parametrize("path", [3, None, b"speech.wav"])
def test_load_audio_names_a_path_of_the_wrong_type(path):
    with pytest.raises(TypeError, match="path must be a file path"):
        load_audio(path)


def test_a_long_stereo_recording_is_read_in_blocks_like_a_short_one(tmp_path, monkeypatch):
    import gesturelib.features as features

    voice = speech(4.0)
    path = tmp_path / "stereo.wav"
    soundfile.write(path, np.stack([voice, 0.5 * voice], axis=1), RATE)
    whole = load_audio(path, 22_050)[0]
    monkeypatch.setattr(features, "_BLOCK_S", 0.25)  # sixteen blocks
    np.testing.assert_array_equal(load_audio(path, 22_050)[0], whole)


# --------------------------------------------------------------------------- sampling


@pytest.fixture(scope="module")
def shipped():
    from gesturelib.pretrained import load_run, pretrained_folder

    model, normaliser, _ = load_run(pretrained_folder("moglow"))
    return model, normaliser


def features_of(seconds=2.0):
    from gesturelib.features import speech_features

    audio = speech(seconds)
    return speech_features(audio, RATE), who_is_talking(audio, RATE)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s: s * 1e30, "far outside the range of speech features"),
        (lambda s: s - 12.0, "looks like a raw log-mel spectrogram"),
        (lambda s: np.where(np.arange(len(s))[:, None] == 3, np.nan, s), "frame 3"),
    ],
)
def test_sampling_refuses_what_cannot_be_speech_features(shipped, change, message):
    from gesturelib.sampling import generate

    speech_frames, activity = features_of()
    with pytest.raises(ValueError, match=message):
        generate(*shipped, change(speech_frames), activity)


@pytest.mark.parametrize("temperature", [1e9, 1e300, 3.5])
def test_a_temperature_beyond_three_is_refused_with_its_range(shipped, temperature):
    from gesturelib.sampling import generate

    speech_frames, activity = features_of()
    with pytest.raises(ValueError, match=r"temperature must lie in \[0, 3\]"):
        generate(*shipped, speech_frames, activity, temperature=temperature)


def test_style_is_refused_for_a_model_without_style_inputs(shipped):
    from gesturelib.sampling import Stream

    model, normaliser = shipped
    assert not model.config.style
    with pytest.raises(ValueError, match="trained without style inputs"):
        Stream(model, normaliser, style=normaliser.style_at_percentiles({}))


def test_style_far_beyond_the_training_values_is_refused(short_windows, trained_looking):
    from gesturelib.models import MoGlowConfig
    from gesturelib.sampling import Stream

    _, normaliser, batch, _ = short_windows
    config = MoGlowConfig.quick(speech_past=2, speech_future=3, past_poses=2, style=True)
    model = trained_looking(config, normaliser, batch)
    style = normaliser.style_at_percentiles({})
    Stream(model, normaliser, style=style)  # the median is fine
    with pytest.raises(ValueError, match="far outside the training values"):
        Stream(model, normaliser, style=style + np.array([1e9, 0, 0, 0]))
    with pytest.raises(ValueError, match="finite numbers"):
        Stream(model, normaliser, style=[np.nan, 0, 0, 0])


def test_a_finished_stream_takes_no_more_speech(shipped):
    from gesturelib.sampling import Stream

    speech_frames, activity = features_of()
    stream = Stream(*shipped, seed=0)
    stream.push(speech_frames, activity)
    stream.finish()
    with pytest.raises(RuntimeError, match="finished"):
        stream.push(speech_frames, activity)
    with pytest.raises(RuntimeError, match="finished"):
        stream.finish()


@pytest.mark.parametrize("bad", ["model", "normaliser"])
def test_a_stream_names_a_missing_model_or_normaliser(shipped, bad):
    from gesturelib.sampling import Stream

    model, normaliser = shipped
    with pytest.raises(TypeError, match=bad):
        Stream(None if bad == "model" else model, None if bad == "normaliser" else normaliser)


# --------------------------------------------------------------------------- run folders


def damaged_copy(run, tmp_path, change):
    copy = tmp_path / "damaged"
    shutil.copytree(run, copy)
    checkpoint = torch.load(copy / "best.pt", weights_only=True)
    change(checkpoint)
    torch.save(checkpoint, copy / "best.pt")
    return copy


def drop(key):
    return lambda checkpoint: checkpoint.pop(key)


def nan_weights(checkpoint):
    for value in checkpoint["model"].values():
        if value.is_floating_point():
            value.fill_(float("nan"))


@pytest.mark.parametrize(
    "change",
    [
        lambda c: c["normaliser"].pop("pose_mean"),
        lambda c: c["normaliser"]["pose_std"].__setitem__(0, 0.0),
        lambda c: c.__setitem__("normaliser", [1, 2]),
        lambda c: c.__setitem__("history", {"bogus": 1}),
        lambda c: c.__setitem__("history", None),
        drop("score"),
        lambda c: c.__setitem__("score", "low"),
        nan_weights,
    ],
    ids=[
        "normaliser-key",
        "normaliser-std",
        "normaliser-list",
        "history-bad",
        "history-none",
        "no-score",
        "score-str",
        "nan-weights",
    ],
)
@pytest.mark.parametrize("command", ["info", "generate"])
def test_a_damaged_checkpoint_is_named(moglow_run, recording, tmp_path, capsys, change, command):
    run = damaged_copy(moglow_run, tmp_path, change)
    args = [str(run)] if command == "info" else [str(run), "--audio", str(recording)]
    out = [] if command == "info" else ["--out", str(tmp_path / "out")]
    assert main([command, *args, *out]) == 2
    assert "best.pt" in one_line_error(capsys, command)


@pytest.mark.parametrize(
    "contents", ["[1, 2]", "{bad json", b"\xff\xfe", '{"data": 3}', '{"data": ["a"]}']
)
@pytest.mark.parametrize("command", ["info", "evaluate"])
def test_a_damaged_run_json_is_named(moglow_run, tmp_path, capsys, contents, command):
    run = tmp_path / "run"
    shutil.copytree(moglow_run, run)
    summary = run / "run.json"
    summary.write_bytes(contents) if isinstance(contents, bytes) else summary.write_text(contents)
    out = [] if command == "info" else ["--out", str(tmp_path / "out"), "--quick"]
    assert main([command, str(run), *out]) == 2
    assert "run.json" in one_line_error(capsys, command)


def test_evaluate_refuses_two_copies_of_one_run(moglow_run, tmp_path, capsys):
    copies = [tmp_path / "moglow-1", tmp_path / "moglow-2"]
    for copy in copies:
        shutil.copytree(moglow_run, copy)
    command = ["evaluate", *map(str, copies), "--out", str(tmp_path / "out"), "--quick"]
    assert main(command) == 2
    assert "same trained model" in one_line_error(capsys, "evaluate")


def test_evaluate_names_a_cache_that_is_a_file(moglow_run, tmp_path, capsys):
    cache = tmp_path / "cache.txt"
    cache.write_text("not a folder")
    out = ["--out", str(tmp_path / "out"), "--quick", "--cache", str(cache)]
    assert main(["evaluate", str(moglow_run), *out]) == 2
    assert "--cache" in one_line_error(capsys, "evaluate")


def test_a_conversation_given_with_its_extension_is_told_the_stem(
    moglow_run, tiny_data, tmp_path, capsys
):
    wav = next((tiny_data / "test").glob("*.wav"))
    command = ["generate", str(moglow_run), "--conversation", str(wav), "--out", str(tmp_path)]
    assert main(command) == 2
    assert str(wav.with_suffix("")) in one_line_error(capsys, "generate")


def test_a_file_name_starting_with_a_dash_gets_advice(moglow_run, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["generate", str(moglow_run), "--audio", "-take1.wav", "--out", "x"])
    assert exit_.value.code == 2
    assert "needs ./ before it" in capsys.readouterr().err


def test_an_interrupted_train_says_to_resume(tiny_data, tmp_path, capsys, monkeypatch):
    import gesturelib.train as training

    run = tmp_path / "run"
    real = training._Run.end_epoch

    def interrupt_after_the_first_epoch(self, *args, **kwargs):
        real(self, *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(training._Run, "end_epoch", interrupt_after_the_first_epoch)
    assert main(["train", "cvae", "--out", str(run), "--quick", "--data", str(tiny_data)]) == 130
    assert "--resume" in capsys.readouterr().err
    monkeypatch.setattr(training._Run, "end_epoch", real)
    command = ["train", "cvae", "--out", str(run), "--quick", "--data", str(tiny_data)]
    assert main([*command, "--resume"]) == 0


# --------------------------------------------------------------------------- the generator


def test_a_dataset_too_large_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    from data_synth import ConfigError, write_dataset
    from data_synth.__main__ import main as data_synth

    big = ["--minutes", "99990", "--conversation-seconds", "600", "--out", str(tmp_path / "big")]
    assert data_synth(big) == 2
    assert "600 minutes" in capsys.readouterr().err
    free = shutil.disk_usage(tmp_path)._replace(free=10_000_000)
    monkeypatch.setattr("data_synth.dataset.shutil.disk_usage", lambda _: free)
    with pytest.raises(ConfigError, match="MB free"):
        write_dataset(tmp_path / "data", minutes=30, seed=0, progress=False)
    assert not (tmp_path / "data").exists() and not (tmp_path / "big").exists()


def test_the_output_record_lists_what_was_written(moglow_run, recording, tmp_path):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--no-video") == 0
    record = json.loads((out / ".gesturelib-output").read_text())
    assert record["command"] == "generate" and set(record["files"]) == {"motion.npz", "agent.bvh"}


# --------------------------------------------------------------------------- the explorer


def test_the_explorer_names_what_is_wrong_with_its_inputs(shipped):
    from gesturelib.widgets import Clip, Explorer, wav_data_url

    audio = speech(2.0)
    activity = who_is_talking(audio, RATE)
    clip = Clip(audio, RATE, activity)
    with pytest.raises(TypeError, match="must be a \\(model, normaliser\\) pair"):
        Explorer({"moglow": shipped[0]}, {"clip": clip})
    with pytest.raises(ValueError, match="truth must be \\(T, 9, 3\\)"):
        Clip(audio, RATE, activity, truth=np.zeros((3, 9, 3)))
    with pytest.raises(ValueError, match="finite"):
        wav_data_url(np.full(100, np.nan, np.float32), RATE)
    from data_synth import generate_conversation

    with pytest.raises(ValueError, match="must be finite"):
        Clip.from_conversation(generate_conversation(5.0, seed=1), start_s=float("nan"))


def test_a_second_training_run_in_one_folder_is_told_another_is_writing(
    tiny_data, tmp_path, capsys
):
    import fcntl

    run = tmp_path / "run"
    run.mkdir()
    command = ["train", "cvae", "--out", str(run), "--quick", "--data", str(tiny_data)]
    with open(run / ".lock", "w") as held:  # another run holds the folder
        held.write("4242")
        held.flush()
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        assert main([*command, "--overwrite"]) == 2
        assert "process 4242 is writing" in one_line_error(capsys, "train")
    # a lock file left by a run that died holds no lock: the next run takes the folder
    assert main([*command, "--overwrite"]) == 0
    assert not (run / ".lock").exists()


def test_an_output_record_cannot_reach_outside_its_folder(tmp_path):
    from gesturelib.outputs import MARKER, OutputError, OutputFolder

    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    out = tmp_path / "out"
    out.mkdir()
    record = {"command": "generate", "files": {"../victim.txt": "0" * 64}}
    (out / MARKER).write_text(json.dumps(record))
    folder = OutputFolder(out, "generate")
    with folder.staging() as stage:
        stage.path("motion.npz").write_text("new")
    assert victim.read_text() == "mine"
    (out / "motion.npz").write_text("changed by hand")
    with pytest.raises(OutputError, match="motion.npz"):
        OutputFolder(out, "generate")


def test_overwrite_never_removes_an_earlier_file_a_person_changed(moglow_run, recording, tmp_path):
    out = tmp_path / "out"
    assert generate(moglow_run, recording, out, "--no-video", "--samples", "2") == 0
    (out / "sample-2" / "agent.bvh").write_text("my edit")
    shutil.rmtree(out / "sample-1")  # and a folder of the earlier run is gone
    assert generate(moglow_run, recording, out, "--no-video", "--overwrite") == 0
    assert (out / "sample-2" / "agent.bvh").read_text() == "my edit"
    assert not (out / "sample-2" / "motion.npz").exists()  # the unchanged stale file went
    assert generate(moglow_run, recording, out, "--no-video", "--seed", "3") == 2  # the edit


def test_generate_refuses_activity_of_another_length(shipped):
    from gesturelib.sampling import generate as sample

    speech_frames, activity = features_of()
    with pytest.raises(ValueError, match="one per speech frame"):
        sample(*shipped, speech_frames, np.concatenate([activity, activity]))


def test_a_folder_written_before_records_is_taken_as_the_commands_own(
    moglow_run, recording, tmp_path
):
    out = tmp_path / "out"
    out.mkdir()
    (out / ".gesturelib-output").write_text(
        "This folder was written by `python -m gesturelib generate`.\n"
    )
    (out / "agent.mp4").write_bytes(b"an old video")
    assert generate(moglow_run, recording, out, "--no-video") == 0
    assert not (out / "agent.mp4").exists()  # the old run's video went with it


def test_a_folder_in_place_of_the_output_record_is_named(moglow_run, recording, tmp_path, capsys):
    out = tmp_path / "out"
    (out / ".gesturelib-output").mkdir(parents=True)
    assert generate(moglow_run, recording, out, "--no-video") == 2
    assert ".gesturelib-output is not a file" in one_line_error(capsys, "generate")


def test_a_negative_seed_is_named(shipped):
    from gesturelib.sampling import generate as sample

    speech_frames, activity = features_of()
    with pytest.raises(ValueError, match="seed must be a non-negative integer, got -1"):
        sample(*shipped, speech_frames, activity, seed=-1)


def test_a_model_whose_weights_blow_up_is_named(moglow_run, recording, tmp_path, capsys):
    def huge(checkpoint):
        for value in checkpoint["model"].values():
            if value.is_floating_point():
                value.mul_(1e4)

    run = damaged_copy(moglow_run, tmp_path, huge)
    assert generate(run, recording, tmp_path / "out", "--no-video") == 2
    error = one_line_error(capsys, "generate")
    assert str(run) in error and "NaN or infinite" in error
