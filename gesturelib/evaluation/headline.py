"""Measures of generated motion on held-out conversations, against the ground truth.

The course's headline measures, computed the same way wherever a chapter or a benchmark reports
them (``docs/architecture.md`` states the contract):

* :func:`wrist_speed_hellinger`: how natural the motion's speeds are. Speeds of both wrists,
  pooled over all frames of all conversations into one histogram of 4 cm/s bins from 0 to
  400 cm/s, and its Hellinger distance (Kucherenko et al. 2021) to the ground truth's.
* :func:`speaking_listening_ratio`: how much more the wrists move while the agent speaks than
  while it listens (Taylor et al. 2021: listening moves towards the mean pose).
* :func:`stroke_lead`: by how much the wrists' speed leads the emphasis of the agent's speech,
  measured from the audio (``data_synth.measure_stroke_lead``); the generator's strokes lead
  their accents by ``stroke_lead_s`` = 0.2 s.
* :func:`hand_sharing` (of :func:`speaking_wrist_speeds`): whether one hand rests while the
  other gestures, as the agent's often does, or both always move together.
* :func:`pause_wrist_speed`: how much the wrists move in the agent's short pauses, where the
  generator's hands retract after a phrase and rise before the next; with the speed while it
  speaks, the two parts of the speaking/listening ratio that models get most wrong;
  :func:`pause_speed_profile` follows it through those pauses, frame by frame.
* :func:`error_over_time` and :func:`drift`: whether generated motion wanders off as a
  conversation goes on: its limb-angle error to the recorded motion per 10 s, and how much larger
  it is at the end than at the start. One sample's drift varies much from draw to draw: average
  it over samples.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gesturelib.conventions import FPS, Activity
from gesturelib.metrics import JOINT_GROUPS, hellinger_distance, speed, speed_histogram

#: Bin edges of the wrist-speed histograms, cm/s (faster speeds count in the last bin).
WRIST_SPEED_BINS = np.arange(0.0, 404.0, 4.0)


def wrist_speeds(positions: np.ndarray, fps: int = FPS) -> np.ndarray:
    """Speeds of both wrists, ``(T - 1, 2)`` cm/s, from keypoints ``(T, 9, 3)``."""
    return speed(positions, fps)[:, list(JOINT_GROUPS["wrists"])]


def joint_speed_histogram(
    motions: Sequence[np.ndarray], group: str = "wrists", fps: int = FPS
) -> np.ndarray:
    """The normalised histogram (:data:`WRIST_SPEED_BINS`) of the speeds of a joint group of
    :data:`gesturelib.metrics.JOINT_GROUPS`, pooled over the joints and all frames of
    ``motions``."""
    joints = list(JOINT_GROUPS[group])
    speeds = np.concatenate([speed(m, fps)[:, joints].ravel() for m in motions])
    return speed_histogram(speeds, WRIST_SPEED_BINS)


def wrist_speed_histogram(motions: Sequence[np.ndarray], fps: int = FPS) -> np.ndarray:
    """The normalised histogram of both wrists' speeds over all frames of ``motions``."""
    return joint_speed_histogram(motions, "wrists", fps)


def wrist_speed_hellinger(
    motions: Sequence[np.ndarray], truth: Sequence[np.ndarray], fps: int = FPS
) -> float:
    """Hellinger distance in [0, 1] between the wrist-speed histograms of ``motions`` and
    ``truth`` (lists of ``(T, 9, 3)`` keypoints, e.g. one per held-out conversation)."""
    return hellinger_distance(
        wrist_speed_histogram(motions, fps), wrist_speed_histogram(truth, fps)
    )


