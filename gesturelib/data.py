"""Training windows from conversations: what a model sees at each motion frame.

For a frame ``t`` the papers' models get a *control signal* and predict the pose ``x_t``:

* ``past_pose``: the previous ``tau`` poses ``x_{t-tau} .. x_{t-1}`` (tau = 5 in MoGlow and the
  Flow-VAE paper), the autoregressive context;
* ``speech``: rows ``t - past .. t + future`` of the speech features (the log-mel normalised
  per recording, :func:`gesturelib.features.speech_features`) (5 past and 25 future frames: 1 s of
  look-ahead, because gestures *anticipate* the speech they go with);
* ``activity``: the who-is-talking one-hot over the same window;
* ``style``: MoGlow's style inputs, measured from the motion itself (:mod:`gesturelib.style`).

Items are dictionaries of named parts, so that a model takes what it needs and ignores the rest.
An item covers ``sequence_length`` consecutive target frames (1 for frame-wise models, e.g. 100
for the 4 s excerpts MoGlow trains on), and every part has that leading axis ``L``:

=============  ===================================  ==========================================
part           shape                                meaning
=============  ===================================  ==========================================
``pose``       ``(L, 54)``                          target poses x_t (6D rotations, normalised)
``past_pose``  ``(L, tau, 54)``                     x_{t-tau} .. x_{t-1} for each target frame
``speech``     ``(L, past + 1 + future, 27)``       speech window around each target frame
``activity``   ``(L, past + 1 + future, 4)``        activity one-hot over the same window
``style``      ``(L, 4)``                           style of each target frame (normalised)
=============  ===================================  ==========================================

A ``DataLoader`` adds the batch axis in front: ``(B, L, ...)``. Only windows whose whole context
lies inside the conversation are used, so no padding value is ever learned.

Poses, speech and style are standardised with statistics fitted on the *training* split only
(:class:`Normaliser`); mirroring (left-right, :func:`gesturelib.skeleton.mirror_rotations`) doubles
the training data with the control signal duplicated, as in the Flow-VAE paper.

Checks happen where data enters: :class:`ConversationFeatures` and :class:`Normaliser` refuse
wrong shapes and non-finite values when they are built (or loaded), and the datasets refuse what
is not a list of features; past that, the windowing trusts its inputs.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Protocol

import numpy as np
import torch
from torch.utils.data import Dataset

from gesturelib.configs import SpeechContext, check_fields
from gesturelib.conventions import FPS, N_MELS, NUM_ACTIVITIES
from gesturelib.features import activity_one_hot, speech_features
from gesturelib.skeleton import NUM_JOINTS, POSE_DIM, forward_kinematics, mirror_rotations
from gesturelib.style import STYLE_FEATURES, style_features

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
class WindowConfig(SpeechContext):
    """How much context each training window carries.

    Attributes:
        speech_past, speech_future: the speech and activity window around each target frame
            (:class:`~gesturelib.configs.SpeechContext`: 5 and 25 frames, 1 s of look-ahead).
        past_poses: tau, the number of previous poses in the control signal.
        sequence_length: consecutive target frames per item (1 for frame-wise models).
        stride: frames between the starts of consecutive items.
    """

    past_poses: int = 5
    sequence_length: int = 1
    stride: int = 1

    def __post_init__(self):
        super().__post_init__()
        check_fields(self, counts=("past_poses",), positive=("sequence_length", "stride"))

    @property
    def frames_needed(self) -> int:
        """Shortest conversation that yields one item."""
        return max(self.past_poses, self.speech_past) + self.sequence_length + self.speech_future


@dataclass(frozen=True)
class ConversationFeatures:
    """Per-frame arrays of one conversation, as the models read them (before normalisation).

    Attributes:
        pose: ``(T, 54)`` limb rotations, 6D, flattened joint-major.
        speech: ``(T, n_mels)`` log-mel normalised per recording
            (:func:`~gesturelib.features.speech_features`; 27 bands by default).
        activity: ``(T, 4)`` one-hot.
        style: ``(T, 4)`` the style measured from the motion (:mod:`gesturelib.style`).

    Raises:
        ValueError: when built with wrong shapes, arrays of different lengths, or NaN or
            infinite values; the message names the array and the first bad frame.
    """

    pose: np.ndarray
    speech: np.ndarray
    activity: np.ndarray
    style: np.ndarray

    def __post_init__(self):
        lengths = {}
        parts = (("pose", POSE_DIM), ("speech", None), ("activity", NUM_ACTIVITIES))
        for name, width in (*parts, ("style", len(STYLE_FEATURES))):
            array = np.asarray(getattr(self, name))
            if (
                array.dtype.kind not in "biuf"
                or array.ndim != 2
                or (width is not None and array.shape[1] != width)
            ):
                raise ValueError(
                    f"ConversationFeatures.{name} must be a numeric array of shape "
                    f"(T, {width or 'n_mels'}), got {array.dtype} of shape {array.shape}"
                )
            bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
            if bad.size:
                raise ValueError(
                    f"ConversationFeatures.{name} holds NaN or infinite values at frame {bad[0]} "
                    f"({bad.size} of {len(array)} frames): fix or regenerate the conversation"
                )
            lengths[name] = len(array)
            object.__setattr__(self, name, array)
        if len(set(lengths.values())) != 1:
            raise ValueError(
                f"ConversationFeatures arrays disagree in length: {lengths['pose']} pose frames, "
                f"{lengths['speech']} speech frames, {lengths['activity']} activity frames, "
                f"{lengths['style']} style frames (a conversation's rotations, audio and "
                "activity must cover the same frames)"
            )

    @classmethod
    def from_conversation(
        cls, conversation: ConversationLike, n_mels: int = N_MELS
    ) -> ConversationFeatures:
        """Compute the features of a conversation; its motion and audio must cover the same frames.

        Raises:
            TypeError: if ``conversation`` lacks the attributes of :class:`ConversationLike`.
            ValueError: for wrong shapes, lengths or frame rate, non-finite rotations, or limbs
                marked unseen in ``conversation.visible``; :class:`~gesturelib.features.AudioError`
                for unusable audio.
        """
        missing = [
            name
            for name in ("audio", "sample_rate", "fps", "activity", "rotations")
            if not hasattr(conversation, name)
        ]
        if missing:
            raise TypeError(
                f"conversation must be a data_synth.Conversation (or have its audio, sample_rate, "
                f"fps, activity and rotations); a {type(conversation).__name__} lacks {missing}"
            )
        rotations = np.asarray(conversation.rotations, dtype=np.float32)
        if rotations.ndim != 3 or rotations.shape[1:] != (NUM_JOINTS, 6):
            raise ValueError(
                f"conversation.rotations must have shape (T, {NUM_JOINTS}, 6), got {rotations.shape}"
            )
        if conversation.fps != FPS:
            raise ValueError(
                f"conversation runs at {conversation.fps} fps; the models expect {FPS} fps"
            )
        visible = getattr(conversation, "visible", None)
        if visible is not None and not np.all(visible):
            raise ValueError(
                f"conversation has limbs a tracker did not see ({int(np.size(visible) - np.sum(visible))} "
                "limb-frames marked in conversation.visible): fill the gaps first, e.g. with the "
                "imputing autoencoder of notebook 06, and train on the filled motion"
            )
        speech = speech_features(
            conversation.audio, conversation.sample_rate, fps=conversation.fps, n_mels=n_mels
        )
        activity = activity_one_hot(np.asarray(conversation.activity))
        return cls(
            pose=rotations.reshape(len(rotations), POSE_DIM),
            speech=speech,
            activity=activity,
            style=_style_of(rotations),
        )

    def mirrored(self) -> ConversationFeatures:
        """The left-right mirror image of the motion, with the same speech and activity, and the
        style measured again from the mirrored motion (the hand height is the right hand's)."""
        rotations = mirror_rotations(self.pose.reshape(-1, NUM_JOINTS, 6))
        return ConversationFeatures(
            pose=rotations.reshape(-1, POSE_DIM),
            speech=self.speech,
            activity=self.activity,
            style=_style_of(rotations),
        )


def _style_of(rotations: np.ndarray) -> np.ndarray:
    """The style ``(T, 4)`` of limb rotations ``(T, 9, 6)``, measured on their keypoints."""
    return style_features(forward_kinematics(rotations.astype(np.float64))).astype(np.float32)


@dataclass(frozen=True)
class Normaliser:
    """Per-dimension standardisation of poses, speech and style, fitted on training data.

    ``normalised = (value - mean) / std``. It also keeps the percentiles of the training style
    (``style_percentiles[p, i]``: the ``p``-th percentile of feature ``i``, ``p`` = 0..100), the
    values style control asks for. Saved and loaded as JSON so that a checkpoint carries the
    statistics its model was trained with.
    """

    pose_mean: np.ndarray  # (54,)
    pose_std: np.ndarray  # (54,)
    speech_mean: np.ndarray  # (n_mels,)
    speech_std: np.ndarray  # (n_mels,)
    style_mean: np.ndarray  # (4,)
    style_std: np.ndarray  # (4,)
    style_percentiles: np.ndarray  # (101, 4)

    def __post_init__(self):
        n_mels, n_style = np.size(self.speech_mean), len(STYLE_FEATURES)
        for name, dim in (
            ("pose_mean", POSE_DIM),
            ("pose_std", POSE_DIM),
            ("speech_mean", n_mels),
            ("speech_std", n_mels),
            ("style_mean", n_style),
            ("style_std", n_style),
            ("style_percentiles", (101, n_style)),
        ):
            try:
                value = np.asarray(getattr(self, name), dtype=np.float32)
            except (TypeError, ValueError) as error:
                raise ValueError(f"Normaliser.{name} must be a list of numbers: {error}") from error
            shape = dim if isinstance(dim, tuple) else (dim,)
            if value.shape != shape or dim == 0:
                raise ValueError(f"Normaliser.{name} must have shape {shape}, got {value.shape}")
            is_std = name.endswith("std")
            usable = np.isfinite(value) & (value > 0 if is_std else True)
            if not usable.all():
                index = int(np.flatnonzero(~usable)[0])
                raise ValueError(
                    f"Normaliser.{name}[{index}] is {value[index]}, but it must be "
                    f"{'positive and finite' if is_std else 'finite'}: fit the statistics again "
                    "(Normaliser.fit on the training split)"
                )
            object.__setattr__(self, name, value)

    @classmethod
    def fit(cls, features: Sequence[ConversationFeatures]) -> Normaliser:
        """Statistics over every frame of ``features`` (the training split, mirrored or not)."""
        _check_features_list(features, "features")
        bands = sorted({f.speech.shape[1] for f in features})
        if len(bands) > 1:
            raise ValueError(
                f"features mix speech of {bands} mel bands; compute all with one n_mels"
            )
        pose, speech, style = (
            np.concatenate([getattr(f, part) for f in features]).astype(np.float64)
            for part in ("pose", "speech", "style")
        )
        return cls(
            pose_mean=pose.mean(0),
            pose_std=np.maximum(pose.std(0), MIN_STD),
            speech_mean=speech.mean(0),
            speech_std=np.maximum(speech.std(0), MIN_STD),
            style_mean=style.mean(0),
            style_std=np.maximum(style.std(0), MIN_STD),
            style_percentiles=np.percentile(style, np.arange(101), axis=0),
        )

    def normalise_pose(self, pose):
        """``(..., 54)`` raw 6D poses -> standardised."""
        _check_last_dim(pose, POSE_DIM, "pose")
        return (pose - _like(self.pose_mean, pose)) / _like(self.pose_std, pose)

    def denormalise_pose(self, pose):
        """``(..., 54)`` standardised -> raw 6D poses (reshape to ``(..., 9, 6)`` for kinematics)."""
        _check_last_dim(pose, POSE_DIM, "pose")
        return pose * _like(self.pose_std, pose) + _like(self.pose_mean, pose)

    def normalise_speech(self, speech):
        """``(..., n_mels)`` speech features -> standardised."""
        _check_last_dim(speech, len(self.speech_mean), "speech")
        return (speech - _like(self.speech_mean, speech)) / _like(self.speech_std, speech)

    def normalise_style(self, style):
        """``(..., 4)`` style features (:data:`~gesturelib.style.STYLE_FEATURES`) -> standardised."""
        _check_last_dim(style, len(STYLE_FEATURES), "style")
        return (style - _like(self.style_mean, style)) / _like(self.style_std, style)

    def style_at_percentiles(self, percentiles: dict[str, float]) -> np.ndarray:
        """The style ``(4,)`` that holds each named feature at a percentile of its training
        values (e.g. ``{"hand_height": 85}``) and the others at their median."""
        unknown = sorted(set(percentiles) - set(STYLE_FEATURES))
        if unknown:
            raise ValueError(f"unknown style {unknown}; the style features are {STYLE_FEATURES}")
        chosen = np.array([percentiles.get(name, 50.0) for name in STYLE_FEATURES], np.float64)
        if not np.all((chosen >= 0) & (chosen <= 100)):
            raise ValueError(f"style percentiles must lie in [0, 100], got {percentiles}")
        grid = np.arange(101)
        columns = self.style_percentiles.T.astype(np.float64)
        return np.array(
            [np.interp(p, grid, column) for p, column in zip(chosen, columns, strict=True)]
        )

    def to_dict(self) -> dict:
        """JSON-able form (lists of floats)."""
        return {name: value.tolist() for name, value in asdict(self).items()}

    @classmethod
    def from_dict(cls, values: dict) -> Normaliser:
        """Inverse of :meth:`to_dict`; ``ValueError`` for missing keys, wrong lengths, NaN, std <= 0."""
        expected = {f.name for f in fields(cls)}
        if not isinstance(values, Mapping):
            raise ValueError(
                f"normaliser statistics must be a dictionary, got {type(values).__name__}"
            )
        if set(values) != expected:
            raise ValueError(
                f"normaliser needs exactly the keys {sorted(expected)}, got {sorted(map(str, values))}"
            )
        return cls(**values)

    def save(self, path: str | os.PathLike, overwrite: bool = False) -> None:
        """Write the statistics as JSON; an existing file is kept unless ``overwrite``.

        The file is written whole or not at all (a temporary file, then renamed).
        """
        path = Path(path)
        if path.is_dir():
            raise IsADirectoryError(f"{path} is a folder; give a file name such as normaliser.json")
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} already exists; pass overwrite=True to replace it")
        temporary = path.with_name(path.name + ".partial")
        try:
            temporary.write_text(json.dumps(self.to_dict()))
            os.replace(temporary, path)
        finally:
            temporary.unlink(missing_ok=True)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Normaliser:
        """Read statistics written by :meth:`save`; ``ValueError`` naming the file if unusable."""
        path = Path(path)
        try:
            return cls.from_dict(json.loads(path.read_text()))
        except (OSError, ValueError) as error:
            raise ValueError(
                f"cannot read normalisation statistics from {path}: {error}"
            ) from error


