"""Motion capture imported as a dataset: each take on our skeleton, with its recordings.

``python -m gesturelib import-bvh SRC --out DATA`` (:func:`import_bvh`) reads a folder ``SRC``
of takes, ``NAME.bvh`` with the agent's voice ``NAME.wav`` and, optionally, the partner's
``NAME_partner.wav``, and writes::

    DATA/manifest.json     format, version, source, rig, units, rates, and what is where
    DATA/train/NAME.wav    both voices mixed, 16 kHz mono (what the models hear)
    DATA/train/NAME.npz    activity (T,), rotations (T, 9, 6), positions (T, 9, 3)
    DATA/val/...  DATA/test/...

Splits are by take (a model is tested on takes it never saw): about 10 % each to validation
and test, at least one each, drawn with a fixed seed. Who is talking comes from voice activity in
each voice (:func:`gesturelib.features.who_is_talking`). Such data has no generator behind it:
no events, so the rule-based measures of the evaluation stay empty, and no floor.
:func:`load_recordings` reads the folder back, checking what it reads.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from gesturelib.conventions import FPS, NUM_ACTIVITIES, SAMPLE_RATE
from gesturelib.features import load_audio, mix_voices, num_frames, save_audio, who_is_talking
from gesturelib.mocap.bvh_reader import read_bvh
from gesturelib.mocap.retarget import retarget
from gesturelib.mocap.rigs import RigError
from gesturelib.rotations import RotationError
from gesturelib.skeleton import NUM_JOINTS

FORMAT = "gesturelib.mocap"
VERSION = 1
SPLITS = ("train", "val", "test")
MANIFEST_NAME = "manifest.json"
#: How far the motion and the agent's recording (or the two recordings) may differ in length.
LENGTH_TOLERANCE_S = 0.5
#: Share of the takes in each of validation and test.
HELD_OUT_FRACTION = 0.1
PARTNER_SUFFIX = "_partner"
#: A take's files in the dataset.
SUFFIXES = (".wav", ".npz")


class MocapError(ValueError):
    """A folder of takes that cannot be imported, or an imported dataset that cannot be read;
    the message names the file and what to do."""


@dataclass
class Recording:
    """One imported take, as the training and the evaluation read it (see
    ``gesturelib.data.ConversationLike``).

    Attributes:
        name: the take's name (its files' stem).
        audio: ``(n,)`` float32, both voices mixed, at ``sample_rate``.
        sample_rate, fps: audio samples and motion frames a second.
        activity: ``(T,)`` int64 activity codes, ``T = floor(n * fps / sample_rate)``.
        rotations: ``(T, 9, 6)`` limb rotations on our skeleton; positions: ``(T, 9, 3)`` cm.
    """

    name: str
    audio: np.ndarray
    sample_rate: int
    fps: int
    activity: np.ndarray
    rotations: np.ndarray
    positions: np.ndarray
    #: No generator made it: no events (the rule-based measures are empty), every limb seen.
    events = None
    visible = None

    @property
    def num_frames(self) -> int:
        return len(self.activity)


def find_takes(src: str | os.PathLike) -> list[tuple[str, Path, Path, Path | None]]:
    """``(name, bvh, wav, partner wav or None)`` for each ``NAME.bvh`` of ``src``, by name.

    Raises:
        MocapError: ``src`` is not a folder, holds no BVH file, or a BVH without its WAV.
    """
    src = Path(src)
    if not src.is_dir():
        raise MocapError(f"{src} is not a folder; give the folder of NAME.bvh and NAME.wav files")
    takes, lonely = [], []
    for bvh in sorted(src.glob("*.bvh")):
        wav = bvh.with_suffix(".wav")
        partner = bvh.with_name(f"{bvh.stem}{PARTNER_SUFFIX}.wav")
        if not wav.is_file():
            lonely.append(bvh.name)
        takes.append((bvh.stem, bvh, wav, partner if partner.is_file() else None))
    if not takes:
        raise MocapError(f"{src} holds no .bvh file; give the folder of NAME.bvh and NAME.wav")
    if lonely:
        raise MocapError(
            f"{src}: {', '.join(lonely[:5])} {'has' if len(lonely) == 1 else 'have'} no "
            "recording beside it; each NAME.bvh needs the agent's voice as NAME.wav"
        )
    return takes


def import_take(bvh: Path, wav: Path, partner: Path | None, rig: str | None = None):
    """One take as a :class:`Recording`, with what the import found: ``(recording, {"rig",
    "units", "source_fps", "duration_s"})``.

    Raises:
        MocapError: motion and recording (or the two recordings) of lengths more than
            :data:`LENGTH_TOLERANCE_S` apart; with the reader's, the rig's and the audio's errors
            for broken or unsuitable files.
    """
    agent, rate = load_audio(wav, SAMPLE_RATE)
    seconds = len(agent) / rate
    voices = agent
    partner_audio = None
    if partner is not None:
        partner_audio, _ = load_audio(partner, SAMPLE_RATE)
        _check_length(partner, len(partner_audio) / rate, wav, seconds)
        partner_audio = np.pad(partner_audio, (0, max(0, len(agent) - len(partner_audio))))
        partner_audio = partner_audio[: len(agent)]  # to the agent's length
        voices = mix_voices(agent, partner_audio)
    take = read_bvh(bvh)
    _check_length(bvh, take.num_frames * take.frame_time, wav, seconds)
    frames = num_frames(len(agent), rate, FPS)
    try:
        moved = retarget(take, frames, rig)
    except (RigError, RotationError) as error:
        raise MocapError(f"{bvh}: {error}") from None
    activity = who_is_talking(agent, rate, partner_audio)
    recording = Recording(
        bvh.stem, voices.astype(np.float32), rate, FPS, activity, moved.rotations, moved.positions
    )
    found = {
        "rig": moved.rig,
        "units": moved.units,
        "source_fps": moved.source_fps,
        "duration_s": seconds,
    }
    return recording, found


def _check_length(path: Path, seconds: float, reference: Path, reference_s: float) -> None:
    if abs(seconds - reference_s) > LENGTH_TOLERANCE_S:
        raise MocapError(
            f"{path} lasts {seconds:.2f} s and {reference} {reference_s:.2f} s; a take's motion "
            f"and recordings must have one length (to within {LENGTH_TOLERANCE_S} s): trim them "
            "to the same span"
        )


def split_takes(names: list[str], seed: int = 0) -> dict[str, list[str]]:
    """Takes per split: about :data:`HELD_OUT_FRACTION` each to val and test (at least one
    each), drawn with ``seed``; each split's names sorted."""
    if len(names) < 3:
        raise MocapError(
            f"{len(names)} take(s): a dataset needs at least 3 (a training, a validation and a "
            "test take); cut a long recording into several takes"
        )
    held_out = max(1, round(HELD_OUT_FRACTION * len(names)))
    order = [names[i] for i in np.random.default_rng(seed).permutation(len(names))]
    return {
        "val": sorted(order[:held_out]),
        "test": sorted(order[held_out : 2 * held_out]),
        "train": sorted(order[2 * held_out :]),
    }


