"""What the winch says and is asked: ``STATUSTEXT`` notices, ``COMMAND_LONG`` requests and
their ``COMMAND_ACK``, ``WINCH_STATUS`` and its flags, and what one call of the winch asks
its process to send (:class:`WinchOutput`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from groundstation.tether_fix import TetherFix
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl

#: WINCH_STATUS ``temperature`` when unknown (INT16_MAX, as the message defines).
TEMPERATURE_UNKNOWN = 32767
#: STATUSTEXT holds at most this many characters in one message.
STATUSTEXT_MAX_LEN = 50

# MAV_WINCH_STATUS_FLAG bits; 0 for those the installed dialect does not define
FLAG_HEALTHY = cl.winch_status_flag("HEALTHY")
FLAG_FULLY_RETRACTED = cl.winch_status_flag("FULLY_RETRACTED")
FLAG_MOVING = cl.winch_status_flag("MOVING")
FLAG_CLUTCH_ENGAGED = cl.winch_status_flag("CLUTCH_ENGAGED")
FLAG_LOCKED = cl.winch_status_flag("LOCKED")
FLAG_RETRACTING = cl.winch_status_flag("RETRACTING")


class Notice(NamedTuple):
    """A ``STATUSTEXT``: ``MAV_SEVERITY`` and text (at most 50 characters)."""

    severity: int
    text: str


class CommandRequest(NamedTuple):
    """A ``COMMAND_LONG`` or ``COMMAND_INT`` as received: its command id, target ids, the
    sender's ids, ``param1..param4`` and ``confirmation`` (0 for COMMAND_INT)."""

    command: int
    target_system: int
    target_component: int
    source_system: int
    source_component: int
    param1: float
    param2: float
    param3: float
    param4: float
    confirmation: int = 0


class CommandReply(NamedTuple):
    """The ``COMMAND_ACK`` to send (``result`` a ``MAV_RESULT``, addressed to the
    command's sender) and the notices that go with it."""

    command: int
    result: int
    target_system: int
    target_component: int
    notices: tuple[Notice, ...]


class WinchStatusReport(NamedTuple):
    """The fields of a ``WINCH_STATUS``: length [m], line speed [m/s, + paying out],
    tension [kg], bus voltage [V] and current [A] (NaN unknown), temperature [degC]
    (INT16_MAX unknown), ``MAV_WINCH_STATUS_FLAG`` bits."""

    line_length_m: float
    speed_m_s: float
    tension_kg: float
    voltage_v: float
    current_a: float
    temperature_c: int
    flags: int


@dataclass
class WinchOutput:
    """What one call asks the process to send."""

    frames: list[cp.Frame] = field(default_factory=list)
    notices: list[Notice] = field(default_factory=list)
    status: WinchStatusReport | None = None
    fix: TetherFix | None = None
    """A tether fix of the UAV's position to send to the vehicle (ODOMETRY)."""

    def extend(self, other: WinchOutput) -> None:
        """Append ``other``'s frames and notices; its status and fix, if any, replace
        ours."""
        self.frames.extend(other.frames)
        self.notices.extend(other.notices)
        if other.status is not None:
            self.status = other.status
        if other.fix is not None:
            self.fix = other.fix


def notice(severity: int, text: str) -> Notice:
    """A STATUSTEXT, its text cut to what one message holds."""
    return Notice(severity, text[:STATUSTEXT_MAX_LEN])
