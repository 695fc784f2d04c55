"""The evaluation table: every system's measures on the held-out conversations, with spreads.

A *system* is anything that gives motion for a conversation's speech: a trained model (one run,
or several runs of one recipe from different seeds), or a reference. Its motion is given as
*draws*: ``runs[r][k][i]``, keypoints ``(T, 9, 3)`` of sample ``k`` of run ``r`` for held-out
conversation ``i``. Every measure is computed on each draw (all conversations pooled), and the
table gives the mean and the standard deviation over draws (the samples of every run together);
diversity, a measure *between* samples, is computed per run.

The references (:func:`reference_draws`), on the same conversations:

* ``ground_truth``: the recorded motion (the target values of measures that are not distances);
* ``floor``: motion drawn again by the generator for the same speech: as natural and as
  appropriate as motion can be without being the recorded one (the generator's data only);
* ``mismatched``: recorded motion of other conversations: natural, but for other speech;
* ``mean_pose``: the training data's mean pose, held still.

Columns (:data:`METRICS`): naturalness first, then appropriateness. A measure that is undefined
for a system (the mean pose has no strokes, so no lead) is NaN, written empty.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gesturelib.conventions import FPS
from gesturelib.evaluation.headline import (
    DRIFT_CHUNK_S,
    drift,
    headline_measures,
    joint_speed_histogram,
    reference_motions,
)
from gesturelib.evaluation.rules import rule_measures
from gesturelib.evaluation.transfer import style_transfer
from gesturelib.metrics import (
    JOINT_GROUPS,
    acceleration,
    hellinger_distance,
    jerk,
)

#: The table's measures, in column order, with what they say (the README lists them).
METRICS: dict[str, str] = {
    "hellinger": "wrist-speed Hellinger distance to the ground truth (0: the same speeds)",
    "hellinger_elbows": "the same for the elbows",
    "hellinger_all": "the same for all nine keypoints",
    "acceleration": "mean wrist acceleration, cm/s^2",
    "jerk": "mean wrist jerk, cm/s^3 (jittery motion: high)",
    "fgd": "Frechet gesture distance to the ground truth (0: the same distribution of windows)",
    "diversity": "mean distance in cm between two samples for the same speech",
    "ratio": "wrist speed while speaking over wrist speed while listening",
    "lead": "seconds by which wrist speed leads the speech's emphasis (the rule: 0.2)",
    "accent_hits": "fraction of the agent's accents with a stroke on the rule's time",
    "stroke_precision": "fraction of the strokes found that are on a rule's time",
    "lead_error": "median seconds between a stroke's lead over its accent and the rule's",
    "nods": "fraction of the partner's phrase ends answered by a nod when the rule says",
    "nod_precision": "fraction of the nods found that are in a rule's window",
    "beat_align": "Bailando's beat-alignment score against speech onsets (the field's proxy)",
    "transfer": "slope of the style realised against a reference's, by its latent codes, averaged"
    " over the style features (1: taken in full; models that replay a reference only)",
    "drift": "limb-angle error to the ground truth in the last 10 s over the first 10 s, the"
    " samples averaged first (1: an error that does not grow; models only)",
}

#: The references' row names (:func:`reference_draws`).
REFERENCES = ("ground_truth", "floor", "mismatched", "mean_pose")

Draws = Sequence[Sequence[Sequence[np.ndarray]]]  # runs[r][k][i]: (T, 9, 3)


def score_draw(conversations, motions: Sequence[np.ndarray], features=None) -> dict[str, float]:
    """Every measure but diversity for one draw: ``motions`` one ``(T, 9, 3)`` per conversation.

    Args:
        features: a trained :class:`~gesturelib.evaluation.fgd.MotionFeatureNetwork` for the
            FGD, or None to leave it out (NaN).
    """
    from gesturelib.evaluation.fgd import fgd

    truth = [c.positions for c in conversations]
    scores = headline_measures(conversations, motions)
    for group in ("elbows", "all"):
        scores[f"hellinger_{group}"] = hellinger_distance(
            joint_speed_histogram(motions, group), joint_speed_histogram(truth, group)
        )
    wrists = list(JOINT_GROUPS["wrists"])
    scores["acceleration"] = _pooled_mean(acceleration, motions, wrists)
    scores["jerk"] = _pooled_mean(jerk, motions, wrists)
    scores["fgd"] = fgd(features, motions, truth) if features is not None else np.nan
    scores.update(rule_measures(conversations, motions))
    return scores


def diversity(samples: Sequence[Sequence[np.ndarray]]) -> float:
    """Mean distance in cm between the same keypoint of two samples for the same speech, over
    keypoints, frames, pairs of samples and conversations; ``samples[k][i]`` is ``(T, 9, 3)``.
    NaN for a single sample."""
    if len(samples) < 2:
        return np.nan
    distances = [
        np.linalg.norm(samples[a][i] - samples[b][i], axis=-1).mean()
        for a in range(len(samples))
        for b in range(a + 1, len(samples))
        for i in range(len(samples[0]))
    ]
    return float(np.mean(distances))


def score_system(
    conversations, runs: Draws, features=None, deterministic=False, transfer=(), drifts=()
) -> dict:
    """One row of the table: each measure's mean over the draws of every run and its standard
    deviation (``<name>_sd``), and ``seeds``, the number of runs. A measure undefined for any draw
    is NaN (empty in the table), and so is a spread over a single value.

    Diversity is a property of a run's samples together: one value per run, its spread over runs.
    ``deterministic``: the system gives one motion per conversation whatever is drawn (a run is
    one draw), so its diversity is 0. ``transfer``: each run's
    :func:`~gesturelib.evaluation.transfer.style_transfer`, for a model that replays a reference
    (NaN without). ``drifts``: each run's :func:`~gesturelib.evaluation.headline.drift`, for a
    model (NaN without).
    """
    assert len(transfer) in (0, len(runs)), "one transfer per run, or none"
    assert len(drifts) in (0, len(runs)), "one drift per run, or none"
    draws = [score_draw(conversations, sample, features) for run in runs for sample in run]
    per_run = {
        "diversity": [0.0 if deterministic else diversity(run) for run in runs],
        "transfer": list(transfer) or [np.nan],
        "drift": list(drifts) or [np.nan],
    }
    row: dict[str, float] = {"seeds": len(runs)}
    for name in METRICS:
        values = np.array(per_run[name] if name in per_run else [d[name] for d in draws])
        defined = not np.isnan(values).any()
        row[name] = float(values.mean()) if defined else np.nan
        row[f"{name}_sd"] = float(values.std(ddof=1)) if defined and values.size > 1 else np.nan
    return row


def model_rotations(conversations, model, normaliser, samples: int, seed: int = 0) -> list:
    """Limb rotations ``rotations[k][i]`` ``(T, 9, 6)``: sample ``k`` of the model for held-out
    conversation ``i``'s speech and who is talking (never its motion). A deterministic model
    (``noise_dim`` 0) gives one draw, whatever ``samples`` asks."""
    from gesturelib.pipeline import speech_to_motion

    drawn = samples if model.noise_dim > 0 else 1
    per_conversation = [
        speech_to_motion(
            model, normaliser, c.audio, c.sample_rate, activity=c.activity, samples=drawn, seed=seed
        ).rotations
        for c in conversations
    ]
    return [[rotations[k] for rotations in per_conversation] for k in range(drawn)]


def positions_of(rotations: list, smoothed: bool = False) -> list:
    """Keypoints ``[k][i]`` ``(T, 9, 3)`` of :func:`model_rotations`' draws; ``smoothed``: after
    Kucherenko et al.'s post-processing, a One Euro filter and then a 5-frame moving average
    (:mod:`gesturelib.postprocess`)."""
    from gesturelib.postprocess import smooth_rotations
    from gesturelib.skeleton import forward_kinematics

    def post(rotations):
        if not smoothed:
            return rotations
        return smooth_rotations(smooth_rotations(rotations, "one_euro", fps=FPS), "moving_average")

    return [[forward_kinematics(post(r)) for r in draw] for draw in rotations]


def reference_draws(
    conversations, others, mean_pose: np.ndarray, samples: int, seed: int = 0
) -> dict[str, Draws]:
    """The references' draws (one run each) for the held-out ``conversations``.

    Args:
        others: conversations whose recorded motion is mismatched (e.g. the validation split);
            sample ``k`` of conversation ``i`` takes ``others[(i + k) % len(others)]``.
        mean_pose: keypoints ``(9, 3)`` of the training data's mean pose.
        samples: draws of the floor and of mismatched motion.
        seed: motion seeds of the floor's draws start here.
    """
    if len(others) < 1:
        raise ValueError("mismatched motion needs other conversations than the held-out ones")
    draws = [
        reference_motions(
            conversations,
            mean_pose,
            seed=seed + k * len(conversations),
            others=[others[(i + k) % len(others)] for i in range(len(conversations))],
        )
        for k in range(samples)
    ]
    references = {"ground_truth": [[[c.positions for c in conversations]]]}
    if "floor" in draws[0]:  # the generator's data
        references["floor"] = [[d["floor"] for d in draws]]
    return references | {
        "mismatched": [[d["mismatched"] for d in draws]],
        "mean_pose": [[draws[0]["mean_pose"]]],
    }


def evaluate_models(models: dict, splits, samples: int = 3, features=None) -> tuple[dict, dict]:
    """Score the references and every model on a dataset's held-out (test) conversations.

    Args:
        models: row name -> ``[(model, normaliser), ...]``, one per training seed (all
            deterministic, or all not). A deterministic model gets a second row,
            ``<name>+smoothed``, of its motion after Kucherenko et al.'s post-processing
            (:func:`positions_of`), and the ground truth too (``ground_truth+smoothed``: what the
            filters alone do to motion). A model that replays a reference's latent codes
            (``latents``: MoGlow, Ye et al.'s flow) is also scored on style ``transfer``.
        splits: the dataset's ``{"train", "val", "test"}`` conversations: the training split's
            mean pose and the transfer's references, the validation split's motion as
            mismatched motion.
        samples: draws per conversation of each stochastic system.
        features: the FGD's feature network (:func:`~gesturelib.evaluation.fgd.feature_network`),
            or None to leave FGD out.
    Returns:
        ``(rows, draws)``: :func:`score_system`'s row and the draws ``runs[r][k][i]`` of every
        system, references first.
    Raises:
        ValueError: for a row without runs, a row named like a reference, fewer than one sample,
            or a row that mixes deterministic and stochastic models.
    """
    if samples < 1:
        raise ValueError(f"samples must be at least 1, got {samples}")
    for name, runs in models.items():
        if not runs:
            raise ValueError(f"model row {name!r} has no runs")
        if name in REFERENCES or name.endswith("+smoothed"):
            raise ValueError(
                f"{name!r} is a reference's or a smoothed row's name; rename the model"
            )
        if len({model.noise_dim == 0 for model, _ in runs}) > 1:
            raise ValueError(f"model row {name!r} mixes deterministic and stochastic models")
    test = splits["test"]
    draws = reference_draws(test, splits["val"], mean_pose_of(splits["train"]), samples)
    fixed = {"mean_pose"}
    if any(runs[0][0].noise_dim == 0 for runs in models.values()):
        draws["ground_truth+smoothed"] = [positions_of([[c.rotations for c in test]], True)]
    drifts = {}  # where the conversations hold two chunks to compare
    long_enough = min(len(c.rotations) for c in test) >= 2 * DRIFT_CHUNK_S * FPS
    for name, runs in models.items():
        rotations = [
            model_rotations(test, model, normaliser, samples) for model, normaliser in runs
        ]
        drifts[name] = [drift(r, test, DRIFT_CHUNK_S) for r in rotations] if long_enough else []
        draws[name] = [positions_of(r) for r in rotations]
        if runs[0][0].noise_dim == 0:
            fixed |= {name, f"{name}+smoothed"}
            draws[f"{name}+smoothed"] = [positions_of(r, smoothed=True) for r in rotations]
    transfers = {  # a model that replays a reference's latent codes: how far its style follows
        name: [style_transfer(model, normaliser, splits) for model, normaliser in runs]
        for name, runs in models.items()
        if hasattr(runs[0][0], "latents")
    }
    rows = {
        name: score_system(
            test, runs, features, name in fixed, transfers.get(name, ()), drifts.get(name, ())
        )
        for name, runs in draws.items()
    }
    return rows, draws


def mean_pose_of(conversations) -> np.ndarray:
    """Keypoints ``(9, 3)`` of the mean pose over every frame of ``conversations``."""
    return np.concatenate([c.positions for c in conversations]).mean(axis=0)


def _pooled_mean(measure, motions, joints, fps: int = FPS) -> float:
    return float(np.concatenate([measure(m, fps)[:, joints].ravel() for m in motions]).mean())
