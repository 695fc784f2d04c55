"""A generated conversation: audio, who speaks, the agent's motion, the event log; and its files.

Two seeds make a conversation:

* the **conversation seed** draws the turns, the words (syllables, accents, intonation), the two
  voices, the audio and the speaker's gesture style;
* the **motion seed** draws the random details of the agent's motion given all that: which hands
  gesture, where, the beats' exact amplitudes and timing jitter, which nods happen, breathing and
  sway. It defaults to the conversation seed (the two feed separate random streams).

:func:`resample_motion` keeps everything of a conversation but its motion and draws the motion
again with another motion seed: the spread between such draws is how much of the motion the
speech cannot explain, the floor that no model can beat.

Files (:func:`save_conversation`, :func:`load_conversation`): ``STEM.wav`` (the mono mix, 16-bit
PCM), ``STEM.npz`` (``activity`` ``(T,)``, ``rotations`` ``(T, 9, 6)``, ``positions``
``(T, 9, 3)``, and ``visible`` ``(T, 9)`` where a tracker lost limbs: :mod:`data_synth.occlusion`) and ``STEM.json`` (seeds, rates, duration, style, voices, configuration, events,
all readable in a text editor). Loading checks what it reads (shapes, finite motion, activity
codes in range) and raises :class:`DatasetError` naming the damaged file.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from data_synth.config import ConfigError, ConversationConfig, check_value
from data_synth.events import Events, Phrase
from data_synth.motion import AgentMotion, generate_motion
from data_synth.prosody import plan_speech
from data_synth.style import Style, draw_style
from data_synth.turns import END_MARGIN_S, activity_codes, opening_phrase_fits, sample_turns
from data_synth.voice import Voice, draw_voices, mix, synthesize_speech
from gesturelib.conventions import NUM_ACTIVITIES
from gesturelib.features import load_audio, num_frames, save_audio
from gesturelib.skeleton import NUM_JOINTS

#: Version of the generator's rules; written into every file and manifest.
GENERATOR_VERSION = "1.2"
FILE_FORMAT = "data_synth.conversation"
#: The shortest conversation accepted. With the default turns a conversation shorter than about
#: 4 s may draw no phrase at all for some seeds; such a draw is refused (see
#: :func:`generate_conversation`).
MIN_DURATION_S = 2.0
#: The longest conversation: one is made in memory, about 0.7 MB a second (0.4 GB and 15 s of
#: one CPU core for 600 s). Longer recordings are several conversations (a dataset).
MAX_DURATION_S = 600.0

_REWRITE = (
    "restore the file, or write the conversation again (save_conversation; for a dataset, "
    "write_dataset(..., overwrite=True) or `python -m data_synth --out DIR --overwrite`)"
)


class DatasetError(ValueError):
    """A conversation or dataset file that cannot be used: damaged, inconsistent or out of range.

    The message names the file and says how to replace it.
    """


# Independent random streams drawn from the seeds.
_TURNS, _SPEECH_A, _SPEECH_B, _VOICES, _AUDIO, _STYLE, _MOTION = range(7)


@dataclass
class Conversation:
    """One generated conversation (see the module docstring for the seeds).

    Attributes:
        audio: ``(n,)`` float32 mono mix of both speakers in [-1, 1].
        sample_rate: audio samples per second.
        fps: motion frames per second; frame ``t`` covers ``[t / fps, (t + 1) / fps)``.
        activity: ``(T,)`` int64 :class:`~gesturelib.conventions.Activity` codes,
            ``T = floor(n / sample_rate * fps)``.
        rotations: ``(T, 9, 6)`` float32 limb rotations of the agent (6D, relative to the T-pose).
        positions: ``(T, 9, 3)`` float32 keypoints in cm, ``forward_kinematics(rotations)``.
        events: what the generator did and when (:class:`~data_synth.events.Events`).
        style: the agent's gesture style.
        voices: ``{"A": Voice, "B": Voice}``.
        conversation_seed, motion_seed: the two seeds.
        config: the configuration it was generated with.
        visible: ``(T, 9)`` bool, False where a limb was not seen (its rotation is then a
            placeholder: :func:`data_synth.occlusion.occlude`); None when every limb was seen.
    """

    audio: np.ndarray
    sample_rate: int
    fps: int
    activity: np.ndarray
    rotations: np.ndarray
    positions: np.ndarray
    events: Events
    style: Style
    voices: dict[str, Voice]
    conversation_seed: int
    motion_seed: int
    config: ConversationConfig
    visible: np.ndarray | None = None

    @property
    def duration_s(self) -> float:
        """Length of the audio in seconds."""
        return self.audio.size / self.sample_rate

    @property
    def num_frames(self) -> int:
        """Number of motion frames ``T``."""
        return int(self.activity.shape[0])


def _check_seed(seed, name: str) -> int:
    return check_value(seed, f"{name} (a non-negative integer)", 0, integer=True)


def _stream(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([seed, stream])


def generate_conversation(
    duration_s: float,
    seed: int,
    config: ConversationConfig | None = None,
    *,
    motion_seed: int | None = None,
) -> Conversation:
    """Generate a dyadic conversation and the agent's motion.

    Args:
        duration_s: length of the audio in seconds, from :data:`MIN_DURATION_S` to
            :data:`MAX_DURATION_S`.
        seed: the conversation seed (turns, words, voices, audio, style).
        config: the generator's parameters; ``None`` for the defaults.
        motion_seed: the motion seed; ``None`` uses ``seed``.
    Returns:
        The :class:`Conversation`. The same seeds and config give identical arrays.
    Raises:
        ConfigError: for a bad duration, seed or config, and when the turns drawn hold no
            phrase (the lead-in and the opening phrase do not fit in ``duration_s``): a
            conversation without speech is of no use here. The message names the fields.
    """
    duration_s = float(check_duration(duration_s, "duration_s"))
    seed = _check_seed(seed, "seed")
    motion_seed = seed if motion_seed is None else _check_seed(motion_seed, "motion_seed")
    config = ConversationConfig() if config is None else config
    if not isinstance(config, ConversationConfig):
        raise ConfigError(f"config must be a ConversationConfig, got {type(config).__name__}")

    n_samples = int(round(duration_s * config.sample_rate))
    utterances = draw_turns(duration_s, seed, config)
    voices = draw_voices(config.voice, _stream(seed, _VOICES))
    plans = {
        speaker: plan_speech(utterances, speaker, config.voice, duration_s, _stream(seed, stream))
        for speaker, stream in (("A", _SPEECH_A), ("B", _SPEECH_B))
    }
    audio_rng = _stream(seed, _AUDIO)
    tracks = [
        synthesize_speech(plans[s], voices[s], n_samples, config.sample_rate, audio_rng)
        * 10.0 ** (voices[s].level_db / 20.0)
        for s in ("A", "B")
    ]
    audio = mix(tracks, config.voice, audio_rng)
    if not np.isfinite(audio).all():
        raise ConfigError(
            f"the voices of {config.voice} gave audio with NaN or infinite samples; bring the "
            "levels and gains back towards the defaults"
        )
    n_frames = num_frames(n_samples, config.sample_rate, config.fps)
    speech_events = Events(
        phrases=utterances,
        syllables=sorted(plans["A"].syllables + plans["B"].syllables, key=lambda s: s.start),
        accents=sorted(plans["A"].accents + plans["B"].accents, key=lambda a: a.time),
    )
    style = draw_style(config.style, _stream(seed, _STYLE))
    motion = _draw_motion(speech_events, style, config, n_frames, motion_seed)
    return Conversation(
        audio=audio,
        sample_rate=config.sample_rate,
        fps=config.fps,
        activity=activity_codes(utterances, n_frames, config.fps),
        rotations=motion.rotations,
        positions=motion.positions,
        events=_with_motion_events(speech_events, motion),
        style=style,
        voices=voices,
        conversation_seed=seed,
        motion_seed=motion_seed,
        config=config,
    )


def check_duration(duration_s, where: str) -> float:
    """A conversation's length in seconds, checked against the limits; ``ConfigError`` otherwise."""
    duration_s = check_value(duration_s, f"{where} (seconds)", MIN_DURATION_S)
    if duration_s > MAX_DURATION_S:
        raise ConfigError(
            f"{where} = {duration_s:g} s is longer than MAX_DURATION_S = {MAX_DURATION_S:g} s: a "
            "conversation is made in memory (about 0.7 MB a second); generate several shorter "
            "conversations instead (write_dataset splits minutes into conversations)"
        )
    return duration_s


