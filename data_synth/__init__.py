"""Procedural dyadic conversations with known rules: speech audio, who speaks, the agent's motion.

Speaker A (the agent, on camera) talks with speaker B (off camera). We generate both voices
mixed in one track, one activity code per frame (A, B, both, none) and A's upper-body motion on
the 9 keypoints of :mod:`gesturelib.skeleton`. Because the rules that link A's speech to A's
motion are ours, we can measure whether a model learned them.

The rules (defaults in brackets; parameters in :mod:`data_synth.config`):

* **Turn-taking** (:mod:`data_synth.turns`): turns of 1 + Poisson phrases (mean 3 for A, 1.7 for
  B) of 1.2-3 s (A) or 0.9-2.4 s (B), pauses of 0.2-0.6 s between phrases, gaps of 0.2-0.8 s
  between turns, overlaps of 0.15-0.5 s at 20 % of turn changes, long silences at 15 %, and
  "mm-hm" backchannels from the listener after 40 % of phrases. A speaks about twice as much as B.
* **Speech** (:mod:`data_synth.prosody`, :mod:`data_synth.voice`): 4-6 syllables a second of
  consonant noise and formant-filtered voiced vowels; an accent every 3-5 syllables, with an
  emphasis in [0.4, 1] that makes its vowel up to 8 dB louder, 1.4x longer and up to 4 semitones
  higher; pitch declination along each phrase. A's voice is low (110-130 Hz), B's high
  (200-220 Hz), 9 dB quieter and muffled (off-microphone).
* **Beats** (:mod:`data_synth.gestures`): before each of A's phrases its hands rise into a
  gesture space in front of the chest (wrists typically 25-40 cm up, the sternum at 50; the upper
  arms lift), then beat once per accent: the wrist speed peaks 0.2 s *before* the accent
  (``stroke_lead_s``), with a stroke of 11-20 cm x emphasis, downwards, outwards or forwards
  (peaks of 60-200 cm/s); after the phrase the hands retract home, in front of the belly (or
  hold, if A's next phrase follows closely and B stays silent), and sink into the lap when A
  stays silent for long.
* **Nods** (:mod:`data_synth.nods`): with emphasis while A speaks; after B's phrases while A
  listens (80 %); with A's own backchannels.
* **Idle motion** (:mod:`data_synth.motion`): breathing and sway always; while listening the hands
  wait low and idle motion drops to 40 %, so the agent stays close to its mean pose.
* **Style** (:mod:`data_synth.style`): gesture radius, hand height, speed, symmetry, handedness and
  beat amplitude, drawn per conversation and recorded.
* **Two seeds** (:mod:`data_synth.conversation`): the conversation seed fixes the speech and the
  style; the motion seed the details of the motion. :func:`resample_motion` draws another motion
  for the same conversation: the spread between draws is the floor no model can beat.

Gaps in the motion, as a tracker loses keypoints: :mod:`data_synth.occlusion`.

How each rule is measured: :mod:`data_synth.emphasis` (beat timing from the audio alone) and
:mod:`gesturelib.metrics`. The dataset on disk: :mod:`data_synth.dataset` and
``python -m data_synth --out DIR``.
"""

from data_synth.config import (
    ConfigError,
    ConversationConfig,
    MotionConfig,
    StyleRanges,
    TurnConfig,
    VoiceConfig,
)
from data_synth.conversation import (
    GENERATOR_VERSION,
    MAX_DURATION_S,
    MIN_DURATION_S,
    Conversation,
    DatasetError,
    generate_conversation,
    load_conversation,
    resample_motion,
    save_conversation,
)
from data_synth.dataset import (
    course_data,
    data_folder,
    ensure_dataset,
    load_dataset,
    load_split,
    read_manifest,
    write_dataset,
)
from data_synth.emphasis import emphasis_envelope, measure_stroke_lead
from data_synth.events import Events
from data_synth.occlusion import occlude, occlusion_mask
from data_synth.style import Style

__version__ = GENERATOR_VERSION

__all__ = [
    "MAX_DURATION_S",
    "MIN_DURATION_S",
    "ConfigError",
    "Conversation",
    "ConversationConfig",
    "DatasetError",
    "Events",
    "MotionConfig",
    "Style",
    "StyleRanges",
    "TurnConfig",
    "VoiceConfig",
    "course_data",
    "data_folder",
    "emphasis_envelope",
    "ensure_dataset",
    "generate_conversation",
    "load_conversation",
    "load_dataset",
    "load_split",
    "measure_stroke_lead",
    "occlude",
    "occlusion_mask",
    "read_manifest",
    "resample_motion",
    "save_conversation",
    "write_dataset",
]
