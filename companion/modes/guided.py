"""GUIDED: the ground station's commands flown as they come: the take-off, position
targets, velocity targets (stopped after ``guided_velocity_timeout_s`` without an update,
cut at the tether's reach and the ground), a streamed script of full set-points, a turn,
a change of speed. Entered, GUIDED holds (:class:`companion.modes.hold.Hold`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from companion.nav_types import FlightMode, LegTag, NavEvent, Reason, Refusal
from companion.plan import VelocityRef
from companion.reference import RefSample
from companion.statustext import Notice, TextKind

if TYPE_CHECKING:
    from companion.navigation import Navigator

Vec3 = tuple[float, float, float]


class Guided:
    """GUIDED's commands (each refused with its reason, or None when done)."""

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav

    def _refuse_unless_flying(self) -> Refusal | None:
        """Why a GUIDED move cannot be flown now: not in GUIDED, or not flying."""
        nav = self.nav
        if nav.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "not in GUIDED")
        if not nav.flying:
            return Refusal(Reason.NOT_FLYING, "not flying (take off first)")
        return None

    def takeoff(self, alt_m: float) -> Refusal | None:
        """Take off to ``alt_m`` [m above the ground]."""
        nav = self.nav
        if not math.isfinite(alt_m) or alt_m <= 0.0:
            return Refusal(Reason.BAD_VALUE, f"Takeoff: bad altitude {alt_m}")
        if nav.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "Takeoff: not in GUIDED")
        if not nav.armed:
            return Refusal(Reason.NOT_ARMED, "Takeoff: not armed")
        if not nav.landed:
            return Refusal(Reason.FLYING, "Takeoff: already flying")
        target = (nav.position_m[0], nav.position_m[1], alt_m)
        why = nav.check_target(target)
        if why is not None:
            return why
        nav.begin_takeoff(target)
        return None

    def goto(self, pos_m: Vec3, yaw_rad: float | None = None,
             speed_m_s: float | None = None) -> Refusal | None:
        """Fly to ``pos_m`` [m] (``yaw_rad`` there if given, at ``speed_m_s`` [m/s] from
        now on if given)."""
        nav = self.nav
        why = nav.check_target(pos_m) or self._refuse_unless_flying()
        if why is not None:
            return why
        if speed_m_s is not None and speed_m_s > 0 and math.isfinite(speed_m_s):
            nav.speed_override_m_s = float(speed_m_s)
        nav.plan.vel = None
        nav.plan.fly_to(pos_m, yaw_rad)
        return None

    def set_velocity(self, vel_m_s: Vec3, yaw_rad: float | None = None,
                     yaw_rate_rad_s: float | None = None) -> Refusal | None:
        """Fly at ``vel_m_s`` [m/s] until a new target, or a stop after
        ``guided_velocity_timeout_s`` without an update."""
        nav = self.nav
        if not all(math.isfinite(v) for v in vel_m_s):
            return Refusal(Reason.NOT_A_NUMBER, "velocity is not a number")
        why = self._refuse_unless_flying()
        if why is not None:
            return why
        plan = nav.plan
        if plan.vel is None:
            plan.vel = VelocityRef(plan.current_ref(), nav.p.acc_m_s2)
            plan.leg, plan.legs, plan.script = None, [], None
            plan.unpause()
        target = plan.vel
        target.cmd = tuple(float(v) for v in vel_m_s)
        if yaw_rad is not None and math.isfinite(yaw_rad):
            target.yaw = yaw_rad
        target.yaw_rate = yaw_rate_rad_s if (yaw_rate_rad_s is not None
                                             and math.isfinite(yaw_rate_rad_s)) else 0.0
        plan.vel_deadline = nav.time_s + nav.p.guided_velocity_timeout_s
        plan.vel_limited = False
        return None

    def limit_velocity(self) -> None:
        """A velocity target whose stopping point (with margin) leaves the tether's reach
        or goes below the ground loses its outward (downward) part, said once."""
        nav = self.nav
        v = nav.plan.vel
        assert v is not None
        speed = math.sqrt(sum(c * c for c in v.vel))
        margin = 1.5 * speed * speed / (2.0 * nav.p.acc_m_s2) + 0.2
        pos = v.pos
        d = math.sqrt(sum(c * c for c in pos))
        cmd = list(v.cmd)
        cut = False
        if d > 0 and d + margin > nav.reach_m:
            out = sum(cmd[i] * pos[i] for i in range(3)) / d
            if out > 0:
                cmd = [cmd[i] - out * pos[i] / d for i in range(3)]
                cut = True
        if pos[2] - margin < nav.gear_height_m and cmd[2] < 0:
            cmd[2] = 0.0
            cut = True
        if cut:
            v.cmd = (cmd[0], cmd[1], cmd[2])
            if not nav.plan.vel_limited:
                nav.plan.vel_limited = True
                nav._emit(NavEvent.WARNING, Notice(TextKind.VELOCITY_STOPPED,
                                                   "Guided velocity stopped at the reach"))

    def follow(self, source: Callable[[float, Vec3], RefSample]) -> Refusal | None:
        """Fly, at every control period, the reference ``source(t, pos)`` gives for time
        ``t`` [s] with the vehicle at ``pos`` [m] (:meth:`Navigator.follow`)."""
        nav = self.nav
        why = self._refuse_unless_flying()
        if why is not None:
            return why
        nav.plan.leg, nav.plan.legs, nav.plan.vel = None, [], None
        nav.plan.unpause()
        nav.plan.script = source
        nav.plan.script_lag = nav.governor.clock_lag
        nav.governor.reset_clock()
        nav.plan.nominal = None
        return None

    def set_yaw(self, yaw_rad: float) -> Refusal | None:
        """Turn to ``yaw_rad`` [rad] where it is (CONDITION_YAW)."""
        nav = self.nav
        if not math.isfinite(yaw_rad):
            return Refusal(Reason.NOT_A_NUMBER, "yaw is not a number")
        if not nav.flying:
            return Refusal(Reason.NOT_FLYING, "not flying")
        ref = nav.plan.current_ref()
        if nav.plan.vel is not None:
            nav.plan.vel.yaw = yaw_rad
            return None
        target = nav.plan.leg.follower.target_m if nav.plan.leg is not None else None
        nav.plan.fly_to(target if target is not None else ref.pos_m, yaw_rad)
        return None

    def change_speed(self, speed_m_s: float) -> Refusal | None:
        """DO_CHANGE_SPEED: the horizontal speed of planned moves from now on [m/s] (a
        guided target under way is flown again at it)."""
        nav = self.nav
        if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
            return Refusal(Reason.BAD_VALUE, f"bad speed {speed_m_s}")
        nav.speed_override_m_s = min(float(speed_m_s), 20.0)
        leg = nav.plan.leg
        if nav.flying and leg is not None and not leg.landing and leg.tag is LegTag.GOTO:
            target = leg.follower.target_m
            if target is not None:
                nav.plan.fly_to(target, None)
        return None
