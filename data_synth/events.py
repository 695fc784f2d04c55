"""What the generator did and when: the event log of a conversation.

Every time is in seconds from the start of the audio. Speaker ``"A"`` is the agent (on camera,
the one we animate), ``"B"`` the off-screen partner. The log has two halves:

* **Speech** (drawn from the conversation seed, shared by every motion draw): :class:`Phrase`
  (an intonation phrase or a short backchannel), :class:`Syllable` and :class:`Accent` (a
  stressed syllable: louder, longer and higher than its neighbours).
* **Motion** (drawn from the motion seed): :class:`GesturePhrase` (the hands leave their home
  or the lap, gesture, and return), :class:`Stroke` (a beat: the moment of peak wrist speed) and
  :class:`Nod` (the moment the head moves down fastest).

The log is what a test or a notebook uses to check the rules; a model never sees it.
:meth:`Events.to_dict` and :meth:`Events.from_dict` convert it to and from plain JSON.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields


@dataclass(frozen=True)
class Phrase:
    """One stretch of speech without a pause.

    ``kind`` is ``"phrase"`` (an intonation phrase, part of a turn) or ``"backchannel"`` (a short
    "mm-hm" from the listener).
    """

    speaker: str
    start: float
    end: float
    kind: str = "phrase"


@dataclass(frozen=True)
class Syllable:
    """One syllable: an optional onset consonant, a vowel (or a nasal ``"m"``), an optional coda.

    ``vowel_onset`` is when the vowel starts to sound; ``emphasis`` is 0 for an unstressed
    syllable and in ``VoiceConfig.emphasis_range`` for an accented one.
    """

    speaker: str
    start: float
    end: float
    vowel_onset: float
    onset: str
    vowel: str
    coda: str
    emphasis: float


@dataclass(frozen=True)
class Accent:
    """A stressed syllable. ``time`` is the middle of its vowel's rise in loudness (its attack)."""

    speaker: str
    time: float
    emphasis: float


@dataclass(frozen=True)
class Stroke:
    """A beat of the agent's hands: ``time`` is the peak of wrist speed, ``accent_time`` the
    accent it belongs to (``accent_time - time`` is the lead, plus the timing jitter)."""

    time: float
    accent_time: float
    hands: str
    amplitude_cm: float


@dataclass(frozen=True)
class Nod:
    """A head nod of the agent: ``time`` is when the head pitches down fastest.

    ``cause`` is ``"accent"`` (while speaking), ``"partner_phrase_end"`` (a listener's
    backchannel nod) or ``"own_backchannel"`` (with the agent's own "mm-hm").
    """

    time: float
    amplitude_deg: float
    repetitions: int
    cause: str


@dataclass(frozen=True)
class GesturePhrase:
    """The hands' excursion for one phrase of the agent: from leaving their previous position
    (``start``) to being back at home (in front of the belly) or in a hold (``end``); ``hands`` is
    left, right or both."""

    start: float
    end: float
    hands: str
    phrase_start: float
    phrase_end: float


_EVENT_TYPES = {
    "phrases": Phrase,
    "syllables": Syllable,
    "accents": Accent,
    "strokes": Stroke,
    "nods": Nod,
    "gesture_phrases": GesturePhrase,
}


@dataclass
class Events:
    """The event log of one conversation, each list sorted by time."""

    phrases: list[Phrase] = field(default_factory=list)
    syllables: list[Syllable] = field(default_factory=list)
    accents: list[Accent] = field(default_factory=list)
    strokes: list[Stroke] = field(default_factory=list)
    nods: list[Nod] = field(default_factory=list)
    gesture_phrases: list[GesturePhrase] = field(default_factory=list)

    def phrases_of(self, speaker: str, kind: str | None = "phrase") -> list[Phrase]:
        """The phrases of one speaker, of one kind (``None`` for both kinds)."""
        return [
            p for p in self.phrases if p.speaker == speaker and (kind is None or p.kind == kind)
        ]

    def accents_of(self, speaker: str) -> list[Accent]:
        """The accents (stressed syllables) of one speaker."""
        return [a for a in self.accents if a.speaker == speaker]

    def to_dict(self) -> dict[str, list[dict]]:
        """Plain lists of dictionaries, ready for ``json.dump``."""
        return {name: [asdict(event) for event in getattr(self, name)] for name in _EVENT_TYPES}

    @classmethod
    def from_dict(cls, data: dict) -> Events:
        """Inverse of :meth:`to_dict`. Raises ``ValueError`` on missing or unknown keys."""
        if not isinstance(data, dict):
            raise ValueError(f"events must be a dictionary of lists, got {type(data).__name__}")
        missing = set(_EVENT_TYPES) - set(data)
        unknown = set(data) - set(_EVENT_TYPES)
        if missing or unknown:
            raise ValueError(
                f"events must have exactly the keys {sorted(_EVENT_TYPES)}; "
                f"missing {sorted(missing)}, unknown {sorted(unknown)}"
            )
        lists = {}
        for name, event_type in _EVENT_TYPES.items():
            expected = {f.name for f in fields(event_type)}
            items = []
            for item in data[name]:
                if not isinstance(item, dict) or set(item) != expected:
                    raise ValueError(
                        f"each entry of events[{name!r}] must have the keys {sorted(expected)}, "
                        f"got {item!r}"
                    )
                items.append(event_type(**item))
            lists[name] = items
        return cls(**lists)
