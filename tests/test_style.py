"""gesturelib.style: MoGlow's style measures, on motions with a known answer and on the generator."""

import dataclasses

import numpy as np
import pytest

from data_synth import ConversationConfig, generate_conversation
from gesturelib.data import ConversationFeatures, Normaliser
from gesturelib.skeleton import JOINT_INDEX, mirror_positions, t_pose
from gesturelib.style import STYLE_FEATURES, style_features

FPS = 25
LEFT, RIGHT = JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]
HEIGHT, SPEED, RADIUS, SYMMETRY = range(4)


def still(frames: int = 200) -> np.ndarray:
    return np.repeat(t_pose()[None], frames, axis=0)


def test_a_still_pose_has_its_height_and_radius_and_no_speed():
    motion = still()
    style = style_features(motion, FPS)
    assert style.shape == (200, len(STYLE_FEATURES))
    np.testing.assert_allclose(style[:, HEIGHT], motion[0, RIGHT, 1])
    radius = np.hypot(*motion[0, LEFT, [0, 2]]) + np.hypot(*motion[0, RIGHT, [0, 2]])
    np.testing.assert_allclose(style[:, RADIUS], radius)
    np.testing.assert_allclose(style[:, SPEED], 0.0, atol=1e-9)


def test_speed_is_the_sum_of_both_wrists_speeds():
    motion = still()
    motion[:, RIGHT, 1] += 0.4 * np.arange(200)  # 0.4 cm a frame: 10 cm/s
    motion[:, LEFT, 2] += 0.2 * np.arange(200)  # 5 cm/s
    np.testing.assert_allclose(style_features(motion, FPS)[:, SPEED], 15.0)


@pytest.mark.parametrize("sign, expected", [(1.0, 1.0), (-1.0, -1.0)])
def test_symmetry_is_one_for_mirror_images_and_minus_one_for_opposites(sign, expected):
    motion = still()
    wave = 5.0 * np.sin(np.arange(200) / 4)
    motion[:, RIGHT, 0] += wave  # right hand to and fro sideways
    motion[:, LEFT, 0] -= sign * wave  # its mirror image (x negated), or the opposite
    np.testing.assert_allclose(style_features(motion, FPS)[:, SYMMETRY], expected, atol=1e-6)


def test_symmetry_is_zero_for_unrelated_hands():
    motion = still(2000)
    rng = np.random.default_rng(0)
    motion[:, [LEFT, RIGHT]] += rng.standard_normal((2000, 2, 3)).cumsum(0)
    assert np.abs(style_features(motion, FPS)[100:-100, SYMMETRY]).mean() < 0.15


def test_averages_are_over_a_centred_four_second_window():
    motion = still()
    motion[100:, RIGHT, 1] += 10.0  # the right hand steps up by 10 cm at frame 100
    height = style_features(motion, FPS)[:, HEIGHT] - motion[0, RIGHT, 1]
    np.testing.assert_allclose(height[:50], 0.0, atol=1e-9)  # window 50..100 frames away
    assert height[100] == pytest.approx(5.0, abs=0.3)  # half the window above
    np.testing.assert_allclose(height[151:], 10.0)


def test_mirroring_changes_the_right_hands_height_so_it_is_measured_again():
    motion = still()
    motion[:, RIGHT, 1] += 20.0  # only the right hand raised
    mirrored = style_features(mirror_positions(motion), FPS)
    assert mirrored[0, HEIGHT] == pytest.approx(motion[0, LEFT, 1])
    conversation = generate_conversation(12.0, seed=1)
    features = ConversationFeatures.from_conversation(conversation)
    expected = style_features(mirror_positions(conversation.positions), FPS)
    np.testing.assert_allclose(features.mirrored().style, expected, atol=1e-3)


def test_style_percentiles_give_the_training_values():
    features = [ConversationFeatures.from_conversation(generate_conversation(12.0, seed=2))]
    normaliser = Normaliser.fit(features)
    style = features[0].style
    asked = normaliser.style_at_percentiles({"hand_height": 85, "symmetry": 15})
    expected = np.percentile(style, [85, 50, 50, 15], axis=0).diagonal()
    np.testing.assert_allclose(asked, expected, rtol=1e-5)
    with pytest.raises(ValueError, match="unknown style"):
        normaliser.style_at_percentiles({"tempo": 50})
    with pytest.raises(ValueError, match=r"in \[0, 100\]"):
        normaliser.style_at_percentiles({"hand_height": 120})


