"""Training windows from conversations: what a model sees at each motion frame.

For a frame ``t`` the papers' models get a *control signal* and predict the pose ``x_t``:

* ``past_pose``: the previous ``tau`` poses ``x_{t-tau} .. x_{t-1}`` (tau = 5 in MoGlow and the
  Flow-VAE paper), the autoregressive context;
* ``speech``: log-mel rows ``t - past .. t + future`` (5 past and 25 future frames: 1 s of
  look-ahead, because gestures *anticipate* the speech they go with);
* ``activity``: the who-is-talking one-hot over the same window.

Items are dictionaries of named parts, so that a model takes what it needs and later parts (such
as MoGlow's style inputs) can be added without changing any model. An item covers
``sequence_length`` consecutive target frames (1 for frame-wise models, e.g. 80 for the 4 s
excerpts MoGlow trains on), and every part has that leading axis ``L``:

=============  ===================================  ==========================================
part           shape                                meaning
=============  ===================================  ==========================================
``pose``       ``(L, 54)``                          target poses x_t (6D rotations, normalised)
``past_pose``  ``(L, tau, 54)``                     x_{t-tau} .. x_{t-1} for each target frame
``speech``     ``(L, past + 1 + future, 27)``       log-mel window around each target frame
``activity``   ``(L, past + 1 + future, 4)``        activity one-hot over the same window
=============  ===================================  ==========================================

A ``DataLoader`` adds the batch axis in front: ``(B, L, ...)``. Only windows whose whole context
lies inside the conversation are used, so no padding value is ever learned.

Poses and speech features are standardised with statistics fitted on the *training* split only
(:class:`Normaliser`); mirroring (left-right, :func:`gesturelib.skeleton.mirror_rotations`) doubles
the training data with the control signal duplicated, as in the Flow-VAE paper.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch
from torch.utils.data import Dataset

from gesturelib.conventions import FPS, N_MELS, NUM_ACTIVITIES
from gesturelib.features import activity_one_hot, mel_spectrogram
from gesturelib.skeleton import NUM_JOINTS, POSE_DIM, mirror_rotations

#: Standard deviations below this are treated as this, so a (nearly) constant feature is
#: centred but not blown up.
MIN_STD = 1e-4


class ConversationLike(Protocol):
    """What this module needs of a conversation (``data_synth.Conversation`` has it)."""

    audio: np.ndarray  # (n,) float32 mono
    sample_rate: int
    fps: int
    activity: np.ndarray  # (T,) int codes
    rotations: np.ndarray  # (T, 9, 6)


@dataclass(frozen=True)
class WindowConfig:
    """How much context each training window carries.

    Attributes:
        past_poses: tau, the number of previous poses in the control signal.
        speech_past: log-mel / activity frames before the target frame.
        speech_future: log-mel / activity frames after it (25 at 25 fps = 1 s of look-ahead).
        sequence_length: consecutive target frames per item (1 for frame-wise models).
        stride: frames between the starts of consecutive items.
    """

    past_poses: int = 5
    speech_past: int = 5
    speech_future: int = 25
    sequence_length: int = 1
    stride: int = 1

    def __post_init__(self):
        for name in ("past_poses", "speech_past", "speech_future"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 0:
                raise ValueError(
                    f"WindowConfig.{name} must be an integer >= 0, got {getattr(self, name)!r}"
                )
        for name in ("sequence_length", "stride"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(
                    f"WindowConfig.{name} must be an integer >= 1, got {getattr(self, name)!r}"
                )

    @property
    def speech_window(self) -> int:
        """Frames in a speech or activity window: past + the target frame + future."""
        return self.speech_past + 1 + self.speech_future

    @property
    def frames_needed(self) -> int:
        """Shortest conversation that yields one item."""
        return max(self.past_poses, self.speech_past) + self.sequence_length + self.speech_future


@dataclass(frozen=True)
class ConversationFeatures:
    """Per-frame arrays of one conversation, as the models read them (before normalisation).

    Attributes:
        pose: ``(T, 54)`` limb rotations, 6D, flattened joint-major.
        speech: ``(T, 27)`` log-mel.
        activity: ``(T, 4)`` one-hot.
    """

    pose: np.ndarray
    speech: np.ndarray
    activity: np.ndarray

    @classmethod
    def from_conversation(
        cls, conversation: ConversationLike, n_mels: int = N_MELS
    ) -> ConversationFeatures:
        """Compute the features of a conversation; its motion and audio must cover the same frames."""
        rotations = np.asarray(conversation.rotations, dtype=np.float32)
        if rotations.ndim != 3 or rotations.shape[1:] != (NUM_JOINTS, 6):
            raise ValueError(
                f"conversation.rotations must have shape (T, {NUM_JOINTS}, 6), got {rotations.shape}"
            )
        if conversation.fps != FPS:
            raise ValueError(
                f"conversation runs at {conversation.fps} fps; the models expect {FPS} fps"
            )
        speech = mel_spectrogram(
            conversation.audio, conversation.sample_rate, fps=conversation.fps, n_mels=n_mels
        )
        activity = activity_one_hot(np.asarray(conversation.activity))
        if not len(rotations) == len(speech) == len(activity):
            raise ValueError(
                f"conversation arrays disagree in length: {len(rotations)} motion frames, "
                f"{len(speech)} audio frames, {len(activity)} activity frames"
            )
        return cls(
            pose=rotations.reshape(len(rotations), POSE_DIM), speech=speech, activity=activity
        )

    def mirrored(self) -> ConversationFeatures:
        """The left-right mirror image of the motion, with the same speech and activity."""
        rotations = self.pose.reshape(-1, NUM_JOINTS, 6)
        return ConversationFeatures(
            pose=mirror_rotations(rotations).reshape(-1, POSE_DIM),
            speech=self.speech,
            activity=self.activity,
        )


@dataclass(frozen=True)
class Normaliser:
    """Per-dimension standardisation of poses and speech features, fitted on training data.

    ``normalised = (value - mean) / std``. Saved and loaded as JSON so that a checkpoint carries
    the statistics its model was trained with.
    """

    pose_mean: np.ndarray  # (54,)
    pose_std: np.ndarray  # (54,)
    speech_mean: np.ndarray  # (n_mels,)
    speech_std: np.ndarray  # (n_mels,)

    @classmethod
    def fit(cls, features: Sequence[ConversationFeatures]) -> Normaliser:
        """Statistics over every frame of ``features`` (the training split, mirrored or not)."""
        if not features:
            raise ValueError("cannot fit a Normaliser on no conversations")
        pose = np.concatenate([f.pose for f in features]).astype(np.float64)
        speech = np.concatenate([f.speech for f in features]).astype(np.float64)
        return cls(
            pose_mean=pose.mean(0).astype(np.float32),
            pose_std=np.maximum(pose.std(0), MIN_STD).astype(np.float32),
            speech_mean=speech.mean(0).astype(np.float32),
            speech_std=np.maximum(speech.std(0), MIN_STD).astype(np.float32),
        )

    def normalise_pose(self, pose):
        """``(..., 54)`` raw 6D poses -> standardised."""
        return (pose - _like(self.pose_mean, pose)) / _like(self.pose_std, pose)

    def denormalise_pose(self, pose):
        """``(..., 54)`` standardised -> raw 6D poses (reshape to ``(..., 9, 6)`` for kinematics)."""
        return pose * _like(self.pose_std, pose) + _like(self.pose_mean, pose)

    def normalise_speech(self, speech):
        """``(..., n_mels)`` log-mel -> standardised."""
        return (speech - _like(self.speech_mean, speech)) / _like(self.speech_std, speech)

    def to_dict(self) -> dict:
        """JSON-able form (lists of floats)."""
        return {name: value.tolist() for name, value in asdict(self).items()}

    @classmethod
    def from_dict(cls, values: dict) -> Normaliser:
        expected = {"pose_mean", "pose_std", "speech_mean", "speech_std"}
        if set(values) != expected:
            raise ValueError(
                f"normaliser needs exactly the keys {sorted(expected)}, got {sorted(values)}"
            )
        arrays = {name: np.asarray(value, dtype=np.float32) for name, value in values.items()}
        if arrays["pose_mean"].shape != (POSE_DIM,) or arrays["pose_std"].shape != (POSE_DIM,):
            raise ValueError(f"pose statistics must have {POSE_DIM} values each")
        if arrays["speech_mean"].shape != arrays["speech_std"].shape:
            raise ValueError("speech mean and std must have the same length")
        return cls(**arrays)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict()))

    @classmethod
    def load(cls, path: str | Path) -> Normaliser:
        path = Path(path)
        try:
            return cls.from_dict(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as error:
            raise ValueError(
                f"cannot read normalisation statistics from {path}: {error}"
            ) from error


def _like(array: np.ndarray, reference):
    """``array`` as a tensor on ``reference``'s device/dtype when ``reference`` is a tensor."""
    if isinstance(reference, torch.Tensor):
        return torch.as_tensor(array, dtype=reference.dtype, device=reference.device)
    return array


