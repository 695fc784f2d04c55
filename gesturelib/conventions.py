"""The data conventions of the whole project, written once and imported everywhere.

* Motion runs at :data:`FPS` = 25 frames a second (40 ms a frame), as in the Flow-VAE paper.
* Audio runs at :data:`SAMPLE_RATE` = 16 kHz; user files at other rates are resampled on load.
* Speech features are :data:`N_MELS` = 27 log-mel bands, one row per motion frame.
* Positions are in centimetres, y up, the spine base at the origin, the agent facing +z
  (see :mod:`gesturelib.skeleton`).
* Who is talking is one :class:`Activity` code per motion frame.
"""

from __future__ import annotations

from enum import IntEnum

FPS = 25
SAMPLE_RATE = 16_000
N_MELS = 27


class Activity(IntEnum):
    """Speech activity of a frame in the dyadic conversation.

    Speaker A is the agent we animate (on camera); speaker B is the off-screen partner.
    """

    A_SPEAKS = 0
    B_SPEAKS = 1
    BOTH = 2
    NONE = 3

    @property
    def label(self) -> str:
        """A short human-readable name for plots and legends."""
        return _ACTIVITY_LABELS[self]


_ACTIVITY_LABELS = {
    Activity.A_SPEAKS: "A speaks",
    Activity.B_SPEAKS: "B speaks",
    Activity.BOTH: "both",
    Activity.NONE: "none",
}
NUM_ACTIVITIES = len(Activity)
