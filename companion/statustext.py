"""What the vehicle says to ground stations in ``STATUSTEXT``, as ArduPilot says it.

- :class:`TextKind`, :class:`Notice`: the texts that repeat while a condition lasts (the
  tether governor's slowing, braking and resuming, a velocity target cut at the reach, an
  over-tension, a fence breach, a winch that does not answer): each is said with its kind.
- :class:`TextRateLimit`: one text of a kind at most every :data:`TEXT_KIND_INTERVAL_S`
  of simulated time; the navigator's and the autopilot's texts go through the one
  limiter the navigator keeps (``Navigator.texts``), so the offline runner's events and
  the ground stations' ``STATUSTEXT`` say the same.
- :class:`StatusTextChunks`: a text longer than a ``STATUSTEXT``'s 50 characters split as
  ArduPilot's ``GCS::send_textv`` splits it: MAVLink 2's ``id`` (the same, not 0, for
  every chunk of one text; 0 for a text that fits one message) and ``chunk_seq`` (0, 1,
  ...), every chunk but the last exactly 50 characters, the last shorter (an empty one
  after an exact multiple of 50: a receiver takes a chunk shorter than 50 as the last), at
  most ArduPilot's 256 characters. MAVProxy and QGroundControl reassemble them; a
  pymavlink script sees each chunk as a message, which is why the vehicle's own texts keep
  within 50 characters, as ArduPilot's do.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

__all__ = ["MAX_TEXT_BYTES", "STATUSTEXT_LEN", "TEXT_KIND_INTERVAL_S", "Notice",
           "StatusTextChunks", "TextKind", "TextRateLimit"]

#: Characters in one STATUSTEXT's text field.
STATUSTEXT_LEN = 50
#: The longest text sent [bytes] (ArduPilot's statustext buffer); longer ones are cut.
MAX_TEXT_BYTES = 256
#: The shortest time between two texts of one kind [s of simulated time].
TEXT_KIND_INTERVAL_S = 5.0


class TextKind(Enum):
    """Texts that repeat while their condition lasts (rate-limited by kind)."""

    TETHER_SLOWING = "tether slowing"
    TETHER_BRAKING = "tether braking"
    TETHER_RESUMING = "tether resuming"
    TETHER_MOVING_IN = "tether moving in"
    VELOCITY_STOPPED = "velocity stopped"
    RTL_ALT_LIMITED = "rtl altitude limited"
    OVER_TENSION = "over-tension"
    FENCE_BREACH = "fence breach"
    WINCH_NO_ANSWER = "winch no answer"


@dataclass(frozen=True)
class Notice:
    """A text of a :class:`TextKind` (an event's value; ``str()`` is the text)."""

    kind: TextKind
    text: str

    def __str__(self) -> str:
        return self.text


class TextRateLimit:
    """At most one text of each :class:`TextKind` every ``interval_s`` [s]."""

    def __init__(self, interval_s: float = TEXT_KIND_INTERVAL_S) -> None:
        self.interval_s = interval_s
        self._last: dict[TextKind, float] = {}

    def allow(self, kind: TextKind, t_s: float) -> bool:
        """Whether a text of ``kind`` may be said at ``t_s`` [s] (if so, it counts as
        said). A clock that went back (a reboot) starts the kind afresh."""
        last = self._last.get(kind)
        if last is not None and last <= t_s < last + self.interval_s:
            return False
        self._last[kind] = t_s
        return True


class StatusTextChunks:
    """Splits texts into STATUSTEXT chunks, numbering the texts that need several."""

    def __init__(self) -> None:
        self._id = 0

    def split(self, text: str) -> list[tuple[bytes, int, int]]:
        """``text``'s chunks as (text bytes, id, chunk_seq), in order."""
        data = text.encode("utf-8", "replace")[:MAX_TEXT_BYTES]
        if len(data) <= STATUSTEXT_LEN:
            return [(data, 0, 0)]
        self._id = self._id % 65535 + 1
        n = len(data) // STATUSTEXT_LEN + 1      # the last is shorter than 50 (maybe empty)
        return [(data[i * STATUSTEXT_LEN:(i + 1) * STATUSTEXT_LEN], self._id, i)
                for i in range(n)]