def draw_turns(
    duration_s: float, seed: int, config: ConversationConfig, where: str = "duration_s"
) -> list[Phrase]:
    """The turns of conversation ``seed`` (cheap: no audio); ``ConfigError`` if none holds a phrase.

    :func:`data_synth.write_dataset` calls it for every conversation before writing any; ``where``
    is the caller's name for the duration, for the message.
    """
    utterances = sample_turns(duration_s, config.turns, _stream(seed, _TURNS))
    if not utterances:
        turns = config.turns
        some, every = opening_phrase_fits(turns)
        reason = (
            f"no seed can fit a phrase in {where} = {duration_s:g} s"
            if duration_s < some
            else f"seed {seed} draws no phrase in {where} = {duration_s:g} s"
        )
        raise ConfigError(
            f"{reason}: a conversation needs speech, and the lead-in (TurnConfig.lead_in_s = "
            f"{turns.lead_in_s}) and the opening phrase (TurnConfig.a_phrase_s = "
            f"{turns.a_phrase_s}, TurnConfig.b_phrase_s = {turns.b_phrase_s}) must end "
            f"{END_MARGIN_S:g} s before the end; make {where} at least {every:.3g} s (every "
            "seed then has speech) or shorten those ranges"
        )
    return utterances


def resample_motion(conversation: Conversation, seed: int) -> Conversation:
    """Draw the agent's motion again for the same conversation, with motion seed ``seed``.

    Audio, activity, the speech events (phrases, syllables, accents), style and voices are kept;
    rotations, positions and the motion events (strokes, nods, gesture phrases) are new. The input
    is not modified.
    """
    seed = _check_seed(seed, "seed")
    if not isinstance(conversation, Conversation):
        raise ConfigError(f"conversation must be a Conversation, got {type(conversation).__name__}")
    motion = _draw_motion(
        conversation.events, conversation.style, conversation.config, conversation.num_frames, seed
    )
    return replace(
        conversation,
        rotations=motion.rotations,
        positions=motion.positions,
        events=_with_motion_events(conversation.events, motion),
        motion_seed=seed,
    )


