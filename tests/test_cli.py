import json

import numpy as np
import pytest

from gesturelib.checkpoints import VERSION
from gesturelib.cli import main
from gesturelib.features import load_audio
from gesturelib.outputs import MARKER as OUTPUT_MARKER


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    assert main(["demo", "--out", str(out), "--seconds", "4", "--seed", "3"]) == 0
    return out


def test_demo_writes_a_video_with_sound_pictures_and_the_raw_files(demo_folder):
    names = {path.name for path in demo_folder.iterdir()}
    assert {"agent.mp4", "timeline.png", "poses.png", OUTPUT_MARKER} <= names
    assert {"conversation.wav", "conversation.npz", "conversation.json"} <= names
    assert (demo_folder / "agent.mp4").stat().st_size > 10_000
    audio, rate = load_audio(demo_folder / "conversation.wav")
    assert rate == 16_000 and abs(audio.size / rate - 4.0) < 0.05 and np.abs(audio).max() > 0.01
    json.loads((demo_folder / "conversation.json").read_text())


def test_demo_runs_again_into_its_own_folder(demo_folder):
    assert main(["demo", "--out", str(demo_folder), "--seconds", "4.5", "--seed", "3"]) == 0


def test_demo_never_writes_into_a_folder_of_other_files(tmp_path, capsys):
    precious = tmp_path / "thesis.tex"
    precious.write_text("three years of work")
    assert main(["demo", "--out", str(tmp_path), "--seconds", "2"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert precious.read_text() == "three years of work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["thesis.tex"]


def test_demo_rejects_a_non_positive_length(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "out"), "--seconds", "0"]) == 2
    assert "--seconds must be positive" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# train, generate, info: one small MoGlow trained once on a tiny dataset
# ---------------------------------------------------------------------------------------------


def test_train_writes_a_run_folder_that_info_describes(moglow_run, capsys):
    assert {"best.pt", "last.pt", "run.json"} <= {p.name for p in moglow_run.iterdir()}
    summary = json.loads((moglow_run / "run.json").read_text())
    assert summary["model"] == "moglow" and summary["quick"] and summary["version"] == VERSION
    assert main(["info", str(moglow_run)]) == 0
    described = capsys.readouterr().out
    assert "MoGlow (" in described and "parameters" in described and "best epoch" in described


def test_train_refuses_a_folder_in_use_and_resumes_or_replaces_only_when_asked(
    moglow_run, tiny_data, tmp_path, capsys
):
    again = ["train", "moglow", "--out", str(moglow_run), "--quick", "--data", str(tiny_data)]
    assert main(again) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--resume" in error and "--overwrite" in error
    before = (moglow_run / "best.pt").read_bytes()
    assert main([*again, "--resume"]) == 0  # finished: nothing more to train
    assert (moglow_run / "best.pt").read_bytes() == before
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert (
        main(
            ["train", "cvae", "--out", str(other), "--quick", "--data", str(tiny_data), "--resume"]
        )
        == 2
    )
    assert "no run to resume" in capsys.readouterr().err
    assert (
        main(
            [
                "train",
                "cvae",
                "--out",
                str(other),
                "--quick",
                "--data",
                str(tiny_data),
                "--overwrite",
            ]
        )
        == 0
    )
    assert (other / "notes.txt").read_text() == "mine"  # --overwrite replaces the run's files only


def write_wav(path, seconds=3.0, seed=2):
    from data_synth import generate_conversation
    from gesturelib.features import save_audio

    conversation = generate_conversation(max(seconds, 5.0), seed=seed)
    samples = int(seconds * conversation.sample_rate)
    save_audio(path, conversation.audio[:samples], conversation.sample_rate)
    return samples


