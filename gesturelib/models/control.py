"""The control signal of the autoregressive flows (MoGlow, the Flow-VAE), and its shared encoder.

The control ``c_t`` of frame ``t`` is what the next-frame flow is conditioned on:

* the previous ``tau`` poses (``past_pose``), with **data dropout** while training: each past pose
  is replaced by the mean pose (zero, in normalised units) with probability ``dropout``,
  independently, so that the model cannot simply continue its past and ignore the speech
  (Alexanderson et al. 2020); validation and generation never drop;
* the speech window (``speech_past`` past frames, the current one and 25 future ones: 1 s of
  look-ahead, because gestures lead the speech they go with) and the same window of who is
  talking. With ``voice_shift``, training moves each excerpt's speech up or down by a few mel
  bands, as a higher or lower voice would: the course's few voices then stand for more, and a
  new voice is met by a model that has heard its register before (``docs/benchmarks.md``, "A
  range the models never heard");
* optionally MoGlow's style inputs (:mod:`gesturelib.style`).

That is about 1.2k numbers a frame with 5 past speech frames (the papers'), 1.5k with 15 (the
course's MoGlow and Flow-VAE). Read by the recurrent network of each of the ``K`` couplings, it
would dominate the cost, so one small network (as Ye et al.'s global encoder) turns it into
``control_size`` numbers that all couplings read; ``control_size=0`` passes the raw control
on, as the reference MoGlow code does. The style's four numbers (standardised) pass beside the
encoder: mixed into its first layer with the other 1.5k they were mostly ignored, and the samples
followed little of a style asked (``docs/benchmarks.md``, "Style that obeys").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import nn

from gesturelib.configs import SpeechContext, check_fields
from gesturelib.conventions import N_MELS, NUM_ACTIVITIES
from gesturelib.models.common import batch_parts
from gesturelib.skeleton import POSE_DIM
from gesturelib.style import STYLE_FEATURES


@dataclass(frozen=True)
class ControlConfig(SpeechContext):
    """What the control of a frame holds, and how it is encoded.

    Attributes:
        speech_past, speech_future: the speech and activity window (5 and 25 frames).
        past_poses: tau, the previous poses in the control.
        style: also condition on the style measured from the motion (:mod:`gesturelib.style`).
        control_size: numbers the shared control encoder outputs; 0 passes the raw control on.
        dropout: probability of replacing each past pose by the mean pose while training.
        voice_shift: while training, each excerpt's speech is moved by a whole number of mel
            bands drawn uniformly from ``[-voice_shift, voice_shift]`` (0: never).
    """

    #: Fields added after runs were saved, with the value those runs were trained with, so that
    #: their checkpoints load as they were trained (:func:`gesturelib.configs.config_from_dict`).
    FIELDS_ADDED: ClassVar[dict] = {"voice_shift": 0}

    past_poses: int = 5
    style: bool = False
    control_size: int = 64
    dropout: float = 0.4
    voice_shift: int = 0

    def __post_init__(self):
        super().__post_init__()
        check_fields(
            self,
            counts=("past_poses", "control_size", "voice_shift"),
            fractions=("dropout",),
            flags=("style",),
        )

    @property
    def raw_control_size(self) -> int:
        """Numbers in the control of one frame that the encoder reads (all but the style)."""
        window = self.speech_window * (N_MELS + NUM_ACTIVITIES)
        return self.past_poses * POSE_DIM + window

    @property
    def encoded_size(self) -> int:
        """Numbers in the control the couplings read: ``control_size`` (or the raw size), and
        the style."""
        style = len(STYLE_FEATURES) if self.style else 0
        return (self.control_size or self.raw_control_size) + style


def control_shapes(config) -> dict[str, tuple[int, ...]]:
    """The parts of a frame's control and their shapes after ``(B, L)``, for
    :func:`~gesturelib.models.common.batch_parts`: ``past_pose``, ``speech``, ``activity`` (and
    ``style`` if ``config.style``). ``config``: any config with ``past_poses``, the speech window
    and ``style``."""
    shapes = {
        "past_pose": (config.past_poses, POSE_DIM),
        "speech": (config.speech_window, N_MELS),
        "activity": (config.speech_window, NUM_ACTIVITIES),
    }
    if config.style:
        shapes["style"] = (len(STYLE_FEATURES),)
    return shapes


class ControlEncoder(nn.Module):
    """The control of every frame of a batch: ``(B, L, encoded_size)``.

    Args:
        config: what the control holds (any :class:`ControlConfig`).
        hidden: width of the encoder's hidden layer.
    """

    def __init__(self, config: ControlConfig, hidden: int):
        super().__init__()
        self.config = config
        if config.control_size:
            self.encoder = nn.Sequential(
                nn.Linear(config.raw_control_size, hidden),
                nn.ReLU(),
                nn.Linear(hidden, config.control_size),
            )
        else:
            self.encoder = nn.Identity()

    def forward(self, batch: dict[str, torch.Tensor], training: bool = False) -> torch.Tensor:
        """Encode ``past_pose (B, L, tau, 54)``, ``speech (B, L, W, 27)`` and ``activity (B, L,
        W, 4)`` into ``(B, L, encoded_size)``, with ``style (B, L, 4)`` (if the config has it)
        appended as it is; ``training`` applies the voice shift and data dropout."""
        config = self.config
        past, speech, activity, *style = batch_parts(
            batch, control_shapes(config), type(self).__name__
        )
        if training and config.voice_shift > 0:
            shifts = torch.randint(
                -config.voice_shift, config.voice_shift + 1, (len(speech),), device=speech.device
            )
            speech = shift_bands(speech, shifts)
        if training and config.dropout > 0:
            kept = torch.rand(past.shape[:3], device=past.device) >= config.dropout
            past = past * kept[..., None]  # a dropped pose becomes the mean pose, zero
        flat = [part.flatten(2) for part in (past, speech, activity)]
        return torch.cat([self.encoder(torch.cat(flat, dim=-1)), *style], dim=-1)


def shift_bands(speech: torch.Tensor, shifts: torch.Tensor) -> torch.Tensor:
    """Each item's speech moved up (``shifts > 0``) or down the mel bands, the bands it leaves
    empty filled with the nearest one it kept: ``speech (B, ..., n_mels)``, ``shifts (B,)`` whole
    numbers -> ``(B, ..., n_mels)``."""
    bands = torch.arange(speech.shape[-1], device=speech.device)
    shifts = shifts.reshape(-1, *[1] * (speech.ndim - 1))
    source = (bands - shifts).clamp(0, speech.shape[-1] - 1)  # (B, 1, ..., n_mels)
    return speech.gather(-1, source.expand(speech.shape))