def _draw_motion(
    events: Events, style: Style, config: ConversationConfig, n_frames: int, motion_seed: int
) -> AgentMotion:
    """The agent's motion given the speech events; only the motion seed's stream is used."""
    return generate_motion(
        events.phrases,
        events.accents_of("A"),
        style,
        config.motion,
        n_frames,
        config.fps,
        _stream(motion_seed, _MOTION),
    )


def _with_motion_events(events: Events, motion: AgentMotion) -> Events:
    return replace(
        events, strokes=motion.strokes, nods=motion.nods, gesture_phrases=motion.gesture_phrases
    )


# --------------------------------------------------------------------------- files


def conversation_paths(path_stem: str | os.PathLike) -> dict[str, Path]:
    """The three files of a conversation: ``{"audio": .wav, "arrays": .npz, "metadata": .json}``."""
    stem = Path(path_stem)
    return {
        "audio": stem.with_name(stem.name + ".wav"),
        "arrays": stem.with_name(stem.name + ".npz"),
        "metadata": stem.with_name(stem.name + ".json"),
    }


def save_conversation(
    conversation: Conversation, path_stem: str | os.PathLike, overwrite: bool = False
) -> list[Path]:
    """Write ``STEM.wav``, ``STEM.npz`` and ``STEM.json``; return their paths.

    Raises:
        FileExistsError: if any of the three exists and ``overwrite`` is False (nothing is
            written then).
        ValueError: if the folder does not exist.
    """
    paths = conversation_paths(path_stem)
    if not paths["audio"].parent.is_dir():
        raise ValueError(
            f"cannot write {path_stem}: the folder {paths['audio'].parent} does not exist"
        )
    existing = [str(p) for p in paths.values() if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(
            f"{', '.join(existing)} already exist(s); pass overwrite=True to replace"
        )
    save_audio(paths["audio"], conversation.audio, conversation.sample_rate, overwrite=True)
    arrays = {
        "activity": conversation.activity,
        "rotations": conversation.rotations,
        "positions": conversation.positions,
    }
    if conversation.visible is not None:
        arrays["visible"] = conversation.visible
    with open(paths["arrays"], "wb") as file:
        np.savez_compressed(file, **arrays)
    metadata = {
        "format": FILE_FORMAT,
        "generator_version": GENERATOR_VERSION,
        "conversation_seed": conversation.conversation_seed,
        "motion_seed": conversation.motion_seed,
        "sample_rate": conversation.sample_rate,
        "fps": conversation.fps,
        "duration_s": conversation.duration_s,
        "num_samples": int(conversation.audio.size),
        "num_frames": conversation.num_frames,
        "files": {kind: path.name for kind, path in paths.items()},
        "style": conversation.style.to_dict(),
        "voices": {speaker: asdict(voice) for speaker, voice in conversation.voices.items()},
        "config": conversation.config.to_dict(),
        "events": conversation.events.to_dict(),
    }
    paths["metadata"].write_text(json.dumps(metadata, indent=1))
    return list(paths.values())


def load_conversation(path_stem: str | os.PathLike) -> Conversation:
    """Read a conversation written by :func:`save_conversation`.

    The audio comes back quantised to 16 bits; everything else exactly.

    Raises:
        FileNotFoundError: naming the missing file.
        DatasetError: naming the file whose content is damaged, inconsistent or out of range
            (a truncated file, wrong shapes, NaN motion, activity codes outside 0..3), or that
            another version of the generator wrote.
    """
    paths = conversation_paths(path_stem)
    for path in paths.values():
        if not path.is_file():
            what = "a folder, not a file" if path.is_dir() else "missing"
            raise FileNotFoundError(
                f"{path} is {what}: a conversation needs the .wav, .npz and .json files"
            )
    metadata_path = paths["metadata"]
    try:
        metadata = json.loads(metadata_path.read_text())
        if metadata.get("format") != FILE_FORMAT:
            raise ValueError(f"it is not a {FILE_FORMAT} file")
    except (ValueError, AttributeError) as error:
        raise DatasetError(f"{metadata_path} is damaged ({error}); {_REWRITE}") from error
    written_by = metadata.get("generator_version")
    if written_by != GENERATOR_VERSION:
        raise DatasetError(
            f"{metadata_path} was written by version {written_by} of the generator, whose files "
            f"this version ({GENERATOR_VERSION}) does not read; make the conversation again "
            "(generate_conversation and save_conversation, or `python -m data_synth` for a dataset)"
        )
    try:
        config = ConversationConfig.from_dict(metadata["config"])
        events = Events.from_dict(metadata["events"])
        style = Style.from_dict(metadata["style"])
        voices = {speaker: Voice(**voice) for speaker, voice in metadata["voices"].items()}
        sample_rate = check_value(metadata["sample_rate"], "sample_rate", 1, integer=True)
        fps = check_value(metadata["fps"], "fps", 1, integer=True)
        num_samples = check_value(metadata["num_samples"], "num_samples", 1, integer=True)
        seeds = int(metadata["conversation_seed"]), int(metadata["motion_seed"])
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise DatasetError(f"{metadata_path} is damaged ({error}); {_REWRITE}") from error

    try:
        audio, _ = load_audio(paths["audio"], sample_rate=None)
    except ValueError as error:
        raise DatasetError(f"{paths['audio']} is damaged ({error}); {_REWRITE}") from error
    try:
        with np.load(paths["arrays"]) as arrays:
            activity, rotations, positions = (
                arrays["activity"],
                arrays["rotations"],
                arrays["positions"],
            )
            visible = arrays["visible"] if "visible" in arrays else None
    except (ValueError, KeyError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as error:
        raise DatasetError(
            f"{paths['arrays']} is damaged or truncated ({error}); {_REWRITE}"
        ) from error
    if audio.size != num_samples:
        raise DatasetError(
            f"{paths['audio']} holds {audio.size} samples, but {metadata_path} says "
            f"{num_samples}; {_REWRITE}"
        )
    _check_arrays(
        paths["arrays"],
        num_frames(num_samples, sample_rate, fps),
        activity,
        rotations,
        positions,
        visible,
    )
    return Conversation(
        audio,
        sample_rate,
        fps,
        activity.astype(np.int64),
        rotations,
        positions,
        events,
        style,
        voices,
        seeds[0],
        seeds[1],
        config,
        visible,
    )


def _check_arrays(path: Path, n_frames: int, activity, rotations, positions, visible) -> None:
    """The arrays of a ``.npz`` file: shapes, integer codes in range, finite motion, a boolean
    mask of seen limbs (if any)."""
    if visible is not None and (visible.shape != (n_frames, NUM_JOINTS) or visible.dtype != bool):
        raise DatasetError(
            f"{path}: visible must be a bool mask of shape {(n_frames, NUM_JOINTS)}, got "
            f"{visible.dtype} {visible.shape}; {_REWRITE}"
        )
    expected = {
        "activity": (n_frames,),
        "rotations": (n_frames, NUM_JOINTS, 6),
        "positions": (n_frames, NUM_JOINTS, 3),
    }
    arrays = {"activity": activity, "rotations": rotations, "positions": positions}
    for name, array in arrays.items():
        if array.shape != expected[name]:
            raise DatasetError(
                f"{path}: {name} has shape {array.shape}, expected {expected[name]}; {_REWRITE}"
            )
    if activity.dtype.kind not in "iu":
        raise DatasetError(
            f"{path}: activity codes must be integers, got dtype {activity.dtype}; {_REWRITE}"
        )
    bad = np.flatnonzero((activity < 0) | (activity >= NUM_ACTIVITIES))
    if bad.size:
        raise DatasetError(
            f"{path}: activity code {activity[bad[0]]} at frame {bad[0]} is not one of "
            f"0..{NUM_ACTIVITIES - 1} ({bad.size} of {n_frames} frames are out of range); {_REWRITE}"
        )
    for name in ("rotations", "positions"):
        array = arrays[name]
        if array.dtype.kind != "f":
            raise DatasetError(
                f"{path}: {name} must be floats, got dtype {array.dtype}; {_REWRITE}"
            )
        bad = np.flatnonzero(~np.isfinite(array).reshape(n_frames, -1).all(axis=1))
        if bad.size:
            raise DatasetError(
                f"{path}: {name} holds NaN or infinite values at frame {bad[0]} ({bad.size} of "
                f"{n_frames} frames); {_REWRITE}"
            )
