"""Pictures, animations and sound: how a person looks at poses, motion and speech.

* :func:`plot_pose` draws a stick figure from the front and from the side.
* :func:`animate` makes a matplotlib animation of one or more motions side by side, at least
  :data:`MIN_ANIMATION_WIDTH_PX` pixels wide, with a legend for the agent's left and right;
  :func:`animation_html` embeds it in a notebook (``FuncAnimation.to_jshtml``: no ffmpeg needed)
  and :func:`save_animation` writes it to a file: MP4 with the speech muxed in when an ffmpeg
  binary is available (the ``imageio-ffmpeg`` dependency ships one), a silent GIF otherwise.
* :func:`side_legend` names the bone colours (the agent's left and right arm) in a figure.
* :func:`plot_timeline` shows a mel spectrogram with who is talking underneath;
  :func:`shade_activity` shades any time axis by who is talking.
* :func:`audio_player` plays audio in a notebook.

Views: the agent faces +z with y up, so the *front* view (x horizontal, y up) shows the agent as a
person facing you: its left hand (+x) on your right. The *side* view (z horizontal, y up) shows the
agent facing right, seen from its right side: its right arm is the nearer one and would hide the
left arm wherever the two overlap, so the far arm is drawn on top of it, thinner
(:data:`FAR_ARM_WIDTH`), and both stay visible.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib import animation
from matplotlib.colors import ListedColormap
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from gesturelib.conventions import FPS, Activity
from gesturelib.rotations import check_trailing_shape
from gesturelib.skeleton import BONES, KEYPOINTS, NUM_JOINTS

#: Which coordinates each view puts on its horizontal and vertical axes.
VIEWS = {"front": (0, 1), "side": (2, 1)}
ACTIVITY_COLOURS = {
    Activity.A_SPEAKS: "#d95f02",
    Activity.B_SPEAKS: "#1b9e77",
    Activity.BOTH: "#7570b3",
    Activity.NONE: "#e6e6e6",
}


#: Bone colours: the agent's left side, its right side, and the midline (spine, neck, head).
SIDE_COLOURS = {"left": "#1f77b4", "right": "#d62728", "midline": "#444444"}
#: The side of the agent that is further from you in each view (None: neither, in the front view).
FAR_SIDE = {"front": None, "side": "left"}
#: The far arm's line width, as a fraction of the near arm's: drawn on top, it leaves the near arm
#: showing on both sides of it.
FAR_ARM_WIDTH = 0.5
#: Every animation is at least this wide, whatever its number of panels and its dpi.
MIN_ANIMATION_WIDTH_PX = 720
#: Width and height of one view of an animation, in inches (360 x 400 pixels at 100 dpi).
_ANIMATION_PANEL_INCHES = (3.6, 4.0)


def bone_side(child: int) -> str:
    """``"left"``, ``"right"`` or ``"midline"``: where the bone ending at ``child`` is."""
    side = KEYPOINTS[child].split("_")[0]
    return side if side in ("left", "right") else "midline"


def bone_colour(child: int) -> str:
    return SIDE_COLOURS[bone_side(child)]


def side_legend(target, extra=(), **legend_options):
    """Add a legend naming the bone colours, "left arm" and "right arm", to a figure or an axes.

    The sides are the agent's own: in the front view its left arm is on your right.
    ``extra`` handles (e.g. a ``Line2D`` for a reference pose drawn in one colour) follow the two
    arms in the same legend. ``legend_options`` go to ``target.legend`` (by default: lower right,
    in one row, no frame). Returns the ``Legend``.
    """
    handles = [
        Line2D([], [], color=SIDE_COLOURS[side], linewidth=3, label=f"{side} arm")
        for side in ("left", "right")
    ]
    handles += list(extra)
    options = {
        "loc": "lower right",
        "ncol": len(handles),
        "fontsize": 9,
        "frameon": False,
        **legend_options,
    }
    return target.legend(handles=handles, **options)


def _with_root(positions: np.ndarray) -> np.ndarray:
    """Append the root (origin) as joint index -1, so BONES can index it directly."""
    root = np.zeros((*positions.shape[:-2], 1, 3), dtype=positions.dtype)
    return np.concatenate([positions, root], axis=-2)


def _as_motion(positions, name: str = "positions") -> np.ndarray:
    positions = np.asarray(positions, dtype=float)
    check_trailing_shape(positions, (NUM_JOINTS, 3), name)
    if not np.isfinite(positions).all():
        raise ValueError(f"{name} contains NaN or infinite values; cannot draw them")
    return positions


def _axis_limits(positions: np.ndarray, view: str, margin: float = 10.0):
    horizontal, vertical = VIEWS[view]
    points = _with_root(positions).reshape(-1, 3)
    low, high = points.min(0) - margin, points.max(0) + margin
    # Square axes centred on the body so that proportions are true.
    centre = (low + high) / 2
    half = max(high[horizontal] - low[horizontal], high[vertical] - low[vertical]) / 2
    return (
        (centre[horizontal] - half, centre[horizontal] + half),
        (centre[vertical] - half, centre[vertical] + half),
    )


def _skeleton_lines(ax, view: str, **line_style) -> list:
    """One ``Line2D`` per bone, empty; :func:`_update_lines` fills them with a pose.

    The bones take their side's colour unless ``line_style`` has a ``color`` for all of them; the
    arm on the view's far side (:data:`FAR_SIDE`) is drawn thinner and on top of the near one.
    """
    style = {"linewidth": 3, "marker": "o", "markersize": 3, **line_style}
    colour = style.pop("color", None)
    lines = []
    for _, child in BONES:
        bone_style = dict(style)
        if bone_side(child) == FAR_SIDE[view]:
            bone_style["linewidth"] = FAR_ARM_WIDTH * style["linewidth"]
            bone_style["zorder"] = bone_style.get("zorder", 2) + 0.1
        line = ax.plot([], [], color=colour or bone_colour(child), **bone_style)[0]
        lines.append(line)
    return lines


def _update_lines(lines: list, pose: np.ndarray, view: str) -> list:
    horizontal, vertical = VIEWS[view]
    points = _with_root(pose)
    for line, (parent, child) in zip(lines, BONES, strict=True):
        line.set_data(points[[parent, child], horizontal], points[[parent, child], vertical])
    return lines


def _style_axis(ax, view: str, limits) -> None:
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)" if view == "front" else "z (cm, forward)")
    ax.set_ylabel("y (cm)")
    ax.set_title(f"{view} view", fontsize=9)
    ax.grid(alpha=0.3)


def _style_animation_axis(ax, view: str, limits) -> None:
    """Like :func:`_style_axis` but without ticks, which cost most of the time of each frame."""
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(f"{view} view", fontsize=9)
    # A 50 cm scale bar in the lower left corner instead of axes, its label underneath, where no
    # keypoint is (the root, the lowest one, stands above the bar).
    x0, y0 = limits[0][0] + 5, limits[1][0] + 5
    ax.plot([x0, x0 + 50], [y0, y0], color="0.5", linewidth=1)
    ax.annotate(
        "50 cm",
        (x0 + 25, y0),
        xytext=(0, -2),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=7,
        color="0.4",
    )


def plot_pose(
    positions, views: Sequence[str] = ("front", "side"), axes=None, title=None, **line_style
):
    """Draw one pose, or several overlaid, as stick figures.

    Args:
        positions: ``(9, 3)`` one pose, or ``(N, 9, 3)`` poses drawn on top of each other (lighter),
            in cm.
        views: which of ``"front"`` and ``"side"`` to draw, one axis each.
        axes: existing matplotlib axes, one per view; a new figure is made when omitted, with a
            legend for the left and right arm (for given axes, :func:`side_legend` adds one).
        title: figure title.
        **line_style: passed to ``Axes.plot`` (e.g. ``alpha``, ``linewidth``); a ``color`` draws
            every bone in that colour (e.g. a reference pose in grey) instead of its side's.
    Returns:
        The matplotlib ``Figure``.
    """
    positions = _as_motion(positions)
    poses = positions.reshape(-1, NUM_JOINTS, 3)
    unknown = set(views) - set(VIEWS)
    if unknown:
        raise ValueError(f"unknown view(s) {sorted(unknown)}; choose from {sorted(VIEWS)}")
    made_figure = axes is None
    if made_figure:
        fig, axes = plt.subplots(1, len(views), figsize=(3.2 * len(views), 3.6), squeeze=False)
        axes = axes[0]
    fig = axes[0].figure
    alpha = line_style.pop("alpha", min(1.0, max(0.08, 3.0 / len(poses))))
    for ax, view in zip(axes, views, strict=True):
        for pose in poses:
            _update_lines(_skeleton_lines(ax, view, alpha=alpha, **line_style), pose, view)
        _style_axis(ax, view, _axis_limits(poses, view))
    if title:
        fig.suptitle(title)
    if made_figure:
        side_legend(fig)
        fig.tight_layout(rect=(0, 0.1, 1, 1))  # room for the legend underneath
    else:
        fig.tight_layout()
    return fig


def animate(
    motions,
    fps: float = FPS,
    titles: Sequence[str] | None = None,
    views: Sequence[str] = ("front", "side"),
    stride: int = 1,
    dpi: int = 100,
):
    """Animate one motion, or several side by side (e.g. ground truth and a model's sample).

    Each view is a 3.6 x 4 inch panel (360 x 400 pixels at the default dpi), and the figure is
    widened where its panels would make it narrower than :data:`MIN_ANIMATION_WIDTH_PX` pixels. A
    legend names the colours of the agent's left and right arm; a clock shows the time.

    Args:
        motions: ``(T, 9, 3)`` positions in cm, or a list of such arrays (same ``T``).
        fps: frame rate of the motions.
        titles: one title per motion.
        views: the views to show for each motion.
        stride: draw every ``stride``-th frame (the playback speed stays real time); use it to
            keep notebook animations light.
        dpi: pixels per inch of the rendered frames (the width never drops below
            :data:`MIN_ANIMATION_WIDTH_PX` pixels; a higher dpi renders more slowly).
    Returns:
        A ``matplotlib.animation.FuncAnimation``; the figure is closed so that notebooks show only
        the animation, via :func:`animation_html`.
    """
    if isinstance(motions, np.ndarray) and motions.ndim == 3:
        motions = [motions]
    motions = [_as_motion(m, f"motions[{i}]") for i, m in enumerate(motions)]
    lengths = {len(m) for m in motions}
    if len(lengths) != 1:
        raise ValueError(
            f"motions to animate side by side must have the same length, got {sorted(lengths)}"
        )
    if titles is not None and len(titles) != len(motions):
        raise ValueError(f"got {len(titles)} titles for {len(motions)} motions")
    if stride < 1:
        raise ValueError(f"stride must be a positive integer, got {stride}")
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    if dpi <= 0:
        raise ValueError(f"dpi must be positive, got {dpi}")

    n_frames = lengths.pop()
    n_panels = len(motions) * len(views)
    panel_width, height = _ANIMATION_PANEL_INCHES
    width = max(panel_width * n_panels, MIN_ANIMATION_WIDTH_PX / dpi)
    fig, axes = plt.subplots(1, n_panels, figsize=(width, height), squeeze=False, dpi=dpi)
    axes = axes[0]
    panels = []  # (lines, motion, view)
    for i, motion in enumerate(motions):
        for j, view in enumerate(views):
            ax = axes[i * len(views) + j]
            _style_animation_axis(ax, view, _axis_limits(motion, view))
            if titles is not None and j == 0:
                ax.set_title(f"{titles[i]}\n{view} view", fontsize=9)
            panels.append((_skeleton_lines(ax, view), motion, view))
    # The clock belongs to an axes: a figure-level artist that changes every frame (animated)
    # is left out when the frames are saved.
    clock = axes[0].text(0.01, 0.03, "", transform=fig.transFigure, fontsize=9)
    side_legend(fig, loc="lower right")
    # Fixed margins rather than tight_layout, which clips two-line titles above square axes.
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.1, top=0.86, wspace=0.05)

    def draw(frame: int):
        artists = [clock]
        for lines, motion, view in panels:
            artists += _update_lines(lines, motion[frame], view)
        clock.set_text(f"t = {frame / fps:5.2f} s")
        return artists

    anim = SkeletonAnimation(fig, draw, range(0, n_frames, stride), 1000.0 * stride / fps)
    plt.close(fig)
    return anim


class SkeletonAnimation(animation.FuncAnimation):
    """:func:`animate`'s animation: a ``FuncAnimation`` that can also give its frames as pixels
    with the still parts (panels, titles, legend) drawn once, which :func:`save_animation` writes
    several times faster than matplotlib's writers, which redraw the whole figure every frame.

    Args:
        fig: the figure.
        draw: ``draw(frame) -> artists``, the artists that change.
        frames: the frame indices to draw.
        interval: milliseconds between drawn frames.
    """

    def __init__(self, fig, draw, frames: range, interval: float):
        super().__init__(fig, draw, frames=frames, interval=interval, blit=True)
        self.figure, self.draw, self.frames = fig, draw, frames

    def rgba_frames(self):
        """Yield each frame as RGBA bytes, ``height x width x 4``, the size of
        :meth:`frame_size`."""
        canvas = self.figure.canvas
        moving = self.draw(self.frames[0])
        for artist in moving:
            artist.set_animated(True)
        canvas.draw()  # everything but the moving artists
        background = canvas.copy_from_bbox(self.figure.bbox)
        for frame in self.frames:
            canvas.restore_region(background)
            for artist in sorted(self.draw(frame), key=lambda artist: artist.get_zorder()):
                self.figure.draw_artist(artist)
            yield bytes(canvas.buffer_rgba())

    def frame_size(self) -> tuple[int, int]:
        """``(width, height)`` of a frame in pixels."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        if not isinstance(self.figure.canvas, FigureCanvasAgg):
            FigureCanvasAgg(self.figure)  # a closed figure may hold a canvas that cannot render
        width, height = self.figure.canvas.get_width_height(physical=True)
        return int(width), int(height)


def animation_html(anim) -> str:
    """HTML with a JavaScript player for ``anim`` (``IPython.display.HTML(...)`` shows it)."""
    return anim.to_jshtml(default_mode="once")


def ffmpeg_executable() -> str | None:
    """Path of an ffmpeg binary: the one shipped with ``imageio-ffmpeg``, else one on the PATH."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        return shutil.which("ffmpeg")


def save_animation(
    anim,
    path,
    audio=None,
    sample_rate: int | None = None,
    overwrite: bool = False,
) -> Path:
    """Write an animation to a file that any player opens.

    Args:
        anim: from :func:`animate`; the file plays in real time at the frame rate and stride the
            animation was made with.
        path: ``.mp4`` or ``.gif``. An MP4 needs ffmpeg (see :func:`ffmpeg_executable`); without it
            the animation is written as a GIF next to ``path`` instead, without sound.
        audio: optional mono float audio ``(N,)`` to mux into the MP4, starting at frame 0.
        sample_rate: the audio's sample rate (required with ``audio``).
        overwrite: replace an existing file; otherwise an existing file raises ``FileExistsError``.
    Returns:
        The path actually written.
    """
    path = Path(path)
    if path.suffix.lower() not in {".mp4", ".gif"}:
        raise ValueError(f"save_animation writes .mp4 or .gif files, got {path.name!r}")
    if audio is not None and sample_rate is None:
        raise ValueError("sample_rate is required when audio is given")
    ffmpeg = ffmpeg_executable()
    if path.suffix.lower() == ".mp4" and ffmpeg is None:
        path = path.with_suffix(".gif")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    playback_fps = 1000.0 / anim.event_source.interval  # animate() folded the stride into it

    if path.suffix.lower() == ".gif":
        anim.save(path, writer=animation.PillowWriter(fps=playback_fps))
        return path

    with tempfile.TemporaryDirectory() as tmp:
        inputs = []
        if audio is not None:
            from gesturelib.features import save_audio

            wav = Path(tmp) / "speech.wav"
            save_audio(wav, np.asarray(audio, dtype=np.float32), sample_rate)
            inputs = ["-i", str(wav), "-c:a", "aac", "-shortest"]
        partial = Path(tmp) / path.name
        if isinstance(anim, SkeletonAnimation):
            _encode_frames(ffmpeg, anim, playback_fps, inputs, partial)
        else:
            silent = Path(tmp) / "silent.mp4"
            plt.rcParams["animation.ffmpeg_path"] = ffmpeg
            writer = animation.FFMpegWriter(
                fps=playback_fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"]
            )
            anim.save(silent, writer=writer)
            _run_ffmpeg([ffmpeg, "-i", str(silent), *inputs, "-c:v", "copy", str(partial)], path)
        shutil.move(partial, path)
    return path


def _encode_frames(ffmpeg: str, anim: SkeletonAnimation, fps: float, inputs, path: Path) -> None:
    """Pipe ``anim``'s raw frames into ffmpeg and encode them as H.264 (with ``inputs``' sound)."""
    width, height = anim.frame_size()
    command = [
        ffmpeg,
        "-loglevel",
        "error",
        "-y",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgba",
        "-s",
        f"{width}x{height}",
        "-r",
        f"{fps:g}",
        "-i",
        "-",
        *inputs,
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        "-vf",
        "pad=ceil(iw/2)*2:ceil(ih/2)*2",  # H.264 in yuv420p needs an even width and height
        str(path),
    ]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for frame in anim.rgba_frames():
            process.stdin.write(frame)
    except BrokenPipeError:
        pass  # ffmpeg stopped early: its message follows
    finally:
        process.stdin.close()
        error = process.stderr.read().decode(errors="replace")
        process.wait()
    if process.returncode != 0:
        raise RuntimeError(f"ffmpeg could not write {path.name}: {error.strip()}")


def _run_ffmpeg(command: list[str], path: Path) -> None:
    """Run an ffmpeg command that writes ``path``; a failure raises with ffmpeg's message."""
    command = [command[0], "-loglevel", "error", "-y", *command[1:]]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"ffmpeg could not write {path}: {result.stderr.strip()}")


