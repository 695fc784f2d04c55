import re
import subprocess

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.lines import Line2D

from gesturelib import viz
from gesturelib.skeleton import KEYPOINTS, forward_kinematics, identity_rot6d


@pytest.fixture(scope="module")
def motion():
    """A short (20, 9, 3) motion: the T-pose with a slow random drift of the limbs."""
    rng = np.random.default_rng(0)
    rot6d = np.tile(identity_rot6d(), (20, 9, 1)) + np.cumsum(rng.normal(0, 0.02, (20, 9, 6)), 0)
    return forward_kinematics(rot6d)


def _legend_labels(figure) -> list[list[str]]:
    return [[text.get_text() for text in legend.get_texts()] for legend in figure.legends]


def test_plot_pose_front_and_side(motion):
    figure = viz.plot_pose(motion[0])
    assert [ax.get_title() for ax in figure.axes] == ["front view", "side view"]
    assert len(figure.axes[0].lines) == 9  # one line per limb
    assert _legend_labels(figure) == [["left arm", "right arm"]]
    plt.close(figure)
    figure = viz.plot_pose(motion[::5], views=("front",))
    assert len(figure.axes) == 1 and len(figure.axes[0].lines) == 4 * 9
    plt.close(figure)


def test_plot_pose_into_given_axes_leaves_the_legend_to_the_caller(motion):
    figure, axes = plt.subplots(1, 2)
    viz.plot_pose(motion[0], axes=axes)
    assert figure.legends == []
    viz.side_legend(figure)
    assert _legend_labels(figure) == [["left arm", "right arm"]]
    plt.close(figure)


def test_the_far_arm_is_drawn_thinner_on_top_of_the_near_one_in_the_side_view(motion):
    figure = viz.plot_pose(motion[0])
    front, side = figure.axes
    left, right = KEYPOINTS.index("left_elbow"), KEYPOINTS.index("right_elbow")
    # Bone i ends at keypoint i: line i of each view draws it.
    assert front.lines[left].get_linewidth() == front.lines[right].get_linewidth() == 3
    assert front.lines[left].get_zorder() == front.lines[right].get_zorder()
    assert side.lines[left].get_linewidth() == pytest.approx(3 * viz.FAR_ARM_WIDTH)
    assert viz.FAR_ARM_WIDTH < 1 and side.lines[right].get_linewidth() == 3
    assert side.lines[left].get_zorder() > side.lines[right].get_zorder()
    plt.close(figure)


def test_one_colour_for_every_bone_and_extra_legend_entries(motion):
    figure, ax = plt.subplots()
    viz.plot_pose(motion[0], views=("front",), axes=[ax], color="0.7")
    assert {line.get_color() for line in ax.lines} == {"0.7"}
    reference = Line2D([], [], color="0.7", label="T-pose")
    viz.side_legend(figure, extra=[reference])
    assert _legend_labels(figure) == [["left arm", "right arm", "T-pose"]]
    plt.close(figure)


def test_the_scale_bar_label_hangs_below_the_bar(motion):
    figure = viz.animate(motion, stride=10)._fig
    for ax in figure.axes:
        label = next(text for text in ax.texts if text.get_text() == "50 cm")
        bar = next(line for line in ax.lines if line.get_color() == "0.5")  # the bones have none
        assert label.get_va() == "top" and label.xy[1] == bar.get_ydata()[0]


def test_animate_draws_every_stride_th_frame(motion):
    anim = viz.animate([motion, motion], titles=["a", "b"], stride=3)
    assert len(list(anim.new_frame_seq())) == 7  # frames 0, 3, ..., 18
    assert anim.event_source.interval == pytest.approx(3 * 1000 / 25)
    assert "<script" in viz.animation_html(anim)


@pytest.mark.parametrize(
    ("count", "views"), [(1, ("front",)), (1, ("front", "side")), (3, ("front",))]
)
def test_animations_are_wide_enough_and_name_left_and_right(motion, count, views):
    anim = viz.animate([motion] * count, views=views, stride=10)
    figure = anim._fig  # FuncAnimation keeps its figure there
    width, _ = figure.get_size_inches() * figure.dpi
    assert width >= viz.MIN_ANIMATION_WIDTH_PX
    assert width == pytest.approx(max(720, 360 * count * len(views)))
    assert _legend_labels(figure) == [["left arm", "right arm"]]


def _streams(path) -> str:
    """ffmpeg's description of the streams in a file (it exits non-zero without an output)."""
    result = subprocess.run(
        [viz.ffmpeg_executable(), "-i", str(path)], capture_output=True, text=True
    )
    return result.stderr


def test_save_animation_muxes_the_audio_into_an_mp4(motion, tmp_path):
    audio = (0.1 * np.sin(np.arange(16000) / 5)).astype(np.float32)
    path = viz.save_animation(
        viz.animate(motion), tmp_path / "a.mp4", audio=audio, sample_rate=16000
    )
    assert path == tmp_path / "a.mp4"
    streams = _streams(path)
    assert "Video: h264" in streams and "Audio: aac" in streams
    width, height = map(int, re.search(r"Video: h264.*?, (\d+)x(\d+)", streams).groups())
    assert (width, height) == (720, 400)  # one motion, front and side view, at 100 dpi
    with pytest.raises(FileExistsError, match="overwrite=True"):
        viz.save_animation(viz.animate(motion), path)


