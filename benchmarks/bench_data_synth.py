"""Speed of the synthetic conversation generator on this machine.

    python benchmarks/bench_data_synth.py

Targets (issue: data_synth): 10 minutes of conversation in under 10 s; the full dataset
(30 minutes, written to disk) in under a minute. The stages of one 10-minute conversation are
timed too, to show where the time goes.
"""

from __future__ import annotations

import tempfile
import time

import numpy as np

from data_synth import ConversationConfig, generate_conversation, resample_motion, write_dataset
from data_synth.dataset import FULL_CONVERSATION_S, FULL_MINUTES
from data_synth.prosody import plan_speech
from data_synth.turns import sample_turns
from data_synth.voice import draw_voices, mix, synthesize_speech


def timed(function) -> tuple[float, object]:
    """Wall-clock seconds of one call, and its result."""
    start = time.perf_counter()
    result = function()
    return time.perf_counter() - start, result


def stages(duration_s: float) -> list[tuple[str, float]]:
    """Seconds spent in each stage of generating one conversation."""
    config = ConversationConfig()
    rng = np.random.default_rng(0)
    n_samples = int(duration_s * config.sample_rate)
    turns_s, utterances = timed(lambda: sample_turns(duration_s, config.turns, rng))
    voices = draw_voices(config.voice, rng)
    plan_s, plans = timed(
        lambda: [plan_speech(utterances, s, config.voice, duration_s, rng) for s in "AB"]
    )
    audio_s, tracks = timed(
        lambda: [
            synthesize_speech(plan, voices[plan.speaker], n_samples, config.sample_rate, rng)
            for plan in plans
        ]
    )
    mix_s, _ = timed(lambda: mix(tracks, config.voice, rng))
    conversation = generate_conversation(duration_s, seed=0)
    motion_s, _ = timed(lambda: resample_motion(conversation, 1))
    return [
        ("turn-taking", turns_s),
        ("syllables, accents, pitch", plan_s),
        ("source-filter synthesis", audio_s),
        ("mix", mix_s),
        ("motion", motion_s),
    ]


def main() -> None:
    minutes = 10
    seconds, _ = timed(lambda: generate_conversation(minutes * 60.0, seed=0))
    verdict = "ok" if seconds < 10.0 else "MISSED"
    print(f"{'what':<55} {'seconds':>8}  target")
    print(f"{f'one conversation of {minutes} minutes':<55} {seconds:8.2f}  < 10 s {verdict}")
    for name, stage_seconds in stages(minutes * 60.0):
        print(f"{'  ' + name:<55} {stage_seconds:8.2f}")
    with tempfile.TemporaryDirectory() as folder:
        seconds, manifest = timed(
            lambda: write_dataset(
                folder, FULL_MINUTES, seed=0, conversation_s=FULL_CONVERSATION_S, progress=False
            )
        )
    n = sum(len(entries) for entries in manifest["splits"].values())
    what = f"full dataset on disk ({FULL_MINUTES:g} min, {n} conversations)"
    verdict = "ok" if seconds < 60.0 else "MISSED"
    print(f"{what:<55} {seconds:8.2f}  < 60 s {verdict}")


if __name__ == "__main__":
    main()
