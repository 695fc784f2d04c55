"""A dataset folder, whoever made it: the generator's (:mod:`data_synth`) or motion capture
imported with ``python -m gesturelib import-bvh`` (:mod:`gesturelib.mocap.dataset`).

Both give ``{"train", "val", "test"}`` lists of conversations or takes with what training and
evaluation read: ``audio``, ``sample_rate``, ``fps``, ``activity``, ``rotations``,
``positions``, and ``events`` (None for imported takes).
"""

from __future__ import annotations

import json
import os
from pathlib import Path


def dataset_format(folder: str | os.PathLike) -> str | None:
    """The ``format`` its manifest names, or None without a readable manifest."""
    from gesturelib.mocap.dataset import MANIFEST_NAME

    try:
        return json.loads((Path(folder) / MANIFEST_NAME).read_text()).get("format")
    except (OSError, ValueError, AttributeError):
        return None


def load_dataset(folder: str | os.PathLike) -> dict[str, list]:
    """Every split of the dataset in ``folder``, checked as its own loader checks it.

    Raises:
        ValueError (``DatasetError`` or ``MocapError``): naming the damaged file, or a folder
            that holds no dataset.
    """
    from gesturelib.mocap.dataset import FORMAT, load_recordings

    if dataset_format(folder) == FORMAT:
        return load_recordings(folder)
    from data_synth import load_dataset as load_generated

    return load_generated(folder)