@pytest.mark.parametrize(
    "parameter, feature",
    [
        ("hand_height_cm", "hand_height"),
        ("gesture_radius_cm", "gesture_radius"),
        ("symmetry", "symmetry"),
        ("beat_amplitude_cm", "hand_speed"),
    ],
)
def test_each_measure_follows_the_generators_style(parameter, feature):
    # The same speech and motion seed, the style parameter at the bottom and the top of its
    # range: the measure, averaged over the frames where the agent speaks, must rise.
    config = ConversationConfig()
    low, high = getattr(config.style, parameter)
    measured = []
    for value in (low, high):
        ranges = dataclasses.replace(config.style, **{parameter: (value, value)})
        conversation = generate_conversation(
            20.0, seed=3, config=dataclasses.replace(config, style=ranges)
        )
        speaking = conversation.activity == 0
        style = style_features(conversation.positions, FPS)[speaking]
        measured.append(style[:, STYLE_FEATURES.index(feature)].mean())
    assert measured[1] > measured[0]


# gesturelib.evaluation.style_control: the share of a style change realised, on known answers.


class _Percentiles:
    """A normaliser's style percentiles, each feature's p-th percentile equal to ``p``."""

    style_percentiles = np.repeat(np.arange(101.0)[:, None], len(STYLE_FEATURES), axis=1)

    def style_at_percentiles(self, percentiles):
        return np.array([percentiles.get(name, 50.0) for name in STYLE_FEATURES])


def _standing_with_right_hand_at(height: float, frames: int = 50) -> np.ndarray:
    motion = still(frames)
    motion[:, RIGHT, 1] = height
    return motion


@pytest.mark.parametrize("obeys, share", [(1.0, 1.0), (0.25, 0.25), (0.0, 0.0)])
def test_the_share_realised_of_a_hand_height_asked(monkeypatch, obeys, share):
    from gesturelib.evaluation import style_control

    def generate_for(conversations, model, normaliser, samples, seed, temperature, style):
        ((name, level),) = style.items()
        height = 50.0 + obeys * (level - 50.0) if name == "hand_height" else 40.0
        return [np.stack([_standing_with_right_hand_at(height)] * samples) for _ in conversations]

    monkeypatch.setattr(style_control, "generate_for", generate_for)
    model = type("Styled", (), {"config": type("Config", (), {"style": True})()})()
    responses = style_control.style_response(model, _Percentiles(), [None, None], samples=2)
    height = responses["hand_height"]
    np.testing.assert_allclose(height.asked, [15, 50, 85])
    np.testing.assert_allclose(height.realised, 50.0 + obeys * (np.array([15, 50, 85]) - 50.0))
    assert height.share == pytest.approx(share)
    if obeys:
        assert height.rank_correlation == pytest.approx(1.0)
    else:  # the same motion at every level: no ranks to correlate
        assert np.isnan(height.rank_correlation)
    assert responses["gesture_radius"].share == pytest.approx(0.0)


def test_a_model_without_style_inputs_is_refused():
    from gesturelib.evaluation.style_control import style_response

    model = type("Plain", (), {"config": type("Config", (), {"style": False})()})()
    with pytest.raises(ValueError, match="no style inputs"):
        style_response(model, _Percentiles(), [])


def test_the_span_of_recorded_clips_over_the_change_asked():
    from gesturelib.evaluation.style_control import conversation_span
    from gesturelib.evaluation.transfer import clip_style

    heights = np.linspace(40.0, 60.0, 21)  # clip averages whose 15th-85th percentiles span 14
    clips = np.array([clip_style(_standing_with_right_hand_at(h)) for h in heights])
    span = conversation_span(_Percentiles(), clips)
    assert span["hand_height"] == pytest.approx(14.0 / 70.0)  # asked: 15 -> 85
    assert span["hand_speed"] == pytest.approx(0.0)


def test_the_style_response_figure_has_a_panel_per_feature():
    import matplotlib

    matplotlib.use("Agg")
    from gesturelib.evaluation.figures import plot_style_response
    from gesturelib.evaluation.style_control import StyleResponse

    levels = np.array([15.0, 50.0, 85.0])
    responses = {
        name: StyleResponse(levels, 50.0 + 0.5 * (levels - 50.0), 0.5, 1.0)
        for name in STYLE_FEATURES
    }
    figure = plot_style_response(responses, np.full((6, 4), 50.0) + np.arange(6)[:, None])
    assert [ax.get_title() for ax in figure.axes] == [f"{n}: share 0.50" for n in STYLE_FEATURES]
    assert len(figure.axes[0].lines) == 2  # obeyed in full, and realised
