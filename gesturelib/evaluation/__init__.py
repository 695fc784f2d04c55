"""How generated motion is measured, against the ground truth, references and the generator's rules.

* :mod:`~gesturelib.evaluation.headline`: the course's headline measures (wrist-speed
  Hellinger distance, speaking/listening ratio, stroke lead, how the hands share the
  gesturing), the references every model is compared with, and generation for held-out
  conversations (exported here);
* :mod:`~gesturelib.evaluation.rules`: appropriateness against the generator's event log, and
  Bailando's beat alignment;
* :mod:`~gesturelib.evaluation.fgd`: the Fréchet gesture distance and its feature network;
* :mod:`~gesturelib.evaluation.table`: every system scored into one table with spreads
  (``evaluate_models``);
* :mod:`~gesturelib.evaluation.report` and :mod:`~gesturelib.evaluation.figures`: the files and
  pictures an evaluation writes.
"""

from gesturelib.evaluation.headline import (
    WRIST_SPEED_BINS,
    generate_for,
    hand_sharing,
    headline_measures,
    pause_speed_profile,
    pause_wrist_speed,
    reference_motions,
    speaking_listening_ratio,
    speaking_wrist_speeds,
    stroke_lead,
    wrist_speed_hellinger,
    wrist_speed_histogram,
    wrist_speeds,
)

__all__ = [
    "WRIST_SPEED_BINS",
    "generate_for",
    "hand_sharing",
    "headline_measures",
    "pause_speed_profile",
    "pause_wrist_speed",
    "reference_motions",
    "speaking_listening_ratio",
    "speaking_wrist_speeds",
    "stroke_lead",
    "wrist_speed_hellinger",
    "wrist_speed_histogram",
    "wrist_speeds",
]
