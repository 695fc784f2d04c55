"""Generation: motion for any length of speech, frame by frame, with the model's state carried.

Every generative model of the course generates one frame at a time through the same protocol:

* ``model.step(frame, state, noise) -> (pose (B, 54), state)``: the next pose (normalised) from
  the control of one frame, in the layout of a training batch with ``L = 1`` (``past_pose
  (B, 1, tau, 54)``, ``speech (B, 1, W, 27)``, ``activity (B, 1, W, 4)``, ``style (B, 1, 4)``),
  the state after the previous frame (None at the start) and the noise of this frame;
* ``model.noise_dim``: numbers of noise per frame (0 for a deterministic model);
* ``model.generating()``: a context in which the weights are fixed (optional);
* a model may write ``n`` frames at once (the diffusion model's chunk, ``config.chunk``): its
  ``step`` then returns ``(B, n, 54)`` from the control of the first of them, and ``noise`` is
  the noise of the whole chunk.

**Overlapping chunks.** Chunks laid end to end meet with a jump: a chunk is written from the poses
before it but does not land exactly on them. So a chunk's last ``overlap`` frames are held back,
the next chunk is asked for from the first held frame on (its past ends before them), and over
those frames the two are cross-faded, the new one's weight rising linearly, ``1 / (overlap + 1)``
to ``overlap / (overlap + 1)`` (as DiffuseStyleGesture blends its windows). The jump is spread over the overlap, at the price of
``n / (n - overlap)`` times the model's work per frame.

:class:`Stream` keeps everything else: the speech and activity windows, padded with silence
beyond either end, the model's own past poses (starting from the mean pose) and its state. A live
caller pushes speech frames as they arrive; because the control looks ``speech_future`` frames
(1 s) ahead, the pose of a frame comes out that much later, and :meth:`Stream.finish` flushes the
rest. :func:`generate` is the same for a whole recording.

* **Temperature** scales the noise: ``z = temperature * eps``; 0 gives ``z = 0``, the base
  distribution's mode pushed through the model (deterministic). Defaults to the model's
  ``default_temperature``.
* **Seeds**: ``seed=s`` gives sample ``k`` a generator of its own, derived from ``(s, k)``, so the
  same seed gives the same motion, and sample 1 of three is sample 1 of one.
* **Samples**: ``samples=K`` draws K motions for the same speech at once (a batch).
* Every output pose is put back on the pose surface (:func:`gesturelib.pose_surface.project`,
  which keeps each limb's direction) before it is fed back and returned.
"""

from __future__ import annotations

import contextlib
import functools

import numpy as np
import torch

from gesturelib.configs import check_temperature
from gesturelib.conventions import FPS, Activity
from gesturelib.features import activity_one_hot
from gesturelib.flows import RecurrentFlow
from gesturelib.pose_surface import project
from gesturelib.runtime import device_of, standard_normal
from gesturelib.skeleton import NUM_JOINTS, POSE_DIM
from gesturelib.style import STYLE_FEATURES


class NonFiniteMotionError(ValueError):
    """A model gave a NaN or infinite pose: its weights are damaged, or it diverged."""


#: Silence as :func:`~gesturelib.features.speech_features` gives it (the noise floor): what the
#: speech window holds beyond either end of a recording.
SILENCE = 0.0


