"""The record of a training run: per-epoch losses, learning rate and timing, and their plot.

:func:`gesturelib.train.train` fills a :class:`History` as it goes and stores it in every
checkpoint, so a finished run loaded from disk can still show how it trained.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np


@dataclass
class History:
    """What happened in each epoch (epochs are numbered from 1).

    Attributes:
        train: per logged scalar (``"loss"``, ``"kl"``, ...), its mean over each epoch's batches.
        val: the same on the validation data (empty without validation data).
        learning_rate: the rate of each epoch's last step.
        epoch_seconds: wall time of each epoch, validation included.
        best_epoch: the epoch whose weights were kept (best validation loss).
        stopped_early: whether early stopping ended the run.
    """

    train: dict[str, list[float]] = field(default_factory=dict)
    val: dict[str, list[float]] = field(default_factory=dict)
    learning_rate: list[float] = field(default_factory=list)
    epoch_seconds: list[float] = field(default_factory=list)
    best_epoch: int | None = None
    stopped_early: bool = False

    @property
    def epochs(self) -> int:
        """Epochs completed."""
        return len(self.learning_rate)

    def append(self, train: dict, val: dict, learning_rate: float, seconds: float) -> None:
        """Record one epoch; its logged scalars must be those of the earlier epochs."""
        for name, record, values in (
            ("training", self.train, train),
            ("validation", self.val, val),
        ):
            if self.epochs and set(record) != set(values):
                raise ValueError(
                    f"the model logged {sorted(values)} on the {name} data in epoch "
                    f"{self.epochs + 1}, but {sorted(record)} before; loss() must return the same "
                    "scalars every time"
                )
            for key, value in values.items():
                record.setdefault(key, []).append(value)
        self.learning_rate.append(learning_rate)
        self.epoch_seconds.append(seconds)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> History:
        """Inverse of :meth:`to_dict`; the keys must be exactly the fields."""
        names = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(data, dict) or set(data) != names:
            got = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise ValueError(f"a History needs exactly the keys {sorted(names)}, got {got}")
        return cls(
            train={key: list(values) for key, values in data["train"].items()},
            val={key: list(values) for key, values in data["val"].items()},
            learning_rate=list(data["learning_rate"]),
            epoch_seconds=list(data["epoch_seconds"]),
            best_epoch=data["best_epoch"],
            stopped_early=bool(data["stopped_early"]),
        )

    def plot(self, keys: list[str] | None = None):
        """One panel per logged scalar (training and validation) and one for the learning rate.

        Args:
            keys: which scalars to show; all by default.
        Returns:
            The matplotlib figure. The dotted line marks the best epoch, whose weights are kept.
        """
        import matplotlib.pyplot as plt  # here: importing pyplot is slow, and only plots need it
        from matplotlib.ticker import MaxNLocator

        keys = list(self.train) if keys is None else keys
        epochs = np.arange(1, self.epochs + 1)
        fig, axes = plt.subplots(
            1, len(keys) + 1, figsize=(3.6 * (len(keys) + 1), 3), squeeze=False
        )
        for ax in axes[0]:
            ax.set_xlabel("epoch")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            if self.best_epoch is not None:
                ax.axvline(
                    self.best_epoch, color="k", linestyle=":", linewidth=1, label="best (kept)"
                )
        for ax, key in zip(axes[0, :-1], keys, strict=True):
            ax.plot(epochs, self.train[key], label="training")
            if key in self.val:
                ax.plot(epochs, self.val[key], label="validation")
            ax.set_title(key)
            ax.legend()
        axes[0, -1].plot(epochs, self.learning_rate, color="grey")
        axes[0, -1].set_title("learning rate")
        fig.tight_layout()
        return fig
