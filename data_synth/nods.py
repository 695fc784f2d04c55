"""The agent's head nods: with its own emphasis while speaking, as feedback while listening.

Rules (parameters in :class:`data_synth.config.MotionConfig`):

* **Accent nods.** On each accent of the agent, a nod with probability
  ``accent_nod_probability * emphasis``, of ``accent_nod_deg * emphasis`` degrees, timed like the
  beats: the head moves down fastest ``stroke_lead_s`` before the accent.
* **Listening nods.** When the partner (B) ends a phrase and the agent is silent for the next
  0.6 s, a nod with probability ``listening_nod_probability``, starting ``nod_delay_s`` after the
  phrase end, of ``listening_nod_deg`` degrees, repeated 1-3 times (probabilities 0.5, 0.3, 0.2),
  each repetition 0.6 times the previous one.
* **Backchannel nods.** The agent's own "mm-hm" always comes with a nod (1-2 repetitions).
* A nod never starts before the previous one has finished (the later one is dropped).

One nod is a down-and-up cycle of ``nod_duration_s / style.speed`` seconds,
``amplitude * (1 - cos(2 pi tau / W)) / 2`` degrees of head pitch; its fastest downward motion,
the nod's ``time``, is a quarter of the cycle after its start. The nose-head limb turns by the
full pitch, the sternum-head limb (the neck) by 30 % of it (:mod:`data_synth.motion`).
"""

from __future__ import annotations

import numpy as np

from data_synth.config import MotionConfig
from data_synth.events import Accent, Nod, Phrase
from data_synth.style import Style

#: The agent must stay silent this long after the partner's phrase for a listening nod.
LISTENING_WINDOW_S = 0.6
REPETITION_PROBABILITIES = (0.5, 0.3, 0.2)
REPETITION_DECAY = 0.6


def plan_nods(
    utterances: list[Phrase],
    accents: list[Accent],
    style: Style,
    config: MotionConfig,
    rng: np.random.Generator,
) -> list[Nod]:
    """Draw the agent's nods (see the module rules), sorted by time.

    Args:
        utterances: every phrase and backchannel of both speakers.
        accents: the agent's accents (speaker A).
    """
    cycle = config.nod_duration_s / style.speed
    candidates: list[Nod] = []
    for accent in accents:
        if rng.random() < config.accent_nod_probability * accent.emphasis:
            candidates.append(
                Nod(
                    float(accent.time - config.stroke_lead_s),
                    float(config.accent_nod_deg * accent.emphasis),
                    1,
                    "accent",
                )
            )
    agent = [u for u in utterances if u.speaker == "A"]
    for phrase in utterances:
        if phrase.speaker != "B" or phrase.kind != "phrase":
            continue
        agent_talks = any(
            u.start < phrase.end + LISTENING_WINDOW_S and u.end > phrase.end for u in agent
        )
        if not agent_talks and rng.random() < config.listening_nod_probability:
            repetitions = 1 + int(rng.choice(3, p=REPETITION_PROBABILITIES))
            time = phrase.end + rng.uniform(*config.nod_delay_s) + cycle / 4
            candidates.append(
                Nod(
                    float(time),
                    float(rng.uniform(*config.listening_nod_deg)),
                    repetitions,
                    "partner_phrase_end",
                )
            )
    for backchannel in agent:
        if backchannel.kind == "backchannel":
            candidates.append(
                Nod(
                    float(backchannel.start + cycle / 4),
                    float(rng.uniform(*config.listening_nod_deg)),
                    1 + int(rng.integers(2)),
                    "own_backchannel",
                )
            )

    nods: list[Nod] = []
    free_from = -np.inf
    for nod in sorted(candidates, key=lambda n: n.time):
        start = nod.time - cycle / 4
        if start >= free_from:
            nods.append(nod)
            free_from = start + nod.repetitions * cycle
    return nods


def nod_pitch(nods: list[Nod], times: np.ndarray, cycle_s: float) -> np.ndarray:
    """Head pitch ``(T,)`` in radians (positive: down) made by ``nods`` at sorted ``times``."""
    pitch = np.zeros_like(times)
    for nod in nods:
        start = nod.time - cycle_s / 4
        for repetition in range(nod.repetitions):
            begin = start + repetition * cycle_s
            window = slice(*np.searchsorted(times, [begin, begin + cycle_s]))
            phase = 2.0 * np.pi * (times[window] - begin) / cycle_s
            amplitude = nod.amplitude_deg * REPETITION_DECAY**repetition
            pitch[window] += np.radians(amplitude) * 0.5 * (1.0 - np.cos(phase))
    return pitch
