"""The dataset on disk: separate conversations in train/val/test folders, and a manifest.

Layout of a dataset folder::

    DIR/manifest.json           what is where: splits, files, seeds, config, rates, durations
    DIR/train/conv_0000.wav     one conversation: audio (see data_synth.conversation)
    DIR/train/conv_0000.npz     activity, rotations, positions
    DIR/train/conv_0000.json    seeds, style, voices, config, events
    DIR/val/...  DIR/test/...

Every conversation has its own conversation seed, ``(seed + 1) * 10000 + index``, so the splits
share no speech: a model is tested on conversations it never heard. Seeds below 10000 are never
used by a dataset, so the small seeds of demos and notebooks never replay a dataset's speech. About 10 % of the conversations
go to validation and 10 % to test (at least one each), the rest to training.

The manifest is written last: a folder without one is an incomplete dataset. Writing refuses to
replace an existing dataset (or any file it would write) unless ``overwrite`` is given; even then
it only deletes files that the old manifest lists, never anything else in the folder. Every
conversation's turns are drawn before anything is written, so a size that cannot work (a
conversation without speech, too many conversations) is refused with nothing on disk.

Reading checks the manifest whole (every entry, no conversation in two splits, files inside the
folder) and each conversation's files (see :func:`data_synth.load_conversation`); a damaged one
raises :class:`~data_synth.conversation.DatasetError` naming the file and how to regenerate it.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path, PurePosixPath

from tqdm.auto import tqdm

from data_synth.config import ConfigError, ConversationConfig, check_value
from data_synth.conversation import (
    FILE_FORMAT,
    GENERATOR_VERSION,
    Conversation,
    DatasetError,
    check_duration,
    conversation_paths,
    draw_turns,
    generate_conversation,
    load_conversation,
    save_conversation,
)
from gesturelib.locks import exclusive

SPLITS = ("train", "val", "test")
MANIFEST_NAME = "manifest.json"
DATASET_FORMAT = "data_synth.dataset"
#: Sizes of the two presets: minutes of conversation, and the length of each conversation.
QUICK_MINUTES, QUICK_CONVERSATION_S = 3.0, 30.0
FULL_MINUTES, FULL_CONVERSATION_S = 30.0, 60.0
#: Fraction of the conversations in each of val and test.
HELD_OUT_FRACTION = 0.1
#: Conversation seeds are ``(dataset seed + 1) * SEED_STRIDE + index``: never below SEED_STRIDE.
SEED_STRIDE = 10_000


def split_sizes(n_conversations: int) -> dict[str, int]:
    """How many conversations go to each split (at least one each; needs 3 or more)."""
    if n_conversations < 3:
        raise ConfigError(
            f"a dataset needs at least 3 conversations (one per split), got {n_conversations}"
        )
    held_out = max(1, round(HELD_OUT_FRACTION * n_conversations))
    return {"train": n_conversations - 2 * held_out, "val": held_out, "test": held_out}


def conversation_seed(dataset_seed: int, index: int) -> int:
    """The conversation seed of conversation ``index`` of a dataset."""
    if not 0 <= index < SEED_STRIDE:
        raise ConfigError(f"index must be in [0, {SEED_STRIDE}), got {index}")
    return (dataset_seed + 1) * SEED_STRIDE + index


def write_dataset(
    out_dir: str | os.PathLike,
    minutes: float,
    seed: int,
    conversation_s: float = FULL_CONVERSATION_S,
    config: ConversationConfig | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> dict:
    """Generate a dataset of ``minutes`` of conversation into ``out_dir``.

    Args:
        out_dir: the dataset folder (created if needed).
        minutes: total length; it is split into conversations of ``conversation_s`` seconds
            (at least 3, at most ``SEED_STRIDE`` conversations).
        seed: the dataset seed (each conversation gets its own seed from it).
        conversation_s: length of each conversation in seconds (at most
            :data:`~data_synth.conversation.MAX_DURATION_S`); long enough for every
            conversation's turns to hold a phrase.
        config: the generator's configuration; ``None`` for the defaults.
        overwrite: replace an existing dataset or files in the way.
        progress: show a progress bar.
    Returns:
        The manifest (also written to ``out_dir/manifest.json``).
    Raises:
        FileExistsError: if ``out_dir`` already holds a dataset or any file this would write,
            and ``overwrite`` is False. Nothing is written then.
        ConfigError: (a ``ValueError``) for bad sizes, seeds or config, or a conversation whose
            turns hold no phrase. Nothing is written then.
    """
    minutes, seed, conversation_s, config = _check_arguments(minutes, seed, conversation_s, config)
    if minutes > MAX_MINUTES:
        raise ConfigError(
            f"minutes = {minutes:g} is more than the {MAX_MINUTES:g} minutes (10 hours) a dataset "
            "of this generator may hold; the course trains on 30"
        )
    n_conversations = max(3, round(minutes * 60.0 / conversation_s))
    if n_conversations > SEED_STRIDE:
        raise ConfigError(
            f"minutes = {minutes:g} in conversations of {conversation_s:g} s makes "
            f"{n_conversations} conversations, more than the {SEED_STRIDE} a dataset seed can "
            "give distinct seeds to; ask for fewer minutes or longer conversations"
        )
    sizes = split_sizes(n_conversations)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"{out_dir} exists and is not a folder")
    _check_free_space(out_dir, n_conversations * conversation_s * BYTES_PER_SECOND)

    # Plan every file first, so that a refusal happens before anything is written.
    plan = []
    index = 0
    for split in SPLITS:
        for _ in range(sizes[split]):
            draw_turns(conversation_s, conversation_seed(seed, index), config, "conversation_s")
            plan.append((split, index, out_dir / split / f"conv_{index:04d}"))
            index += 1
    manifest_path = out_dir / MANIFEST_NAME
    planned = [manifest_path] + [p for *_, stem in plan for p in conversation_paths(stem).values()]
    in_the_way = [p for p in planned if p.exists()]
    if in_the_way and not overwrite:
        what = "a dataset" if manifest_path.exists() else "files"
        shown = ", ".join(str(p) for p in in_the_way[:3])
        more = f" and {len(in_the_way) - 3} more" if len(in_the_way) > 3 else ""
        raise FileExistsError(
            f"{out_dir} already holds {what} ({shown}{more}); "
            "pass overwrite=True (--overwrite) to replace it"
        )
    if overwrite and manifest_path.exists():
        _remove_old_dataset(out_dir, manifest_path, set(planned))

    for folder in sorted({stem.parent for _, _, stem in plan}):  # before any work: can we write?
        folder.mkdir(parents=True, exist_ok=True)
    splits: dict[str, list[dict]] = {split: [] for split in SPLITS}
    for split, index, stem in tqdm(plan, desc="conversations", disable=not progress):
        conversation = generate_conversation(conversation_s, conversation_seed(seed, index), config)
        save_conversation(conversation, stem, overwrite=overwrite)
        splits[split].append(
            {
                "name": stem.name,
                "conversation_seed": conversation.conversation_seed,
                "motion_seed": conversation.motion_seed,
                "duration_s": conversation.duration_s,
                "num_frames": conversation.num_frames,
                "files": {
                    kind: path.relative_to(out_dir).as_posix()
                    for kind, path in conversation_paths(stem).items()
                },
            }
        )
    manifest = {
        **_provenance(minutes, seed, conversation_s, config),
        "fps": config.fps,
        "sample_rate": config.sample_rate,
        "durations_s": {
            split: sum(e["duration_s"] for e in entries) for split, entries in splits.items()
        },
        "splits": splits,
    }
    text = json.dumps(manifest, indent=1)
    manifest_path.write_text(text)
    return json.loads(text)  # exactly what read_manifest will give (tuples read back as lists)


#: The most a dataset may hold, and what a second of conversation takes on disk (its audio,
#: arrays and metadata: 40 kB, measured on the course's data).
MAX_MINUTES = 600.0
BYTES_PER_SECOND = 40_000


def _check_free_space(out_dir: Path, needed: float) -> None:
    """ConfigError if the disk holding ``out_dir`` has less than ``needed`` bytes free (with a
    margin of a fifth)."""
    existing = next(p for p in (out_dir, *out_dir.parents) if p.exists())
    free = shutil.disk_usage(existing).free
    if free < 1.2 * needed:
        raise ConfigError(
            f"the dataset would take about {needed / 1e6:,.0f} MB and {existing} has "
            f"{free / 1e6:,.0f} MB free; ask for fewer minutes or free some space"
        )


def _check_arguments(minutes, seed, conversation_s, config) -> tuple:
    """``(minutes, seed, conversation_s, config)`` checked, as Python numbers; ConfigError if bad."""
    seed = check_value(seed, "seed (a non-negative integer)", 0, integer=True)
    minutes = check_value(minutes, "minutes", 0.0, low_open=True)
    conversation_s = check_duration(conversation_s, "conversation_s")
    config = ConversationConfig() if config is None else config
    if not isinstance(config, ConversationConfig):
        raise ConfigError(f"config must be a ConversationConfig, got {type(config).__name__}")
    return minutes, seed, conversation_s, config


def _provenance(
    minutes: float, seed: int, conversation_s: float, config: ConversationConfig
) -> dict:
    """The manifest entries that decide a dataset's content: same entries, same files."""
    return {
        "format": DATASET_FORMAT,
        "generator_version": GENERATOR_VERSION,
        "conversation_format": FILE_FORMAT,
        "seed": seed,
        "minutes": minutes,
        "conversation_s": conversation_s,
        "config": config.to_dict(),
    }


