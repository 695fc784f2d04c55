"""Fixtures shared by the test modules: windows of a short conversation, a tiny dataset on disk and
a quick MoGlow run trained on it."""

import pytest
import torch

from gesturelib.cli import main


@pytest.fixture(scope="module")
def one_thread():
    """One torch thread for a module of small models: on the shared 2-core machine threads cost
    more than they give (training was 5 times slower with two)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def short_windows():
    """A short conversation, its normaliser, its 12-frame windows (context: 2 past poses, speech
    2 frames back and 3 ahead) and the first three of them stacked as a batch."""
    from data_synth import generate_conversation
    from gesturelib.data import ConversationFeatures, Normaliser, WindowConfig, WindowDataset

    conversation = generate_conversation(8.0, seed=5)
    features = ConversationFeatures.from_conversation(conversation)
    normaliser = Normaliser.fit([features])
    windows = WindowConfig(
        speech_past=2, speech_future=3, past_poses=2, sequence_length=12, stride=12
    )
    dataset = WindowDataset([features], windows, normaliser)
    batch = {name: torch.stack([dataset[i][name] for i in range(3)]) for name in dataset[0]}
    return conversation, normaliser, batch, dataset


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory):
    """A dataset of three 10 s conversations (one per split)."""
    from data_synth import write_dataset

    folder = tmp_path_factory.mktemp("data")
    write_dataset(folder, minutes=0.5, seed=0, conversation_s=10.0, progress=False)
    return folder


@pytest.fixture(scope="session")
def moglow_run(tmp_path_factory, tiny_data):
    """A quick MoGlow run folder, trained once with ``python -m gesturelib train``."""
    run = tmp_path_factory.mktemp("runs") / "moglow"
    assert main(["train", "moglow", "--out", str(run), "--quick", "--data", str(tiny_data)]) == 0
    return run


@pytest.fixture(scope="session")
def trained_looking():
    """A function ``(config, normaliser, batch, seed=0, spread=0.2) -> MoGlow`` giving a model
    whose every weight is random (so no layer is an identity and every input reaches the output:
    noise of ``spread`` added to each) and whose ActNorm layers have seen ``batch``."""
    from gesturelib.models import MoGlow

    def make(config, normaliser, batch, seed=0, spread=0.2):
        torch.manual_seed(seed)
        model = MoGlow(config, normaliser)
        model.loss(batch)  # initialises ActNorm and the conditioners
        generator = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for parameter in model.parameters():
                parameter.add_(spread * torch.randn(parameter.shape, generator=generator))
        return model.eval()

    return make


@pytest.fixture(scope="session")
def step_through():
    """A function ``(model, batch, z, **extra) -> (B, L, D)``: the model's ``step`` on each frame
    of ``batch`` (its control, ``L = 1`` at a time, with ``extra`` entries added) for the noise
    ``z`` ``(B, L, noise_dim)``, the state carried: generation frame by frame, to compare with
    what the whole sequence gives."""

    def run(model, batch, z, **extra):
        state, frames = None, []
        with model.generating():
            for t in range(z.shape[1]):
                frame = {name: part[:, t : t + 1] for name, part in batch.items()}
                pose, state = model.step({**frame, **extra}, state, z[:, t])
                frames.append(pose)
        return torch.stack(frames, dim=1)

    return run
