"""Run-time switches shared by notebooks, the command line and CI: quick mode and seeding.

Quick mode is one environment variable, ``GESTURELIB_QUICK``; CI sets it to 1 so that every
notebook runs on less data and fewer training steps, through the same code path.
"""

from __future__ import annotations

import os
import random

import numpy as np
import torch

QUICK_ENV_VAR = "GESTURELIB_QUICK"
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"", "0", "false", "no", "off"}


def quick_mode() -> bool:
    """True when ``GESTURELIB_QUICK`` is set to 1/true/yes/on (case-insensitive).

    Raises:
        ValueError: for any other value, so that a typo does not silently run the long version.
    """
    value = os.environ.get(QUICK_ENV_VAR, "").strip().lower()
    if value in _TRUE:
        return True
    if value in _FALSE:
        return False
    raise ValueError(
        f"{QUICK_ENV_VAR}={os.environ[QUICK_ENV_VAR]!r} is not understood; "
        "use 1 for quick mode or 0 (or leave it unset) for full mode"
    )


def seed_everything(seed: int) -> tuple[np.random.Generator, torch.Generator]:
    """Seed Python's, NumPy's and PyTorch's global generators, for a notebook's own cells.

    Library functions take explicit generators; this returns a fresh pair for that:
    ``rng, generator = seed_everything(0)``. The global ones are seeded as well because
    ``torch.nn`` draws initial weights from PyTorch's global generator.
    """
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - third-party code may draw from NumPy's global generator
    torch.manual_seed(seed)
    return np.random.default_rng(seed), torch.Generator().manual_seed(seed)