def plot_timeline(
    mel,
    activity,
    fps: float = FPS,
    events: dict | None = None,
    ax=None,
    title: str | None = None,
    cmap: str = "magma",
):
    """A log-mel spectrogram with the speech activity as a coloured band underneath.

    Args:
        mel: ``(T, n_mels)`` log-mel features, one row per motion frame.
        activity: ``(T,)`` integer :class:`~gesturelib.conventions.Activity` codes.
        fps: frames per second of both.
        events: optional ``{label: times_in_seconds}`` drawn as vertical ticks over the
            spectrogram (e.g. stressed syllables, gesture strokes).
        ax: two stacked axes ``(spectrogram_ax, activity_ax)``; a new figure when omitted.
        title: figure title.
        cmap: colour map of the spectrogram; ``"Greys"`` (loud is dark) lets markers in the
            activity colours stand out, which they do not on ``"magma"``'s oranges.
    Returns:
        The matplotlib ``Figure``.
    """
    mel = np.asarray(mel)
    activity = np.asarray(activity)
    if mel.ndim != 2:
        raise ValueError(f"mel must have shape (T, n_mels), got {mel.shape}")
    if activity.shape != (len(mel),):
        raise ValueError(
            f"activity must have shape ({len(mel)},) to match mel, got {activity.shape}"
        )
    if ax is None:
        fig, ax = plt.subplots(
            2, 1, figsize=(10, 3.2), sharex=True, gridspec_kw={"height_ratios": [4, 1]}
        )
    spec_ax, act_ax = ax
    fig = spec_ax.figure
    duration = len(mel) / fps
    spec_ax.imshow(
        mel.T, origin="lower", aspect="auto", extent=(0, duration, 0, mel.shape[1]), cmap=cmap
    )
    spec_ax.set_ylabel("mel band")
    for (label, times), colour in zip((events or {}).items(), plt.cm.tab10.colors, strict=False):
        spec_ax.vlines(times, 0, mel.shape[1], colors=[colour], linewidth=1.0, label=label)
    if events:
        spec_ax.legend(loc="upper right", fontsize=8)
    cmap = ListedColormap([ACTIVITY_COLOURS[a] for a in Activity])
    act_ax.imshow(
        activity[None, :],
        aspect="auto",
        cmap=cmap,
        vmin=-0.5,
        vmax=len(Activity) - 0.5,
        extent=(0, duration, 0, 1),
        interpolation="nearest",
    )
    act_ax.set_yticks([])
    act_ax.set_xlabel("time (s)")
    fig.legend(
        handles=[Patch(color=ACTIVITY_COLOURS[a], label=a.label) for a in Activity],
        loc="lower center",
        ncol=len(Activity),
        fontsize=8,
        frameon=False,
    )
    if title:
        spec_ax.set_title(title)
    fig.tight_layout(rect=(0, 0.07, 1, 1))  # leave room for the legend underneath
    return fig