class WindowDataset(Dataset):
    """Every valid window of a list of conversations, as dictionaries of named tensors.

    Args:
        features: per-conversation arrays (:meth:`ConversationFeatures.from_conversation`).
        config: the context sizes.
        normaliser: fitted on the training split; applied to poses and speech.
        mirror: also serve the left-right mirror image of every conversation (training only).

    Items: see the module docstring (``pose (L, 54)``, ``past_pose (L, tau, 54)``,
    ``speech (L, W, 27)``, ``activity (L, W, 4)`` with ``W = past + 1 + future``), float32.
    """

    def __init__(
        self,
        features: Sequence[ConversationFeatures],
        config: WindowConfig,
        normaliser: Normaliser,
        mirror: bool = False,
    ):
        self.config = config
        if mirror:
            features = [*features, *(f.mirrored() for f in features)]
        self._streams = []  # per conversation: normalised (T, D) tensors
        self._index = []  # (conversation, first target frame)
        first = max(config.past_poses, config.speech_past)
        for number, conversation in enumerate(features):
            n_frames = len(conversation.pose)
            last = n_frames - config.speech_future - config.sequence_length  # inclusive
            self._streams.append(
                {
                    "pose": torch.from_numpy(
                        normaliser.normalise_pose(conversation.pose).astype(np.float32)
                    ),
                    "speech": torch.from_numpy(
                        normaliser.normalise_speech(conversation.speech).astype(np.float32)
                    ),
                    "activity": torch.from_numpy(conversation.activity.astype(np.float32)),
                }
            )
            self._index.extend((number, start) for start in range(first, last + 1, config.stride))
        if not self._index:
            raise ValueError(
                f"no conversation is long enough for one window: each needs at least "
                f"{config.frames_needed} frames ({config.frames_needed / FPS:.1f} s)"
            )

    def __len__(self) -> int:
        return len(self._index)

    def __getitem__(self, item: int) -> dict[str, torch.Tensor]:
        number, start = self._index[item]
        streams, config = self._streams[number], self.config
        length = config.sequence_length
        targets = slice(start, start + length)
        past = slice(start - config.past_poses, start + length - 1)
        context = slice(start - config.speech_past, start + length + config.speech_future)
        return {
            "pose": streams["pose"][targets],
            "past_pose": _windows(streams["pose"][past], config.past_poses),
            "speech": _windows(streams["speech"][context], config.speech_window),
            "activity": _windows(streams["activity"][context], config.speech_window),
        }


