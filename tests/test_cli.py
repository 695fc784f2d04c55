import json

import numpy as np
import pytest

from gesturelib.cli import OUTPUT_MARKER, main
from gesturelib.features import load_audio


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
    assert main(["demo", "--out", str(demo_folder), "--seconds", "2"]) == 0


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