def ensure_dataset(
    out_dir: str | os.PathLike,
    minutes: float,
    seed: int,
    conversation_s: float = FULL_CONVERSATION_S,
    config: ConversationConfig | None = None,
    progress: bool = True,
) -> dict:
    """The dataset these arguments describe, in ``out_dir``: reused if it is there, else written.

    This is what notebooks call, so that a dataset is generated once and shared by all of them,
    yet never silently reused once it is stale. An existing dataset is reused only if its manifest
    records the same seed, sizes and generator configuration *and* the current generator and
    file-format versions; otherwise it is regenerated in place, saying why, which deletes only the
    files the old manifest lists (see :func:`write_dataset`). Anything else is left for a person
    to decide: a damaged manifest, or files in the way without one (an interrupted write, or
    someone else's files), raise as in :func:`write_dataset`.

    Args: as :func:`write_dataset` (without ``overwrite``).
    Returns:
        The manifest of the dataset now in ``out_dir``.
    Raises:
        FileExistsError: if ``out_dir`` holds a damaged manifest, or files this would write but
            no manifest. Nothing is written then.
        ValueError: for bad sizes or seeds, or if ``out_dir`` is a file.
    """
    minutes, seed, conversation_s, config = _check_arguments(minutes, seed, conversation_s, config)
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    # Two notebooks (or test workers) asking at once: the first writes, the other waits and reuses.
    with exclusive(out_dir.parent / f".{out_dir.name}.lock", wait_for=f"writing {out_dir}"):
        return _ensure_dataset(out_dir, minutes, seed, conversation_s, config, progress)