def _windows(stream: torch.Tensor, size: int) -> torch.Tensor:
    """``(N, D)`` -> ``(N - size + 1, size, D)``: every run of ``size`` consecutive rows (a view)."""
    if size == 0:
        return stream.new_zeros(len(stream) + 1, 0, stream.shape[1])
    return stream.unfold(0, size, 1).transpose(1, 2)


def make_datasets(
    splits: dict[str, Sequence[ConversationLike]], config: WindowConfig, mirror_train: bool = True
) -> tuple[dict[str, WindowDataset], Normaliser]:
    """Window datasets for every split, normalised with statistics of the training split.

    Args:
        splits: conversations by split name; must include ``"train"`` (e.g. the result of
            ``data_synth.load_dataset``).
        config: the context sizes.
        mirror_train: add the mirror image of every training conversation (validation and test
            are never mirrored, so that they measure the data as it is).
    Returns:
        ``(datasets, normaliser)``: a :class:`WindowDataset` per split, and the fitted statistics
        (save them with the model: :meth:`Normaliser.to_dict`).
    """
    if "train" not in splits:
        raise ValueError(
            f"splits must include 'train' to fit the normalisation; got {sorted(splits)}"
        )
    features = {
        name: [ConversationFeatures.from_conversation(c) for c in convs]
        for name, convs in splits.items()
    }
    train = features["train"]
    normaliser = Normaliser.fit([*train, *(f.mirrored() for f in train)] if mirror_train else train)
    datasets = {
        name: WindowDataset(split, config, normaliser, mirror=mirror_train and name == "train")
        for name, split in features.items()
    }
    return datasets, normaliser


def control_dims(config: WindowConfig, n_mels: int = N_MELS) -> dict[str, int]:
    """Flattened size of each control part of one target frame, e.g. for a model's input layer."""
    return {
        "past_pose": config.past_poses * POSE_DIM,
        "speech": config.speech_window * n_mels,
        "activity": config.speech_window * NUM_ACTIVITIES,
    }