def speaking_listening_ratio(positions, activity, fps: int = FPS) -> float:
    """Mean wrist speed while the agent speaks over the mean while it does not.

    Args:
        positions: ``(T, 9, 3)`` keypoints, or a list of them (pooled).
        activity: ``(T,)`` who-is-talking codes, or a list of them; a speed between frames
            ``t - 1`` and ``t`` counts for frame ``t``'s activity. "Speaks" is ``A_SPEAKS`` or
            ``BOTH``.
    Returns:
        The ratio; NaN where it is undefined (wrists that never move while listening).
    """
    if isinstance(positions, np.ndarray) and positions.ndim == 3:
        positions, activity = [positions], [activity]
    speeds, speaking = [], []
    for motion, codes in zip(positions, activity, strict=True):
        speeds.append(wrist_speeds(motion, fps).mean(axis=1))
        speaking.append(np.isin(np.asarray(codes)[1:], [Activity.A_SPEAKS, Activity.BOTH]))
    speeds, speaking = np.concatenate(speeds), np.concatenate(speaking)
    if speaking.all() or not speaking.any():
        raise ValueError("the agent must both speak and listen for a speaking/listening ratio")
    listening = speeds[~speaking].mean()
    return float(speeds[speaking].mean() / listening) if listening > 0 else float("nan")


def speaking_wrist_speeds(
    motions: Sequence[np.ndarray], conversations, fps: int = FPS
) -> np.ndarray:
    """Both wrists' speeds ``(N, 2)`` cm/s over the frames where the agent speaks (``A_SPEAKS``),
    pooled over ``motions`` (keypoints ``(T, 9, 3)``, one per conversation of ``conversations``,
    whose ``activity`` says who talks): what :func:`hand_sharing` reads."""
    return np.concatenate(
        [
            wrist_speeds(motion, fps)[np.asarray(c.activity)[1:] == Activity.A_SPEAKS]
            for motion, c in zip(motions, conversations, strict=True)
        ]
    )


def _short_pauses(activity, longest_s: float, fps: int, between_phrases: bool = False):
    """``(start, end)`` speed-frame indices (frame ``t`` is the speed from ``t`` to ``t + 1``
    of the keypoints) of the agent's pauses shorter than ``longest_s``: runs of frames where it
    does not speak (neither ``A_SPEAKS`` nor ``BOTH``; the partner may). ``between_phrases``:
    only those with the agent's speech on both sides."""
    silent = ~np.isin(np.asarray(activity)[1:], [Activity.A_SPEAKS, Activity.BOTH])
    edges = np.flatnonzero(np.diff(np.r_[False, silent, False]))
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        inside = 0 < start and end < len(silent)
        if end - start < longest_s * fps and (inside or not between_phrases):
            yield start, end


def pause_wrist_speed(
    motions: Sequence[np.ndarray], conversations, longest_s: float = 4.0, fps: int = FPS
) -> float:
    """The mean speed (cm/s) of both wrists over the agent's pauses shorter than ``longest_s``.

    A pause is a run of frames where the agent does not speak (neither ``A_SPEAKS`` nor
    ``BOTH``; the partner may); a speed between frames ``t - 1`` and ``t`` counts for frame
    ``t``. ``motions`` are keypoints ``(T, 9, 3)``, one per conversation of ``conversations``
    (whose ``activity`` says who talks). NaN where there is no such pause."""
    speeds = []
    for motion, conversation in zip(motions, conversations, strict=True):
        per_frame = wrist_speeds(motion, fps).mean(axis=1)
        for start, end in _short_pauses(conversation.activity, longest_s, fps):
            speeds.append(per_frame[start:end])
    return float(np.concatenate(speeds).mean()) if speeds else float("nan")


def pause_speed_profile(
    motions: Sequence[np.ndarray],
    conversations,
    seconds: float = 2.0,
    longest_s: float = 4.0,
    fps: int = FPS,
) -> tuple[np.ndarray, np.ndarray]:
    """How fast both wrists move through the agent's short pauses between two of its phrases,
    frame by frame: where the generator's hands retract, rest and rise again.

    Args:
        motions: keypoints ``(T, 9, 3)``, one per conversation of ``conversations`` (whose
            ``activity`` says who talks).
        seconds: how far into the pauses to look, from either end.
        longest_s: the pauses counted are shorter than this (as :func:`pause_wrist_speed`'s),
            with the agent speaking before and after.
    Returns:
        ``(after_end, before_start)``, each ``(round(seconds * fps),)`` cm/s: ``after_end[k]``
        the wrists' mean speed ``k`` frames after the agent's phrase ends (k = 0: the pause's
        first frame), over the pauses at least ``k + 1`` frames long; ``before_start[k]`` the
        same ``k`` frames before its next phrase starts (k = 0: the pause's last frame). NaN
        where no pause is that long.
    """
    frames = round(seconds * fps)
    sums, counts = np.zeros((2, frames)), np.zeros((2, frames))
    for motion, conversation in zip(motions, conversations, strict=True):
        per_frame = wrist_speeds(motion, fps).mean(axis=1)
        for start, end in _short_pauses(conversation.activity, longest_s, fps, True):
            n = min(frames, end - start)
            sums[0, :n] += per_frame[start : start + n]
            sums[1, :n] += per_frame[end - n : end][::-1]
            counts[:, :n] += 1
    with np.errstate(invalid="ignore"):
        after_end, before_start = sums / counts
    return after_end, before_start