def _ensure_dataset(out_dir: Path, minutes, seed, conversation_s, config, progress) -> dict:
    """:func:`ensure_dataset` with checked arguments, under the folder's lock."""
    # As a manifest reads back: tuples become lists.
    wanted = json.loads(json.dumps(_provenance(minutes, seed, conversation_s, config)))
    stale = False
    if (Path(out_dir) / MANIFEST_NAME).is_file():
        try:
            manifest = read_manifest(out_dir)
        except ValueError as error:
            raise FileExistsError(
                f"{error}; delete the folder or regenerate it with "
                f"`python -m data_synth --out {out_dir} --overwrite`"
            ) from error
        differences = {key: value for key, value in wanted.items() if manifest.get(key) != value}
        if not differences:
            return manifest
        reasons = [
            "generator settings"
            if key == "config"
            else f"{key} ({manifest.get(key)!r}, now {value!r})"
            for key, value in differences.items()
        ]
        print(
            f"Regenerating the dataset in {out_dir}: it was made with different {', '.join(reasons)}"
        )
        stale = True
    return write_dataset(
        out_dir, minutes, seed, conversation_s, config, overwrite=stale, progress=progress
    )


def _remove_old_dataset(out_dir: Path, manifest_path: Path, keep: set[Path]) -> None:
    """Delete the manifest and the files the old manifest lists (only those); ``keep`` are
    overwritten anyway."""
    try:
        old = read_manifest(out_dir)
    except ValueError:
        old = {"splits": {}}  # a damaged manifest: leave its files alone (ensure_dataset refuses)
    manifest_path.unlink()
    for entries in old["splits"].values():
        for entry in entries:
            for relative in entry["files"].values():
                path = out_dir / relative
                if path not in keep and path.is_file():
                    path.unlink()