def shade_activity(ax, activity, fps: float = FPS, alpha: float = 0.25) -> list:
    """Shade the time axis of ``ax`` (in seconds) by who is talking, in :data:`ACTIVITY_COLOURS`.

    One span per run of frames of one class; frames where nobody talks stay unshaded. Frame ``t``
    covers ``[t / fps, (t + 1) / fps)``.

    Args:
        ax: a matplotlib axes whose x axis is time in seconds.
        activity: ``(T,)`` integer :class:`~gesturelib.conventions.Activity` codes.
        fps: frames per second.
        alpha: opacity of the shading.
    Returns:
        Legend handles, one per class that was shaded: ``ax.legend(handles=...)`` names them.
    """
    activity = np.asarray(activity)
    if activity.ndim != 1 or activity.size == 0:
        raise ValueError(f"activity must be a non-empty array of shape (T,), got {activity.shape}")
    changes = np.flatnonzero(np.diff(activity)) + 1
    shaded = []
    for start, end in zip(np.r_[0, changes], np.r_[changes, len(activity)], strict=True):
        code = Activity(int(activity[start]))
        if code != Activity.NONE:
            ax.axvspan(start / fps, end / fps, color=ACTIVITY_COLOURS[code], alpha=alpha, lw=0)
            shaded.append(code)
    return [
        Patch(color=ACTIVITY_COLOURS[code], alpha=alpha, label=code.label)
        for code in Activity
        if code in shaded
    ]


