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
``(T, 9, 3)``) and ``STEM.json`` (seeds, rates, duration, style, voices, configuration, events,
all readable in a text editor).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from data_synth.config import ConversationConfig
from data_synth.events import Events
from data_synth.motion import AgentMotion, generate_motion
from data_synth.prosody import plan_speech
from data_synth.style import Style, draw_style
from data_synth.turns import activity_codes, sample_turns
from data_synth.voice import Voice, draw_voices, mix, synthesize_speech
from gesturelib.features import load_audio, num_frames, save_audio
from gesturelib.skeleton import NUM_JOINTS

#: Version of the generator's rules; written into every file and manifest.
GENERATOR_VERSION = "1.1"
FILE_FORMAT = "data_synth.conversation"
#: The shortest conversation: long enough for a phrase and its preparation.
MIN_DURATION_S = 2.0

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

    @property
    def duration_s(self) -> float:
        """Length of the audio in seconds."""
        return self.audio.size / self.sample_rate

    @property
    def num_frames(self) -> int:
        """Number of motion frames ``T``."""
        return int(self.activity.shape[0])


def _check_seed(seed, name: str) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {seed!r}")
    return int(seed)


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
        duration_s: length of the audio in seconds (at least :data:`MIN_DURATION_S`).
        seed: the conversation seed (turns, words, voices, audio, style).
        config: the generator's parameters; ``None`` for the defaults.
        motion_seed: the motion seed; ``None`` uses ``seed``.
    Returns:
        The :class:`Conversation`. The same seeds and config give identical arrays.
    """
    if (
        isinstance(duration_s, bool)
        or not isinstance(duration_s, (int, float))
        or not math.isfinite(duration_s)
        or duration_s < MIN_DURATION_S
    ):
        raise ValueError(
            f"duration_s must be a number of seconds >= {MIN_DURATION_S}, got {duration_s!r}"
        )
    seed = _check_seed(seed, "seed")
    motion_seed = seed if motion_seed is None else _check_seed(motion_seed, "motion_seed")
    config = ConversationConfig() if config is None else config
    if not isinstance(config, ConversationConfig):
        raise ValueError(f"config must be a ConversationConfig, got {type(config).__name__}")

    duration_s = float(duration_s)
    n_samples = int(round(duration_s * config.sample_rate))
    utterances = sample_turns(duration_s, config.turns, _stream(seed, _TURNS))
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


def resample_motion(conversation: Conversation, seed: int) -> Conversation:
    """Draw the agent's motion again for the same conversation, with motion seed ``seed``.

    Audio, activity, the speech events (phrases, syllables, accents), style and voices are kept;
    rotations, positions and the motion events (strokes, nods, gesture phrases) are new. The input
    is not modified.
    """
    seed = _check_seed(seed, "seed")
    if not isinstance(conversation, Conversation):
        raise ValueError(f"conversation must be a Conversation, got {type(conversation).__name__}")
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
    with open(paths["arrays"], "wb") as file:
        np.savez_compressed(
            file,
            activity=conversation.activity,
            rotations=conversation.rotations,
            positions=conversation.positions,
        )
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
        ValueError: naming the file whose content is damaged or inconsistent.
    """
    paths = conversation_paths(path_stem)
    for path in paths.values():
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} is missing: a conversation needs the .wav, .npz and .json files"
            )
    metadata_path = paths["metadata"]
    try:
        metadata = json.loads(metadata_path.read_text())
        if metadata.get("format") != FILE_FORMAT:
            raise ValueError(f"it is not a {FILE_FORMAT} file")
        config = ConversationConfig.from_dict(metadata["config"])
        events = Events.from_dict(metadata["events"])
        style = Style.from_dict(metadata["style"])
        voices = {speaker: Voice(**voice) for speaker, voice in metadata["voices"].items()}
        sample_rate, fps = int(metadata["sample_rate"]), int(metadata["fps"])
        num_samples = int(metadata["num_samples"])
        seeds = int(metadata["conversation_seed"]), int(metadata["motion_seed"])
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"{metadata_path} is damaged: {error}") from error

    try:
        audio, _ = load_audio(paths["audio"], sample_rate=None)
    except ValueError as error:
        raise ValueError(f"{paths['audio']} is damaged: {error}") from error
    try:
        with np.load(paths["arrays"]) as arrays:
            activity, rotations, positions = (
                arrays["activity"],
                arrays["rotations"],
                arrays["positions"],
            )
    except (ValueError, KeyError, OSError, EOFError) as error:
        raise ValueError(f"{paths['arrays']} is damaged: {error}") from error
    n_frames = num_frames(num_samples, sample_rate, fps)
    if audio.size != num_samples:
        raise ValueError(
            f"{paths['audio']} holds {audio.size} samples, but {metadata_path} says {num_samples}"
        )
    expected = {
        "activity": (n_frames,),
        "rotations": (n_frames, NUM_JOINTS, 6),
        "positions": (n_frames, NUM_JOINTS, 3),
    }
    for name, array in (("activity", activity), ("rotations", rotations), ("positions", positions)):
        if array.shape != expected[name]:
            raise ValueError(
                f"{paths['arrays']}: {name} has shape {array.shape}, expected {expected[name]}"
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
    )
