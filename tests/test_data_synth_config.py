"""Tests of data_synth's configuration checks, its building blocks and its bad-input errors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from data_synth import (
    MAX_DURATION_S,
    ConfigError,
    ConversationConfig,
    MotionConfig,
    StyleRanges,
    TurnConfig,
    VoiceConfig,
    generate_conversation,
    resample_motion,
)
from data_synth.dataset import write_dataset
from data_synth.emphasis import emphasis_envelope
from data_synth.kinematics import euler_matrix, minimum_jerk_path, smooth_noise, two_bone_ik

# --------------------------------------------------------------------------- configs


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: TurnConfig(a_phrase_s=(-1.0, 2.0)), "a_phrase_s"),
        (lambda: TurnConfig(b_phrase_s=(3.0, 2.0)), "b_phrase_s"),
        (lambda: TurnConfig(overlap_probability=1.5), "overlap_probability"),
        (lambda: TurnConfig(backchannel_probability=-0.1), "backchannel_probability"),
        (lambda: TurnConfig(phrase_pause_s=(0.0, 0.5)), "phrase_pause_s"),
        (lambda: TurnConfig(a_phrases_per_turn=0.5), "a_phrases_per_turn"),
        (lambda: TurnConfig(overlap_s=(0.5, 1.0)), "overlap_s"),
        (
            lambda: TurnConfig(overlap_probability=0.6, long_silence_probability=0.6),
            "long_silence_probability",
        ),
        (lambda: VoiceConfig(syllable_rate_hz=(0.0, 5.0)), "syllable_rate_hz"),
        (lambda: VoiceConfig(accent_spacing_syllables=(1, 3)), "accent_spacing_syllables"),
        (lambda: VoiceConfig(accent_spacing_syllables=(2.5, 3)), "accent_spacing_syllables"),
        (lambda: VoiceConfig(emphasis_range=(0.5, 1.5)), "emphasis_range"),
        (lambda: VoiceConfig(peak_level=1.2), "peak_level"),
        (lambda: VoiceConfig(accent_gain_db=float("nan")), "accent_gain_db"),
        (lambda: VoiceConfig(question_probability="0.2"), "question_probability"),
        (lambda: MotionConfig(stroke_lead_s=-0.1), "stroke_lead_s"),
        (lambda: MotionConfig(stroke_duration_s=0.0), "stroke_duration_s"),
        (lambda: MotionConfig(listening_nod_probability=2.0), "listening_nod_probability"),
        (lambda: MotionConfig(breathing_rate_hz=(0.0, 0.3)), "breathing_rate_hz"),
        (lambda: MotionConfig(listening_activity=0.0), "listening_activity"),
        (lambda: StyleRanges(symmetry=(0.5, 1.5)), "symmetry"),
        (lambda: StyleRanges(speed=(0.0, 1.0)), "speed"),
        (lambda: ConversationConfig(motion=MotionConfig(stroke_lead_s=1.5)), "stroke_lead_s"),
        (
            lambda: ConversationConfig(motion=MotionConfig(stroke_duration_s=0.6)),
            "stroke_duration_s",
        ),
        (lambda: ConversationConfig(sample_rate=8000), "sample_rate"),
        (lambda: ConversationConfig(fps=0), "fps"),
        (lambda: ConversationConfig(fps=25.5), "fps"),
        (lambda: ConversationConfig(turns=MotionConfig()), "turns"),
    ],
)
def test_invalid_config_is_rejected_naming_the_field(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_defaults_are_valid_and_survive_a_dict_round_trip():
    config = ConversationConfig()
    assert ConversationConfig.from_dict(config.to_dict()) == config
    changed = dataclasses.replace(config, motion=MotionConfig(stroke_lead_s=0.3))
    assert ConversationConfig.from_dict(changed.to_dict()) == changed


def test_config_dict_with_an_unknown_key_is_rejected_naming_it():
    data = ConversationConfig().to_dict()
    data["motion"]["stroke_lead"] = 0.3  # a typo must not be silently ignored
    with pytest.raises(ValueError, match="stroke_lead"):
        ConversationConfig.from_dict(data)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"duration_s": -1.0, "seed": 0}, "duration_s"),
        ({"duration_s": math.nan, "seed": 0}, "duration_s"),
        ({"duration_s": 1.0, "seed": 0}, "duration_s"),
        ({"duration_s": 10.0, "seed": -1}, "seed"),
        ({"duration_s": 10.0, "seed": 1.5}, "seed"),
        ({"duration_s": 10.0, "seed": 0, "motion_seed": -2}, "motion_seed"),
        ({"duration_s": 10.0, "seed": 0, "config": {"fps": 25}}, "config"),
    ],
)
def test_generate_conversation_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        generate_conversation(**kwargs)


def test_resample_motion_rejects_a_bad_seed_or_input():
    with pytest.raises(ValueError, match="seed"):
        resample_motion(generate_conversation(3.0, 0), -3)
    with pytest.raises(ValueError, match="Conversation"):
        resample_motion({"audio": None}, 1)


def test_numpy_scalars_in_configs_are_stored_as_python_numbers():
    config = ConversationConfig(
        turns=TurnConfig(overlap_probability=np.float32(0.25), lead_in_s=np.array([0.3, 1.0])),
        voice=VoiceConfig(accent_spacing_syllables=(np.int64(3), 5), peak_level=np.float64(0.8)),
        sample_rate=np.int64(16000),
    )
    plain = ConversationConfig(
        turns=TurnConfig(overlap_probability=0.25, lead_in_s=(0.3, 1.0)),
        voice=VoiceConfig(accent_spacing_syllables=(3, 5), peak_level=0.8),
        sample_rate=16000,
    )
    assert config == plain
    assert type(config.turns.overlap_probability) is float
    assert type(config.voice.peak_level) is float  # not np.float64, a float subclass
    assert type(config.sample_rate) is int
    assert all(type(end) is int for end in config.voice.accent_spacing_syllables)
    assert config.turns.lead_in_s == (0.3, 1.0) and type(config.turns.lead_in_s[0]) is float
    with pytest.raises(ConfigError, match="overlap_probability must be a finite number"):
        TurnConfig(overlap_probability=np.bool_(True))


def test_numpy_scalars_as_duration_and_seeds_give_the_same_conversation():
    plain = generate_conversation(3.0, 2, motion_seed=4)
    numpy = generate_conversation(np.float32(3.0), np.int64(2), motion_seed=np.int32(4))
    np.testing.assert_array_equal(numpy.rotations, plain.rotations)
    assert type(numpy.conversation_seed) is int and type(numpy.motion_seed) is int


def test_a_duration_above_the_maximum_is_refused_before_any_work():
    with pytest.raises(ConfigError, match="longer than MAX_DURATION_S = 600 s.*several shorter"):
        generate_conversation(MAX_DURATION_S + 1.0, 0)


def test_a_config_that_leaves_no_room_for_speech_is_refused_naming_the_fields():
    silent = ConversationConfig(turns=TurnConfig(lead_in_s=(20.0, 20.0)))
    with pytest.raises(
        ConfigError,
        match=r"no seed can fit a phrase in duration_s = 10 s.*TurnConfig.lead_in_s = \(20.0, 20.0\)"
        r".*TurnConfig.a_phrase_s.*at least 23.1 s",
    ):
        generate_conversation(10.0, 0, silent)
    # With the default turns, 2 s fits a phrase for some seeds only: seed 1 draws none.
    assert generate_conversation(2.0, 0).events.phrases
    with pytest.raises(ConfigError, match="seed 1 draws no phrase.*at least 4.1 s"):
        generate_conversation(2.0, 1)


def test_write_dataset_refuses_sizes_that_cannot_work_before_writing(tmp_path):
    out = tmp_path / "data"
    with pytest.raises(
        ConfigError, match="draws no phrase in conversation_s = 2 s.*conversation_s at least 4.1 s"
    ):
        write_dataset(out, 0.1, 0, conversation_s=2.0, progress=False)
    with pytest.raises(ConfigError, match="15000 conversations, more than the 10000"):
        write_dataset(out, 500.0, 0, conversation_s=2.0, progress=False)
    with pytest.raises(ConfigError, match="more than the 600 minutes"):
        write_dataset(out, 1000.0, 0, conversation_s=60.0, progress=False)
    with pytest.raises(ConfigError, match="conversation_s = 601 s is longer than MAX_DURATION_S"):
        write_dataset(out, 30.0, 0, conversation_s=601.0, progress=False)
    assert not out.exists()


# --------------------------------------------------------------------------- building blocks


def test_minimum_jerk_path_has_known_values_and_bell_shaped_speed():
    duration, distance = 0.4, 10.0
    times = np.linspace(0.0, duration, 4001)
    path = minimum_jerk_path(np.array([0.0, duration]), np.array([[0.0], [distance]]), times)
    assert path[0, 0] == 0.0 and path[-1, 0] == pytest.approx(distance)
    assert path[2000, 0] == pytest.approx(distance / 2)  # symmetric about the middle
    velocity = np.gradient(path[:, 0], times)
    assert np.argmax(velocity) == pytest.approx(2000, abs=1)
    assert velocity.max() == pytest.approx(1.875 * distance / duration, rel=1e-4)
    assert abs(velocity[0]) < 1e-3 and abs(velocity[-1]) < 1e-3  # starts and stops at rest
    held = minimum_jerk_path(np.array([0.0, 1.0]), np.array([[1.0], [2.0]]), np.array([-5.0, 9.0]))
    np.testing.assert_allclose(held[:, 0], [1.0, 2.0])


def test_minimum_jerk_path_rejects_unsorted_keyframes():
    with pytest.raises(ValueError, match="increasing"):
        minimum_jerk_path(np.array([1.0, 0.0]), np.zeros((2, 3)), np.zeros(3))


def test_two_bone_ik_reaches_the_target_with_exact_bones_and_bends_towards_the_pole():
    rng = np.random.default_rng(0)
    root = np.zeros((200, 3))
    target = rng.uniform(-30, 30, (200, 3)) + np.array([0.0, 0.0, 20.0])
    pole = np.array([0.0, -1.0, -0.2])
    middle, end = two_bone_ik(root, target, pole, 30.0, 25.0)
    np.testing.assert_allclose(np.linalg.norm(middle - root, axis=1), 30.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(end - middle, axis=1), 25.0, atol=1e-9)
    reachable = np.linalg.norm(target, axis=1) < 0.98 * 55.0
    np.testing.assert_allclose(end[reachable], target[reachable], atol=1e-9)
    # The bend (middle joint off the root-end line) points to the pole's side.
    line = end / np.linalg.norm(end, axis=1, keepdims=True)
    bend = middle - np.sum(middle * line, axis=1, keepdims=True) * line
    pole_side = pole - (line @ pole)[:, None] * line
    assert np.all(np.sum(bend * pole_side, axis=1) > 0)


def test_two_bone_ik_pulls_an_unreachable_target_in_along_its_direction():
    middle, end = two_bone_ik(
        np.zeros((1, 3)), np.array([[100.0, 0.0, 0.0]]), np.array([0.0, -1.0, 0.0]), 30.0, 25.0
    )
    np.testing.assert_allclose(end, [[0.98 * 55.0, 0.0, 0.0]])


def test_euler_matrix_is_a_rotation_with_the_documented_directions():
    angles = np.radians([10.0, 20.0, 30.0])
    matrix = euler_matrix(angles[:1], angles[1:2], angles[2:])[0]
    np.testing.assert_allclose(matrix @ matrix.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(matrix) == pytest.approx(1.0)
    nod = euler_matrix(np.radians([10.0]), np.zeros(1), np.zeros(1))[0]
    assert (nod @ [0.0, 0.0, 1.0])[1] < 0  # the face tips down
    assert (nod @ [0.0, 1.0, 0.0])[2] > 0  # the top tips forwards


def test_smooth_noise_has_unit_variance_and_is_reproducible():
    noise = smooth_noise(np.random.default_rng(3), 20000, 5.0, 2)
    assert noise.shape == (20000, 2)
    np.testing.assert_allclose(noise.std(axis=0), 1.0, atol=0.1)
    np.testing.assert_array_equal(noise, smooth_noise(np.random.default_rng(3), 20000, 5.0, 2))


def test_emphasis_envelope_peaks_where_a_sound_starts():
    sample_rate, fps = 16000, 25
    t = np.arange(2 * sample_rate) / sample_rate
    audio = (0.5 * np.sin(2 * np.pi * 200 * t) * (t >= 1.0)).astype(np.float32)  # on at 1.0 s
    envelope = emphasis_envelope(audio, sample_rate, fps)
    assert envelope.shape == (2 * fps - 1,)
    # Row t is the change from frame t to t + 1, at time (t + 1) / fps: the onset at 1.0 s is
    # the change from frame 24 (0.96-1.00 s, silent) to frame 25 (1.00-1.04 s, sounding).
    assert np.argmax(envelope) == 24
    assert envelope.max() == 1.0 and envelope.min() >= 0.0


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: ConversationConfig(sample_rate=10**9), r"sample_rate.*\[16000, 96000\]"),
        (lambda: ConversationConfig(fps=10**4), r"fps.*\[1, 240\]"),
        (lambda: VoiceConfig(accent_gain_db=1e4), r"accent_gain_db.*\[0.0, 40.0\]"),
    ],
)
def test_sizes_and_gains_beyond_any_use_are_refused(make, message):
    with pytest.raises(ConfigError, match=message):
        make()