def read_manifest(dataset_dir: str | os.PathLike) -> dict:
    """Read and check ``dataset_dir/manifest.json``.

    Every entry of every split must name its conversation, seed, frame count and three files
    (relative paths inside the folder sharing one stem), and no conversation (file or seed) may
    be listed twice: a conversation in two splits would test a model on what it trained on.

    Raises:
        FileNotFoundError: if the folder or its manifest is missing.
        DatasetError: (a ``ValueError``) if the manifest is not a valid data_synth manifest.
    """
    dataset_dir = Path(dataset_dir)
    path = dataset_dir / MANIFEST_NAME
    if dataset_dir.exists() and not dataset_dir.is_dir():
        raise FileNotFoundError(f"{dataset_dir} is a file, not a dataset folder")
    if not dataset_dir.is_dir():
        raise FileNotFoundError(f"dataset folder {dataset_dir} does not exist")
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} is missing: {dataset_dir} is not a complete data_synth dataset (writing "
            "may have been interrupted); regenerate it with "
            f"`python -m data_synth --out {dataset_dir} --overwrite`"
        )
    try:
        manifest = json.loads(path.read_text())
        _check_manifest(manifest)
    except ValueError as error:
        raise DatasetError(
            f"{path} is damaged: {error}; fix it, or regenerate the dataset with "
            f"`python -m data_synth --out {dataset_dir} --overwrite` "
            "(or write_dataset(..., overwrite=True))"
        ) from error
    return manifest


def _check_manifest(manifest) -> None:
    """Raise ``ValueError`` saying what is wrong with a manifest's structure."""
    if not isinstance(manifest, dict):
        raise ValueError(f"it holds a {type(manifest).__name__}, not a JSON object")
    if manifest.get("format") != DATASET_FORMAT:
        raise ValueError(f"its format is {manifest.get('format')!r}, not {DATASET_FORMAT!r}")
    splits = manifest.get("splits")
    if not isinstance(splits, dict) or not all(isinstance(splits.get(s), list) for s in SPLITS):
        raise ValueError(f"'splits' must map each of {list(SPLITS)} to a list of conversations")
    listed: dict[object, str] = {}  # stem or seed -> the split that lists it
    for split in SPLITS:
        for number, entry in enumerate(splits[split]):
            where = f"entry {number} of split {split!r}"
            if not isinstance(entry, dict):
                raise ValueError(f"{where} is a {type(entry).__name__}, not a JSON object")
            for key, kind in (("name", str), ("conversation_seed", int), ("num_frames", int)):
                if not isinstance(entry.get(key), kind) or isinstance(entry.get(key), bool):
                    raise ValueError(
                        f"{where} needs {key!r} ({kind.__name__}), got {entry.get(key)!r}"
                    )
            stem = _entry_stem(entry, where)
            for key in (stem, ("seed", entry["conversation_seed"])):
                if key in listed:
                    raise ValueError(
                        f"conversation {entry['name']!r} (seed {entry['conversation_seed']}) is "
                        f"listed twice, in {listed[key]!r} and {split!r}: a conversation belongs "
                        "to one split"
                    )
                listed[key] = split


