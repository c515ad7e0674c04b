"""The winch's modes, one class each behind one interface (:class:`ModeLogic`): what the
drum's length reference does in the mode, from the ``DO_WINCH`` that starts it to each
encoder frame's torque (``groundstation.winch`` holds the shared parts: the frames, the
safety checks, the status, the commands).

- :class:`Relaxed` (``WINCH_RELAXED``, the default): follow L-bar through the host's step;
  the ground pre-tension while the UAV is on the ground or unknown; the rejoin of L-bar
  from a longer line and the join from a shorter one; the slack guard.
- :class:`RelativeLength`, :class:`Rate`, :class:`Retract`: a ramped length reference the
  length law tracks, within the taut floor and the drum's ends (:class:`ReferenceMode`).
- :class:`Braked` (``WINCH_LOCK``, ``WINCH_HOLD``): the axis IDLE, the brake holds.
"""

from __future__ import annotations

import enum
import math
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch_report import Notice, WinchOutput, notice
from groundstation.winder_control import WinderCommand

if TYPE_CHECKING:
    from groundstation.winch import Winch


class WinchMode(enum.IntEnum):
    """The winch's mode: the ``WINCH_ACTIONS`` value of the last accepted action."""

    RELAXED = mavlink2.WINCH_RELAXED
    RELATIVE_LENGTH = mavlink2.WINCH_RELATIVE_LENGTH_CONTROL
    RATE = mavlink2.WINCH_RATE_CONTROL
    LOCK = mavlink2.WINCH_LOCK
    HOLD = mavlink2.WINCH_HOLD
    RETRACT = mavlink2.WINCH_RETRACT


#: Modes in which the brake holds the drum (axis IDLE).
BRAKED_MODES = frozenset({WinchMode.LOCK, WinchMode.HOLD})
#: A line longer than L-bar by more than this [m] when RELAXED begins is wound back to it
#: at ``rejoin_rate_m_s``.
REJOIN_MARGIN_M = 0.5
#: How fast that wind-in speeds up and slows down [m/s^2].
REJOIN_ACC_M_S2 = 0.5
#: A line shorter than L-bar by more than this [m] when RELAXED begins or the UAV leaves
#: the ground (an in-air start's first report) is paid out to it the same way: a step of
#: the reference there set the drum paying out faster than the line took it, which lay
#: slack at the exit and snapped taut when the drum stopped (the lumped line: 70-150 N).
JOIN_MARGIN_M = 0.05


class ModeLogic:
    """One winch mode: how it starts, resumes and steps the length reference."""

    mode: WinchMode
    #: whether the mode keeps the axis IDLE (the brake holds the drum)
    brakes = False

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        """The mode begins from the measured length (an accepted ``DO_WINCH``: its length
        ``param3`` [m] and its speed [m/s], both checked); returns what to say."""
        self.resume_from(w, w.length_m)
        return []

    def resume_from(self, w: Winch, length_m: float) -> None:
        """The reference taken up from ``length_m`` [m] after the drum was held."""
        w.ref_m, w.ref_rate_m_s = length_m, 0.0

    def control(self, w: Winch, out: WinchOutput) -> WinderCommand:
        """This encoder frame's step of the law in the mode (the axis closed-loop)."""
        return w.track(w.ref_m, w.ref_rate_m_s)

    def after_pay_out(self, w: Winch) -> None:
        """The over-tension pay-out moved the reference (``w.ref_m``): take it from there."""

    @property
    def retracting(self) -> bool:
        """Whether WINCH_STATUS says RETRACTING."""
        return False


class Braked(ModeLogic):
    """LOCK and HOLD: the axis IDLE, the brake holds the drum whatever the UAV does."""

    brakes = True

    def __init__(self, mode: WinchMode) -> None:
        self.mode = mode

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        return []