def test_generate_from_a_wav_writes_the_motion_of_every_frame(moglow_run, tmp_path):
    samples = write_wav(tmp_path / "speech.wav", seconds=2.5)
    out = tmp_path / "out"
    args = ["generate", str(moglow_run), "--audio", str(tmp_path / "speech.wav"), "--out", str(out)]
    assert main([*args, "--no-video", "--samples", "2"]) == 0
    frames = samples * 25 // 16_000
    for number in (1, 2):
        motion = np.load(out / f"sample-{number}" / "motion.npz")
        assert motion["rotations"].shape == (frames, 9, 6)
        assert motion["positions"].shape == (frames, 9, 3)
        assert motion["activity"].shape == (frames,) and int(motion["fps"]) == 25
    first = np.load(out / "sample-1" / "motion.npz")["rotations"]
    assert not np.array_equal(first, np.load(out / "sample-2" / "motion.npz")["rotations"])
    # a new process, the same seed: the same motion
    import subprocess
    import sys

    again = tmp_path / "again"
    command = [
        sys.executable,
        "-m",
        "gesturelib",
        *args[:-1],
        str(again),
        "--no-video",
        "--samples",
        "2",
    ]
    subprocess.run(command, check=True, capture_output=True)
    np.testing.assert_array_equal(np.load(again / "sample-1" / "motion.npz")["rotations"], first)


