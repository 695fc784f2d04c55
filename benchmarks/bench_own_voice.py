"""Speech the generator did not make: the models on the recordings of ``tests/data/voices/``.

For each recording (espeak-ng voices, clean, reverberant, noisy, through a telephone's band;
``tools/make_test_voices.py``) and each model, the agent speaks where the recording holds speech
(:func:`gesturelib.features.who_is_talking`) and K samples are drawn (seeds 0..K-1 of one call):

* the speaking/silence ratio: the wrists' mean speed while the voice speaks over their mean speed
  in its pauses, all samples pooled (:func:`~gesturelib.evaluation.speaking_listening_ratio`);
* the lead of each sample's strokes over the speech's emphasis
  (:func:`~gesturelib.evaluation.stroke_lead`; the data's rule is 0.2 s).

Prints one Markdown table (the one in ``docs/benchmarks.md``) and the median ratio per model;
then, as a reference, the ratio of the ground truth and of each model on a few of the generator's
conversations laid out like the recordings (one phrase of the agent, then 3-4 s of silence, no
partner): what the layout alone gives, with voices the models know.

``--recordings DIR`` measures another folder of recordings instead (FLAC or WAV files), such as
the selection set of ``tools/make_test_voices.py --selection DIR``: to choose between recipes or
front ends on recordings other than the five that test them.

Usage (the shipped models by default; any run folders of generative models otherwise)::

    .venv/bin/python benchmarks/bench_own_voice.py [RUN ...] [--samples 3] [--temperature 0.8]
        [--generated 6] [--recordings DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from data_synth import ConversationConfig, TurnConfig, generate_conversation
from gesturelib.configs import check_temperature
from gesturelib.evaluation import speaking_listening_ratio, stroke_lead
from gesturelib.evaluation.headline import generate_for
from gesturelib.features import load_audio
from gesturelib.pipeline import speech_to_motion
from gesturelib.pretrained import NAMES, load_run, pretrained_folder

VOICES = Path(__file__).resolve().parents[1] / "tests" / "data" / "voices"
#: The recordings' layout for the generator: a phrase of the agent alone, then a long silence.
RECORDING_LAYOUT = TurnConfig(
    a_phrases_per_turn=1.0,
    a_phrase_s=(2.5, 3.2),
    keep_turn_probability=1.0,
    long_silence_probability=1.0,
    long_silence_s=(3.0, 4.0),
    overlap_probability=0.0,
    backchannel_probability=0.0,
    first_speaker_a_probability=1.0,
    lead_in_s=(1.5, 1.7),
)


def on_recording(
    model, normaliser, recording: Path, samples: int, temperature: float | None = None
) -> tuple[float, list[float]]:
    """``(speaking/silence ratio, one stroke lead per sample)`` of a model on ``recording`` (at
    ``temperature``, or the model's own)."""
    audio, rate = load_audio(recording)
    motion = speech_to_motion(
        model, normaliser, audio, rate, samples=samples, temperature=temperature, seed=0
    )
    activity = motion.activity
    ratio = speaking_listening_ratio(list(motion.positions), [activity] * samples)
    return ratio, [stroke_lead(audio, rate, activity, m) for m in motion.positions]


def laid_out_like_the_recordings(count: int, seconds: float = 30.0) -> list:
    """``count`` of the generator's conversations (seeds 1000...) in :data:`RECORDING_LAYOUT`."""
    config = ConversationConfig(turns=RECORDING_LAYOUT)
    return [generate_conversation(seconds, 1000 + i, config) for i in range(count)]


def on_conversations(model, normaliser, conversations, samples: int, temperature=None) -> float:
    """The speaking/silence ratio of a model's samples for ``conversations``, all pooled."""
    motions = generate_for(
        conversations, model, normaliser, samples=samples, temperature=temperature, seed=0
    )
    activity = [c.activity for c in conversations for _ in range(samples)]
    return speaking_listening_ratio([m for draws in motions for m in draws], activity)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path, help="run folders (default: shipped models)")
    parser.add_argument("--samples", type=int, default=3, help="samples per recording")
    parser.add_argument("--temperature", type=float, default=None, help="the model's own if unset")
    parser.add_argument(
        "--generated",
        type=int,
        default=6,
        help="the generator's conversations in the recordings' layout, as a reference (0: none)",
    )
    parser.add_argument(
        "--recordings",
        type=Path,
        default=VOICES,
        metavar="DIR",
        help="a folder of recordings (.flac, .wav) to measure (default: tests/data/voices)",
    )
    args = parser.parse_args()
    if not args.recordings.is_dir():
        parser.error(f"--recordings: {args.recordings} is not a folder")
    recordings = sorted(
        path
        for path in args.recordings.iterdir()
        if path.is_file()
        and not path.name.startswith(".")
        and path.suffix.lower() in (".flac", ".wav")
    )
    if not recordings:
        parser.error(f"--recordings: {args.recordings} holds no .flac or .wav recordings")
    if args.samples < 1:
        parser.error(f"--samples must be at least 1, got {args.samples}")
    if args.generated < 0:
        parser.error(f"--generated must be at least 0, got {args.generated}")
    if args.temperature is not None:
        try:
            check_temperature(args.temperature)
        except ValueError as error:
            parser.error(f"--temperature: {error}")
    runs = args.runs or [pretrained_folder(name) for name in NAMES]
    if len({run.name for run in runs}) < len(runs):
        parser.error("give run folders of different names: the table is headed by them")
    torch.set_num_threads(1)  # frame-by-frame generation is small work: one thread is fastest

    laid_out = laid_out_like_the_recordings(args.generated)
    results = {}  # run name -> [(ratio, leads) per recording]
    references = {}  # run name -> ratio on the generator's conversations in the same layout
    if laid_out:
        references["ground truth"] = speaking_listening_ratio(
            [c.positions for c in laid_out], [c.activity for c in laid_out]
        )
    for run in runs:
        model, normaliser, _ = load_run(run)
        if not hasattr(model, "step"):
            raise SystemExit(
                f"{run} holds a {type(model).__name__}, which does not generate motion"
            )
        results[run.name] = [
            on_recording(model, normaliser, r, args.samples, args.temperature) for r in recordings
        ]
        if laid_out:
            references[run.name] = on_conversations(
                model, normaliser, laid_out, args.samples, args.temperature
            )

    header = " | ".join(f"{name} ratio | {name} leads (s)" for name in results)
    print(f"| recording | {header} |")
    print("|---|" + "---|---|" * len(results))
    for index, recording in enumerate(recordings):
        cells = []
        for measured in results.values():
            ratio, leads = measured[index]
            cells += [f"{ratio:.2f}", ", ".join(f"{lead:.2f}" for lead in leads)]
        print(f"| `{recording.stem}` | {' | '.join(cells)} |")
    for name, measured in results.items():
        print(f"{name}: median ratio {np.median([ratio for ratio, _ in measured]):.2f}")
    if laid_out:
        print(
            f"The generator's voices in the recordings' layout ({len(laid_out)} "
            f"conversation{'s' * (len(laid_out) > 1)}): "
            + ", ".join(f"{name} {ratio:.2f}" for name, ratio in references.items())
        )


if __name__ == "__main__":
    main()
