"""The sampling explorer: pick a model, some speech, a temperature, a seed, how many samples, who
is talking and a style, and watch the motion the model samples for it, with its sound.

* :class:`Clip`: what the models hear of a stretch of speech (the audio and who is talking), and
  the motion recorded with it when there is one.
* :class:`PoseViewer`: a widget that draws motions side by side in the browser (an HTML canvas,
  drag to turn the view), plays the sound in step and shows who is talking on a timeline under
  them (click it to jump). It is fed the pose arrays, so a new motion shows at once, where a
  matplotlib animation would first render every frame.
* :class:`Explorer`: the controls, a thin layer over :func:`gesturelib.sampling.generate`.
  :meth:`Explorer.render` returns the :class:`Take` that the viewer shows, so the explorer can be
  tested without a browser.

The viewer keeps the conventions of :mod:`gesturelib.viz`: the agent faces you at first (its left
arm, in :data:`~gesturelib.viz.SIDE_COLOURS`, on your right), with a legend for its arms, a clock
and at least :data:`~gesturelib.viz.MIN_ANIMATION_WIDTH_PX` pixels of width.
"""

from __future__ import annotations

import base64
import html
import io
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import anywidget
import ipywidgets
import numpy as np
import soundfile
import traitlets

from gesturelib.conventions import FPS, Activity
from gesturelib.features import AudioError, load_audio, who_is_talking
from gesturelib.pipeline import speech_to_motion
from gesturelib.skeleton import BONES
from gesturelib.style import STYLE_FEATURES
from gesturelib.viz import ACTIVITY_COLOURS, MIN_ANIMATION_WIDTH_PX, SIDE_COLOURS, bone_colour

#: Who is talking, as the explorer offers it: as recorded, or forced for the whole clip.
TALKING = {
    "as recorded": None,
    "the agent speaks": Activity.A_SPEAKS,
    "the agent listens": Activity.B_SPEAKS,
    "nobody speaks": Activity.NONE,
}


