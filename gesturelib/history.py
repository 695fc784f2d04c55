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
        epoch_seconds: wall time of each epoch, validation and judging included.
        best_epoch: the epoch whose weights were kept: the best validation loss, or the best
            judged epoch once an epoch has been judged with a finite score.
        stopped_early: whether early stopping ended the run.
        judged: the judge's score (lower is better) of each judged epoch, by epoch: the last
            ``TrainConfig.judged_epochs`` epochs of a run trained with a judge (none if it
            stopped early before them).
    """

    train: dict[str, list[float]] = field(default_factory=dict)
    val: dict[str, list[float]] = field(default_factory=dict)
    learning_rate: list[float] = field(default_factory=list)
    epoch_seconds: list[float] = field(default_factory=list)
    best_epoch: int | None = None
    stopped_early: bool = False
    judged: dict[int, float] = field(default_factory=dict)

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
        """Inverse of :meth:`to_dict`; the keys must be the fields (``judged`` may be missing:
        histories written before judging existed)."""
        names = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(data, dict) or not names - {"judged"} <= set(data) <= names:
            got = sorted(data) if isinstance(data, dict) else type(data).__name__
            raise ValueError(
                f"a History needs the keys {sorted(names)} ('judged' may be missing), got {got}"
            )
        return cls(
            train={key: list(values) for key, values in data["train"].items()},
            val={key: list(values) for key, values in data["val"].items()},
            learning_rate=list(data["learning_rate"]),
            epoch_seconds=list(data["epoch_seconds"]),
            best_epoch=data["best_epoch"],
            stopped_early=bool(data["stopped_early"]),
            judged={int(epoch): float(score) for epoch, score in data.get("judged", {}).items()},
        )

    def plot(self, keys: list[str] | None = None):
        """One panel per logged scalar (training and validation), one for the judge's scores of
        a judged run, and one for the learning rate.

        Args:
            keys: which scalars to show; all by default.
        Returns:
            The matplotlib figure. The dotted line marks the best epoch, whose weights are kept.
        """
        import matplotlib.pyplot as plt  # here: importing pyplot is slow, and only plots need it
        from matplotlib.ticker import MaxNLocator

        keys = list(self.train) if keys is None else keys
        panels = len(keys) + bool(self.judged) + 1
        epochs = np.arange(1, self.epochs + 1)
        fig, axes = plt.subplots(1, panels, figsize=(3.6 * panels, 3), squeeze=False)
        for ax in axes[0]:
            ax.set_xlabel("epoch")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            if self.best_epoch is not None:
                ax.axvline(
                    self.best_epoch, color="k", linestyle=":", linewidth=1, label="best (kept)"
                )
        for ax, key in zip(axes[0, : len(keys)], keys, strict=True):
            ax.plot(epochs, self.train[key], label="training")
            if key in self.val:
                ax.plot(epochs, self.val[key], label="validation")
            ax.set_title(key)
            ax.legend()
        if self.judged:
            ax = axes[0, len(keys)]
            ax.plot(list(self.judged), list(self.judged.values()), "o-", color="C2")
            ax.set_title("judged (lower is better)")
        axes[0, -1].plot(epochs, self.learning_rate, color="grey")
        axes[0, -1].set_title("learning rate")
        fig.tight_layout()
        return fig
