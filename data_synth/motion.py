"""The agent's upper-body motion: gestures, nods, breathing and sway on the 9-keypoint skeleton.

The rules, all at once (details and parameters in :mod:`data_synth.gestures`,
:mod:`data_synth.nods` and :class:`data_synth.config.MotionConfig`):

* **Always**: breathing (a rate drawn from ``breathing_rate_hz``; the chest pitches 0.3 degrees
  and the shoulders rise by 1.2 degrees with each breath) and a slow sway of torso and head
  (``sway_deg``) and of the hands (``idle_hand_cm``; a hand lying in the lap drifts at 20 %).
* **Speaking** (the agent's phrases): gesture phrases with beats that lead the accents by
  ``stroke_lead_s``, nods with emphasis; within a gesture phrase the torso leans 1 degree
  forwards and the idle motion is at full strength.
* **Listening and silence** (outside gesture phrases): hands at home in front of the belly, or in
  the lap after a while (or holding, in a short pause between two phrases of the agent),
  backchannel nods after the partner's phrases, and the idle motion of torso, head and hands
  scaled down to ``listening_activity`` (40 %), with a 0.4 s transition: the agent stays close to
  its mean pose, as Taylor et al. observed of their speaker.
* **Cross-talk**: the agent's own phrases decide (it gestures while both talk); the partner's
  backchannels during the agent's phrases change nothing.

How a pose is built, frame by frame (frame ``t`` is sampled at its centre ``(t + 0.5) / fps``):

1. In a *body frame* (the spine base at the origin, upright): the sternum 50 cm up, the
   shoulders 18 cm to either side (raised by breathing), the wrists at the targets of
   :mod:`data_synth.gestures` plus idle drift, the elbows from two-bone inverse kinematics
   (:func:`elbow_pole`): with the hands low the elbows hang under the shoulders, pointing down
   and a little back; as the hands rise into the gesture space the upper arms lift, the elbows
   swinging outwards and forwards. Elbows always bend the natural way. The head sits 20 cm above
   the sternum and the nose in front of it, turned by the nods and the head's idle motion.
2. The whole body frame is turned by the torso's pitch, yaw and roll (breathing, sway, lean).
3. Limb rotations come from :func:`gesturelib.skeleton.rotations_from_positions`, and the
   positions are recomputed from them with :func:`gesturelib.skeleton.forward_kinematics`, so the
   two agree exactly and the bone lengths are those of the skeleton in every frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from data_synth.config import MotionConfig
from data_synth.events import Accent, GesturePhrase, Nod, Phrase, Stroke
from data_synth.gestures import HANDS, REST_WRIST, SIDE, plan_gestures
from data_synth.kinematics import euler_matrix, minimum_jerk_path, smooth_noise, two_bone_ik
from data_synth.nods import nod_pitch, plan_nods
from data_synth.style import Style
from data_synth.turns import frame_times
from gesturelib.skeleton import (
    BONE_LENGTHS,
    JOINT_INDEX,
    NUM_JOINTS,
    T_POSE_OFFSETS,
    forward_kinematics,
    rotations_from_positions,
)

#: Direction the left elbow points to (the right one mirrored) with the hand at rest: down, a
#: little outwards and back, so the elbow hangs under the shoulder ...
ELBOW_POLE_REST = np.array([0.1, -1.0, -0.2])
#: ... and with the hand raised into the gesture space: outwards and a little forwards, so the
#: upper arm lifts away from the body, as a speaker's does. The elbow turns from one to the other
#: as the wrist rises from ELBOW_LIFT_CM[0] to ELBOW_LIFT_CM[1] above its rest height.
ELBOW_POLE_RAISED = np.array([0.5, -1.0, 0.25])
ELBOW_LIFT_CM = (12.0, 24.0)
#: The elbow follows a smoothed wrist height (Gaussian sigma, s): it rises with a gesture phrase
#: and stays up through its beats, rather than flapping with every stroke.
ELBOW_FOLLOW_S = 0.3
#: How much further out the elbow points as the hand moves out beyond the shoulder.
ELBOW_OUTWARD_GAIN = 2.0
#: Breathing: chest pitch and shoulder rise, degrees at the peak of a breath.
BREATH_CHEST_DEG = 0.3
BREATH_SHOULDER_DEG = 1.2
#: Breathing rate varies by this fraction, on this time scale.
BREATH_RATE_WANDER = 0.1
BREATH_WANDER_TIME_S = 4.0
#: The torso leans forwards this much while the agent gestures.
SPEAKING_LEAN_DEG = 1.0
#: Idle head motion at full activity, degrees: pitch, yaw, roll.
HEAD_IDLE_DEG = np.array([2.0, 5.0, 2.0])
#: The neck (sternum-head limb) follows this fraction of the head's pitch, yaw and roll.
NECK_SHARE = 0.3
#: Time scales (Gaussian sigma) of the idle motions, seconds.
SWAY_TIME_S = 1.5
HEAD_TIME_S = 1.0
HAND_TIME_S = 0.8
#: A hand's idle drift grows from LAP_DRIFT (of ``idle_hand_cm``) in the lap to full strength
#: HAND_SUPPORT_CM above it.
LAP_DRIFT = 0.2
HAND_SUPPORT_CM = 6.0
#: How quickly the idle activity follows the change between speaking and listening.
ACTIVITY_TIME_S = 0.4


@dataclass
class AgentMotion:
    """One motion draw: ``positions`` ``(T, 9, 3)`` cm and ``rotations`` ``(T, 9, 6)`` (float32,
    consistent by forward kinematics) and the motion's events."""

    positions: np.ndarray
    rotations: np.ndarray
    strokes: list[Stroke]
    nods: list[Nod]
    gesture_phrases: list[GesturePhrase]


