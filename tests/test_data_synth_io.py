"""Tests of data_synth's files: a conversation's save/load, and the dataset on disk and its CLI."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from data_synth import (
    DatasetError,
    ensure_dataset,
    generate_conversation,
    load_conversation,
    load_dataset,
    load_split,
    read_manifest,
    save_conversation,
    write_dataset,
)
from data_synth.__main__ import main
from data_synth.dataset import SPLITS

REPOSITORY = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def conversation():
    return generate_conversation(8.0, seed=5, motion_seed=6)


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    """A tiny dataset: 0.3 minutes in 6-second conversations (one per split)."""
    out = tmp_path_factory.mktemp("data") / "synthetic"
    assert (
        main(
            [
                "--out",
                str(out),
                "--minutes",
                "0.3",
                "--seed",
                "2",
                "--conversation-seconds",
                "6",
                "--no-progress",
            ]
        )
        == 0
    )
    return out


# --------------------------------------------------------------------------- one conversation


def test_save_and_load_round_trip(conversation, tmp_path):
    written = save_conversation(conversation, tmp_path / "talk")
    assert sorted(p.name for p in written) == ["talk.json", "talk.npz", "talk.wav"]
    loaded = load_conversation(tmp_path / "talk")
    np.testing.assert_allclose(loaded.audio, conversation.audio, atol=1.01 / 32768)  # 16-bit
    for name in ("activity", "rotations", "positions"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(conversation, name))
    assert loaded.events == conversation.events
    assert loaded.style == conversation.style and loaded.voices == conversation.voices
    assert loaded.config == conversation.config
    assert (loaded.conversation_seed, loaded.motion_seed) == (5, 6)
    assert (loaded.sample_rate, loaded.fps) == (conversation.sample_rate, conversation.fps)
    metadata = json.loads((tmp_path / "talk.json").read_text())  # readable by a person
    assert metadata["events"]["strokes"] and metadata["style"]["speed"] > 0


def test_save_never_overwrites_unless_asked(conversation, tmp_path):
    (tmp_path / "talk.npz").write_bytes(b"precious")
    with pytest.raises(FileExistsError, match="talk.npz"):
        save_conversation(conversation, tmp_path / "talk")
    assert not (tmp_path / "talk.wav").exists()  # nothing was written
    assert (tmp_path / "talk.npz").read_bytes() == b"precious"
    save_conversation(conversation, tmp_path / "talk", overwrite=True)
    assert load_conversation(tmp_path / "talk").num_frames == conversation.num_frames


def test_loading_names_the_missing_or_damaged_file(conversation, tmp_path):
    save_conversation(conversation, tmp_path / "talk")
    (tmp_path / "talk.json").write_text("{not json")
    with pytest.raises(ValueError, match="talk.json"):
        load_conversation(tmp_path / "talk")
    save_conversation(conversation, tmp_path / "talk", overwrite=True)
    (tmp_path / "talk.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="talk.npz"):
        load_conversation(tmp_path / "talk")
    (tmp_path / "talk.wav").unlink()
    with pytest.raises(FileNotFoundError, match="talk.wav"):
        load_conversation(tmp_path / "talk")


def test_a_conversation_of_another_generator_version_says_so(conversation, tmp_path):
    save_conversation(conversation, tmp_path / "talk")
    metadata = json.loads((tmp_path / "talk.json").read_text())
    (tmp_path / "talk.json").write_text(json.dumps({**metadata, "generator_version": "1.1"}))
    with pytest.raises(DatasetError, match="talk.json was written by version 1.1 of the generator"):
        load_conversation(tmp_path / "talk")


# --------------------------------------------------------------------------- the dataset


def test_dataset_has_separate_conversations_in_each_split(dataset_dir):
    manifest = read_manifest(dataset_dir)
    assert (manifest["fps"], manifest["sample_rate"], manifest["seed"]) == (25, 16000, 2)
    assert manifest["config"]["motion"]["stroke_lead_s"] == 0.2
    data = load_dataset(dataset_dir)
    assert {split: len(data[split]) for split in SPLITS} == {"train": 1, "val": 1, "test": 1}
    seeds = [c.conversation_seed for split in SPLITS for c in data[split]]
    assert len(set(seeds)) == 3  # separate conversations
    audio = [c.audio for split in SPLITS for c in data[split]]
    assert not np.array_equal(audio[0], audio[1])
    for split in SPLITS:
        for entry, conv in zip(manifest["splits"][split], data[split], strict=True):
            assert conv.duration_s == entry["duration_s"] == 6.0
            assert conv.num_frames == entry["num_frames"] == 150
            assert (dataset_dir / entry["files"]["audio"]).is_file()
    assert manifest["durations_s"]["train"] == 6.0
    assert len(load_split(dataset_dir, "val")) == 1


def test_dataset_is_reproducible_from_its_seed(dataset_dir):
    manifest = read_manifest(dataset_dir)
    entry = manifest["splits"]["test"][0]
    test = load_split(dataset_dir, "test")[0]
    again = generate_conversation(6.0, seed=entry["conversation_seed"])
    np.testing.assert_array_equal(again.positions, test.positions)


def test_writing_refuses_an_existing_dataset_unless_asked(dataset_dir, capsys):
    stamp = (dataset_dir / "manifest.json").stat().st_mtime_ns
    assert (
        main(
            [
                "--out",
                str(dataset_dir),
                "--minutes",
                "0.3",
                "--conversation-seconds",
                "6",
                "--no-progress",
            ]
        )
        == 2
    )
    assert "overwrite" in capsys.readouterr().err
    assert (dataset_dir / "manifest.json").stat().st_mtime_ns == stamp  # untouched
    with pytest.raises(FileExistsError, match="already holds a dataset"):
        write_dataset(dataset_dir, 0.3, 2, conversation_s=6.0, progress=False)


def test_overwriting_keeps_unrelated_files(tmp_path):
    out = tmp_path / "data"
    write_dataset(out, 0.4, 1, conversation_s=6.0, progress=False)  # 4 conversations
    assert len(read_manifest(out)["splits"]["train"]) == 2
    notes = out / "train" / "notes.txt"
    notes.write_text("mine")
    write_dataset(out, 0.3, 1, conversation_s=6.0, overwrite=True, progress=False)
    assert notes.read_text() == "mine"
    assert not (out / "test" / "conv_0003.wav").exists()  # the old dataset's extra files went
    assert {len(v) for v in load_dataset(out).values()} == {1}


def test_ensure_dataset_reuses_a_matching_dataset_and_regenerates_a_stale_one(tmp_path, capsys):
    out = tmp_path / "data"
    first = ensure_dataset(out, 0.3, 1, conversation_s=6.0, progress=False)
    stamp = (out / "manifest.json").stat().st_mtime_ns
    assert ensure_dataset(out, 0.3, 1, conversation_s=6.0, progress=False) == first
    assert (out / "manifest.json").stat().st_mtime_ns == stamp  # reused, not rewritten
    assert capsys.readouterr().out == ""

    # A dataset made by an older generator is regenerated, and the user's own files stay.
    notes = out / "train" / "notes.txt"
    notes.write_text("mine")
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["generator_version"] = "0.9"
    (out / "manifest.json").write_text(json.dumps(manifest))
    again = ensure_dataset(out, 0.3, 1, conversation_s=6.0, progress=False)
    assert "generator_version ('0.9', now" in capsys.readouterr().out
    assert again["generator_version"] == first["generator_version"]
    assert notes.read_text() == "mine"

    # So is one of another size or seed, deleting the files only the old one had.
    ensure_dataset(out, 0.4, 1, conversation_s=6.0, progress=False)
    assert "minutes (0.3, now 0.4)" in capsys.readouterr().out
    assert (out / "test" / "conv_0003.wav").exists()
    ensure_dataset(out, 0.3, 1, conversation_s=6.0, progress=False)
    assert not (out / "test" / "conv_0003.wav").exists()
    assert (
        load_dataset(out)["train"][0].conversation_seed
        == first["splits"]["train"][0]["conversation_seed"]
    )


def test_ensure_dataset_leaves_damaged_or_foreign_folders_to_a_person(tmp_path):
    out = tmp_path / "data"
    (out / "train").mkdir(parents=True)
    (out / "train" / "conv_0000.wav").write_bytes(b"someone else's")
    with pytest.raises(FileExistsError, match="conv_0000.wav"):
        ensure_dataset(out, 0.3, 0, conversation_s=6.0, progress=False)
    assert (out / "train" / "conv_0000.wav").read_bytes() == b"someone else's"

    (out / "manifest.json").write_text("{not json")
    with pytest.raises(FileExistsError, match="damaged.*--overwrite"):
        ensure_dataset(out, 0.3, 0, conversation_s=6.0, progress=False)
    assert (out / "train" / "conv_0000.wav").read_bytes() == b"someone else's"


def test_writing_refuses_files_in_the_way(tmp_path):
    out = tmp_path / "data"
    (out / "train").mkdir(parents=True)
    (out / "train" / "conv_0000.wav").write_bytes(b"someone else's")
    with pytest.raises(FileExistsError, match="conv_0000.wav"):
        write_dataset(out, 0.3, 0, conversation_s=6.0, progress=False)
    assert not (out / "manifest.json").exists()


def test_a_damaged_or_incomplete_dataset_names_the_bad_file(dataset_dir, tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    for path in dataset_dir.rglob("*"):
        if path.is_file():
            target = broken / path.relative_to(dataset_dir)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(path.read_bytes())
    (broken / "val" / "conv_0001.npz").unlink()
    with pytest.raises(FileNotFoundError, match="conv_0001.npz"):
        load_dataset(broken)
    (broken / "manifest.json").write_text('{"format": "data_synth.dataset"}')
    with pytest.raises(ValueError, match="manifest.json"):
        load_dataset(broken)
    (broken / "manifest.json").unlink()
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        load_dataset(broken)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_dataset(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="split"):
        load_split(dataset_dir, "training")


def damaged_copy(dataset_dir, tmp_path, damage):
    """A copy of the dataset with ``damage(copy)`` applied."""
    copy = tmp_path / "copy"
    shutil.copytree(dataset_dir, copy)
    damage(copy)
    return copy


def edit_manifest(edit):
    def damage(copy):
        manifest = json.loads((copy / "manifest.json").read_text())
        edit(manifest)
        (copy / "manifest.json").write_text(json.dumps(manifest))

    return damage


def edit_arrays(name, edit):
    def damage(copy):
        path = copy / "train" / "conv_0000.npz"
        with np.load(path) as loaded:
            arrays = dict(loaded)
        edit(arrays[name])
        np.savez_compressed(path, **arrays)

    return damage


def truncate(relative):
    def damage(copy):
        data = (copy / relative).read_bytes()
        (copy / relative).write_bytes(data[: len(data) // 2])

    return damage


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (truncate("train/conv_0000.npz"), r"conv_0000.npz is damaged or truncated"),
        (truncate("train/conv_0000.wav"), r"conv_0000.wav is damaged .*truncated"),
        (edit_arrays("rotations", lambda a: a.__setitem__((3, 2, 1), np.nan)), "NaN .* frame 3"),
        (edit_arrays("positions", lambda a: a.__setitem__((7, 0, 0), np.inf)), "NaN .* frame 7"),
        (edit_arrays("activity", lambda a: a.__setitem__(5, 7)), "code 7 at frame 5 is not one of"),
    ],
)
def test_a_damaged_conversation_file_is_named_with_what_to_do(
    dataset_dir, tmp_path, damage, message
):
    broken = damaged_copy(dataset_dir, tmp_path, damage)
    with pytest.raises(DatasetError, match=message) as caught:
        load_split(broken, "train")
    assert "write the conversation again" in str(caught.value)
    assert {len(v) for v in load_dataset(dataset_dir).values()} == {1}  # the original still loads


def test_float_activity_codes_are_refused(dataset_dir, tmp_path):
    def damage(copy):
        path = copy / "train" / "conv_0000.npz"
        with np.load(path) as loaded:
            arrays = dict(loaded)
        arrays["activity"] = arrays["activity"] + 0.5
        np.savez_compressed(path, **arrays)

    with pytest.raises(DatasetError, match="activity codes must be integers, got dtype float64"):
        load_split(damaged_copy(dataset_dir, tmp_path, damage), "train")


def move_to_test(manifest):
    manifest["splits"]["test"].append(manifest["splits"]["train"][0])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda m: m["splits"]["train"][0].pop("num_frames"),
            "entry 0 of split 'train' needs 'num_frames'",
        ),
        (lambda m: m["splits"]["val"][0].pop("conversation_seed"), "needs 'conversation_seed'"),
        (lambda m: m["splits"]["val"][0]["files"].update(audio=5), "audio file must be a path"),
        (lambda m: m["splits"]["val"].__setitem__(0, "conv_0001"), "is a str, not a JSON object"),
        (lambda m: m.__setitem__("splits", []), "'splits' must map each of"),
        (move_to_test, "'conv_0000' .* is listed twice, in 'train' and 'test'"),
        (
            lambda m: m["splits"]["val"][0]["files"].update(
                audio="../x.wav", arrays="../x.npz", metadata="../x.json"
            ),
            "must lie inside the folder",
        ),
    ],
)
def test_a_damaged_manifest_is_named_with_what_to_do(dataset_dir, tmp_path, edit, message):
    broken = damaged_copy(dataset_dir, tmp_path, edit_manifest(edit))
    with pytest.raises(DatasetError, match=message) as caught:
        load_dataset(broken)
    assert "manifest.json is damaged" in str(caught.value)
    assert "--overwrite" in str(caught.value)


def test_a_manifest_that_is_not_an_object_or_a_dataset_path_that_is_a_file(dataset_dir, tmp_path):
    broken = damaged_copy(dataset_dir, tmp_path, lambda c: (c / "manifest.json").write_text("[]"))
    with pytest.raises(DatasetError, match="holds a list, not a JSON object"):
        read_manifest(broken)
    with pytest.raises(FileNotFoundError, match="is a file, not a dataset folder"):
        load_dataset(broken / "manifest.json")


def test_command_line_entry_point(tmp_path):
    out = tmp_path / "cli"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "data_synth",
            "--out",
            str(out),
            "--minutes",
            "0.15",
            "--conversation-seconds",
            "3",
            "--no-progress",
        ],
        capture_output=True,
        text=True,
        cwd=REPOSITORY,
        timeout=120,
        env={**os.environ, "GESTURELIB_QUICK": "0"},
    )
    assert result.returncode == 0, result.stderr
    assert "train" in result.stdout
    assert {len(v) for v in load_dataset(out).values()} == {1}


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--minutes", "-1"], "minutes"),
        (["--seed", "-3"], "seed"),
        (["--conversation-seconds", "0.5"], "conversation_s"),
    ],
)
def test_command_line_rejects_bad_sizes(tmp_path, capsys, arguments, message):
    assert main(["--out", str(tmp_path / "data"), "--no-progress", *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "data").exists()


def test_dataset_seeds_never_collide_with_the_small_seeds_of_demos():
    from data_synth.dataset import SEED_STRIDE, conversation_seed

    assert (
        min(conversation_seed(seed, index) for seed in range(3) for index in range(30))
        >= SEED_STRIDE
    )
    assert len({conversation_seed(seed, index) for seed in range(3) for index in range(30)}) == 90


def test_the_command_line_says_in_one_line_when_it_cannot_write(tmp_path, capsys):
    blocker = tmp_path / "notes.txt"
    blocker.write_text("a file where a folder would be needed")
    assert main(["--out", str(blocker / "dataset"), "--quick"]) == 2
    error = capsys.readouterr().err
    assert "error:" in error and error.count("\n") == 1
    assert blocker.read_text() == "a file where a folder would be needed"
