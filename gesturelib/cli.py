"""Command line of the course: train, generate, evaluate, describe and demonstrate its models.

Run as ``python -m gesturelib <command>`` (also installed as ``gesturelib``).

Commands (``docs/architecture.md`` has the contract they share):
    train MODEL --out RUN     train a model of the course into a run folder
    generate RUN --audio WAV | --conversation STEM --out DIR
                              the agent's motion for a recording: motion.npz, agent.bvh and
                              agent.mp4
    evaluate RUN [RUN ...] --out DIR
                              score runs and the references on held-out conversations:
                              metrics.csv, models.csv and figures
    info RUN                  what a run folder holds
    import-bvh SRC --out DATA motion capture (NAME.bvh with NAME.wav) as a dataset that train
                              and evaluate take
    demo                      a conversation no model has heard: its recorded motion beside the
                              shipped MoGlow's, rendered with the sound

An error the user can fix is reported in one line on stderr, with exit status 2.
"""

from __future__ import annotations

import argparse
import json
import re
import secrets
import sys
import time
from pathlib import Path

from gesturelib.outputs import OutputError, OutputFolder
from gesturelib.runtime import OneLineParser

#: What the judges of :mod:`gesturelib.evaluation.judge` score, for ``info``.
JUDGES = {"GeneratedMotionFGD": "FGD of its motion generated for the validation conversations"}


class CommandError(Exception):
    """A problem the user can fix; reported as one line, without a traceback."""


# ---------------------------------------------------------------------------------------------
# train
# ---------------------------------------------------------------------------------------------