def generate_motion(
    utterances: list[Phrase],
    accents: list[Accent],
    style: Style,
    config: MotionConfig,
    n_frames: int,
    fps: int,
    rng: np.random.Generator,
) -> AgentMotion:
    """Generate the agent's motion for a conversation.

    Args:
        utterances: every phrase and backchannel of both speakers.
        accents: the agent's accents (speaker A).
        style: the conversation's gesture style.
        config: the motion rules' parameters.
        n_frames: number of frames ``T``.
        fps: frames per second.
        rng: the motion's random generator (the motion seed).
    """
    times = frame_times(n_frames, fps)
    plan = plan_gestures(utterances, accents, style, config, rng)
    nods = plan_nods(utterances, accents, style, config, rng)
    gesturing = _gesturing(plan.gesture_phrases, times, fps)
    activity = config.listening_activity + (1.0 - config.listening_activity) * gesturing

    # Breathing: a rate drawn per motion draw, wandering by a few percent.
    wander = smooth_noise(rng, n_frames, BREATH_WANDER_TIME_S * fps)[:, 0]
    rate = rng.uniform(*config.breathing_rate_hz) * (1.0 + BREATH_RATE_WANDER * wander)
    breath = np.sin(2 * np.pi * np.cumsum(rate) / fps + rng.uniform(0, 2 * np.pi))
    # The torso (the whole body frame) turns with breathing, sway and a lean while gesturing.
    sway = smooth_noise(rng, n_frames, SWAY_TIME_S * fps, 3) * np.radians(config.sway_deg)
    sway *= activity[:, None] * np.array([1.0, 1.0, 0.6])
    lean = np.radians(SPEAKING_LEAN_DEG) * gesturing
    torso = euler_matrix(
        np.radians(BREATH_CHEST_DEG) * breath + sway[:, 0] + lean, sway[:, 1], sway[:, 2]
    )

    body = np.zeros((n_frames, NUM_JOINTS, 3))
    sternum = T_POSE_OFFSETS[JOINT_INDEX["sternum"]]
    body[:, JOINT_INDEX["sternum"]] = sternum
    shrug = np.radians(BREATH_SHOULDER_DEG) * (0.5 + 0.5 * breath)
    width = BONE_LENGTHS[JOINT_INDEX["left_shoulder"]]
    hand_noise = smooth_noise(rng, n_frames, HAND_TIME_S * fps, 6).reshape(n_frames, 2, 3)
    hand_noise *= config.idle_hand_cm * activity[:, None, None]
    for h, hand in enumerate(HANDS):
        side = SIDE[hand]
        shoulder = sternum + width * np.stack(
            [side * np.cos(shrug), np.sin(shrug), np.zeros(n_frames)], -1
        )
        target = minimum_jerk_path(plan.key_times[hand], plan.key_points[hand], times)
        # A hand held up drifts; one lying in the lap barely moves.
        raised = np.clip((target[:, 1] - REST_WRIST[1]) / HAND_SUPPORT_CM, LAP_DRIFT, 1.0)
        target += hand_noise[:, h] * raised[:, None]
        elbow, wrist = two_bone_ik(
            shoulder,
            target,
            elbow_pole(shoulder, target, side, fps),
            BONE_LENGTHS[JOINT_INDEX[f"{hand}_elbow"]],
            BONE_LENGTHS[JOINT_INDEX[f"{hand}_wrist"]],
        )
        body[:, JOINT_INDEX[f"{hand}_shoulder"]] = shoulder
        body[:, JOINT_INDEX[f"{hand}_elbow"]] = elbow
        body[:, JOINT_INDEX[f"{hand}_wrist"]] = wrist

    # Head: nods and idle motion; the neck takes a share of it.
    head_angles = smooth_noise(rng, n_frames, HEAD_TIME_S * fps, 3) * np.radians(HEAD_IDLE_DEG)
    head_angles *= activity[:, None]
    head_angles[:, 0] += nod_pitch(nods, times, config.nod_duration_s / style.speed)
    neck = euler_matrix(*(NECK_SHARE * head_angles.T))
    head_turn = euler_matrix(*head_angles.T)
    body[:, JOINT_INDEX["head"]] = sternum + neck @ T_POSE_OFFSETS[JOINT_INDEX["head"]]
    body[:, JOINT_INDEX["nose"]] = (
        body[:, JOINT_INDEX["head"]] + head_turn @ T_POSE_OFFSETS[JOINT_INDEX["nose"]]
    )

    world = np.einsum("tij,tkj->tki", torso, body)
    rotations = rotations_from_positions(world).astype(np.float32)
    positions = forward_kinematics(rotations.astype(np.float64)).astype(np.float32)
    return AgentMotion(positions, rotations, plan.strokes, nods, plan.gesture_phrases)