def import_bvh(
    src: str | os.PathLike,
    out: str | os.PathLike,
    rig: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> dict:
    """Import the takes of ``src`` into the dataset folder ``out`` (see the module docstring).

    The takes are imported one by one into a staging folder inside ``out`` and moved into place
    only when every one has been, with the manifest last: a take that fails, or a full disk,
    leaves ``out`` as it was. An earlier import in ``out`` is replaced only with ``overwrite``,
    and then only the files its manifest lists; another dataset's folder, or files of the same
    names that no import wrote, are refused.

    Returns:
        The manifest.
    Raises:
        FileExistsError: ``out`` holds an import without ``overwrite``, another kind of dataset,
            or files in the way that no import wrote.
        MocapError: (a ``ValueError``) for a take that cannot be imported, naming its file;
            with the reader's and the audio's errors.
    """
    takes = find_takes(src)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MocapError(f"{out} is a file; give a folder for the dataset")
    splits = split_takes([name for name, *_ in takes])
    split_of = {name: split for split, names in splits.items() for name in names}
    listed = _listed_files(out, overwrite)
    planned = [
        out / split_of[name] / f"{name}{suffix}" for name, *_ in takes for suffix in SUFFIXES
    ]
    in_the_way = [p for p in planned if p.exists() and p not in listed]
    if in_the_way:
        raise FileExistsError(
            f"{out} holds {in_the_way[0]}"
            + (f" and {len(in_the_way) - 1} more" if len(in_the_way) > 1 else "")
            + ", which no import wrote; move them, or choose another folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".importing-", dir=out))
    try:
        entries, found = _import_into(staging, takes, split_of, rig, progress)
        manifest = {
            "format": FORMAT,
            "version": VERSION,
            "source": str(Path(src).resolve()),
            "rig": sorted({what["rig"] for what in found}),
            "units": sorted({what["units"] for what in found}),
            "fps": FPS,
            "sample_rate": SAMPLE_RATE,
            "splits": entries,
        }
        (staging / MANIFEST_NAME).write_text(json.dumps(manifest, indent=1))
        for path in listed:  # the earlier import, now that the new one is whole
            path.unlink(missing_ok=True)
        for split in SPLITS:
            (out / split).mkdir(exist_ok=True)
            for entry in entries[split]:
                for suffix in SUFFIXES:
                    name = f"{entry['name']}{suffix}"
                    os.replace(staging / split / name, out / split / name)
        os.replace(staging / MANIFEST_NAME, out / MANIFEST_NAME)  # last: the dataset is whole
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return manifest


def _listed_files(out: Path, overwrite: bool) -> set[Path]:
    """The files of an earlier import in ``out`` (its manifest with them), which ``overwrite``
    may replace; refuse an earlier import without ``overwrite``, and any other dataset."""
    manifest_path = out / MANIFEST_NAME
    if not manifest_path.exists():
        return set()
    try:
        old = read_manifest(out)
    except MocapError:
        raise FileExistsError(
            f"{out} holds another dataset (its {MANIFEST_NAME} is not an import's); choose "
            "another folder"
        ) from None
    if not overwrite:
        raise FileExistsError(
            f"{out} already holds an imported dataset; pass --overwrite (overwrite=True) to "
            "replace it"
        )
    files = {manifest_path}
    for split, entries in old["splits"].items():
        files |= {out / split / f"{e['name']}{suffix}" for e in entries for suffix in SUFFIXES}
    return files


def _import_into(staging: Path, takes, split_of: dict, rig, progress: bool):
    """Import each take into ``staging/SPLIT/``; return the manifest's entries per split and what
    each take's import found."""
    entries: dict[str, list] = {split: [] for split in SPLITS}
    found = []
    for name, bvh, wav, partner in tqdm(takes, desc="takes", disable=not progress):
        recording, what = import_take(bvh, wav, partner, rig)
        split = split_of[name]
        (staging / split).mkdir(exist_ok=True)
        stem = staging / split / name
        save_audio(stem.with_suffix(".wav"), recording.audio, recording.sample_rate)
        with open(stem.with_suffix(".npz"), "wb") as stream:
            np.savez_compressed(
                stream,
                activity=recording.activity,
                rotations=recording.rotations,
                positions=recording.positions,
            )
        entries[split].append(
            {
                "name": name,
                "num_frames": recording.num_frames,
                "duration_s": what["duration_s"],
                "source_fps": what["source_fps"],
                "units": what["units"],
                "rig": what["rig"],
            }
        )
        found.append(what)
    return entries, found


def read_manifest(folder: str | os.PathLike) -> dict:
    """The manifest of an imported dataset, checked.

    Raises:
        MocapError: naming the file, for a missing, damaged or foreign manifest.
    """
    path = Path(folder) / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text())
        if manifest.get("format") != FORMAT or manifest.get("version") != VERSION:
            raise ValueError(f"not a {FORMAT} manifest of version {VERSION}")
        for split in SPLITS:
            for entry in manifest["splits"][split]:
                name = entry["name"]
                if not isinstance(name, str) or Path(name).name != name or not name:
                    raise ValueError(f"take name {name!r} is not a file name")
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise MocapError(
            f"{path} cannot be read ({error}); import the takes again with "
            "`python -m gesturelib import-bvh SRC --out DATA --overwrite`"
        ) from None
    return manifest


def load_recordings(folder: str | os.PathLike) -> dict[str, list[Recording]]:
    """The takes of an imported dataset, ``{"train", "val", "test"}``, each checked.

    Raises:
        MocapError: naming the file, for a damaged manifest, recording or motion file.
    """
    folder = Path(folder)
    manifest = read_manifest(folder)
    return {
        split: [_load(folder / split / entry["name"]) for entry in manifest["splits"][split]]
        for split in SPLITS
    }


def _load(stem: Path) -> Recording:
    again = "import the takes again (`python -m gesturelib import-bvh SRC --out DATA --overwrite`)"
    try:
        audio, rate = load_audio(stem.with_suffix(".wav"), sample_rate=None)
        with np.load(stem.with_suffix(".npz")) as arrays:
            activity, rotations, positions = (
                arrays["activity"],
                arrays["rotations"],
                arrays["positions"],
            )
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        raise MocapError(f"{stem}.wav or .npz is damaged ({error}); {again}") from None
    frames = num_frames(len(audio), rate, FPS)
    shapes = {
        "activity": (activity.shape, (frames,)),
        "rotations": (rotations.shape, (frames, NUM_JOINTS, 6)),
        "positions": (positions.shape, (frames, NUM_JOINTS, 3)),
    }
    for name, (shape, expected) in shapes.items():
        if shape != expected:
            raise MocapError(f"{stem}.npz: {name} has shape {shape}, expected {expected}; {again}")
    if activity.dtype.kind not in "iu" or activity.min() < 0 or activity.max() >= NUM_ACTIVITIES:
        raise MocapError(f"{stem}.npz: activity codes outside 0..{NUM_ACTIVITIES - 1}; {again}")
    if not (np.isfinite(rotations).all() and np.isfinite(positions).all()):
        raise MocapError(f"{stem}.npz holds NaN or infinite motion; {again}")
    return Recording(stem.name, audio, rate, FPS, activity.astype(np.int64), rotations, positions)