def _check_last_dim(values, dim: int, name: str) -> None:
    shape = tuple(np.shape(values))
    if shape[-1:] != (dim,):
        hint = (
            f"; flatten the joints: reshape(..., {POSE_DIM})"
            if shape[-2:] == (NUM_JOINTS, 6)
            else ""
        )
        raise ValueError(f"{name} must have shape (..., {dim}), got {shape}{hint}")


def _check_features_list(features, name: str) -> None:
    """``features`` must be a non-empty list of :class:`ConversationFeatures`."""
    if isinstance(features, ConversationFeatures) or not isinstance(features, Sequence):
        raise TypeError(
            f"{name} must be a list of ConversationFeatures (one per conversation), got "
            f"{type(features).__name__}"
        )
    if not features:
        raise ValueError(f"{name} is empty: give at least one conversation")
    for number, item in enumerate(features):
        if not isinstance(item, ConversationFeatures):
            raise TypeError(
                f"{name}[{number}] is a {type(item).__name__}, not ConversationFeatures: compute "
                "them with ConversationFeatures.from_conversation (or use make_datasets)"
            )


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
    ``speech (L, W, 27)``, ``activity (L, W, 4)`` with ``W = past + 1 + future``, ``style
    (L, 4)``), float32.
    """

    def __init__(
        self,
        features: Sequence[ConversationFeatures],
        config: WindowConfig,
        normaliser: Normaliser,
        mirror: bool = False,
    ):
        _check_features_list(features, "features")
        if not isinstance(config, WindowConfig):
            raise TypeError(f"config must be a WindowConfig, got {type(config).__name__}")
        if not isinstance(normaliser, Normaliser):
            raise TypeError(f"normaliser must be a Normaliser, got {type(normaliser).__name__}")
        n_mels = len(normaliser.speech_mean)
        for number, conversation in enumerate(features):
            if conversation.speech.shape[1] != n_mels:
                raise ValueError(
                    f"features[{number}] has {conversation.speech.shape[1]} mel bands but the "
                    f"normaliser was fitted on {n_mels}: compute both with the same n_mels"
                )
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
                    "style": torch.from_numpy(
                        normaliser.normalise_style(conversation.style).astype(np.float32)
                    ),
                }
            )
            self._index.extend((number, start) for start in range(first, last + 1, config.stride))
        if not self._index:
            raise ValueError(
                f"no conversation is long enough for one window: each needs at least "
                f"{config.frames_needed} frames ({config.frames_needed / FPS:.1f} s)"
            )

    def fingerprint(self) -> str:
        """A short hash of everything the items are cut from: the window config and the
        normalised arrays of every conversation."""
        from gesturelib.checkpoints import hash_value

        hasher = hashlib.sha256()
        hash_value(hasher, [asdict(self.config), self._streams])
        return hasher.hexdigest()[:16]

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
            "style": streams["style"][targets],
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
    if not isinstance(splits, Mapping):
        raise TypeError(
            f"splits must be a dictionary of conversation lists by split name (as "
            f"data_synth.load_dataset returns), got {type(splits).__name__}"
        )
    if "train" not in splits:
        raise ValueError(
            f"splits must include 'train' to fit the normalisation; got {sorted(splits)}"
        )
    for name, conversations in splits.items():
        if isinstance(conversations, (str, bytes)) or not isinstance(conversations, Sequence):
            raise TypeError(
                f"split {name!r} must be a list of conversations, got {type(conversations).__name__}"
            )
        if not conversations:
            raise ValueError(f"split {name!r} has no conversations; drop it or fill it")
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
        "style": len(STYLE_FEATURES),
    }