def run_train(args) -> Path:
    """Train ``args.model`` into the run folder ``args.out``; return the folder.

    Every input (the folder, the data, the device) is checked before anything on disk changes;
    ``--overwrite`` then replaces only the files of a run: its checkpoints (and its stage one's)
    and ``run.json``."""
    import torch

    from data_synth import course_data
    from gesturelib import distributed
    from gesturelib.checkpoints import FORMAT, VERSION
    from gesturelib.datasets import load_dataset
    from gesturelib.pipeline import train_model
    from gesturelib.runtime import device, quick_mode

    quick = args.quick or quick_mode()
    device(args.device)
    # Under torchrun: join the other processes first; all check, then process 0 alone writes.
    train_device = distributed.start_from_environment(args.device)
    first = distributed.world()[0] == 0
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CommandError(f"--out {out} is a file, not a folder")
    held = [p.name for p in out.iterdir()] if out.is_dir() else []
    if held and not (args.resume or args.overwrite):
        raise CommandError(
            f"{out} is not empty; pass --resume to continue the run in it, --overwrite to replace "
            "it, or choose another --out"
        )
    if args.resume and not (out / "last.pt").exists():
        raise CommandError(f"{out} holds no run to resume (no last.pt)")
    data = course_data(quick) if args.data is None else Path(args.data)
    splits = load_dataset(data)
    torch.set_num_threads(args.threads)
    distributed.barrier()  # every process has checked the folder before any writes to it
    if args.overwrite and first:
        (out / "run.json").unlink(missing_ok=True)

    started = time.perf_counter()
    trained = train_model(
        args.model,
        splits,
        quick=quick,
        seed=args.seed,
        train_changes={"device": train_device},
        cache=args.cache,
        out=out,
        overwrite=args.overwrite,
        progress=first,
    )
    distributed.finish()
    if not first:
        return out
    summary = {
        "format": FORMAT,
        "version": VERSION,
        "model": args.model,
        "model_class": type(trained.model).__name__,
        "quick": quick,
        "data": str(data.resolve()),
        "seed": args.seed,
        "epochs": trained.history.epochs,
        "best_epoch": trained.history.best_epoch,
        "training_seconds": round(sum(trained.history.epoch_seconds), 1),
        "finished": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    (out / "run.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"Trained {args.model} in {time.perf_counter() - started:.0f} s; run folder {out}/")
    return out


# ---------------------------------------------------------------------------------------------
# generate, info
# ---------------------------------------------------------------------------------------------


def run_generate(args) -> list[Path]:
    """Generate motion for a recording with a trained run; return the files written."""
    from data_synth import load_conversation
    from gesturelib.features import AudioError, load_audio
    from gesturelib.pipeline import speech_to_motion
    from gesturelib.pretrained import load_run
    from gesturelib.sampling import NonFiniteMotionError

    model, normaliser, _ = load_run(args.run, args.device)
    if not hasattr(model, "step"):
        raise CommandError(
            f"{args.run} holds a {type(model).__name__}, which does not generate motion"
        )
    if args.partner is not None and args.audio is None:
        raise CommandError("--partner goes with --audio (a conversation brings both voices)")
    if args.style and not getattr(model.config, "style", False):
        raise CommandError(f"{args.run} was trained without style control; drop --style")
    style = _parse_style(args.style or [])
    style_from = None if args.style_from is None else _reference_motion(args.style_from, model)
    _set_sampling(model, args)
    if args.audio is not None:
        audio, sample_rate = load_audio(args.audio)
        partner = None if args.partner is None else load_audio(args.partner, sample_rate)[0]
        activity, heard = (
            None,
            args.audio if partner is None else f"{args.audio} with {args.partner}",
        )
    else:
        stem = Path(args.conversation)
        if stem.suffix in (".wav", ".npz", ".json") and not Path(f"{stem}.wav").exists():
            raise CommandError(
                f"--conversation takes a path stem, without {stem.suffix}: "
                f"--conversation {stem.with_suffix('')}"
            )
        conversation = load_conversation(stem)  # its motion is never read
        audio, sample_rate, partner = conversation.audio, conversation.sample_rate, None
        activity, heard = conversation.activity, args.conversation
    folder = OutputFolder(args.out, "generate", args.overwrite)  # refused now, not after the work
    try:
        motion = speech_to_motion(
            model,
            normaliser,
            audio,
            sample_rate,
            partner=partner,
            activity=activity,
            style=style,
            style_from=style_from,
            samples=args.samples,
            temperature=args.temperature,
            seed=args.seed,
            progress=len(audio) > 60 * sample_rate,  # a bar for recordings over a minute
        )
    except AudioError as error:
        raise CommandError(f"{heard}: {error}") from error
    except NonFiniteMotionError as error:
        raise CommandError(f"{args.run}: {error}") from error
    with folder.staging() as stage:
        for number, (rotations, positions) in enumerate(
            zip(motion.rotations, motion.positions, strict=True), start=1
        ):
            within = "" if args.samples == 1 else f"sample-{number}/"
            _write_motion(stage, within, rotations, positions, motion.activity)
            if not args.no_video:
                _render(
                    [positions],
                    ["the agent"],
                    motion.audio,
                    motion.sample_rate,
                    stage.path(f"{within}agent.mp4"),
                )
    return stage.files


def _reference_motion(source: Path, model):
    """The recording of ``--style-from``: a conversation's path stem, its motion and its speech;
    refused for a model that cannot take a reference's style."""
    from data_synth import load_conversation
    from gesturelib.conventions import FPS

    if not callable(getattr(model, "latents", None)):
        raise CommandError(
            f"a {type(model).__name__} does not take its style from a reference; drop "
            "--style-from (it is for moglow and styleflow runs)"
        )
    if source.suffix in (".npz", ".wav", ".json"):
        raise CommandError(
            f"--style-from takes a conversation's path stem (its motion and its speech, which "
            f"the style is read with), without {source.suffix}: --style-from "
            f"{source.with_suffix('')}"
        )
    if not Path(f"{source}.npz").exists() or not Path(f"{source}.wav").exists():
        raise CommandError(
            f"--style-from {source}: not a conversation's path stem (needs {source}.npz and "
            f"{source}.wav)"
        )
    reference = load_conversation(source)
    config = model.config
    needed = max(config.past_poses, config.speech_past) + config.speech_future + 1
    if len(reference.rotations) < needed:
        raise CommandError(
            f"--style-from {source} is {len(reference.rotations)} frames long; this model reads "
            f"a reference of at least {needed} frames ({needed / FPS:.1f} s)"
        )
    return reference


def _set_sampling(model, args) -> None:
    """Apply ``--steps``, ``--sampler`` and ``--guidance`` to a diffusion model; refuse them for
    the others."""
    import dataclasses

    changes = {
        field: value
        for field, value in (
            ("steps", args.steps),
            ("method", args.sampler),
            ("guidance", args.guidance),
        )
        if value is not None
    }
    if not changes:
        return
    if not hasattr(model, "sampling"):
        given = ", ".join(f"--{'sampler' if f == 'method' else f}" for f in changes)
        raise CommandError(
            f"{args.run} holds a {type(model).__name__}, which does not denoise: drop {given}"
        )
    try:
        model.sampling = dataclasses.replace(model.sampling, **changes)
    except ValueError as error:
        raise CommandError(str(error)) from None


def _write_motion(stage, within: str, rotations, positions, activity) -> None:
    """``motion.npz`` and ``agent.bvh`` (in the subfolder ``within`` of a staging folder): limb
    rotations ``(T, 9, 6)``, their keypoints ``(T, 9, 3)`` and who is talking ``(T,)``."""
    import numpy as np

    from gesturelib.bvh import write_bvh
    from gesturelib.conventions import FPS

    np.savez(
        stage.path(f"{within}motion.npz"),
        rotations=rotations.astype(np.float32),
        positions=positions.astype(np.float32),
        activity=np.asarray(activity, dtype=np.int64),
        fps=np.int64(FPS),
    )
    write_bvh(stage.path(f"{within}agent.bvh"), rotations)


def _parse_style(pairs: list[str]) -> dict[str, float]:
    parsed = {}
    for pair in pairs:
        name, _, value = pair.partition("=")
        try:
            parsed[name] = float(value)
        except ValueError:
            raise CommandError(
                f"--style takes NAME=PERCENTILE, e.g. hand_height=85; got {pair!r}"
            ) from None
    return parsed


def _render(motions, titles, audio, sample_rate: int, path: Path, views=("front", "side")) -> None:
    """An MP4 at ``path``: the motions ``[(T, 9, 3), ...]`` side by side, each in ``views``,
    with the sound."""
    import matplotlib

    matplotlib.use("Agg")
    from gesturelib import viz

    animation = viz.animate(motions, titles=titles, views=views)
    viz.save_animation(animation, path, audio=audio, sample_rate=sample_rate)


def run_info(args) -> str:
    """A description of a run folder."""
    from gesturelib.datasets import dataset_format
    from gesturelib.history import History
    from gesturelib.mocap.dataset import FORMAT as MOCAP_FORMAT
    from gesturelib.mocap.dataset import read_manifest
    from gesturelib.pretrained import load_run, read_summary

    model, _, checkpoint = load_run(args.run)
    history = History.from_dict(checkpoint["history"])
    parameters = sum(p.numel() for p in model.parameters())
    size = sum(p.stat().st_size for p in Path(args.run).rglob("*") if p.is_file())
    summary = read_summary(args.run)
    kept_by = "validation loss"
    if history.best_epoch in history.judged:
        judge = checkpoint["judge"]["judge"]
        kept_by = JUDGES.get(judge, f"the score of its judge, {judge},")
    lines = [
        f"run folder      {args.run}",
        f"model           {checkpoint['model_class']} ({parameters:,} parameters)",
        f"model config    {json.dumps(checkpoint['model_config'])}",
        f"training config {json.dumps(checkpoint['train_config'])}",
        f"data            {summary.get('data', '(unknown)')} (fingerprint {checkpoint['data']})",
        f"training        {history.epochs} epochs in {sum(history.epoch_seconds):.0f} s, best "
        f"epoch {history.best_epoch} ({kept_by} {checkpoint['score']:.4g})",
        f"size on disk    {size / 1e6:.1f} MB",
    ]
    data = summary.get("data")
    if data is not None and dataset_format(data) == MOCAP_FORMAT:
        manifest = read_manifest(data)
        lines.insert(
            5,
            f"motion capture  imported from {manifest['source']} (rig {', '.join(manifest['rig'])}, units "
            f"{', '.join(manifest['units'])}, on the course's skeleton)",
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# evaluate
# ---------------------------------------------------------------------------------------------


def run_evaluate(args) -> list[Path]:
    """Score run folders and the references on held-out conversations; return the files written:
    ``metrics.csv``, ``models.csv`` and the figures."""
    import matplotlib
    import torch

    matplotlib.use("Agg")
    from gesturelib.datasets import load_dataset
    from gesturelib.evaluation import report
    from gesturelib.evaluation.fgd import feature_network
    from gesturelib.evaluation.table import evaluate_models
    from gesturelib.runtime import quick_mode

    quick = args.quick or quick_mode()
    groups = _run_groups(args.runs)
    splits = load_dataset(_evaluation_data(args, quick, groups))
    if not (splits["test"] and splits["val"]):
        raise CommandError("evaluation needs conversations in both the test and the val split")
    folder = OutputFolder(args.out, "evaluate", args.overwrite)
    if Path(args.cache).exists() and not Path(args.cache).is_dir():
        raise CommandError(f"--cache {args.cache} is a file; give a folder for trained networks")
    torch.set_num_threads(args.threads)

    print(f"The FGD's motion-feature network for this data (trained once, cached in {args.cache}/)")
    features = feature_network(
        [c.positions for c in splits["train"]],
        [c.positions for c in splits["val"]],
        args.cache,
        quick=quick,
    )
    models = {name: [(m, n) for m, n, *_ in runs] for name, runs in groups.items()}
    rows, draws = evaluate_models(models, splits, args.samples, features)
    histories = {name: [(m, h) for m, _, h, _ in runs] for name, runs in groups.items()}
    with folder.staging() as stage:
        report.write_evaluation(rows, draws, histories, splits, stage.root)
    return stage.files


def _run_groups(folders: list[Path]) -> dict[str, list]:
    """The runs, loaded, grouped into the table's rows: runs of one model, config and data that
    differ only in their seed share a row. Row name -> ``[(model, normaliser, history, folder),
    ...]``,
    each with its run folder last."""
    from gesturelib.checkpoints import state_fingerprint
    from gesturelib.evaluation.table import REFERENCES
    from gesturelib.history import History
    from gesturelib.pretrained import load_run
    from gesturelib.train import EXECUTION_FIELDS

    resolved = [Path(folder).resolve() for folder in folders]
    repeated = {str(f) for f in resolved if resolved.count(f) > 1}
    if repeated:
        raise CommandError(f"a run folder is given twice: {', '.join(sorted(repeated))}")
    groups: dict[str, list] = {}
    seen: dict[str, Path] = {}  # the weights' fingerprint -> the folder that holds them
    for folder in folders:
        model, normaliser, checkpoint = load_run(folder)
        weights = state_fingerprint(model)
        if weights in seen:
            raise CommandError(
                f"{seen[weights]} and {folder} hold the same trained model (copies of one run); "
                "give each run once: copies are no seeds"
            )
        seen[weights] = Path(folder)
        if not hasattr(model, "step"):
            raise CommandError(
                f"{folder} holds a {type(model).__name__}, which does not generate motion"
            )
        kept = {
            k: v
            for k, v in checkpoint["train_config"].items()
            if k not in EXECUTION_FIELDS | {"seed"}
        }
        key = json.dumps(
            [checkpoint["model_class"], checkpoint["model_config"], kept, checkpoint["data"]],
            sort_keys=True,
        )
        history = History.from_dict(checkpoint["history"])
        groups.setdefault(key, []).append((model, normaliser, history, Path(folder)))
    named = {}
    for members in groups.values():
        names = [folder.absolute().name for *_, folder in members]
        name = names[0] if len(members) == 1 else _common_name(names, members[0][0])
        if name in named or name in REFERENCES:
            raise CommandError(
                f"two rows would be called {name!r} (a run folder's name, or a reference's); "
                "rename one of the run folders"
            )
        named[name] = members
    return named


def _common_name(names: list[str], model) -> str:
    """The row name of runs from several seeds: their folders' name without a trailing seed
    number (``moglow-1``, ``moglow-2``: ``moglow``) where they share it, else the model's class."""
    stems = {re.sub(r"[-_.]?\d+$", "", name) for name in names}
    return stems.pop() if len(stems) == 1 and "" not in stems else type(model).__name__


def _evaluation_data(args, quick: bool, groups: dict) -> Path:
    """The dataset to evaluate on: ``--data``, else the one the runs were trained on, else the
    course's synthetic one (generated if absent)."""
    from data_synth import course_data

    if args.data is not None:
        return Path(args.data)
    from gesturelib.pretrained import read_summary

    trained_on = set()
    for *_, folder in (run for runs in groups.values() for run in runs):
        trained_on.add(read_summary(folder).get("data"))
    trained_on.discard(None)
    if len(trained_on) > 1:
        raise CommandError(
            f"the runs were trained on different data ({', '.join(sorted(trained_on))}); "
            "choose one with --data"
        )
    if trained_on:
        data = Path(trained_on.pop())
        if not data.is_dir():
            raise CommandError(f"the runs were trained on {data}, which is gone; give --data")
        return data
    return course_data(quick)


# ---------------------------------------------------------------------------------------------
# demo
# ---------------------------------------------------------------------------------------------


def run_demo(out: Path, seconds: float, seed: int, overwrite: bool = False) -> list[Path]:
    """Generate a conversation no model has heard, let the shipped MoGlow move the agent to its
    speech, and render the recorded motion and MoGlow's side by side (a video with sound), with
    pictures of the speech and the poses; return the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from data_synth import generate_conversation, save_conversation
    from gesturelib import viz
    from gesturelib.features import mel_spectrogram
    from gesturelib.pipeline import speech_to_motion
    from gesturelib.pretrained import load_run, pretrained_folder

    if seconds <= 0:
        raise CommandError(f"--seconds must be positive, got {seconds}")
    model, normaliser, _ = load_run(pretrained_folder("moglow"))
    folder = OutputFolder(out, "demo", overwrite)
    print(
        f"Generating a {seconds:g} s conversation (seed {seed}; --seed {seed} draws it again) ..."
    )
    conversation = generate_conversation(seconds, seed=seed)
    with folder.staging() as stage:
        stem = stage.path("conversation")
        save_conversation(conversation, stem)
        print("The shipped MoGlow moves the agent to the conversation's speech ...")
        motion = speech_to_motion(
            model,
            normaliser,
            conversation.audio,
            conversation.sample_rate,
            activity=conversation.activity,
            seed=seed,
        )
        positions = motion.positions[0]
        _write_motion(stage, "", motion.rotations[0], positions, conversation.activity)
        print("Rendering the recorded motion and MoGlow's side by side, with the speech ...")
        motions = [conversation.positions, positions]
        titles = ["recorded (the generator's rules)", "MoGlow (shipped model)"]
        # From the front only: two motions in both views would take twice as long to render.
        audio, rate = conversation.audio, conversation.sample_rate
        _render(motions, titles, audio, rate, stage.path("agent.mp4"), views=("front",))
        mel = mel_spectrogram(conversation.audio, conversation.sample_rate, fps=conversation.fps)
        figure = viz.plot_timeline(
            mel,
            conversation.activity,
            fps=conversation.fps,
            title="Speech (log-mel) and who is talking",
        )
        figure.savefig(stage.path("timeline.png"), dpi=120)
        plt.close(figure)
        # One pose a second, overlaid, as in the Flow-VAE paper's figures.
        figure = viz.plot_pose(
            conversation.positions[:: int(conversation.fps)],
            title="The agent's poses, one a second",
        )
        figure.savefig(stage.path("poses.png"), dpi=120)
        plt.close(figure)
    return stage.files


# ---------------------------------------------------------------------------------------------
# import-bvh
# ---------------------------------------------------------------------------------------------


def run_import(args) -> dict:
    """Import the takes of ``args.src`` into the dataset folder ``args.out``; return its
    manifest."""
    from gesturelib.mocap.dataset import import_bvh

    manifest = import_bvh(args.src, args.out, rig=args.rig, overwrite=args.overwrite)
    counts = {split: len(entries) for split, entries in manifest["splits"].items()}
    minutes = sum(e["duration_s"] for es in manifest["splits"].values() for e in es) / 60
    print(
        f"Imported {sum(counts.values())} takes ({minutes:.1f} min; rig {', '.join(manifest['rig'])}, "
        f"units {', '.join(manifest['units'])}) into {args.out}/: "
        + ", ".join(f"{n} {split}" for split, n in counts.items())
    )
    return manifest


# ---------------------------------------------------------------------------------------------
# the parser
# ---------------------------------------------------------------------------------------------


def _at_least(minimum: int):
    """An argparse type: an integer >= ``minimum`` (argparse names the option in its error)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    return parse


def _parser() -> argparse.ArgumentParser:
    from gesturelib.mocap.rigs import RIG_NAMES
    from gesturelib.recipes import RECIPES

    parser = OneLineParser(prog="gesturelib", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    train = commands.add_parser("train", help="train a model into a run folder")
    train.add_argument("model", choices=sorted(RECIPES), help="which model")
    train.add_argument("--out", required=True, type=Path, help="the run folder")
    train.add_argument("--quick", action="store_true", help="quick configs and quick data")
    train.add_argument("--data", type=Path, help="a dataset folder (default: the synthetic one)")
    train.add_argument(
        "--seed", type=_at_least(0), default=0, help="seeds the weights and the training"
    )
    again = train.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue the run in --out")
    again.add_argument("--overwrite", action="store_true", help="replace the run in --out")
    train.add_argument("--device", default="cpu", help="cpu or cuda")
    train.add_argument("--threads", type=_at_least(1), default=1, help="torch threads (default 1)")
    train.add_argument(
        "--cache",
        type=Path,
        default=Path("checkpoints"),
        help="where the FGD's motion-feature network that judges a model's last epochs is cached "
        "(flowvae; default checkpoints/)",
    )

    generate = commands.add_parser("generate", help="the agent's motion for a recording")
    generate.add_argument("run", type=Path, help="a run folder")
    source = generate.add_mutually_exclusive_group(required=True)
    source.add_argument("--audio", type=Path, help="a recording of the agent's speech")
    source.add_argument("--conversation", type=Path, help="a conversation's path stem")
    generate.add_argument(
        "--partner",
        type=Path,
        help="the partner's recording, as long as the agent's (with --audio)",
    )
    generate.add_argument("--out", required=True, type=Path, help="the output folder")
    generate.add_argument("--seed", type=_at_least(0), default=0)
    generate.add_argument("--temperature", type=float, help="default: the model's own")
    generate.add_argument(
        "--samples", type=_at_least(1), default=1, help="how many motions to draw"
    )
    generate.add_argument(
        "--style", nargs="+", metavar="NAME=PERCENTILE", help="e.g. hand_height=85"
    )
    generate.add_argument(
        "--style-from",
        type=Path,
        metavar="REF",
        help="take the style of this conversation (its path stem: motion and speech; "
        "moglow and styleflow)",
    )
    generate.add_argument(
        "--steps", type=_at_least(1), help="denoising steps per chunk (diffusion only)"
    )
    generate.add_argument(
        "--sampler",
        choices=("ddim", "ddpm"),
        help="the reverse process (diffusion only; default ddim)",
    )
    generate.add_argument(
        "--guidance",
        type=float,
        help="classifier-free guidance weight >= 0 (diffusion only; 1: none)",
    )
    generate.add_argument("--no-video", action="store_true", help="write motion.npz only")
    generate.add_argument(
        "--overwrite", action="store_true", help="write into a folder of others' files"
    )
    generate.add_argument("--device", default="cpu")

    evaluate = commands.add_parser(
        "evaluate", help="score run folders and the references on held-out conversations"
    )
    evaluate.add_argument("runs", type=Path, nargs="+", metavar="RUN", help="run folders")
    evaluate.add_argument("--out", required=True, type=Path, help="the output folder")
    evaluate.add_argument("--data", type=Path, help="a dataset folder (default: the runs' own)")
    evaluate.add_argument(
        "--samples", type=_at_least(1), default=3, help="samples per conversation (default 3)"
    )
    evaluate.add_argument("--quick", action="store_true", help="quick data and feature network")
    evaluate.add_argument(
        "--cache",
        type=Path,
        default=Path("checkpoints"),
        help="where the motion-feature network of the FGD is cached (default checkpoints/)",
    )
    evaluate.add_argument("--threads", type=_at_least(1), default=1, help="torch threads")
    evaluate.add_argument(
        "--overwrite", action="store_true", help="write into a folder of others' files"
    )

    info = commands.add_parser("info", help="what a run folder holds")
    info.add_argument("run", type=Path)

    imported = commands.add_parser(
        "import-bvh", help="motion capture (NAME.bvh with NAME.wav) as a dataset"
    )
    imported.add_argument("src", type=Path, help="a folder of NAME.bvh, NAME.wav, NAME_partner.wav")
    imported.add_argument("--out", required=True, type=Path, help="the dataset folder")
    imported.add_argument(
        "--rig", choices=RIG_NAMES, help="the skeleton's joint names (default: detected)"
    )
    imported.add_argument(
        "--overwrite", action="store_true", help="replace a dataset imported there before"
    )

    demo = commands.add_parser(
        "demo", help="a new conversation: its recorded motion and the shipped MoGlow's, rendered"
    )
    demo.add_argument("--out", type=Path, default=Path("outputs/demo"), help="output folder")
    demo.add_argument("--seconds", type=float, default=20.0, help="length of the conversation")
    demo.add_argument(
        "--seed",
        type=_at_least(0),
        help="seed of the conversation and the motion (default: a new one, printed)",
    )
    demo.add_argument(
        "--overwrite", action="store_true", help="write into a folder of others' files"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    from gesturelib.checkpoints import CheckpointError

    args = _parser().parse_args(argv)
    try:
        if args.command == "train":
            run_train(args)
        elif args.command == "generate":
            files = run_generate(args)
            print(
                f"Wrote {len(files)} files to {args.out}/: "
                + ", ".join(str(f.relative_to(args.out)) for f in files)
            )
        elif args.command == "evaluate":
            files = run_evaluate(args)
            print(f"Wrote {len(files)} files to {args.out}/: " + ", ".join(f.name for f in files))
        elif args.command == "info":
            print(run_info(args))
        elif args.command == "import-bvh":
            run_import(args)
        else:
            seed = secrets.randbelow(10_000) if args.seed is None else args.seed
            files = run_demo(args.out, args.seconds, seed, args.overwrite)
            print(f"\nWrote {len(files)} files to {args.out}/:")
            for path in files:
                print(f"  {path.name}")
            print("Open agent.mp4 to watch and hear the agent.")
    except KeyboardInterrupt:
        advice = (
            f"; the run in {args.out} continues with the same command and --resume (in place "
            "of --overwrite)"
            if args.command == "train" and (Path(args.out) / "last.pt").exists()
            else ""
        )
        print(f"gesturelib {args.command}: interrupted{advice}", file=sys.stderr)
        return 130
    except (CommandError, CheckpointError, OutputError, OSError, ValueError) as error:
        # One line: the message's first line, and its first detail if it lists some.
        lines = [line.strip() for line in str(error).strip().splitlines()] or [type(error).__name__]
        message = lines[0] + (f" {lines[1]}" if lines[0].endswith(":") and len(lines) > 1 else "")
        print(f"gesturelib {args.command}: error: {message}", file=sys.stderr)
        return 2
    return 0