def audio_player(audio, sample_rate: int):
    """An ``IPython.display.Audio`` widget playing mono audio ``(N,)`` (not re-normalised)."""
    from IPython.display import Audio

    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim != 1 or audio.size == 0:
        raise ValueError(f"audio must be a non-empty 1-D array, got shape {audio.shape}")
    return Audio(audio, rate=sample_rate, normalize=False)


def video_player(anim, audio=None, sample_rate: int | None = None):
    """A notebook video of ``anim`` with the speech playing along, when ffmpeg is available.

    Renders the animation to an MP4 (see :func:`save_animation`) and embeds it in the notebook.
    Without ffmpeg, falls back to the JavaScript player of :func:`animation_html` (no sound)
    followed by an audio player for ``audio``, if given.

    Returns:
        An IPython display object (``IPython.display.display`` shows it).
    """
    from IPython.display import HTML, Video

    if ffmpeg_executable() is None:
        sound = "" if audio is None else audio_player(audio, sample_rate)._repr_html_()
        return HTML(animation_html(anim) + sound)
    with tempfile.TemporaryDirectory() as tmp:
        path = save_animation(anim, Path(tmp) / "motion.mp4", audio=audio, sample_rate=sample_rate)
        return Video(
            data=path.read_bytes(), embed=True, mimetype="video/mp4", html_attributes="controls"
        )
