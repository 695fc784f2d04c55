"""The contract every registered model keeps (``docs/adding_a_model.md``), checked for each entry
of :data:`gesturelib.recipes.RECIPES`: a new model is covered by adding its recipe."""

import numpy as np
import pytest
import torch

from data_synth import load_dataset, load_split
from gesturelib.cli import main
from gesturelib.data import make_datasets
from gesturelib.features import speech_features
from gesturelib.pipeline import train_model
from gesturelib.pretrained import load_run
from gesturelib.recipes import GENERATORS, RECIPES
from gesturelib.sampling import Stream


@pytest.fixture(scope="module")
def splits(tiny_data):
    return load_dataset(tiny_data)


@pytest.fixture(scope="module")
def held_out(tiny_data):
    """The held-out conversation's path stem and its number of frames."""
    stem = next((tiny_data / "test").glob("*.wav")).with_suffix("")
    return stem, len(load_split(tiny_data, "test")[0].activity)


@pytest.fixture(scope="module")
def runs(splits, tmp_path_factory, one_thread):
    """Each registered model trained for one quick epoch, twice from seed 1 (after different
    draws of the caller's): name -> (trained, trained again, run folder of the first)."""
    made, cache = {}, tmp_path_factory.mktemp("cache")  # the judge's feature network
    for name in RECIPES:
        folders = [tmp_path_factory.mktemp(name) / run for run in ("a", "b")]
        trained = []
        for caller_seed, folder in zip((100, 200), folders, strict=True):
            torch.manual_seed(caller_seed)  # the caller's random state must not matter
            trained.append(
                train_model(
                    name,
                    splits,
                    quick=True,
                    seed=1,
                    train_changes={"epochs": 1},
                    cache=cache,
                    out=folder,
                    progress=False,
                )
            )
        made[name] = (*trained, folders[0])
    return made


@pytest.mark.parametrize("name", list(RECIPES))
def test_training_from_one_seed_gives_the_same_weights_bit_for_bit(name, runs):
    first, second, _ = runs[name]
    state, again = first.model.state_dict(), second.model.state_dict()
    assert state.keys() == again.keys()
    different = [key for key in state if not torch.equal(state[key], again[key])]
    assert not different, f"{name}: {different[:5]} differ between two runs of seed 1"


@pytest.mark.parametrize("name", list(RECIPES))
def test_the_loss_is_a_dict_of_finite_scalars_with_loss_among_them(name, runs, splits):
    trained = runs[name][0]
    windows = RECIPES[name].settings(True)[0]
    data = make_datasets(splits, windows)[0]["val"]
    batch = {key: torch.stack([data[i][key] for i in range(2)]) for key in data[0]}
    with torch.no_grad():
        terms = trained.model.loss(batch)
    assert "loss" in terms
    for key, value in terms.items():
        assert value.shape == () and torch.isfinite(value), f"{name}: {key} = {value}"


@pytest.mark.parametrize("name", list(RECIPES))
def test_the_run_folder_loads_the_same_model_and_normaliser(name, runs):
    trained, _, folder = runs[name]
    model, normaliser, checkpoint = load_run(folder)
    assert type(model) is type(trained.model) and checkpoint["model_class"] == type(model).__name__
    loaded = model.state_dict()
    for key, value in trained.model.state_dict().items():
        assert torch.equal(loaded[key], value.cpu()), f"{name}: {key} changed on the round trip"
    assert normaliser.to_dict() == trained.normaliser.to_dict()


@pytest.mark.parametrize("name", GENERATORS)
def test_a_generating_model_streams_poses_of_the_skeleton(name, runs, tiny_data):
    trained = runs[name][0]
    model = trained.model
    assert isinstance(model.noise_dim, int) and model.noise_dim >= 0
    conversation = load_split(tiny_data, "test")[0]
    speech = speech_features(conversation.audio, conversation.sample_rate)[:40]
    stream = Stream(model, trained.normaliser, samples=2, seed=0)
    poses = np.concatenate(
        [stream.push(speech, conversation.activity[:40]), stream.finish()], axis=1
    )
    assert poses.shape == (2, 40, 9, 6) and np.isfinite(poses).all()


@pytest.mark.parametrize("name", GENERATORS)
def test_a_generating_model_generates_through_the_command_line(name, runs, held_out, tmp_path):
    stem, frames = held_out
    out = tmp_path / "out"
    command = ["generate", str(runs[name][2]), "--conversation", str(stem), "--out", str(out)]
    assert main([*command, "--no-video"]) == 0
    motion = np.load(out / "motion.npz")
    assert motion["rotations"].shape == (frames, 9, 6)
    assert motion["positions"].shape == (frames, 9, 3)


@pytest.mark.parametrize("name", GENERATORS)
def test_only_a_diffusion_run_takes_denoising_steps_and_guidance(name, runs, held_out, tmp_path):
    stem, frames = held_out
    command = ["generate", str(runs[name][2]), "--conversation", str(stem), "--no-video"]
    command += ["--steps", "3", "--sampler", "ddpm", "--guidance", "2", "--out", str(tmp_path)]
    denoises = hasattr(runs[name][0].model, "sampling")
    assert main(command) == (0 if denoises else 2)
    if denoises:
        assert np.load(tmp_path / "motion.npz")["rotations"].shape == (frames, 9, 6)


def test_every_model_that_is_not_a_generator_is_refused_by_generate(runs, held_out, tmp_path):
    stem = held_out[0]
    for name in set(RECIPES) - set(GENERATORS):
        command = ["generate", str(runs[name][2]), "--conversation", str(stem)]
        assert main([*command, "--out", str(tmp_path / name)]) == 2


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("name", list(RECIPES))
def test_a_gpu_trains_every_model_and_generates_what_the_cpu_does(
    name, runs, splits, held_out, tmp_path
):
    """Training on a GPU gives a run that loads on the CPU; with z = 0 (temperature 0, no random
    draw) the same run generates on the GPU the motion it generates on the CPU, to rounding."""
    folder = tmp_path / "gpu"
    trained = train_model(
        name,
        splits,
        quick=True,
        seed=1,
        train_changes={"epochs": 1, "device": "cuda"},
        cache=tmp_path / "cache",
        out=folder,
        progress=False,
    )
    assert all(p.is_cuda for p in trained.model.parameters())
    model, _, _ = load_run(folder)
    assert all(torch.isfinite(p).all() and not p.is_cuda for p in model.parameters())
    if name in GENERATORS:
        stem = held_out[0]
        command = ["generate", str(runs[name][2]), "--conversation", str(stem), "--no-video"]
        command += ["--temperature", "0"]
        for device in ("cpu", "cuda"):
            assert main([*command, "--out", str(tmp_path / device), "--device", device]) == 0
        cpu, gpu = (np.load(tmp_path / d / "motion.npz")["positions"] for d in ("cpu", "cuda"))
        np.testing.assert_allclose(gpu, cpu, atol=0.1)  # cm