@dataclass(frozen=True)
class Clip:
    """A stretch of speech to drive the agent with.

    Attributes:
        audio: ``(n,)`` float32 samples at full scale.
        sample_rate: in Hz.
        activity: ``(T,)`` who-is-talking codes, one per motion frame.
        truth: ``(T, 9, 3)`` the motion recorded with the speech, in cm, or None.
    """

    audio: np.ndarray
    sample_rate: int
    activity: np.ndarray
    truth: np.ndarray | None = None

    def __post_init__(self):
        frames = len(np.asarray(self.activity))
        if np.asarray(self.audio).ndim != 1 or not np.isfinite(self.audio).all():
            raise ValueError("a clip's audio must be (n,) finite samples")
        if self.truth is not None and np.shape(self.truth) != (frames, 9, 3):
            raise ValueError(
                f"a clip's truth must be (T, 9, 3) keypoints for its {frames} frames of "
                f"activity, got {np.shape(self.truth)}"
            )

    @classmethod
    def from_conversation(cls, conversation, start_s: float = 0.0, seconds: float = 10.0) -> Clip:
        """``seconds`` of a conversation from ``start_s`` on, with its recorded motion."""
        if not (np.isfinite(start_s) and np.isfinite(seconds)):
            raise ValueError(f"start_s and seconds must be finite, got {start_s} and {seconds}")
        first, frames = round(start_s * FPS), round(seconds * FPS)
        if not 0 <= first < conversation.num_frames or frames < 1:
            raise ValueError(
                f"a clip from {start_s} s lasting {seconds} s does not fit in a conversation of "
                f"{conversation.num_frames / FPS:g} s"
            )
        frames = min(frames, conversation.num_frames - first)
        rate = conversation.sample_rate
        samples = slice(first * rate // FPS, (first + frames) * rate // FPS)
        return cls(
            audio=np.asarray(conversation.audio[samples], np.float32),
            sample_rate=rate,
            activity=np.asarray(conversation.activity[first : first + frames]),
            truth=np.asarray(conversation.positions[first : first + frames], np.float32),
        )

    @classmethod
    def from_recording(cls, audio: np.ndarray, sample_rate: int) -> Clip:
        """A recording of the agent's voice: it speaks wherever the recording holds speech.

        Raises:
            AudioError: for unusable audio, or a recording without speech.
        """
        activity = who_is_talking(audio, sample_rate)
        frames = len(activity)
        return cls(np.asarray(audio[: frames * sample_rate // FPS]), sample_rate, activity)

    @classmethod
    def from_file(cls, path: str | Path) -> Clip:
        """A recording in a file librosa reads (WAV, FLAC, OGG; any rate; stereo is down-mixed)."""
        return cls.from_recording(*load_audio(path))


@dataclass(frozen=True)
class Take:
    """What the viewer shows: motions side by side, their sound and who is talking.

    Attributes:
        motions: ``(K, T, 9, 3)`` positions in cm.
        titles: ``K`` names, one per motion.
        activity: ``(T,)`` the codes the model was given.
        audio, sample_rate: the sound.
        sampling_s: how long the model took to sample the motion, in seconds.
    """

    motions: np.ndarray
    titles: tuple[str, ...]
    activity: np.ndarray
    audio: np.ndarray
    sample_rate: int
    sampling_s: float


class PoseViewer(anywidget.AnyWidget):
    """Motions side by side, drawn in the browser, with their sound and who is talking.

    Set :meth:`show` with a :class:`Take`; the browser gets the positions as float32 bytes.
    """

    _sent_audio = None  # the audio array the browser plays now

    _esm = Path(__file__).with_name("viewer.js")
    motions = traitlets.Bytes(b"").tag(sync=True)  # (K, T, 9, 3) float32, little-endian
    count = traitlets.Int(0).tag(sync=True)
    titles = traitlets.List([]).tag(sync=True)
    activity = traitlets.List([]).tag(sync=True)
    audio = traitlets.Unicode("").tag(sync=True)  # a data URL of a WAV file
    fps = traitlets.Float(float(FPS)).tag(sync=True)
    width = traitlets.Int(MIN_ANIMATION_WIDTH_PX).tag(sync=True)
    bones = traitlets.List([[parent, child] for parent, child in BONES]).tag(sync=True)
    colours = traitlets.List([bone_colour(child) for _, child in BONES]).tag(sync=True)
    legend = traitlets.List([[f"{s} arm", SIDE_COLOURS[s]] for s in ("left", "right")]).tag(
        sync=True
    )
    # Who is talking: the colour of each code (0..3), and the legend under the timeline.
    palette = traitlets.List([ACTIVITY_COLOURS[Activity(c)] for c in range(len(Activity))]).tag(
        sync=True
    )
    talking_legend = traitlets.List([[a.label, ACTIVITY_COLOURS[a]] for a in Activity]).tag(
        sync=True
    )

    def show(self, take: Take) -> None:
        """Show ``take``; its sound is encoded and sent again only when it is another recording."""
        with self.hold_sync():
            self.count = len(take.motions)
            self.titles = list(take.titles)
            self.activity = [int(code) for code in take.activity]
            if take.audio is not self._sent_audio:
                self.audio = wav_data_url(take.audio, take.sample_rate)
                self._sent_audio = take.audio
            self.motions = np.ascontiguousarray(take.motions, dtype="<f4").tobytes()


def wav_data_url(audio: np.ndarray, sample_rate: int) -> str:
    """``audio`` ``(n,)`` as a 16-bit WAV in a ``data:`` URL, which an ``<audio>`` element plays."""
    if not np.isfinite(audio).all():
        raise ValueError("audio holds NaN or infinite samples; a WAV cannot play them")
    buffer = io.BytesIO()
    soundfile.write(buffer, np.clip(audio, -1, 1), sample_rate, format="WAV", subtype="PCM_16")
    return "data:audio/wav;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


class Explorer:
    """Controls for sampling, and the viewer that shows the result.

    Args:
        models: name -> ``(model, normaliser)``, e.g. from
            :func:`gesturelib.pretrained.load_run`.
        clips: name -> :class:`Clip`; a recording uploaded in the explorer joins them.

    Changing any control samples again and shows the new motion. ``Explorer(...)`` displays
    itself in a notebook; :meth:`render` returns what it would show.
    """

    def __init__(self, models: Mapping[str, tuple], clips: Mapping[str, Clip]) -> None:
        if not models or not clips:
            raise ValueError("the explorer needs at least one model and one clip")
        for name, pair in models.items():
            if not (isinstance(pair, tuple) and len(pair) == 2):
                raise TypeError(
                    f"models[{name!r}] must be a (model, normaliser) pair, e.g. load_run(...)[:2]; "
                    f"got {type(pair).__name__}"
                )
            model = pair[0]
            if not hasattr(model, "step"):
                raise ValueError(
                    f"the model {name!r} is a {type(model).__name__}, which does not generate "
                    "motion frame by frame; give MoGlow or a Flow-VAE"
                )
        self.models, self.clips = dict(models), dict(clips)
        slider = {"continuous_update": False, "style": {"description_width": "initial"}}
        self.model = ipywidgets.Dropdown(options=list(self.models), description="model")
        self.clip = ipywidgets.Dropdown(options=list(self.clips), description="speech")
        self.upload = ipywidgets.FileUpload(
            accept=".wav,.flac,.ogg,audio/*", description="your own"
        )
        self.temperature = ipywidgets.FloatSlider(
            value=1.0, min=0.0, max=1.5, step=0.05, description="temperature", **slider
        )
        self.seed = ipywidgets.BoundedIntText(value=0, min=0, max=2**31 - 1, description="seed")
        self.samples = ipywidgets.IntSlider(
            value=1, min=1, max=3, description="samples side by side", **slider
        )
        self.talking = ipywidgets.Dropdown(options=list(TALKING), description="who talks")
        self.style = {
            name: ipywidgets.FloatSlider(
                value=50, min=0, max=100, step=5, description=f"{name} (percentile)", **slider
            )
            for name in STYLE_FEATURES
        }
        self.truth = ipywidgets.Checkbox(
            value=True, description="show the recorded motion beside it", indent=False
        )
        self.status = ipywidgets.HTML()
        self.viewer = PoseViewer()
        controls = [
            self.model,
            self.clip,
            self.temperature,
            self.seed,
            self.samples,
            self.talking,
            self.truth,
        ]
        for control in (*controls, *self.style.values()):
            control.observe(self._changed, names="value")
        self.upload.observe(self._uploaded, names="value")
        self.widget = ipywidgets.VBox(
            [
                ipywidgets.HBox(
                    [ipywidgets.VBox(controls), ipywidgets.VBox(list(self.style.values()))]
                ),
                ipywidgets.HBox([self.upload, self.status]),
                self.viewer,
            ]
        )
        self.update()

    def _ipython_display_(self):
        from IPython.display import display

        display(self.widget)

    def render(self) -> Take:
        """Sample the motion the controls ask for: the :class:`Take` the viewer shows."""
        model, normaliser = self.models[self.model.value]
        clip = self.clips[self.clip.value]
        forced = TALKING[self.talking.value]
        activity = clip.activity if forced is None else np.full_like(clip.activity, forced)
        has_style = getattr(model.config, "style", False)
        style = {n: s.value for n, s in self.style.items()} if has_style else None
        started = time.perf_counter()
        motion = speech_to_motion(
            model,
            normaliser,
            clip.audio,
            clip.sample_rate,
            activity=activity,
            style=style,
            samples=self.samples.value,
            temperature=self.temperature.value,
            seed=self.seed.value,
        )
        sampling_s = time.perf_counter() - started
        motions = list(motion.positions.astype(np.float32))
        name = self.model.value
        titles = (
            [name]
            if len(motions) == 1
            else [f"{name}, sample {k + 1}" for k in range(len(motions))]
        )
        if clip.truth is not None and self.truth.value:
            motions.insert(0, clip.truth)
            titles.insert(0, "recorded motion")
        return Take(
            np.stack(motions), tuple(titles), activity, clip.audio, clip.sample_rate, sampling_s
        )

    def update(self) -> Take:
        """Sample again and show it; return the :class:`Take` shown."""
        model, _ = self.models[self.model.value]
        has_style = getattr(model.config, "style", False)
        for slider in self.style.values():
            slider.disabled = not has_style
        self.truth.disabled = self.clips[self.clip.value].truth is None
        take = self.render()
        self.viewer.show(take)
        self.status.value = (
            f"sampled {len(take.activity) / FPS:.1f} s of motion in {take.sampling_s:.2f} s"
        )
        return take

    def add_clip(self, name: str, clip: Clip) -> None:
        """Offer ``clip`` as ``name`` (in place of a clip of that name) and show it."""
        self.clips[name] = clip
        # New options reset the dropdown to the first; unobserved, that samples nothing.
        self.clip.unobserve(self._changed, names="value")
        try:
            self.clip.options = list(self.clips)
            self.clip.value = name
        finally:
            self.clip.observe(self._changed, names="value")
        self.update()

    def _changed(self, _change) -> None:
        self.update()

    def _uploaded(self, change) -> None:
        for upload in change["new"]:
            suffix = Path(upload["name"]).suffix or ".wav"
            with tempfile.NamedTemporaryFile(suffix=suffix) as file:
                file.write(bytes(upload["content"]))
                file.flush()
                try:
                    clip = Clip.from_file(file.name)
                except AudioError as error:
                    reason = str(error).replace(file.name, "the file")  # not a temporary path
                    self.status.value = (
                        f"<b>{html.escape(upload['name'])}</b>: {html.escape(reason)}"
                    )
                    continue
            self.add_clip(upload["name"], clip)
