"""Fixtures shared by the test modules: a tiny dataset on disk and a quick MoGlow run trained on it."""

import pytest

from gesturelib.cli import main


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
