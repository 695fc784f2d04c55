"""How the beat rule is measured: audio emphasis against wrist speed.

The rule is "the wrist's speed peaks ``stroke_lead_s`` before each stressed syllable"
(:mod:`data_synth.gestures`). To check that the *audio* carries it (not just the generator's
event log), the timing of stress is measured from the waveform alone:

1. :func:`gesturelib.features.mel_spectrogram` gives the log-mel power of each motion frame
   (a 40 ms window centred on the frame's centre).
2. *Loudness* is the total mel power raised to the power 0.3 (Stevens's law: perceived loudness
   grows as intensity to the 0.3). Unlike the log energy, it barely rises at the onset of a quiet
   consonant after silence and rises most at a loud (stressed) vowel.
3. The *emphasis envelope* is the positive part of the loudness's change from frame ``t`` to
   ``t + 1``: large when a loud vowel starts, which is when an accent happens. It is normalised to
   a maximum of 1. Its row ``t`` sits at the boundary between frames ``t`` and ``t + 1``, exactly
   like row ``t`` of :func:`gesturelib.metrics.speed`, so the two series align row by row.

:func:`measure_stroke_lead` then finds the lag that best aligns the agent's wrist speed with
that envelope (:func:`gesturelib.metrics.lead_lag`, parabolic refinement to a fraction of a
frame). The partner's voice is left out using the activity labels (the envelope is zeroed where
the agent is not speaking): a model sees the same activity labels, and B's accents have no beats.
"""

from __future__ import annotations

import numpy as np

from gesturelib.conventions import FPS, Activity
from gesturelib.features import mel_spectrogram
from gesturelib.metrics import JOINT_GROUPS, lead_lag, speed

#: Exponent of Stevens's power law: loudness ~ intensity ** 0.3.
LOUDNESS_EXPONENT = 0.3


def loudness(audio: np.ndarray, sample_rate: int, fps: int = FPS) -> np.ndarray:
    """Loudness ``(T,)`` of each motion frame: total mel power to the power 0.3."""
    mel_power = np.exp(mel_spectrogram(audio, sample_rate, fps=fps).astype(np.float64))
    return mel_power.sum(axis=1) ** LOUDNESS_EXPONENT


def emphasis_envelope(audio: np.ndarray, sample_rate: int, fps: int = FPS) -> np.ndarray:
    """Positive changes of loudness between consecutive frames, ``(T - 1,)`` in [0, 1].

    Args:
        audio: mono signal ``(n,)``.
        sample_rate: its rate in Hz.
        fps: motion frames per second; ``T = floor(n / sample_rate * fps)``.
    Returns:
        Row ``t`` is ``max(0, L[t + 1] - L[t])`` divided by the largest such value (all zeros
        for a constant signal), aligned with row ``t`` of ``gesturelib.metrics.speed``.
    """
    level = loudness(audio, sample_rate, fps)
    if level.size < 2:
        raise ValueError(f"the audio must span at least 2 frames at {fps} fps, got {level.size}")
    rise = np.maximum(np.diff(level), 0.0)
    peak = rise.max()
    return rise / peak if peak > 0 else rise


def agent_emphasis(
    audio: np.ndarray, sample_rate: int, activity: np.ndarray, fps: int = FPS
) -> np.ndarray:
    """:func:`emphasis_envelope` ``(T - 1,)`` kept only where the agent speaks (A or both)."""
    activity = np.asarray(activity)
    envelope = emphasis_envelope(audio, sample_rate, fps)
    if activity.shape != (envelope.size + 1,):
        raise ValueError(
            f"activity must have shape (T,) = ({envelope.size + 1},), got {activity.shape}"
        )
    agent = np.isin(activity, (Activity.A_SPEAKS, Activity.BOTH))
    return envelope * (agent[:-1] & agent[1:])


def wrist_speed(positions: np.ndarray, fps: int = FPS) -> np.ndarray:
    """Summed speed of the two wrists ``(T - 1,)`` in cm/s, from positions ``(T, 9, 3)``."""
    return speed(positions, fps)[:, list(JOINT_GROUPS["wrists"])].sum(axis=1)


def measure_stroke_lead(
    audio: np.ndarray,
    sample_rate: int,
    activity: np.ndarray,
    positions: np.ndarray,
    fps: int = FPS,
    max_lag_s: float = 0.6,
) -> float:
    """Seconds by which the agent's wrist speed leads the emphasis of its speech.

    Args:
        audio: ``(n,)`` the conversation's audio.
        sample_rate: its rate.
        activity: ``(T,)`` activity codes.
        positions: ``(T, 9, 3)`` the agent's keypoints in cm.
        fps: frames per second.
        max_lag_s: the largest lead or lag searched.
    Returns:
        The lead in seconds (positive: the wrists move before the stressed syllables), by
        :func:`gesturelib.metrics.lead_lag` of :func:`wrist_speed` against :func:`agent_emphasis`.
    """
    return lead_lag(
        agent_emphasis(audio, sample_rate, activity, fps),
        wrist_speed(positions, fps),
        fps,
        max_lag_s,
    )
