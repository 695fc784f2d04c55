"""The training judge of generated motion: the FGD of the motion a model generates."""

import math

import numpy as np
import pytest

from gesturelib.data import make_datasets
from gesturelib.evaluation import judge as judge_module
from gesturelib.evaluation.fgd import feature_network
from gesturelib.evaluation.judge import GeneratedMotionFGD
from gesturelib.models import FlowVAE
from gesturelib.recipes import RECIPES
from gesturelib.train import TrainConfig, build_seeded, train

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """Three 20 s training conversations, two held out, the quick Flow-VAE (untrained) with its
    normaliser, and the quick feature network of the training motion."""
    from data_synth import generate_conversation

    splits = {
        "train": [generate_conversation(20.0, seed=seed) for seed in (1, 2, 3)],
        "val": [generate_conversation(12.0, seed=seed) for seed in (4, 5)],
    }
    windows, config, _ = RECIPES["flowvae"].settings(quick=True)
    datasets, normaliser = make_datasets(splits, windows)
    model = build_seeded(FlowVAE, config, 0)
    train(model, datasets["train"], None, TrainConfig.quick(epochs=1), progress=False)
    model.eval()
    cache = tmp_path_factory.mktemp("fgd")
    positions = [c.positions for c in splits["train"]]
    features = feature_network(positions, None, cache, quick=True, progress=False)
    return splits, normaliser, model, features


def test_the_judge_scores_generated_motion_the_same_each_time(setting):
    splits, normaliser, model, features = setting
    judge = GeneratedMotionFGD(splits["val"], normaliser, features, samples=2)
    score = judge(model)
    assert math.isfinite(score) and score > 0
    assert judge(model) == score  # its own seed: every epoch is judged on the same draws
    other = GeneratedMotionFGD(splits["val"], normaliser, features, samples=2, seed=1)
    assert other(model) != score


def test_the_judges_identity_follows_what_determines_its_scores(setting):
    splits, normaliser, _, features = setting

    def identity(conversations=splits["val"], **options):
        return GeneratedMotionFGD(conversations, normaliser, features, **options).identity

    assert identity() == identity()
    assert identity() != identity(samples=2)
    assert identity() != identity(seed=1)
    assert identity() != identity(splits["val"][:1])


def test_motion_that_is_not_finite_is_judged_the_worst(setting, monkeypatch):
    splits, normaliser, model, features = setting
    judge = GeneratedMotionFGD(splits["val"], normaliser, features, samples=1)
    real = judge_module.generate

    def blowing_up(*args, **options):  # a rollout that diverges in its second conversation
        rotations = real(*args, **options)
        if blowing_up.calls:
            rotations[:, -1] = np.inf
        blowing_up.calls += 1
        return rotations

    blowing_up.calls = 0
    monkeypatch.setattr(judge_module, "generate", blowing_up)
    assert judge(model) == math.inf


def test_the_judge_needs_conversations_and_samples(setting):
    splits, normaliser, _, features = setting
    with pytest.raises(ValueError, match="at least one conversation"):
        GeneratedMotionFGD([], normaliser, features)
    with pytest.raises(ValueError, match="samples must be an int >= 1"):
        GeneratedMotionFGD(splits["val"], normaliser, features, samples=0)
