"""Make the small trained models that ship in gesturelib/pretrained/ (see gesturelib.pretrained).

    python tools/make_pretrained.py

Trains the full-mode recipes of :data:`gesturelib.pretrained.NAMES` from seed 0 on the course's
full dataset (or takes them from the notebooks' cache, checkpoints/, where a chapter trained them
already; training them otherwise takes several minutes), and writes their best weights as float16 into
gesturelib/pretrained/<name>/best.pt. Run it only when a release needs new models: a change to the
generator, the speech features or the models.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from data_synth.dataset import course_data, load_dataset
from gesturelib.checkpoints import read_checkpoint
from gesturelib.pipeline import train_model
from gesturelib.pretrained import NAMES, PRETRAINED_DIR, export_run

CHECKPOINTS = Path(__file__).resolve().parents[1] / "checkpoints"


def run_folder_of(model: torch.nn.Module) -> Path:
    """The cached run folder whose best weights are ``model``'s."""
    state = model.state_dict()
    for best in sorted(CHECKPOINTS.glob(f"{type(model).__name__}-*/best.pt")):
        stored = read_checkpoint(best, kind="best")["model"]
        if stored.keys() == state.keys() and all(
            torch.equal(stored[key], value.cpu()) for key, value in state.items()
        ):
            return best.parent
    raise LookupError(f"no run folder in {CHECKPOINTS} holds this {type(model).__name__}")


def main() -> int:
    splits = load_dataset(course_data(quick=False))
    for name in NAMES:
        model = train_model(name, splits, quick=False, seed=0, cache=CHECKPOINTS).model
        path = export_run(run_folder_of(model), PRETRAINED_DIR / name, overwrite=True)
        print(f"{path}: {path.stat().st_size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