#: A wrist slower than this rests (cm/s: the first bin of :data:`WRIST_SPEED_BINS`).
RESTING_SPEED = 4.0
#: A wrist faster than this strokes (cm/s).
STROKING_SPEED = 16.0


def hand_sharing(speeds: np.ndarray) -> dict[str, float]:
    """How the two hands share the gesturing, from wrist speeds ``(N, 2)`` cm/s (left, right;
    e.g. :func:`speaking_wrist_speeds`).

    Returns:
        ``still``: the share of wrist-frames at rest (under :data:`RESTING_SPEED`);
        ``one_hand``: the share of frames where one wrist rests while the other strokes (over
        :data:`STROKING_SPEED`); ``correlation``: the correlation of the two wrists' speeds
        (near 1 when both hands always move together; NaN where a wrist's speed never changes).
    Raises:
        ValueError: ``speeds`` not of shape ``(N, 2)`` with ``N >= 1``.
    """
    speeds = np.asarray(speeds, dtype=float)
    if speeds.ndim != 2 or speeds.shape[1] != 2 or len(speeds) == 0:
        raise ValueError(f"speeds must be (N, 2): the left and right wrist, got {speeds.shape}")
    still, stroking = speeds < RESTING_SPEED, speeds > STROKING_SPEED
    one_hand = (still[:, 0] & stroking[:, 1]) | (still[:, 1] & stroking[:, 0])
    left, right = speeds.T
    varies = left.std() > 0 and right.std() > 0
    return {
        "still": float(still.mean()),
        "one_hand": float(one_hand.mean()),
        "correlation": float(np.corrcoef(left, right)[0, 1]) if varies else float("nan"),
    }


def stroke_lead(
    audio: np.ndarray,
    sample_rate: int,
    activity: np.ndarray,
    positions: np.ndarray,
    max_lag_s: float = 0.6,
) -> float:
    """Seconds by which the wrists' speed leads the emphasis of the agent's speech (positive:
    the gestures come first), by cross-correlation over lags of up to ``max_lag_s``; NaN for
    wrists that never move (a lead is then undefined)."""
    from data_synth import measure_stroke_lead  # the audio's emphasis, as the generator defines it

    if np.ptp(wrist_speeds(positions).sum(axis=1)) == 0:
        return float("nan")
    return measure_stroke_lead(audio, sample_rate, activity, positions, max_lag_s=max_lag_s)


def reference_motions(
    conversations, mean_pose: np.ndarray, seed: int = 0, others=None
) -> dict[str, list]:
    """The references every model is compared with, keypoints ``(T, 9, 3)`` per conversation:

    * ``floor``: the generator's motion drawn again for the same speech
      (``data_synth.resample_motion``): as natural and as appropriate as motion can be, yet not
      the recorded one; no model can be expected to beat it. Only for the generator's
      conversations: recorded data (imported motion capture) has none;
    * ``mismatched``: the recorded motion of another conversation (cut or repeated to length):
      natural, but for other speech;
    * ``mean_pose``: ``mean_pose`` ``(9, 3)`` held still.

    Args:
        conversations: the held-out conversations.
        mean_pose: keypoints ``(9, 3)``, e.g. of the training data's mean pose.
        seed: motion seeds of the floor are ``seed, seed + 1, ...``.
        others: the conversations whose motion is mismatched, one per conversation (e.g. from
            another split); by default each conversation gets the next one's, which needs two.
    """
    from data_synth import resample_motion

    if others is None:
        if len(conversations) < 2:
            raise ValueError("mismatched motion needs at least 2 conversations, or others=")
        others = [conversations[(i + 1) % len(conversations)] for i in range(len(conversations))]
    if len(others) < len(conversations):
        raise ValueError(f"others must give {len(conversations)} conversations, got {len(others)}")
    mean_pose = np.asarray(mean_pose, dtype=np.float64)
    if mean_pose.shape != (9, 3):
        raise ValueError(f"mean_pose must be keypoints (9, 3), got {mean_pose.shape}")
    lengths = [len(c.positions) for c in conversations]
    references = {}
    if all(getattr(c, "events", None) is not None for c in conversations):  # the generator's
        references["floor"] = [
            resample_motion(c, seed + i).positions for i, c in enumerate(conversations)
        ]
    return references | {
        "mismatched": [
            np.resize(o.positions, (n, 9, 3))
            for o, n in zip(others[: len(lengths)], lengths, strict=True)
        ],
        "mean_pose": [np.repeat(mean_pose[None], n, axis=0) for n in lengths],
    }


