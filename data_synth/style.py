"""The speaker's gesture style: a few numbers drawn once per conversation and recorded.

Real speakers differ in how they gesture; MoGlow (Alexanderson et al. 2020) controls style with
the hand height, hand speed, gesture radius and left/right symmetry measured from the motion.
Each conversation draws its own style, uniformly from :class:`data_synth.config.StyleRanges`,
with the conversation seed: every motion draw of a conversation (:func:`data_synth.resample_motion`)
shares it, so style is part of the conversation, not of the random details.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from data_synth.config import StyleRanges


@dataclass(frozen=True)
class Style:
    """One speaker's gesture style.

    Attributes:
        gesture_radius_cm: how far the hands wander around the centre of the gesture space
            from phrase to phrase and beat to beat (larger: more expansive gestures, held
            further out, with more outward sweeps).
        hand_height_cm: height of the gesture space above the hands' rest position.
        speed: tempo of the gestures: durations of strokes, preparations, retractions and nods
            are divided by it (faster strokes peak at higher wrist speeds).
        symmetry: probability that a gesture phrase uses both hands, mirror-symmetrically.
        handedness: probability that a one-handed gesture phrase uses the right hand.
        beat_amplitude_cm: travel of a beat stroke at emphasis 1 (it scales with emphasis).
    """

    gesture_radius_cm: float
    hand_height_cm: float
    speed: float
    symmetry: float
    handedness: float
    beat_amplitude_cm: float

    def to_dict(self) -> dict[str, float]:
        """Plain dictionary for JSON."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Style:
        """Inverse of :meth:`to_dict`; missing or unknown keys raise ``ValueError``."""
        expected = {f.name for f in fields(cls)}
        if not isinstance(data, dict) or set(data) != expected:
            raise ValueError(f"style must have exactly the keys {sorted(expected)}, got {data!r}")
        return cls(**{key: float(value) for key, value in data.items()})


def draw_style(ranges: StyleRanges, rng: np.random.Generator) -> Style:
    """Draw each style parameter uniformly from its range."""
    return Style(**{f.name: float(rng.uniform(*getattr(ranges, f.name))) for f in fields(Style)})
