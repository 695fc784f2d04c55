"""Configs: the checks every config dataclass uses, their JSON form, and the shared speech window.

Every model and training run is described by a frozen dataclass with working defaults. This
module is the one home for what those dataclasses share:

* :func:`check_fields` validates fields by kind (counts, sizes, probabilities, ...) with messages
  that name the class and the field;
* :func:`config_to_dict` / :func:`config_from_dict` turn a config into the JSON-able dict stored in
  checkpoints and back (unknown keys are refused, nested configs rebuilt);
* :class:`SpeechContext` is the window of speech and activity frames around each pose frame (5
  past and 25 future frames: 1 s of look-ahead), defined once for every config that reads speech;
* :func:`check_temperature` is the one check of a sampling temperature.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import typing
from dataclasses import dataclass


def _is_int(value) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def check_fields(
    config,
    *,
    positive: tuple[str, ...] = (),
    counts: tuple[str, ...] = (),
    sizes: tuple[str, ...] = (),
    fractions: tuple[str, ...] = (),
    non_negative: tuple[str, ...] = (),
    flags: tuple[str, ...] = (),
) -> None:
    """Validate fields of a config dataclass; the error names the class and the field.

    Args:
        positive: integers >= 1.
        counts: integers >= 0.
        sizes: tuples of integers >= 1 (layer sizes; may be empty).
        fractions: numbers in [0, 1) (dropout and other probabilities).
        non_negative: finite numbers >= 0.
        flags: True or False.
    Raises:
        ValueError: for the first bad field.
    """
    kind = type(config).__name__

    def fail(name, what):
        raise ValueError(f"{kind}.{name} must be {what}, got {getattr(config, name)!r}")

    for names, minimum in ((positive, 1), (counts, 0)):
        for name in names:
            value = getattr(config, name)
            if not (_is_int(value) and value >= minimum):
                fail(name, f"an integer >= {minimum}")
            object.__setattr__(config, name, int(value))  # np.int64(5) -> 5, for JSON
    for name in sizes:
        value = getattr(config, name)
        if not (isinstance(value, tuple) and all(_is_int(v) and v >= 1 for v in value)):
            fail(name, "a tuple of integers >= 1")
    for names, bounds in (
        (fractions, "a number in [0, 1)"),
        (non_negative, "a finite number >= 0"),
    ):
        for name in names:
            value = getattr(config, name)
            if not (_is_number(value) and 0 <= value < (1 if names is fractions else math.inf)):
                fail(name, bounds)
            object.__setattr__(config, name, float(value))
    for name in flags:
        if not isinstance(getattr(config, name), bool):
            fail(name, "True or False")


#: The highest sampling temperature: beyond it every draw lies over three standard deviations
#: out, and motion turns to noise.
MAX_TEMPERATURE = 3.0


def check_temperature(temperature) -> float:
    """A sampling temperature as a float: a number in ``[0, MAX_TEMPERATURE]`` (0 gives the
    base's mode, 1 the model's own spread).

    Raises:
        TypeError: if it is not a number; ValueError: if it lies outside that range.
    """
    if isinstance(temperature, bool) or not isinstance(temperature, numbers.Real):
        raise TypeError(f"temperature must be a number, got {type(temperature).__name__}")
    if not (math.isfinite(temperature) and 0 <= temperature <= MAX_TEMPERATURE):
        raise ValueError(
            f"temperature must lie in [0, {MAX_TEMPERATURE:g}] (0: the mode; 1: the model's own "
            f"spread; beyond {MAX_TEMPERATURE:g} motion turns to noise), got {temperature:g}"
        )
    return float(temperature)


@dataclass(frozen=True)
class SpeechContext:
    """The window of speech and activity frames a model reads around each pose frame.

    Subclassed by every config that reads speech, so that the window is defined and checked once.

    Attributes:
        speech_past: frames before the pose frame (5 in MoGlow and the Flow-VAE paper).
        speech_future: frames after it: 25 at 25 fps is the papers' 1 s of look-ahead, because
            gestures anticipate the speech they go with.
    """

    speech_past: int = 5
    speech_future: int = 25

    def __post_init__(self):
        check_fields(self, counts=("speech_past", "speech_future"))

    @property
    def speech_window(self) -> int:
        """Frames in a speech or activity window: past + the pose frame + future."""
        return self.speech_past + 1 + self.speech_future


# ---------------------------------------------------------------------------------------------
# Configs as JSON-able dictionaries (what checkpoints store)
# ---------------------------------------------------------------------------------------------


def config_to_dict(config) -> dict:
    """A config dataclass as a JSON-able dict (tuples become lists, nested configs dicts).

    Raises:
        TypeError: if ``config`` is not a dataclass instance or holds values JSON cannot store.
    """
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"a config must be a dataclass instance, got {type(config).__name__}")
    try:
        return json.loads(json.dumps(dataclasses.asdict(config)))
    except (TypeError, ValueError) as error:
        raise TypeError(
            f"{type(config).__name__} must hold only JSON-able values (numbers, strings, "
            f"booleans, None, lists/tuples, dicts) so that it can be stored: {error}"
        ) from error


def config_from_dict(config_class: type, data: dict):
    """Inverse of :func:`config_to_dict`: unknown keys raise, missing ones take their defaults, or,
    for a field the config class lists in ``FIELDS_ADDED``, the value that runs saved before the
    field existed were trained with.

    Lists become tuples (frozen configs hold sequences as tuples); a field whose type is a
    dataclass is rebuilt from its dict.

    Raises:
        ValueError: for a non-dict, an unknown key, or a value the config rejects.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{config_class.__name__} needs a dict, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(config_class) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(
            f"{config_class.__name__} has no field(s) {unknown}; its fields are {sorted(fields)}"
        )
    types = typing.get_type_hints(config_class)
    values = dict(getattr(config_class, "FIELDS_ADDED", {}))
    for key, value in data.items():
        if dataclasses.is_dataclass(types.get(key)) and isinstance(value, dict):
            value = config_from_dict(types[key], value)
        values[key] = tuple(value) if isinstance(value, list) else value
    try:
        return config_class(**values)
    except TypeError as error:
        raise ValueError(f"cannot build {config_class.__name__} from {data}: {error}") from error
