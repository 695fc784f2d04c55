"""Run-time switches shared by notebooks, the command lines and CI: quick mode, seeds, devices,
and the one-line usage errors of every command line.

Quick mode is one environment variable, ``GESTURELIB_QUICK``; CI sets it to 1 so that every
notebook runs on less data and fewer training steps, through the same code path. Random draws
take explicit generators (:func:`standard_normal`), and devices are named once (:func:`device`).
"""

from __future__ import annotations

import argparse
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


def standard_normal(
    shape: tuple[int, ...],
    generator: torch.Generator | None = None,
    device=None,
    dtype: torch.dtype | None = None,
) -> torch.Tensor:
    """``N(0, I)`` noise of ``shape`` from ``generator``, on ``device`` in ``dtype``.

    Drawn on the generator's own device, then moved, so that a CPU generator (the usual seeded
    one) drives a model on a GPU and gives the same numbers there.
    """
    source = generator.device if generator is not None else device
    noise = torch.randn(shape, generator=generator, device=source, dtype=dtype)
    return noise.to(device) if device is not None else noise


def device(name: str | torch.device) -> torch.device:
    """The device called ``name`` (``"cpu"``, ``"cuda"``, ``"cuda:1"``), checked to exist here.

    Raises:
        ValueError: for a name that is no device, or CUDA on a machine without a CUDA GPU.
    """
    try:
        found = torch.device(name)
    except (RuntimeError, TypeError) as error:
        raise ValueError(f"{name!r} is not a device; use e.g. 'cpu' or 'cuda'") from error
    if found.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"device {name!r} cannot run the models; use 'cpu' or 'cuda'")
    if found.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r} asked for, but no CUDA GPU is available here")
    return found


def device_of(module: torch.nn.Module) -> torch.device:
    """Where a module's parameters live (the CPU for a module without parameters)."""
    parameter = next(module.parameters(), None)
    return torch.device("cpu") if parameter is None else parameter.device


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line on stderr (and exit status 2),
    like every other error a user can fix; ``--help`` shows the usage."""

    def error(self, message: str):
        if message.endswith("expected one argument"):  # e.g. --audio -take1.wav
            message += " (a file name that starts with '-' needs ./ before it)"
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")
