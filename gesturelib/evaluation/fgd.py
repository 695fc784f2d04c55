"""The Fréchet Gesture Distance (FGD) at the course's scale: a small motion autoencoder's features.

FGD (Yoon et al. 2020) is FID for gestures. An autoencoder is trained to reconstruct short
windows of the *training* motion; its encoder then maps any window to a feature vector, and the
FGD between two sets of motion is the Fréchet distance between Gaussians fitted to their window
features (:func:`gesturelib.metrics.frechet_distance`). Unlike a histogram of speeds it sees
poses and their dynamics together. The GENEA 2022 challenge (windows of 34 frames) found it the
objective measure that best tracked people's ratings of human-likeness.

Ours:

* :class:`MotionFeatureNetwork`: windows of ``window`` = 32 frames (1.28 s at 25 fps) of the 9
  keypoints ``(32, 9, 3)`` in cm (root at the origin), flattened to 27 channels, with their
  frame-to-frame differences as 27 more (``velocities``), standardised by the training motion's
  statistics (buffers, saved with the weights); then 1-D convolutions over time, halving it twice
  (32 -> 16 -> 8 frames), and a linear layer to ``feature_size`` = 32 numbers; a mirrored decoder
  reconstructs the window. ``loss(batch)`` is the reconstruction MSE, so :mod:`gesturelib.train`
  trains it like any model of the course (78k parameters; 25 s on one CPU core for the 24
  minutes of the full training split; quick mode: 30k parameters, 3 s).
* :func:`feature_network`: the network of a dataset, trained once and cached with
  :func:`gesturelib.train.load_or_train` (the key covers the motion itself).
* :func:`fgd`: FGD between two lists of ``(T, 9, 3)`` motions (e.g. one per held-out
  conversation), from windows cut every ``stride`` = 8 frames.

Usage::

    network = feature_network([c.positions for c in splits["train"]],
                              [c.positions for c in splits["val"]], "cache")
    truth = [c.positions for c in splits["test"]]
    fgd(network, generated, truth)

FGD is in squared feature units: compare values of one network, never across networks or datasets.
It needs minutes of motion on each side: 3 minutes of held-out motion (the full data's test split)
still varies by a factor of 2 to 3 between redraws of the same conversations' motion, and the
quick data's one 30 s test conversation is too little to rank anything.

Why velocities: with positions alone, 3 minutes of held-out motion held still at the mean pose
scored only 1.6 times the FGD of the worst of 8 redraws of the same conversations' motion
(``data_synth.resample_motion``), because where the hands hover differs by several cm between
draws; with velocities as well, 3.1 times, as a motionless agent then differs in every window.

What FGD does not measure: it compares two *distributions* of windows and never pairs a window
with its speech, so motion that is natural but belongs to other speech (the "mismatched"
condition of GENEA) scores about as well as the ground truth. At this data scale the redraw floor
and mismatched motion overlap (full data's test split: 91 +- 43 over 8 redraws against
106 +- 38 over 9 sets of 3 other conversations; the mean pose held still: 575); the speech-aligned measures of :mod:`~gesturelib.evaluation.headline` (stroke lead,
speaking/listening ratio) are the ones that see appropriateness.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.utils.data import Dataset

from gesturelib.checkpoints import hash_value
from gesturelib.configs import check_fields
from gesturelib.conventions import FPS
from gesturelib.metrics import frechet_distance
from gesturelib.models.common import check_config_type, eval_mode
from gesturelib.skeleton import NUM_JOINTS
from gesturelib.train import TrainConfig, load_or_train

#: Frames between the starts of consecutive windows scored by :func:`fgd`.
FGD_STRIDE = 8
#: Frames between the starts of consecutive training windows.
TRAIN_STRIDE = 4
#: How the feature network is trained, in full and quick mode.
TRAINING = TrainConfig(epochs=20, batch_size=64, warmup_steps=200, lr_max=3e-3, patience=4)
QUICK_TRAINING = TrainConfig.quick(epochs=12, batch_size=16, warmup_steps=50, lr_max=3e-3)

_CHANNELS = NUM_JOINTS * 3  # 27 numbers a frame


@dataclass(frozen=True)
class MotionFeatureConfig:
    """Sizes of the FGD feature network.

    Attributes:
        window: frames in one window (32 = 1.28 s at 25 fps; GENEA 2022 used 34); a multiple of
            ``2 ** levels``.
        feature_size: numbers per window feature (GENEA: 32).
        channels: width of every convolution.
        levels: stride-2 convolutions, each halving the time axis.
        min_std: floor, in cm, of the standard deviations the positions are standardised by, so
            that a coordinate that hardly moves in the training motion (the sternum's height
            varies by 0.03 cm) is not blown up into a feature of its own.
        velocities: also read (and reconstruct) the frame-to-frame differences of the
            keypoints, so that the features see motion as well as where the hands are.
        min_velocity_std: the same floor for the differences, in cm per frame (the wrists'
            standard deviation is about 1 cm per frame).
    """

    window: int = 32
    feature_size: int = 32
    channels: int = 48
    levels: int = 2
    min_std: float = 1.0
    velocities: bool = True
    min_velocity_std: float = 0.1

    def __post_init__(self):
        check_fields(
            self,
            positive=("window", "feature_size", "channels"),
            counts=("levels",),
            non_negative=("min_std", "min_velocity_std"),
            flags=("velocities",),
        )
        if self.window % 2**self.levels:
            raise ValueError(
                f"MotionFeatureConfig.window must be a multiple of 2 ** levels = "
                f"{2**self.levels}, got {self.window}"
            )
        for name in ("min_std", "min_velocity_std"):
            if getattr(self, name) <= 0:
                raise ValueError(
                    f"MotionFeatureConfig.{name} must be > 0 cm, got {getattr(self, name)}"
                )

    @classmethod
    def quick(cls, **changes) -> MotionFeatureConfig:
        """Narrow convolutions for tests and quick mode; ``changes`` override any field."""
        return dataclasses.replace(cls(channels=24), **changes)


class MotionFeatureNetwork(nn.Module):
    """Convolutional autoencoder of keypoint windows; its encoder gives the FGD features.

    ``encode((N, W, 9, 3) cm) -> (N, feature_size)``; ``loss(batch)`` needs
    ``batch["positions"] (B, W, 9, 3)`` in cm and returns the reconstruction MSE (per number, in
    standardised units) as ``loss`` and ``mse``. The standardisation statistics ``mean`` and
    ``std`` ``(C,)`` (C = 54 input channels with velocities, else 27) are buffers: set them with
    :meth:`fit_standardiser` before training; a checkpoint restores them with the weights.
    """

    config_class = MotionFeatureConfig

    def __init__(self, config: MotionFeatureConfig):
        super().__init__()
        check_config_type(self, config)
        self.config = config
        width, short = config.channels, config.window // 2**config.levels
        channels = _CHANNELS * (2 if config.velocities else 1)
        self.register_buffer("mean", torch.zeros(channels))
        self.register_buffer("std", torch.ones(channels))
        encoder = [nn.Conv1d(channels, width, 3, padding=1), nn.LeakyReLU(0.2)]
        decoder = [nn.Unflatten(1, (width, short))]
        for _ in range(config.levels):
            encoder += [nn.Conv1d(width, width, 4, stride=2, padding=1), nn.LeakyReLU(0.2)]
            decoder += [nn.ConvTranspose1d(width, width, 4, stride=2, padding=1), nn.LeakyReLU(0.2)]
        encoder += [nn.Flatten(), nn.Linear(width * short, config.feature_size)]
        self.encoder = nn.Sequential(*encoder)  # (N, C, W) -> (N, feature_size)
        decoder.append(nn.Conv1d(width, channels, 3, padding=1))
        self.decoder = nn.Sequential(
            nn.Linear(config.feature_size, width * short), nn.LeakyReLU(0.2), *decoder
        )  # (N, feature_size) -> (N, C, W)

    @torch.no_grad()
    def fit_standardiser(self, positions: Sequence[np.ndarray]) -> MotionFeatureNetwork:
        """Set ``mean`` and ``std`` to those of every frame of ``positions`` (a list of
        ``(T, 9, 3)`` in cm) and of its frame-to-frame differences, the standard deviations
        floored at ``config.min_std`` and ``config.min_velocity_std``; returns self."""
        motions = [np.asarray(p, dtype=np.float64).reshape(-1, _CHANNELS) for p in positions]
        frames = np.concatenate(motions)
        mean, std = frames.mean(axis=0), np.maximum(frames.std(axis=0), self.config.min_std)
        if self.config.velocities:
            steps = np.concatenate([np.diff(motion, axis=0) for motion in motions])
            mean = np.concatenate([mean, steps.mean(axis=0)])
            std = np.concatenate([std, np.maximum(steps.std(axis=0), self.config.min_velocity_std)])
        self.mean.copy_(torch.from_numpy(mean))
        self.std.copy_(torch.from_numpy(std))
        return self

    def _standardised(self, windows: torch.Tensor) -> torch.Tensor:
        """``(N, W, 9, 3)`` cm -> ``(N, C, W)`` standardised, channels first for the convolutions."""
        expected = (self.config.window, NUM_JOINTS, 3)
        if isinstance(windows, np.ndarray):
            windows = torch.from_numpy(windows)
        if (
            not isinstance(windows, torch.Tensor)
            or windows.ndim != 4
            or windows.shape[1:] != expected
        ):
            got = tuple(windows.shape) if hasattr(windows, "shape") else type(windows).__name__
            raise ValueError(
                f"MotionFeatureNetwork needs windows of shape (N, {', '.join(map(str, expected))})"
                f" (keypoints in cm), got {got}"
            )
        flat = windows.to(self.mean).flatten(2)  # (N, W, 27)
        if self.config.velocities:  # the first frame gets the second's difference
            steps = flat[:, 1:] - flat[:, :-1]  # (N, W - 1, 27)
            flat = torch.cat([flat, torch.cat([steps[:, :1], steps], dim=1)], dim=-1)  # (N, W, 54)
        return ((flat - self.mean) / self.std).transpose(1, 2)

    def encode(self, windows: torch.Tensor) -> torch.Tensor:
        """Windows of keypoints ``(N, W, 9, 3)`` in cm -> features ``(N, feature_size)``."""
        return self.encoder(self._standardised(windows))

    def loss(self, batch: dict) -> dict[str, torch.Tensor]:
        """Reconstruction MSE of ``batch["positions"] (B, W, 9, 3)``, in standardised units."""
        if not isinstance(batch, dict) or "positions" not in batch:
            got = sorted(batch) if isinstance(batch, dict) else type(batch).__name__
            raise ValueError(f"MotionFeatureNetwork.loss needs batch['positions'], got {got}")
        target = self._standardised(batch["positions"])
        mse = torch.mean((self.decoder(self.encoder(target)) - target) ** 2)
        return {"loss": mse, "mse": mse.detach()}


class MotionWindows(Dataset):
    """Windows of ``window`` frames cut every ``stride`` frames from a list of ``(T, 9, 3)``
    motions; item ``{"positions": (window, 9, 3) float32}``.

    ``fingerprint()`` hashes the windows' settings and the motion (what
    :func:`gesturelib.checkpoints.dataset_fingerprint` reads), so a cached network is retrained
    when the motion changes.
    """

    def __init__(
        self, positions: Sequence[np.ndarray], window: int, stride: int, name: str = "positions"
    ):
        self.window, self.stride = int(window), int(stride)
        self.motions = [
            torch.from_numpy(np.ascontiguousarray(p, dtype=np.float32))
            for p in _motion_list(positions, name, window)
        ]
        self._index = [
            (number, start)
            for number, motion in enumerate(self.motions)
            for start in range(0, len(motion) - self.window + 1, self.stride)
        ]

    def fingerprint(self) -> str:
        hasher = hashlib.sha256()
        hash_value(hasher, [self.window, self.stride, self.motions])
        return hasher.hexdigest()[:16]

    def __len__(self) -> int:
        return len(self._index)

    def __getitem__(self, item: int) -> dict[str, torch.Tensor]:
        number, start = self._index[item]
        return {"positions": self.motions[number][start : start + self.window]}


def feature_network(
    train_positions: Sequence[np.ndarray],
    val_positions: Sequence[np.ndarray] | None,
    cache_dir: str | Path,
    quick: bool = False,
    seed: int = 0,
    *,
    progress: bool = True,
) -> MotionFeatureNetwork:
    """The FGD feature network of this training motion: loaded from ``cache_dir`` if trained
    before, else trained (full mode: 25 s on one CPU core for the full data's 24 minutes; quick
    mode: 3 s for 2 minutes).

    Args:
        train_positions: the training motion, a list of ``(T, 9, 3)`` keypoints in cm (e.g.
            ``[c.positions for c in splits["train"]]``); each at least ``window`` frames.
        val_positions: the same for early stopping, or None (then the training loss decides).
        cache_dir: the folder of cached runs (shared with :func:`gesturelib.train.load_or_train`).
        quick: the quick config and training (CI); another network, cached apart.
        seed: initial weights and shuffle order.
        progress: show the progress bar, or the line naming the file loaded.
    Returns:
        The network in eval mode, on the CPU.
    Raises:
        ValueError: naming the motion, if one is not ``(T, 9, 3)``, not finite, or too short.
    """
    config = MotionFeatureConfig.quick() if quick else MotionFeatureConfig()
    train_config = dataclasses.replace(QUICK_TRAINING if quick else TRAINING, seed=seed)
    train_data = MotionWindows(train_positions, config.window, TRAIN_STRIDE, "train_positions")
    val_data = None
    if val_positions is not None:
        val_data = MotionWindows(val_positions, config.window, TRAIN_STRIDE, "val_positions")
    network, _ = load_or_train(
        MotionFeatureNetwork,
        config,
        train_data,
        val_data,
        train_config,
        cache_dir,
        build=lambda c: MotionFeatureNetwork(c).fit_standardiser(train_data.motions),
        progress=progress,
    )
    return network


@torch.no_grad()
def motion_features(
    network: MotionFeatureNetwork,
    motions: Sequence[np.ndarray],
    stride: int = FGD_STRIDE,
    batch_size: int = 512,
    name: str = "motions",
) -> np.ndarray:
    """Features ``(N, feature_size)`` of the windows cut every ``stride`` frames from each of
    ``motions`` (a list of ``(T, 9, 3)``, or one such array), in eval mode."""
    if not isinstance(network, MotionFeatureNetwork):
        raise TypeError(f"network must be a MotionFeatureNetwork, got {type(network).__name__}")
    if not (isinstance(stride, int | np.integer) and stride >= 1):
        raise ValueError(f"stride must be an integer >= 1 (frames), got {stride!r}")
    windows = MotionWindows(motions, network.config.window, stride, name)
    stacked = torch.stack([windows[i]["positions"] for i in range(len(windows))])
    with eval_mode(network):
        parts = [network.encode(chunk) for chunk in stacked.split(batch_size)]
    return torch.cat(parts).cpu().numpy().astype(np.float64)


def fgd(
    network: MotionFeatureNetwork,
    motions: Sequence[np.ndarray],
    reference: Sequence[np.ndarray],
    stride: int = FGD_STRIDE,
) -> float:
    """Fréchet Gesture Distance between ``motions`` and ``reference`` (0: the same features).

    Args:
        network: a trained :class:`MotionFeatureNetwork` (:func:`feature_network`).
        motions, reference: lists of ``(T, 9, 3)`` keypoints in cm at 25 fps (or one such
            array), e.g. one per held-out conversation; each at least ``network.config.window``
            frames, and each list at least two windows in all.
        stride: frames between window starts.
    Returns:
        The Fréchet distance between Gaussians fitted to the two sets of window features, in
        squared feature units (comparable only between values of the same network).
    Raises:
        ValueError: naming the argument, for a wrong shape, non-finite values, a motion shorter
            than a window, or fewer than two windows.
    """
    features = []
    for name, value in (("motions", motions), ("reference", reference)):
        values = motion_features(network, value, stride, name=name)
        if len(values) < 2:
            window = network.config.window
            raise ValueError(
                f"{name} gives {len(values)} window; FGD fits a Gaussian and needs at least 2: "
                f"give at least {window + stride} frames (window {window} + stride {stride})"
            )
        features.append(values)
    return frechet_distance(*features)


def _motion_list(positions, name: str, window: int) -> list[np.ndarray]:
    """``positions`` as a checked list of float ``(T, 9, 3)`` arrays with ``T >= window``."""
    if isinstance(positions, np.ndarray | torch.Tensor) and positions.ndim == 3:
        positions = [positions]
    if isinstance(positions, str | bytes) or not isinstance(positions, Sequence | np.ndarray):
        raise ValueError(
            f"{name} must be a list of (T, {NUM_JOINTS}, 3) keypoint arrays, "
            f"got {type(positions).__name__}"
        )
    if len(positions) == 0:
        raise ValueError(f"{name} is empty: give at least one (T, {NUM_JOINTS}, 3) motion")
    checked = []
    for number, motion in enumerate(positions):
        if isinstance(motion, torch.Tensor):
            motion = motion.detach().cpu().numpy()
        try:
            array = np.asarray(motion, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(
                f"{name}[{number}] must be a (T, {NUM_JOINTS}, 3) array of numbers, "
                f"got {type(motion).__name__}"
            ) from None
        if array.ndim != 3 or array.shape[1:] != (NUM_JOINTS, 3):
            raise ValueError(
                f"{name}[{number}] must have shape (T, {NUM_JOINTS}, 3) (keypoints in cm, e.g. "
                f"Conversation.positions), got {array.shape}"
            )
        if len(array) < window:
            raise ValueError(
                f"{name}[{number}] has {len(array)} frames, fewer than the feature window of "
                f"{window} frames ({window / FPS:.2f} s at {FPS} fps)"
            )
        if not np.isfinite(array).all():
            raise ValueError(f"{name}[{number}] holds NaN or infinite values")
        checked.append(array)
    return checked