def _entry_stem(entry: dict, where: str) -> PurePosixPath:
    """The common stem of an entry's three files, which must be relative paths inside the folder."""
    files = entry.get("files")
    if not isinstance(files, dict) or set(files) != {"audio", "arrays", "metadata"}:
        raise ValueError(f"{where} must list its audio, arrays and metadata files")
    stems = set()
    for kind, suffix in (("audio", ".wav"), ("arrays", ".npz"), ("metadata", ".json")):
        relative = files[kind]
        if not isinstance(relative, str) or not relative.endswith(suffix):
            raise ValueError(f"{where}: its {kind} file must be a path ending in {suffix}")
        relative = PurePosixPath(relative)
        if relative.is_absolute() or ".." in relative.parts:
            raise ValueError(f"{where}: its {kind} file {relative} must lie inside the folder")
        stems.add(relative.with_suffix(""))
    if len(stems) != 1:
        raise ValueError(f"{where}: the files of {entry['name']!r} must share one name stem")
    return stems.pop()


def load_split(dataset_dir: str | os.PathLike, split: str) -> list[Conversation]:
    """Load the conversations of one split (``"train"``, ``"val"`` or ``"test"``).

    Raises:
        FileNotFoundError: naming the missing manifest or conversation file.
        DatasetError: (a ``ValueError``) naming the damaged file.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    dataset_dir = Path(dataset_dir)
    manifest = read_manifest(dataset_dir)
    conversations = []
    for entry in manifest["splits"][split]:
        stem = dataset_dir / _entry_stem(entry, entry["name"])
        conversation = load_conversation(stem)
        if (
            conversation.conversation_seed != entry["conversation_seed"]
            or conversation.num_frames != entry["num_frames"]
        ):
            raise DatasetError(
                f"{stem}.json does not match {dataset_dir / MANIFEST_NAME} (seed or length "
                "differs): the folder mixes files of different datasets; regenerate it with "
                f"`python -m data_synth --out {dataset_dir} --overwrite`"
            )
        conversations.append(conversation)
    return conversations


def load_dataset(dataset_dir: str | os.PathLike) -> dict[str, list[Conversation]]:
    """Load every split: ``{"train": [...], "val": [...], "test": [...]}``.

    Raises:
        FileNotFoundError: naming the missing manifest or conversation file.
        DatasetError: (a ``ValueError``) naming the damaged file.
    """
    return {split: load_split(dataset_dir, split) for split in SPLITS}


def data_folder(quick: bool) -> Path:
    """Where the course's synthetic dataset lives: ``data/quick`` or ``data/full`` of the
    repository (of the working folder when the package is installed outside one); the notebooks
    share it."""
    repository = Path(__file__).resolve().parents[1]
    root = repository if (repository / "pyproject.toml").exists() else Path.cwd()
    return root / "data" / ("quick" if quick else "full")


def course_data(quick: bool, progress: bool = True) -> Path:
    """:func:`data_folder` with the course's quick or full dataset in it, generated the first
    time (:func:`ensure_dataset`, which also replaces a stale one)."""
    minutes, seconds = (
        (QUICK_MINUTES, QUICK_CONVERSATION_S) if quick else (FULL_MINUTES, FULL_CONVERSATION_S)
    )
    folder = data_folder(quick)
    ensure_dataset(folder, minutes=minutes, seed=0, conversation_s=seconds, progress=progress)
    return folder