def elbow_pole(shoulder: np.ndarray, wrist: np.ndarray, side: float, fps: int) -> np.ndarray:
    """Direction ``(T, 3)`` one elbow points to, from shoulder and wrist positions ``(T, 3)``.

    It turns smoothly from :data:`ELBOW_POLE_REST` to :data:`ELBOW_POLE_RAISED` (mirrored by
    ``side``: +1 left, -1 right) as the wrist, smoothed over :data:`ELBOW_FOLLOW_S`, rises
    through :data:`ELBOW_LIFT_CM` above its rest height (a smoothstep of the height). A hand out
    beyond the shoulder takes the elbow further out (:data:`ELBOW_OUTWARD_GAIN`), so the elbow
    never points across the body.
    """
    low, high = ELBOW_LIFT_CM
    height = gaussian_filter1d(wrist[:, 1], ELBOW_FOLLOW_S * fps)
    lift = np.clip((height[:, None] - REST_WRIST[1] - low) / (high - low), 0.0, 1.0)
    lift = lift * lift * (3.0 - 2.0 * lift)
    pole = ELBOW_POLE_REST + lift * (ELBOW_POLE_RAISED - ELBOW_POLE_REST)
    reach = wrist - shoulder
    outward = np.maximum(side * reach[:, 0] / np.linalg.norm(reach, axis=1), 0.0)
    pole[:, 0] += ELBOW_OUTWARD_GAIN * outward**2  # squared: the pole changes smoothly
    return pole * np.array([side, 1.0, 1.0])


def _gesturing(gesture_phrases: list[GesturePhrase], times: np.ndarray, fps: int) -> np.ndarray:
    """1 inside the gesture phrases, 0 outside, with smooth transitions: ``(T,)``."""
    inside = np.zeros(times.shape)
    for phrase in gesture_phrases:
        inside[(times >= phrase.start) & (times < phrase.end)] = 1.0
    return gaussian_filter1d(inside, ACTIVITY_TIME_S * fps)