def generate_for(conversations, model, normaliser, **options) -> list[np.ndarray]:
    """Keypoints ``(samples, T, 9, 3)`` generated for each conversation from its audio and who is
    talking (never its motion); ``options`` as for :func:`gesturelib.pipeline.speech_to_motion`
    (``style`` as percentiles by name)."""
    from gesturelib.pipeline import speech_to_motion

    return [
        speech_to_motion(
            model, normaliser, c.audio, c.sample_rate, activity=c.activity, **options
        ).positions
        for c in conversations
    ]


#: Seconds of each chunk of :func:`error_over_time`.
DRIFT_CHUNK_S = 10.0


def error_over_time(
    rotations: Sequence[np.ndarray], conversations, chunk_s: float = DRIFT_CHUNK_S, fps: int = FPS
) -> np.ndarray:
    """The mean limb-angle error (degrees) of generated rotations to the recorded ones, per whole
    chunk of ``chunk_s`` seconds from the start, averaged over conversations: ``(chunks,)``,
    as many chunks as the shortest conversation holds.

    Args:
        rotations: one ``(T, 9, 6)`` per conversation (e.g. one sample each).
        conversations: the held-out conversations (their ``rotations``).
    """
    from gesturelib.gaps import limb_angle_error

    chunk = int(round(chunk_s * fps))
    count = min(len(c.rotations) for c in conversations) // chunk
    if count < 1:
        raise ValueError(f"conversations shorter than one chunk of {chunk_s} s")
    curves = [
        limb_angle_error(r, c.rotations).mean(axis=1)[: count * chunk].reshape(count, chunk).mean(1)
        for r, c in zip(rotations, conversations, strict=True)
    ]
    return np.mean(curves, axis=0)


def drift(
    samples: Sequence[Sequence[np.ndarray]], conversations, chunk_s: float = DRIFT_CHUNK_S
) -> float:
    """How much a model's motion wanders off: :func:`error_over_time` in the last chunk over the
    first (1: an error that does not grow), the curve averaged over ``samples`` first.

    Args:
        samples: ``samples[k][i]``, rotations ``(T, 9, 6)`` of draw ``k`` for conversation ``i``.
    """
    curve = np.mean([error_over_time(draw, conversations, chunk_s) for draw in samples], axis=0)
    return float(curve[-1] / curve[0])


def headline_measures(conversations, motions: Sequence[np.ndarray]) -> dict[str, float]:
    """The headline measures of ``motions`` (one ``(T, 9, 3)`` per conversation, e.g. a model's
    samples or the ground truth itself) for the held-out ``conversations``.

    Returns:
        ``hellinger`` (wrist speeds against the conversations' own motion), ``ratio`` (speaking
        over listening wrist speed, all conversations pooled) and ``lead`` (median over
        conversations, seconds); NaN where undefined (a motion that never moves has no lead).
    """
    truth = [c.positions for c in conversations]
    leads = [
        stroke_lead(c.audio, c.sample_rate, c.activity, motion)
        for c, motion in zip(conversations, motions, strict=True)
    ]
    return {
        "hellinger": wrist_speed_hellinger(motions, truth),
        "ratio": speaking_listening_ratio(list(motions), [c.activity for c in conversations]),
        "lead": float(np.median(leads)) if not np.isnan(leads).any() else float("nan"),
    }