def test_the_fast_frames_are_the_full_redraw(motion):
    """save_animation draws the still parts once; each frame must be what a full redraw gives."""
    anim = viz.animate([motion, motion[::-1]], titles=["a", "b"], stride=7)
    width, height = anim.frame_size()
    frames = list(anim.rgba_frames())
    assert len(frames) == len(anim.frames) and len(frames[0]) == width * height * 4
    for index in (0, len(frames) // 2, len(frames) - 1):
        for artist in anim.draw(anim.frames[index]):
            artist.set_animated(False)
        anim.figure.canvas.draw()
        redrawn = bytes(anim.figure.canvas.buffer_rgba())
        assert frames[index] == redrawn, f"frame {index} differs from a full redraw"


def test_save_animation_writes_any_matplotlib_animation(tmp_path):
    """An animation not made by viz.animate goes through matplotlib's own writer."""
    from matplotlib import animation as mpl_animation

    figure, ax = plt.subplots()
    (line,) = ax.plot([0, 1], [0, 0])
    anim = mpl_animation.FuncAnimation(
        figure, lambda k: line.set_ydata([0, k]) or [line], frames=5, interval=40
    )
    audio = np.zeros(8000, dtype=np.float32)
    path = viz.save_animation(anim, tmp_path / "b.mp4", audio=audio, sample_rate=16000)
    streams = _streams(path)
    assert "Video: h264" in streams and "Audio: aac" in streams
    plt.close(figure)


def test_save_animation_falls_back_to_gif_without_ffmpeg(motion, tmp_path, monkeypatch):
    monkeypatch.setattr(viz, "ffmpeg_executable", lambda: None)
    path = viz.save_animation(viz.animate(motion, stride=4), tmp_path / "a.mp4")
    assert path == tmp_path / "a.gif" and path.read_bytes()[:3] == b"GIF"


def test_video_player_embeds_an_mp4_or_falls_back_to_html_with_audio(motion, monkeypatch):
    audio = np.zeros(16000, dtype=np.float32)
    video = viz.video_player(viz.animate(motion, stride=4), audio, 16000)
    assert video.mimetype == "video/mp4" and len(video.data) > 1000
    monkeypatch.setattr(viz, "ffmpeg_executable", lambda: None)
    html = viz.video_player(viz.animate(motion, stride=4), audio, 16000).data
    assert "<script" in html and "<audio" in html


def test_plot_timeline_shows_spectrogram_and_activity():
    mel = np.random.default_rng(1).normal(size=(50, 27))
    activity = np.repeat([0, 1, 2, 3, 0], 10)
    figure = viz.plot_timeline(mel, activity, events={"strokes": [0.3, 1.1]})
    assert len(figure.axes) == 2 and figure.axes[0].images[0].get_cmap().name == "magma"
    plt.close(figure)
    figure = viz.plot_timeline(mel, activity, cmap="Greys")
    assert figure.axes[0].images[0].get_cmap().name == "Greys"
    plt.close(figure)


def test_shade_activity_spans_each_run_of_talk_and_leaves_silence_white():
    figure, ax = plt.subplots()
    activity = np.array([3, 0, 0, 1, 1, 1, 3, 0])  # none, A, A, B, B, B, none, A
    handles = viz.shade_activity(ax, activity, fps=2.0)
    spans = [patch.get_x() for patch in ax.patches], [patch.get_width() for patch in ax.patches]
    assert spans == ([0.5, 1.5, 3.5], [1.0, 1.5, 0.5])  # A, B, A; in seconds at 2 fps
    assert [handle.get_label() for handle in handles] == ["A speaks", "B speaks"]
    plt.close(figure)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda m: viz.plot_pose(m[:, :8]), r"positions must have shape \(\.\.\., 9, 3\)"),
        (lambda m: viz.animate([m, m[:10]]), "same length"),
        (lambda m: viz.animate(m, stride=0), "stride must be a positive integer"),
        (lambda m: viz.animate(m, dpi=0), "dpi must be positive"),
        (lambda m: viz.plot_pose(m[0], views=("top",)), "unknown view"),
        (
            lambda m: viz.plot_timeline(np.zeros((5, 27)), np.zeros(4, int)),
            r"activity must have shape \(5,\)",
        ),
        (lambda m: viz.save_animation(viz.animate(m), "clip.avi"), "writes .mp4 or .gif"),
        (lambda m: viz.audio_player(np.zeros((2, 10)), 16000), "1-D"),
        (lambda m: viz.shade_activity(plt.gca(), np.zeros((2, 3), int)), r"shape \(T,\)"),
    ],
)
def test_bad_input_is_rejected(motion, call, message):
    with pytest.raises(ValueError, match=message):
        call(motion)


def test_nan_positions_are_rejected(motion):
    broken = motion.copy()
    broken[3, 2, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        viz.animate(broken)
