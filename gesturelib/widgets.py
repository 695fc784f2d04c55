"""The sampling explorer: pick a model, some speech, a temperature, a seed, who is talking and a
style, and watch the motion the model samples for it, with its sound.

* :class:`Clip`: what the models hear of a stretch of speech (the audio and who is talking), and
  the motion recorded with it when there is one.
* :class:`PoseViewer`: a widget that draws motions side by side in the browser (an HTML canvas,
  drag to turn the view), plays the sound in step and shows who is talking on a timeline under
  them (click it to jump). It is fed the pose arrays, so a new motion shows at once: rendering a
  matplotlib animation instead would take seconds per second of motion.
* :class:`Explorer`: the controls, a thin layer over :func:`gesturelib.sampling.generate`.
  :meth:`Explorer.render` returns the :class:`Take` that the viewer shows, so the explorer can be
  tested without a browser.

The viewer keeps the conventions of :mod:`gesturelib.viz`: the agent faces you at first (its left
arm, in :data:`~gesturelib.viz.SIDE_COLOURS`, on your right), with a legend for its arms, a clock
and at least :data:`~gesturelib.viz.MIN_ANIMATION_WIDTH_PX` pixels of width.
"""

from __future__ import annotations

import base64
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
from gesturelib.features import AudioError, load_audio, speech_features, voice_activity
from gesturelib.sampling import generate
from gesturelib.skeleton import BONES, forward_kinematics
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

    @classmethod
    def from_conversation(cls, conversation, start_s: float = 0.0, seconds: float = 10.0) -> Clip:
        """``seconds`` of a conversation from ``start_s`` on, with its recorded motion."""
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
        speaking = voice_activity(audio, sample_rate)
        if not speaking.any():
            raise AudioError("the recording holds no speech (silent, or too quiet to tell)")
        activity = np.where(speaking, Activity.A_SPEAKS, Activity.NONE).astype(np.int64)
        frames = len(activity)
        return cls(np.asarray(audio[: frames * sample_rate // FPS]), sample_rate, activity)

    @classmethod
    def from_file(cls, path: str | Path) -> Clip:
        """A recording in a file librosa reads (WAV, FLAC, OGG; any rate; stereo is down-mixed)."""
        return cls.from_recording(*load_audio(path))

    @property
    def seconds(self) -> float:
        return len(self.activity) / FPS


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


_VIEWER_JS = """
function render({ model, el }) {
  const width = model.get("width"), height = 400, timelineHeight = 36;
  el.classList.add("gesturelib-viewer");
  const canvas = document.createElement("canvas");
  canvas.width = width; canvas.height = height;
  canvas.title = "drag to turn the view; double-click to face the agent again";
  const timeline = document.createElement("canvas");
  timeline.width = width; timeline.height = timelineHeight;
  timeline.title = "who is talking; click to jump there";
  const audio = document.createElement("audio");
  audio.controls = true; audio.style.width = width + "px";
  el.append(canvas, timeline, audio);
  const ctx = canvas.getContext("2d"), tctx = timeline.getContext("2d");
  let yaw = 0, dragging = null, motions = null, frames = 0, count = 0, limits = null;

  function load() {
    const view = model.get("motions");
    const buffer = view.buffer.slice(view.byteOffset, view.byteOffset + view.byteLength);
    motions = new Float32Array(buffer);
    count = model.get("count"); frames = count ? motions.length / (count * 9 * 3) : 0;
    let high = 1;  // the farthest any joint gets from the root, for one scale in every panel
    for (let i = 0; i < motions.length; i += 3)
      high = Math.max(high, Math.hypot(motions[i], motions[i + 1], motions[i + 2]));
    limits = high * 1.15;
    audio.src = model.get("audio");
    drawTimeline(); draw();
  }
  function joint(k, t, j) {
    if (j < 0) return [0, 0, 0];
    const o = ((k * frames + t) * 9 + j) * 3;
    return [motions[o], motions[o + 1], motions[o + 2]];
  }
  function project([x, y, z], panel) {
    // Yaw 0 is the front view: the agent faces you, so its left (+x) is on your right.
    const c = Math.cos(yaw), s = Math.sin(yaw);
    const h = c * x + s * z, depth = -s * x + c * z;
    const panelWidth = width / count, scale = (Math.min(panelWidth, height - 40) / 2) / limits;
    return [panelWidth * (panel + 0.5) + h * scale, height / 2 + 10 - (y - limits * 0.35) * scale, depth];
  }
  function frameNow() {
    return Math.min(frames - 1, Math.max(0, Math.floor(audio.currentTime * model.get("fps"))));
  }
  function draw() {
    ctx.clearRect(0, 0, width, height);
    if (!frames) return;
    const t = frameNow(), bones = model.get("bones"), colours = model.get("colours");
    const titles = model.get("titles");
    for (let k = 0; k < count; k++) {
      // Painter's order: the bones farthest from you first, so the near arm is drawn over them.
      const segments = bones.map(([a, b], i) => {
        const p = project(joint(k, t, a), k), q = project(joint(k, t, b), k);
        return { p, q, colour: colours[i], depth: (p[2] + q[2]) / 2 };
      }).sort((u, v) => u.depth - v.depth);
      for (const { p, q, colour } of segments) {
        ctx.strokeStyle = colour; ctx.lineWidth = 4; ctx.lineCap = "round";
        ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke();
      }
      ctx.fillStyle = "#222"; ctx.font = "14px sans-serif"; ctx.textAlign = "center";
      ctx.fillText(titles[k], (width / count) * (k + 0.5), 20);
    }
    ctx.textAlign = "left"; ctx.font = "13px sans-serif"; ctx.fillStyle = "#222";
    ctx.fillText(`${(t / model.get("fps")).toFixed(1)} s`, 8, height - 10);
    const legend = model.get("legend");
    let x = width - 8;
    ctx.textAlign = "right";
    for (const [label, colour] of legend.slice().reverse()) {
      ctx.fillStyle = colour; ctx.fillText(label, x, height - 10);
      x -= ctx.measureText(label).width + 16;
    }
    drawPlayhead(t);
  }
  function drawTimeline() {
    const activity = model.get("activity"), palette = model.get("palette");
    tctx.clearRect(0, 0, width, timelineHeight);
    activity.forEach((code, t) => {
      tctx.fillStyle = palette[code];
      tctx.fillRect((t / activity.length) * width, 0, width / activity.length + 1, timelineHeight - 14);
    });
    tctx.font = "11px sans-serif"; tctx.textAlign = "left";
    let x = 4;
    tctx.fillStyle = "#222"; tctx.fillText("who is talking:", x, timelineHeight - 2);
    x += tctx.measureText("who is talking:").width + 8;
    for (const [label, colour] of model.get("talking_legend")) {
      tctx.fillStyle = colour; tctx.fillRect(x, timelineHeight - 11, 10, 10);
      tctx.fillStyle = "#222"; tctx.fillText(label, x + 13, timelineHeight - 2);
      x += 13 + tctx.measureText(label).width + 12;
    }
  }
  function drawPlayhead(t) {
    drawTimeline();
    const x = (t / Math.max(frames, 1)) * width;
    tctx.fillStyle = "#000"; tctx.fillRect(x - 1, 0, 2, timelineHeight - 14);
  }
  function loop() { draw(); if (!audio.paused) requestAnimationFrame(loop); }
  audio.addEventListener("play", () => requestAnimationFrame(loop));
  audio.addEventListener("seeked", draw);
  timeline.addEventListener("click", (e) => {
    audio.currentTime = (e.offsetX / width) * frames / model.get("fps"); draw();
  });
  canvas.addEventListener("pointerdown", (e) => { dragging = [e.clientX, yaw]; });
  window.addEventListener("pointerup", () => { dragging = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (dragging) { yaw = dragging[1] + (e.clientX - dragging[0]) / 100; draw(); }
  });
  canvas.addEventListener("dblclick", () => { yaw = 0; draw(); });
  model.on("change:motions", load);
  model.on("change:audio", () => { audio.src = model.get("audio"); });
  load();
}
export default { render };
"""


class PoseViewer(anywidget.AnyWidget):
    """Motions side by side, drawn in the browser, with their sound and who is talking.

    Set :meth:`show` with a :class:`Take`; the browser gets the positions as float32 bytes.
    """

    _esm = _VIEWER_JS
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

    def show(self, take: Take, audio_changed: bool = True) -> None:
        """Show ``take`` (its sound too, unless ``audio_changed`` is False: the same clip)."""
        with self.hold_sync():
            self.count = len(take.motions)
            self.titles = list(take.titles)
            self.activity = [int(code) for code in take.activity]
            if audio_changed:
                self.audio = wav_data_url(take.audio, take.sample_rate)
            self.motions = np.ascontiguousarray(take.motions, dtype="<f4").tobytes()


def wav_data_url(audio: np.ndarray, sample_rate: int) -> str:
    """``audio`` ``(n,)`` as a 16-bit WAV in a ``data:`` URL, which an ``<audio>`` element plays."""
    buffer = io.BytesIO()
    soundfile.write(buffer, np.clip(audio, -1, 1), sample_rate, format="WAV", subtype="PCM_16")
    return "data:audio/wav;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


class Explorer:
    """Controls for sampling, and the viewer that shows the result.

    Args:
        models: name -> ``(model, normaliser)``, e.g. from
            :func:`gesturelib.pretrained.load_run`.
        clips: name -> :class:`Clip`; a recording uploaded in the explorer joins them.
        samples: how many samples to show side by side.

    Changing any control samples again and shows the new motion. ``Explorer(...)`` displays
    itself in a notebook; :meth:`render` returns what it would show.
    """

    def __init__(
        self, models: Mapping[str, tuple], clips: Mapping[str, Clip], samples: int = 1
    ) -> None:
        if not models or not clips:
            raise ValueError("the explorer needs at least one model and one clip")
        self.models, self.clips, self.samples = dict(models), dict(clips), samples
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
        controls = [self.model, self.clip, self.temperature, self.seed, self.talking, self.truth]
        for control in (*controls, *self.style.values()):
            control.observe(self._changed, names="value")
        self.upload.observe(self._uploaded, names="value")
        self._shown_clip = None
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
        style = None
        if has_style:
            style = normaliser.style_at_percentiles({n: s.value for n, s in self.style.items()})
        started = time.perf_counter()
        speech = speech_features(clip.audio, clip.sample_rate)[: len(activity)]
        rotations = generate(
            model,
            normaliser,
            speech,
            activity,
            samples=self.samples,
            temperature=self.temperature.value,
            seed=self.seed.value,
            style=style,
        )
        sampling_s = time.perf_counter() - started
        motions = [forward_kinematics(sample).astype(np.float32) for sample in rotations]
        titles = [f"{self.model.value}, sample {k + 1}" for k in range(self.samples)]
        if self.samples == 1:
            titles = [self.model.value]
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
        self.viewer.show(take, audio_changed=self.clip.value != self._shown_clip)
        self._shown_clip = self.clip.value
        self.status.value = (
            f"sampled {len(take.activity) / FPS:.1f} s of motion in {take.sampling_s:.2f} s"
        )
        return take

    def add_clip(self, name: str, clip: Clip) -> None:
        """Offer ``clip`` as ``name`` and show it."""
        self.clips[name] = clip
        self.clip.options = list(self.clips)
        self.clip.value = name  # samples again through the observer

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
                except (AudioError, ValueError) as error:
                    self.status.value = f"<b>{upload['name']}</b>: {error}"
                    continue
            self.add_clip(upload["name"], clip)