def test_generate_hears_the_partner_and_writes_a_bvh(moglow_run, tmp_path, capsys):
    from data_synth import generate_conversation
    from gesturelib.conventions import Activity
    from gesturelib.features import save_audio

    samples = write_wav(tmp_path / "agent.wav", seconds=3.0)
    partner = generate_conversation(5.0, seed=9).audio[:samples]
    partner[: samples // 2] = 0.0  # the partner speaks in the second half only
    save_audio(tmp_path / "partner.wav", partner, 16_000)
    out = tmp_path / "out"
    args = ["generate", str(moglow_run), "--audio", str(tmp_path / "agent.wav"), "--out", str(out)]
    assert main([*args, "--partner", str(tmp_path / "partner.wav"), "--no-video"]) == 0
    activity = np.load(out / "motion.npz")["activity"]
    assert {Activity.B_SPEAKS, Activity.BOTH} & set(activity[len(activity) // 2 :].tolist())
    assert not {Activity.B_SPEAKS, Activity.BOTH} & set(activity[: len(activity) // 3].tolist())
    assert (out / "agent.bvh").read_text().startswith("HIERARCHY")
    save_audio(tmp_path / "short.wav", partner[: samples // 2], 16_000)
    cases = (
        [*args[:-1], str(tmp_path / "a"), "--partner", str(tmp_path / "short.wav")],
        ["generate", str(moglow_run), "--conversation", "x", "--partner", "y", "--out", "z"],
    )
    for case, message in zip(cases, ("the agent's length", "goes with --audio"), strict=True):
        assert main(case) == 2
        assert message in capsys.readouterr().err


def test_generate_takes_a_stereo_recording_at_any_rate(moglow_run, tmp_path):
    """A 44.1 kHz stereo FLAC (speech on the left channel only) is down-mixed and resampled."""
    import librosa
    import soundfile

    from data_synth import generate_conversation

    speech = generate_conversation(5.0, seed=4).audio[:32_000]  # 2 s at 16 kHz
    left = librosa.resample(speech, orig_sr=16_000, target_sr=44_100)
    soundfile.write(tmp_path / "stereo.flac", np.stack([left, np.zeros_like(left)], 1), 44_100)
    out = tmp_path / "out"
    command = ["generate", str(moglow_run), "--audio", str(tmp_path / "stereo.flac")]
    assert main([*command, "--out", str(out), "--no-video"]) == 0
    assert np.load(out / "motion.npz")["rotations"].shape == (50, 9, 6)  # 2 s at 25 fps


def test_generate_makes_a_video_with_sound_from_a_conversation(moglow_run, tiny_data, tmp_path):
    stem = next((tiny_data / "test").glob("*.wav")).with_suffix("")
    out = tmp_path / "video"
    assert main(["generate", str(moglow_run), "--conversation", str(stem), "--out", str(out)]) == 0
    assert (out / "agent.mp4").stat().st_size > 10_000 and (out / "motion.npz").exists()


def test_generate_refuses_bad_input_in_one_line(moglow_run, tiny_data, tmp_path, capsys):
    short = tmp_path / "click.wav"
    from gesturelib.features import save_audio

    save_audio(short, np.zeros(100, np.float32), 16_000)
    cases = [
        ["generate", str(moglow_run), "--audio", str(short), "--out", str(tmp_path / "a")],
        [
            "generate",
            str(tmp_path / "nowhere"),
            "--audio",
            str(short),
            "--out",
            str(tmp_path / "b"),
        ],
        [
            "generate",
            str(moglow_run),
            "--audio",
            str(tmp_path / "missing.wav"),
            "--out",
            str(tmp_path / "c"),
        ],
        [
            "generate",
            str(moglow_run),
            "--audio",
            str(short),
            "--out",
            str(tmp_path / "d"),
            "--style",
            "hand_height=85",
        ],
        [
            "generate",
            str(moglow_run),
            "--audio",
            str(short),
            "--out",
            str(tmp_path / "e"),
            "--temperature",
            "-1",
        ],
    ]
    for case in cases:
        assert main(case) == 2, case
        error = capsys.readouterr().err
        assert error.startswith("gesturelib generate: error:") and error.count("\n") == 1, error


def test_generate_refuses_a_run_of_a_model_that_does_not_generate(tiny_data, tmp_path, capsys):
    run = tmp_path / "dae"
    assert (
        main(["train", "motion_dae", "--out", str(run), "--quick", "--data", str(tiny_data)]) == 0
    )
    write_wav(tmp_path / "speech.wav")
    assert (
        main(
            [
                "generate",
                str(run),
                "--audio",
                str(tmp_path / "speech.wav"),
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert "does not generate motion" in capsys.readouterr().err


def test_train_into_a_folder_it_cannot_make_says_so_in_one_line(tiny_data, tmp_path, capsys):
    blocker = tmp_path / "notes.txt"
    blocker.write_text("a file where a folder would be needed")
    out = blocker / "run"
    assert main(["train", "aud2pose", "--out", str(out), "--quick", "--data", str(tiny_data)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert blocker.read_text() == "a file where a folder would be needed"


@pytest.mark.parametrize("model", ["flowvae", "flowvae_elbo"])
def test_the_flowvaes_train_generate_and_describe_themselves(model, tiny_data, tmp_path, capsys):
    run = tmp_path / model
    options = ["--quick", "--data", str(tiny_data), "--cache", str(tmp_path / "cache")]
    assert main(["train", model, "--out", str(run), *options]) == 0
    assert main(["info", str(run)]) == 0
    expected = {"flowvae": "FlowVAE (", "flowvae_elbo": "VariationalFlowVAE ("}[model]
    described = capsys.readouterr().out
    assert expected in described
    # the Flow-VAE keeps the best-judged of its last epochs; the FGD's network is in --cache
    judged = model == "flowvae"
    assert ("FGD of its motion generated for the validation conversations" in described) == judged
    assert any((tmp_path / "cache").glob("MotionFeatureNetwork-*/best.pt")) == judged
    samples = write_wav(tmp_path / "speech.wav", seconds=1.5)
    motions = []
    for out in ("a", "b"):
        folder = tmp_path / out
        args = ["generate", str(run), "--audio", str(tmp_path / "speech.wav"), "--out", str(folder)]
        assert main([*args, "--no-video", "--seed", "3"]) == 0
        motions.append(np.load(folder / "motion.npz")["rotations"])
    assert motions[0].shape == (samples * 25 // 16_000, 9, 6)
    np.testing.assert_array_equal(*motions)


def test_usage_mistakes_are_one_line_naming_the_option(moglow_run, tmp_path, capsys):
    write_wav(tmp_path / "speech.wav")
    generate = ["generate", str(moglow_run), "--audio", str(tmp_path / "speech.wav")]
    for args, message in [
        (
            ["train", "moglow", "--out", str(tmp_path / "r"), "--threads", "0"],
            "--threads: must be at least 1",
        ),
        ([*generate, "--out", str(tmp_path / "o"), "--seed", "-1"], "--seed: must be at least 0"),
        (
            [*generate, "--out", str(tmp_path / "o"), "--samples", "0"],
            "--samples: must be at least 1",
        ),
    ]:
        with pytest.raises(SystemExit) as exit_status:
            main(args)
        assert exit_status.value.code == 2
        error = capsys.readouterr().err
        assert message in error and error.count("\n") == 1, error


@pytest.mark.skipif(
    __import__("torch").cuda.is_available(), reason="needs a machine without a CUDA GPU"
)
def test_generate_on_a_missing_gpu_says_so_in_one_line(moglow_run, tmp_path, capsys):
    write_wav(tmp_path / "speech.wav")
    args = ["generate", str(moglow_run), "--audio", str(tmp_path / "speech.wav")]
    assert main([*args, "--out", str(tmp_path / "o"), "--device", "cuda"]) == 2
    error = capsys.readouterr().err
    assert "no CUDA GPU is available here" in error and error.count("\n") == 1


def test_generate_refuses_a_recording_without_speech(moglow_run, tmp_path, capsys):
    from gesturelib.features import save_audio

    save_audio(tmp_path / "silence.wav", np.zeros(16_000, dtype=np.float32), 16_000)
    args = ["generate", str(moglow_run), "--audio", str(tmp_path / "silence.wav")]
    assert main([*args, "--out", str(tmp_path / "o")]) == 2
    error = capsys.readouterr().err
    assert "holds no speech" in error and error.count("\n") == 1


def test_demo_draws_a_new_conversation_unless_given_a_seed(tmp_path, capsys):
    seeds, audio = [], []
    for args in ([], [], ["--seed", None]):
        out = tmp_path / f"demo-{len(audio)}"
        args = [a if a is not None else str(seeds[0]) for a in args]
        assert main(["demo", "--out", str(out), "--seconds", "4.5", *args]) == 0
        seeds.append(int(capsys.readouterr().out.split("(seed ")[1].split(";")[0]))
        audio.append(load_audio(out / "conversation.wav")[0])
    assert seeds[2] == seeds[0]  # the printed seed draws the conversation again
    np.testing.assert_array_equal(audio[2], audio[0])
    assert (seeds[0] == seeds[1]) == np.array_equal(audio[0], audio[1])


def test_torchrun_trains_in_two_processes_into_a_run_folder_that_generates(tiny_data, tmp_path):
    """``torchrun --nproc_per_node=2 -m gesturelib train``: one run folder, written once (by
    process 0, which also judges the Flow-VAE's last epochs), that the other commands take like
    any other."""
    import subprocess
    import sys

    from gesturelib.checkpoints import read_checkpoint

    run = tmp_path / "flowvae-two"
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2"]
    command += ["-m", "gesturelib", "train", "flowvae", "--quick", "--data", str(tiny_data)]
    command += ["--cache", str(tmp_path / "cache")]
    done = subprocess.run(
        [*command, "--out", str(run)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.count("Trained flowvae") == 1  # process 0 alone reports
    assert {p.name for p in run.iterdir()} == {"best.pt", "last.pt", "run.json"}
    history = read_checkpoint(run / "best.pt")["history"]
    assert set(history["judged"]) == {2, 3} and history["best_epoch"] in history["judged"]
    stem = next((tiny_data / "test").glob("*.wav")).with_suffix("")
    out = tmp_path / "generated"
    command = ["generate", str(run), "--conversation", str(stem), "--out", str(out), "--no-video"]
    assert main(command) == 0
    assert np.isfinite(np.load(out / "motion.npz")["positions"]).all()
