"""A judge for training (:class:`gesturelib.train.Judge`): the FGD of the motion a model generates.

Training keeps the epoch with the best validation loss, which is teacher-forced: every frame is
predicted one step ahead of the *recorded* past. A generating model rolls out on its own past
instead, and how well it does that can change from one epoch to the next while the validation
loss keeps falling (the Flow-VAE's does, every epoch: ``docs/benchmarks.md``, "Choosing the
epoch by the validation conversations' FGD"). :class:`GeneratedMotionFGD` scores what a student
sees: it generates motion for the validation conversations and measures its FGD
(:mod:`~gesturelib.evaluation.fgd`) to their recorded motion. A recipe with
``TrainConfig.judged_epochs`` > 0 is trained with it (:func:`gesturelib.pipeline.train_model`),
and keeps the best-judged of its last epochs.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence

import numpy as np
from torch import nn

from gesturelib.checkpoints import hash_value, state_fingerprint
from gesturelib.data import ConversationLike, Normaliser
from gesturelib.evaluation.fgd import MotionFeatureNetwork, fgd
from gesturelib.features import speech_features
from gesturelib.sampling import generate
from gesturelib.skeleton import forward_kinematics


class GeneratedMotionFGD:
    """``judge(model) -> float``: the FGD between the motion ``model`` generates for
    ``conversations`` (their speech and who is talking) and their recorded motion, averaged over
    ``samples`` draws from ``seed``. Lower is better; ``inf`` for motion that is not finite.

    Args:
        conversations: held-out conversations (``audio``, ``sample_rate``, ``activity``,
            ``positions``), with a few minutes of motion in all: the FGD of less is mostly noise.
        normaliser: the model's normaliser.
        features: the FGD's trained feature network (:func:`~gesturelib.evaluation.fgd.feature_network`).
        samples: draws per conversation (generated together, as one batch).
        seed: of the draws, the same for every epoch judged.
    """

    def __init__(
        self,
        conversations: Sequence[ConversationLike],
        normaliser: Normaliser,
        features: MotionFeatureNetwork,
        *,
        samples: int = 3,
        seed: int = 0,
    ):
        if not conversations:
            raise ValueError("GeneratedMotionFGD needs at least one conversation to judge by")
        if not (isinstance(samples, int) and samples >= 1):
            raise ValueError(f"samples must be an int >= 1, got {samples!r}")
        self.normaliser, self.features = normaliser, features
        self.samples, self.seed = samples, seed
        self.speech = [speech_features(c.audio, c.sample_rate) for c in conversations]
        self.activity = [np.asarray(c.activity) for c in conversations]
        self.truth = [np.asarray(c.positions) for c in conversations]
        hasher = hashlib.sha256()
        hash_value(hasher, [self.speech, self.activity, self.truth])
        self.identity = {
            "judge": type(self).__name__,
            "conversations": hasher.hexdigest()[:16],
            "features": state_fingerprint(features),
            "samples": samples,
            "seed": seed,
        }

    def __call__(self, model: nn.Module) -> float:
        rotations = [  # (samples, T, 9, 6) per conversation
            generate(model, self.normaliser, speech, activity, samples=self.samples, seed=self.seed)
            for speech, activity in zip(self.speech, self.activity, strict=True)
        ]
        if not all(np.isfinite(r).all() for r in rotations):
            return math.inf
        return float(
            np.mean(
                [
                    fgd(self.features, [forward_kinematics(r[k]) for r in rotations], self.truth)
                    for k in range(self.samples)
                ]
            )
        )