class Stream:
    """Frame-by-frame generation for ``samples`` motions of the same speech.

    Args:
        model: follows the generation protocol (module docstring).
        normaliser: the :class:`~gesturelib.data.Normaliser` the model was trained with.
        samples: how many motions to draw, ``K``.
        temperature: scales the noise; None for the model's default; 0: deterministic.
        seed: an int (each sample gets a generator of its own) or a ``torch.Generator`` (all
            samples draw from it), or None (PyTorch's global generator).
        style: the style to hold, ``(4,)`` raw values (e.g. from
            ``normaliser.style_at_percentiles``), for a model with style control; None for its
            median.
        overlap: for a model that writes chunks, the frames by which one chunk overlaps the
            next, cross-faded (module docstring); None for half a chunk, 0 for chunks laid end
            to end.
        style_from: a reference recording whose style to take (a conversation, or anything
            with its ``rotations``, ``audio``, ``sample_rate``, ``fps`` and ``activity``), for a
            recurrent flow (MoGlow, Ye et al.'s flow): the base codes of its motion read with its
            own speech (:func:`reference_latents`) are replayed instead of fresh draws, sample
            ``k`` of ``K`` from ``k / K`` of the way in, from the start again at their end;
            the temperature scales them. None: draw the noise.
        style_code: ``(global_size,)`` a style code from ``model.reference_code`` (Ye et al.'s
            flow) held at every frame in place of the one of the model's own history; None:
            its own history sets it.
    """

    def __init__(
        self,
        model,
        normaliser,
        *,
        samples=1,
        temperature=None,
        seed=None,
        style=None,
        overlap=None,
        style_from=None,
        style_code=None,
    ):
        if not callable(getattr(model, "step", None)) or not hasattr(model, "config"):
            raise TypeError(
                f"model must generate motion (a model with step() and a config), got "
                f"{type(model).__name__}"
            )
        if not hasattr(normaliser, "normalise_speech"):
            raise TypeError(
                f"normaliser must be the model's Normaliser, got {type(normaliser).__name__}"
            )
        if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
            raise ValueError(f"samples must be an integer >= 1, got {samples!r}")
        self.model, self.normaliser, self.samples = model, normaliser, samples
        default = getattr(model, "default_temperature", 1.0)
        self.temperature = check_temperature(default if temperature is None else temperature)
        self.generators = _generators(seed, samples)
        config = model.config
        self.past_poses = getattr(config, "past_poses", 0)
        chunk = getattr(config, "chunk", 1)
        self.overlap = chunk // 2 if overlap is None else overlap
        if isinstance(self.overlap, bool) or not isinstance(self.overlap, int | np.integer):
            raise TypeError(f"overlap must be an int or None, got {overlap!r}")
        if not 0 <= self.overlap < chunk:
            raise ValueError(
                f"overlap must lie in 0..{chunk - 1} for chunks of {chunk} frames, got {overlap}"
            )
        self.speech_past, self.speech_future = config.speech_past, config.speech_future
        self.device = device_of(model)
        # The new chunk's weight over the overlap, (overlap,): (j + 1) / (overlap + 1).
        self.fade_in = torch.arange(1, self.overlap + 1, device=self.device) / (self.overlap + 1)
        self.state = None
        self.past = torch.zeros(samples, self.past_poses, POSE_DIM, device=self.device)
        tensor = functools.partial(torch.as_tensor, dtype=torch.float32, device=self.device)
        self.pose_mean, self.pose_std = tensor(normaliser.pose_mean), tensor(normaliser.pose_std)
        self.silence = tensor(
            normaliser.normalise_speech(np.full(len(normaliser.speech_mean), SILENCE))
        )
        self.none = tensor(activity_one_hot(np.array([Activity.NONE]))[0])
        # What has arrived, normalised, from frame ``first`` on (silence before the start).
        self.speech = self.silence.expand(self.speech_past, -1)
        self.activity = self.none.expand(self.speech_past, -1)
        self.first = -self.speech_past
        self.next_frame = 0  # the frame whose pose comes next
        # The last chunk's frames from next_frame on, held back to be cross-faded, (K, m, 54).
        self.held = torch.zeros(samples, 0, POSE_DIM, device=self.device)
        self.received = 0
        self.style = None
        self.finished = False
        if style is not None and not getattr(config, "style", False):
            raise ValueError(
                f"this {type(model).__name__} was trained without style inputs; pass style=None"
            )
        if getattr(config, "style", False):
            raw = normaliser.style_at_percentiles({}) if style is None else _checked_style(style)
            _check_style_range(raw, normaliser)
            self.style = tensor(normaliser.normalise_style(raw)).expand(samples, 1, -1)
        self.latents, self.replayed = None, None
        if style_from is not None:
            self.latents = tensor(reference_latents(model, normaliser, style_from))
            # Where each sample starts reading the reference's codes: spread over them.
            self.replayed = [k * len(self.latents) // samples for k in range(samples)]
        self.style_code = None
        if style_code is not None:
            size = getattr(config, "global_size", 0)
            code = tensor(style_code).reshape(-1)
            if not size or code.shape != (size,) or not torch.isfinite(code).all():
                raise ValueError(
                    f"style_code must be {size or 'no'} finite numbers from the model's "
                    f"reference_code() (a StyleFlow with a global encoder), got {tuple(code.shape)}"
                )
            self.style_code = code.expand(samples, 1, -1)

    def push(self, speech: np.ndarray, activity: np.ndarray) -> np.ndarray:
        """Add frames of speech; return the poses that can now be generated.

        Args:
            speech: ``(n, n_mels)`` speech frames (as
                :func:`~gesturelib.features.speech_features` gives them; it normalises by the
                whole recording's floor and level, so a live stream needs those measured on an
                earlier recording of the same microphone and room).
            activity: ``(n,)`` who-is-talking codes (:class:`~gesturelib.conventions.Activity`).
        Returns:
            ``(samples, m, 9, 6)`` limb rotations of the ``m`` frames that are now complete: those
            whose ``speech_future`` frames of look-ahead have arrived.
        """
        if self.finished:
            raise RuntimeError("this Stream has finished; start a new Stream for more speech")
        try:
            speech = np.asarray(speech, np.float32)
        except (TypeError, ValueError) as error:
            raise ValueError(f"speech must be numbers, (n, n_mels) frames: {error}") from None
        activity = np.asarray(activity)
        n_mels = len(self.normaliser.speech_mean)
        if speech.ndim != 2 or speech.shape[1] != n_mels:
            raise ValueError(f"speech must be (n, {n_mels}) frames, got {speech.shape}")
        _check_speech(speech)
        if activity.shape != (len(speech),):
            raise ValueError(f"activity must be ({len(speech)},) codes, got {activity.shape}")
        normalised = self.normaliser.normalise_speech(speech)
        codes = activity_one_hot(activity)
        self._append(
            torch.as_tensor(normalised, device=self.device),
            torch.as_tensor(codes, dtype=torch.float32, device=self.device),
        )
        self.received += len(speech)
        return self._generate(self.received - self.speech_future)

    def finish(self) -> np.ndarray:
        """The poses of the last frames, their look-ahead padded with silence:
        ``(samples, m, 9, 6)``."""
        if self.finished:
            raise RuntimeError("this Stream has finished already; start a new Stream")
        self.finished = True
        future = self.speech_future
        self._append(self.silence.expand(future, -1), self.none.expand(future, -1))
        poses = self._generate(self.received)
        poses = np.concatenate([poses, self._rotations([self.held])], axis=1)
        # A model's last chunk may run past the recording's end.
        return poses[:, : poses.shape[1] - (self.next_frame + self.held.shape[1] - self.received)]

    def _append(self, speech: torch.Tensor, activity: torch.Tensor) -> None:
        self.speech = torch.cat([self.speech, speech])
        self.activity = torch.cat([self.activity, activity])

    def _generate(self, until: int) -> np.ndarray:
        """The poses of frames ``next_frame .. until - 1``, as limb rotations."""
        poses = []
        window = self.speech_past + 1 + self.speech_future
        entered = getattr(self.model, "generating", contextlib.nullcontext)
        with entered(), torch.inference_mode():
            while self.next_frame < until:
                start = self.next_frame - self.speech_past - self.first  # its window's first row
                frame = {
                    "past_pose": self.past[:, None],
                    "speech": self.speech[start : start + window].expand(self.samples, 1, -1, -1),
                    "activity": self.activity[start : start + window].expand(
                        self.samples, 1, -1, -1
                    ),
                }
                if self.style is not None:
                    frame["style"] = self.style
                if self.style_code is not None:
                    frame["reference_code"] = self.style_code
                pose, self.state = self.model.step(frame, self.state, self._noise())
                if not torch.isfinite(pose).all():
                    raise NonFiniteMotionError(
                        f"the model's pose for frame {self.next_frame} is NaN or infinite: its "
                        "weights are damaged or it diverged; retrain it"
                    )
                chunk = self._on_surface(pose.reshape(self.samples, -1, POSE_DIM))  # (K, n, 54)
                chunk = self._cross_faded(chunk)
                if self.past_poses:
                    self.past = torch.cat([self.past, chunk], dim=1)[:, -self.past_poses :]
                poses.append(chunk)
                self.next_frame += chunk.shape[1]
        # Forget the frames no window will need again.
        drop = self.next_frame - self.speech_past - self.first
        self.speech, self.activity, self.first = (
            self.speech[drop:],
            self.activity[drop:],
            self.first + drop,
        )
        if not poses:
            return np.zeros((self.samples, 0, NUM_JOINTS, 6))
        return self._rotations(poses)

    def _cross_faded(self, chunk: torch.Tensor) -> torch.Tensor:
        """The frames of a new chunk ``(K, n, 54)`` that are final: its first frames faded in
        over the held ones, up to the ``overlap`` frames it now holds back."""
        if self.overlap == 0:
            return chunk
        assert chunk.shape[1] > self.overlap, "a chunk must be longer than its overlap"
        if self.held.shape[1]:  # none before the first chunk
            fade, m = self.fade_in[:, None], self.overlap
            blended = self._on_surface(self.held * (1 - fade) + chunk[:, :m] * fade)
            chunk = torch.cat([blended, chunk[:, m:]], dim=1)
        self.held = chunk[:, -self.overlap :]
        return chunk[:, : -self.overlap]

    def _rotations(self, poses: list[torch.Tensor]) -> np.ndarray:
        """Normalised poses ``(K, n, 54)`` joined in time, as limb rotations ``(K, T, 9, 6)``."""
        raw = torch.cat(poses, dim=1) * self.pose_std + self.pose_mean
        return raw.double().cpu().numpy().reshape(self.samples, -1, NUM_JOINTS, 6)

    def _noise(self) -> torch.Tensor:
        dim = getattr(self.model, "noise_dim", 0)
        if self.latents is not None:
            rows = [position % len(self.latents) for position in self.replayed]
            self.replayed = [position + 1 for position in self.replayed]
            return self.temperature * self.latents[rows]
        if self.temperature == 0 or dim == 0:
            return torch.zeros(self.samples, dim, device=self.device)
        if isinstance(self.generators, list):
            draws = [standard_normal((1, dim), g, self.device) for g in self.generators]
            return self.temperature * torch.cat(draws)
        return self.temperature * standard_normal((self.samples, dim), self.generators, self.device)

    def _on_surface(self, pose: torch.Tensor) -> torch.Tensor:
        """``pose`` ``(..., 54)`` (normalised) with every limb put back on the pose surface."""
        raw = (pose * self.pose_std + self.pose_mean).unflatten(-1, (NUM_JOINTS, 6))
        return (project(raw).flatten(-2) - self.pose_mean) / self.pose_std


def generate(model, normaliser, speech, activity, progress: bool = False, **options) -> np.ndarray:
    """Motion for a whole recording: limb rotations ``(samples, T, 9, 6)``.

    Args:
        model, normaliser: as for :class:`Stream`.
        speech: ``(T, n_mels)`` the recording's :func:`~gesturelib.features.speech_features`
            (any ``T >= 1``).
        activity: ``(T,)`` who-is-talking codes; pass other codes than the recording's to make the
            agent speak or listen where it did not.
        progress: show a progress bar (the speech is then pushed a minute at a time; the motion
            is the same).
        options: ``samples``, ``temperature``, ``seed``, ``style``, ``overlap``, ``style_from``,
            ``style_code`` of :class:`Stream`.
    """
    from tqdm.auto import tqdm

    if len(activity) != len(speech):
        raise ValueError(
            f"activity must be ({len(speech)},) codes, one per speech frame, got {len(activity)}"
        )
    stream = Stream(model, normaliser, **options)
    step = _PROGRESS_STEP if progress else max(len(speech), 1)
    parts = []
    with tqdm(total=len(speech), unit="frame", desc="generating", disable=not progress) as bar:
        for start in range(0, len(speech), step):
            parts.append(stream.push(speech[start : start + step], activity[start : start + step]))
            bar.update(len(speech[start : start + step]))
    return np.concatenate([*parts, stream.finish()], axis=1)


def shortest_reference(model) -> int:
    """Frames of the shortest reference whose base codes ``model`` can read: its control's whole
    context (past poses or past speech, and the look-ahead) and one frame."""
    config = model.config
    return max(config.past_poses, config.speech_past) + config.speech_future + 1


def reference_latents(model, normaliser, reference) -> np.ndarray:
    """The base codes of a reference recording's motion, read through the flow with its own
    speech and who is talking (teacher forcing): Ye et al.'s style transfer (their section 4.5).
    Replayed with other speech (:class:`Stream`'s ``style_from``), they carry what the flow
    could not explain by the control: where the hands hover, how wide and fast they move.

    Args:
        model, normaliser: a recurrent flow over poses (``model.latents``: MoGlow, Ye et al.'s
            flow) and its normaliser.
        reference: a recording with ``rotations (T, 9, 6)``, ``audio``, ``sample_rate``,
            ``fps`` and ``activity (T,)`` (a conversation; an imported take).
    Returns:
        ``(N, 54)`` float32, one per frame that has its whole control: ``N = T - max(past
        poses, past speech) - speech_future``.
    Raises:
        ValueError: a model without base codes, or a reference too short or malformed (from
            :meth:`~gesturelib.data.ConversationFeatures.from_conversation`).
    """
    if not callable(getattr(model, "latents", None)):
        raise ValueError(
            f"a {type(model).__name__} has no base codes to take a reference's style from; "
            "style_from is for MoGlow and Ye et al.'s flow"
        )
    return model.latents(recording_batch(model, normaliser, reference))[0].cpu().numpy()


def one_step_ahead(model, normaliser, recording, seed: int = 0) -> np.ndarray:
    """Every frame of a recording drawn one step ahead of its *recorded* past: the exposure test.

    The flow's memory and control are those of the recording (teacher forcing, as in training);
    each frame is drawn from the flow given them (temperature 1), and the memory then moves on
    with the recorded frame, not the drawn one. Against :func:`generate`, where every frame is fed
    back, it tells what a model has learned from what it loses to its own output.

    Args:
        model, normaliser: a recurrent flow over poses (MoGlow, Ye et al.'s flow) or over an
            autoencoder's latent (the Flow-VAEs: the recorded poses are encoded, the drawn
            latents decoded), and its normaliser.
        recording: as :func:`reference_latents`'s ``reference``.
        seed: of the draws.
    Returns:
        Limb rotations ``(N, 9, 6)`` on the pose surface, for the recording's frames ``first``
        to ``first + N - 1``, where ``first = max(past poses, past speech)``: the frames that
        have their whole control (:func:`recording_batch`).
    Raises:
        ValueError: a model that is not a recurrent flow, or a recording too short or malformed.
    """
    kind = _recurrent_flow(model)
    if kind is None:
        raise ValueError(
            f"one_step_ahead draws from a recurrent flow (MoGlow, Ye et al.'s flow, the "
            f"Flow-VAEs), not a {type(model).__name__}"
        )
    batch = recording_batch(model, normaliser, recording)
    generator = torch.Generator().manual_seed(seed)
    drawn, state = [], None
    over_latent = kind == "latent"
    with torch.no_grad(), model.generating():
        if over_latent:
            control, recorded = model.control(batch), model.encode(batch["pose"])
        else:
            control, recorded = model.conditioning(batch), batch["pose"]
        # What the flow's frames are measured from (the model's own rule: for a residual model
        # the last recorded pose, or its latent moved towards rest), as a tensor like `recorded`.
        origin = torch.zeros_like(recorded) + model._origin(batch)
        recorded = recorded - origin
        for t in range(recorded.shape[1]):
            noise = standard_normal((1, 1, recorded.shape[-1]), generator, device_of(model))
            frame, _, _ = model.flow.inverse(noise, control[:, t : t + 1], state)
            drawn.append(frame[0, 0] + origin[0, t])
            _, _, state = model.flow(recorded[:, t : t + 1], control[:, t : t + 1], state)
        poses = torch.stack(drawn)
        if over_latent:
            poses = model.decode(poses)
    return _on_surface(normaliser, poses)


def through_autoencoder(model, normaliser, rotations: np.ndarray) -> np.ndarray:
    """Limb rotations ``(T, 9, 6)`` through a Flow-VAE's autoencoder, ``d(e(x))``, on the pose
    surface: the poses its decoder gives for recorded ones. A frame :func:`one_step_ahead` draws
    for a Flow-VAE moved from the last recorded pose *as decoded*; measured from the recorded
    pose itself, its change would also hold the autoencoder's error.

    Raises:
        ValueError: a model that is not a flow over an autoencoder's latent.
    """
    if _recurrent_flow(model) != "latent":
        raise ValueError(
            f"through_autoencoder needs a Flow-VAE (a flow over an autoencoder's latent), not a "
            f"{type(model).__name__}"
        )
    rotations = np.asarray(rotations)
    pose = torch.as_tensor(normaliser.normalise_pose(rotations.reshape(len(rotations), -1)))
    with torch.no_grad():
        decoded = model.decode(model.encode(pose.float().to(device_of(model))))
    return _on_surface(normaliser, decoded)


def _recurrent_flow(model) -> str | None:
    """``"latent"`` for a recurrent flow over an autoencoder's latent (the Flow-VAEs),
    ``"poses"`` for one over poses (MoGlow, Ye et al.'s flow), None for any other model."""
    if not isinstance(getattr(model, "flow", None), RecurrentFlow):
        return None
    if callable(getattr(model, "decode", None)) and callable(getattr(model, "encode", None)):
        return "latent"
    return "poses" if callable(getattr(model, "latents", None)) else None


def _on_surface(normaliser, poses: torch.Tensor) -> np.ndarray:
    """Normalised poses ``(N, 54)`` as limb rotations ``(N, 9, 6)`` on the pose surface."""
    raw = normaliser.denormalise_pose(poses.double().cpu().numpy())
    return project(torch.as_tensor(raw).reshape(-1, NUM_JOINTS, 6)).numpy()


def recording_batch(model, normaliser, recording) -> dict[str, torch.Tensor]:
    """A whole recording as one training item of ``model``: the batch ``(1, N, ...)`` of every
    frame that has its whole control (teacher forcing), on the model's device.

    Args:
        model, normaliser: a model whose config has ``past_poses`` and the speech context.
        recording: as :func:`reference_latents`'s ``reference``.
    Raises:
        ValueError: a recording shorter than :func:`shortest_reference`, or malformed.
    """
    from gesturelib.data import ConversationFeatures, WindowConfig, WindowDataset

    features = ConversationFeatures.from_conversation(recording, len(normaliser.speech_mean))
    config = model.config
    context = {"speech_past": config.speech_past, "speech_future": config.speech_future}
    needed = shortest_reference(model)
    if len(features.pose) < needed:
        raise ValueError(
            f"a style reference must be at least {needed} frames ({needed / FPS:.1f} s) long for "
            f"this model, got {len(features.pose)}"
        )
    frames = len(features.pose) - needed + 1
    windows = WindowConfig(past_poses=config.past_poses, sequence_length=frames, **context)
    batch = WindowDataset([features], windows, normaliser)[0]
    device = device_of(model)
    return {name: value[None].to(device) for name, value in batch.items()}


#: Frames pushed at once when generation shows its progress: a minute of speech.
_PROGRESS_STEP = 60 * FPS


#: Speech features lie within about -2 and 5 (0: the recording's noise floor, 1: its speech
#: level); far beyond these bounds the input is something else.
SPEECH_RANGE = (-20.0, 50.0)


def _check_speech(speech: np.ndarray) -> None:
    """Refuse what cannot be speech features: non-finite values, values far out of their range,
    or a raw log-mel spectrogram (whose silence lies far below zero)."""
    bad = np.flatnonzero(~np.isfinite(speech).all(axis=1))
    if bad.size:
        raise ValueError(
            f"speech holds NaN or infinite values in {bad.size} frames (first: frame {bad[0]})"
        )
    low, high = SPEECH_RANGE
    if speech.size and (speech.min() < low or speech.max() > high):
        raise ValueError(
            f"speech lies in [{speech.min():.3g}, {speech.max():.3g}], far outside the range of "
            f"speech features ({low:g} to {high:g}; about -2 to 5 in practice): pass "
            "gesturelib.features.speech_features(audio, sample_rate)"
        )
    if len(speech) >= 25 and np.median(speech) < -3:
        raise ValueError(
            f"speech has a median of {np.median(speech):.1f}: this looks like a raw log-mel "
            "spectrogram, not speech features (whose silence reads 0); pass "
            "gesturelib.features.speech_features(audio, sample_rate)"
        )


def _checked_style(style) -> np.ndarray:
    try:
        raw = np.asarray(style, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"style must be numbers: {error}") from None
    if raw.shape != (len(STYLE_FEATURES),) or not np.isfinite(raw).all():
        raise ValueError(
            f"style must be {len(STYLE_FEATURES)} finite numbers ({', '.join(STYLE_FEATURES)}), "
            f"got {style!r}"
        )
    return raw


def _check_style_range(raw: np.ndarray, normaliser) -> None:
    """Refuse a style far beyond what the training data held (more than its whole range past
    either end): the model never saw such values, and its motion there means nothing."""
    lowest, highest = normaliser.style_percentiles[0], normaliser.style_percentiles[-1]
    span = highest - lowest
    outside = (raw < lowest - span) | (raw > highest + span)
    if outside.any():
        index = int(np.flatnonzero(outside)[0])
        raise ValueError(
            f"style {STYLE_FEATURES[index]} = {raw[index]:g} lies far outside the training values "
            f"({lowest[index]:.3g} to {highest[index]:.3g}); choose a percentile with "
            "normaliser.style_at_percentiles"
        )


def _generators(seed, samples: int):
    """One generator per sample from an int seed; a given generator (or None) is shared."""
    if seed is None or isinstance(seed, torch.Generator):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise TypeError(f"seed must be an int, a torch.Generator or None, got {seed!r}")
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    states = np.random.SeedSequence(int(seed)).spawn(samples)
    return [torch.Generator().manual_seed(int(s.generate_state(1)[0])) for s in states]