class ReferenceMode(ModeLogic):
    """A length reference moved by the command, then held within the safety limits: never
    below the taut floor (raised with it when the UAV moves away), above the drum's
    capacity less ``end_margin_m`` or below the drum's full stop; the first limit met is
    said once a command."""

    def __init__(self) -> None:
        self.speed_m_s = 0.0            # |ramp rate| (length, retract) or signed rate
        self.target_m = math.nan

    def control(self, w: Winch, out: WinchOutput) -> WinderCommand:
        floor, floor_rate = w.taut_floor()
        self.advance(w, floor)
        if math.isfinite(floor) and w.ref_m < floor:
            w.ref_m = floor
            w.ref_rate_m_s = max(w.ref_rate_m_s, floor_rate)
            if not self.at_floor(floor) and not w.limit_noticed:
                out.notices.append(notice(mavlink2.MAV_SEVERITY_WARNING,
                                          f"winch: stopped at taut limit {floor:.2f} m"))
            w.limit_noticed = True
        if w.ref_m > w.length_max_m:
            w.ref_m = w.length_max_m
            w.ref_rate_m_s = min(w.ref_rate_m_s, 0.0)
            if not w.limit_noticed:
                out.notices.append(notice(mavlink2.MAV_SEVERITY_WARNING,
                                          f"winch: stopped at drum end {w.length_max_m:.2f} m"))
            w.limit_noticed = True
        elif w.ref_m < w.length_min_m:
            w.ref_m = w.length_min_m
            w.ref_rate_m_s = max(w.ref_rate_m_s, 0.0)
        return w.track(w.ref_m, w.ref_rate_m_s)

    def advance(self, w: Winch, floor_m: float) -> None:
        """One period of the reference toward the target at the command's speed."""
        diff = self.target_m - w.ref_m
        step = self.speed_m_s * w.dt_s
        if abs(diff) <= step:
            w.ref_m = self.target_m
            w.ref_rate_m_s = 0.0
            self.reached()
        else:
            w.ref_m += math.copysign(step, diff)
            w.ref_rate_m_s = math.copysign(self.speed_m_s, diff)

    def reached(self) -> None:
        """The reference has reached its target."""

    def at_floor(self, floor_m: float) -> bool:
        """The reference met the taut floor ``floor_m`` [m]; returns whether that is the
        mode's own end (no notice)."""
        return False

    def after_pay_out(self, w: Winch) -> None:
        self.target_m = w.ref_m


class RelativeLength(ReferenceMode):
    """RELATIVE_LENGTH_CONTROL: from the measured length, pay out (+) or wind in (-)
    ``param3`` m at ``|param4|`` m/s, then hold; a target beyond the limits is clamped
    and said."""

    mode = WinchMode.RELATIVE_LENGTH

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        start = w.length_m
        w.ref_m, self.speed_m_s = start, speed_m_s
        target = start + length_m
        floor, _ = w.taut_floor()
        lower = max(floor, w.length_min_m) if math.isfinite(floor) else w.length_min_m
        notices = []
        if target < lower or target > w.length_max_m:
            target = lower if target < lower else w.length_max_m
            w.limit_noticed = True
            notices.append(notice(mavlink2.MAV_SEVERITY_WARNING,
                                  f"winch: length clamped to {target:.2f} m"))
        self.target_m = target
        return notices


class Rate(ReferenceMode):
    """RATE_CONTROL: the reference moves at ``param4`` m/s until the next command."""

    mode = WinchMode.RATE

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        w.ref_m, self.speed_m_s = w.length_m, speed_m_s
        return []

    def advance(self, w: Winch, floor_m: float) -> None:
        w.ref_m += self.speed_m_s * w.dt_s
        w.ref_rate_m_s = self.speed_m_s

    def after_pay_out(self, w: Winch) -> None:
        self.target_m = w.ref_m
        self.speed_m_s = max(self.speed_m_s, 0.0)


class Retract(ReferenceMode):
    """RETRACT: wind in to the taut floor (followed while it moves), then hold it."""

    mode = WinchMode.RETRACT

    def __init__(self) -> None:
        super().__init__()
        self.reached_floor = False

    def start(self, w: Winch, length_m: float, speed_m_s: float) -> list[Notice]:
        self.reached_floor = False
        w.ref_m, self.speed_m_s = w.length_m, speed_m_s
        self.target_m = w.taut_floor()[0]
        return [notice(mavlink2.MAV_SEVERITY_INFO,
                       f"winch: retracting to {self.target_m:.2f} m")]

    def advance(self, w: Winch, floor_m: float) -> None:
        if not self.reached_floor and math.isfinite(floor_m):
            self.target_m = floor_m
        super().advance(w, floor_m)

    def reached(self) -> None:
        self.reached_floor = True

    def at_floor(self, floor_m: float) -> bool:
        self.reached_floor = True
        self.target_m = floor_m
        return True

    def after_pay_out(self, w: Winch) -> None:
        self.target_m = w.ref_m
        self.reached_floor = True

    @property
    def retracting(self) -> bool:
        return not self.reached_floor
