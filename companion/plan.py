"""The navigator's plan: what the vehicle flies now (:class:`Plan`: legs, a guided velocity
target or a streamed script), stepped into the reference of each control period and
governed by the tether governor; a leg (one planned movement, why it is flown) and a
guided velocity target (:class:`VelocityRef`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from companion.governor import GOVERNOR_LOOKAHEAD_S, Verdict
from companion.legs import CircleItem, GotoItem, LegFollower
from companion.nav_types import LegTag, NavEvent
from companion.reference import RefSample
from companion.statustext import Notice, TextKind

if TYPE_CHECKING:
    from companion.navigation import Navigator

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)


class Leg:
    """A planned movement: a LegFollower over one item, optionally open-ended."""

    def __init__(self, follower: LegFollower, item: GotoItem | CircleItem,
                 landing: bool = False, seq: int | None = None,
                 tag: LegTag = LegTag.HOLD, takeoff: bool = False) -> None:
        self.follower = follower
        self.item = item
        self.landing = landing
        self.takeoff = takeoff or tag is LegTag.TAKEOFF   # a climb from the ground
        self.seq = seq
        self.tag = tag
        self.finished = False
        self.reported = False      # its reaching has been reported


class VelocityRef:
    """A guided velocity target: the reference velocity approaches the command as a
    critically damped second-order system (so acceleration is continuous), its
    acceleration limited; the position integrates it."""

    def __init__(self, ref: RefSample, acc_max: float, omega: float = 2.5) -> None:
        self.pos = list(ref.pos_m)
        self.vel = list(ref.vel_m_s)
        self.acc = list(ref.acc_m_s2)
        self.yaw = ref.yaw_rad
        self.cmd: Vec3 = _ZERO3
        self.acc_max = acc_max
        self.omega = omega
        self.yaw_rate = 0.0
        #: the tether governor's cap on the commanded speed [m/s] (inf: none)
        self.cap = math.inf

    def step(self, dt: float) -> RefSample:
        w = self.omega
        c = self.cmd
        n = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
        k = self.cap / n if n > self.cap else 1.0
        jerk = [w * w * (c[i] * k - self.vel[i]) - 2.0 * w * self.acc[i] for i in range(3)]
        acc = [self.acc[i] + jerk[i] * dt for i in range(3)]
        n = math.sqrt(sum(a * a for a in acc))
        if n > self.acc_max:
            acc = [a * self.acc_max / n for a in acc]
        for i in range(3):
            self.vel[i] += 0.5 * (self.acc[i] + acc[i]) * dt
            self.pos[i] += self.vel[i] * dt
        self.acc = acc
        self.yaw = wrap(self.yaw + self.yaw_rate * dt)
        return RefSample(tuple(self.pos), tuple(self.vel), tuple(self.acc), tuple(jerk),
                         self.yaw, self.yaw_rate)


class Plan:
    """What the vehicle flies now: queued legs (the first under way), a guided velocity
    target, or a streamed script; stepped into each control period's reference, governed
    by the tether governor (:class:`companion.governor.TetherGovernor`), whose decisions
    (slow a leg's clock, cap a velocity target, brake, resume, move in) it carries out.

    It belongs to its :class:`companion.navigation.Navigator` ``nav``, whose vehicle state
    (time, estimate, its standard deviation), parameters, modes and events it uses.
    """

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav
        self.leg: Leg | None = None
        self.legs: list[Leg] = []
        self.vel: VelocityRef | None = None
        self.script: Callable[[float, Vec3], RefSample] | None = None
        self.vel_deadline = math.inf      # a velocity target stops after this [s]
        self.vel_limited = False          # a velocity target cut at the reach, said
        self.ref: RefSample | None = None  # the last reference produced
        self.paused: list[Leg] = []       # the legs the governor stopped
        # the governor's slowing of legs runs the leg clock behind the vehicle's
        # (governor.clock_lag); ``nominal`` the leg's unscaled sample
        self.script_lag = 0.0             # clock_lag when a script began [s]
        self.nominal: RefSample | None = None

    def clear(self) -> None:
        """Fly nothing (disarmed): no leg, velocity target, script, stop or pause."""
        self.leg, self.legs, self.vel, self.script = None, [], None, None
        self.unpause()

    def advance(self, t: float, dt: float) -> RefSample:
        """The period's reference: the tether governor's stop while it brakes, else the
        plan's (script, velocity target or legs), governed."""
        gov = self.nav.governor
        if gov.brake is not None:
            ref = self.braking(dt)
            if ref is not None:
                return ref
        if not gov.enabled:
            return self.advance_plan(t, dt)
        leg, script = self.leg, self.script
        slow = self.vel is None and (script is not None or (
            leg is not None and not (leg.landing or leg.takeoff)))
        if slow:
            notice = gov.slow_clock(self.nominal, self.nav.position_m, self.nav.velocity_m_s,
                                    self.nav.position_sigma_m, dt)
            if notice is not None:
                self.nav._emit(NavEvent.WARNING, notice)
        elif gov.s != 1.0 or gov.sd != 0.0:
            gov.reset_clock()
        ref = self.advance_plan(t, dt)
        if slow and self.leg is leg and self.script is script:
            self.nominal = ref
            ref = gov.scaled(ref)
        else:
            self.nominal = None
        return self.govern(ref, dt)

    @property
    def leg_clock(self) -> float:
        """The legs' clock [s]: the vehicle's, less what the governor's slowing took."""
        return self.nav.time_s - self.nav.governor.clock_lag

    def leg_velocity_ahead(self) -> Vec3 | None:
        """The velocity [m/s] the current leg's plan has :data:`GOVERNOR_LOOKAHEAD_S` on
        its own clock (None: no leg, or a streamed script, whose future is unknown)."""
        leg = self.leg
        if leg is None or self.script is not None:
            return None
        return leg.follower.trajectory.sample(self.leg_clock + GOVERNOR_LOOKAHEAD_S).vel_m_s

    def govern(self, ref: RefSample, dt: float) -> RefSample:
        """The tether governor, in every mode (:meth:`TetherGovernor.check`): a reference
        whose stopping point would pass its limit brakes now (what it was doing is
        paused: a leg is resumed once the drum has paid out room again, a script or a
        velocity target ends); at rest, a paused leg resumes or the vehicle moves in
        (:meth:`at_rest`)."""
        leg = self.leg
        if leg is not None and (leg.landing or leg.takeoff):
            # the final descent: the ground stops it; the take-off: the winch pays out on
            # its ground pre-tension as the climb pulls (no reported length to keep
            # within until it follows L-bar), and a snag there stops a climb, not a run
            return ref
        nav = self.nav
        decision = nav.governor.check(ref, nav.position_m, nav.velocity_m_s, nav.position_sigma_m)
        if decision.verdict is Verdict.AT_REST:
            return self.at_rest(ref, decision.limit_m)
        if decision.verdict is Verdict.BRAKE:
            return self.start_brake(ref, decision.limit_m, dt)
        return ref

    def start_brake(self, ref: RefSample, lim: float, dt: float) -> RefSample:
        """Brake the reference (:meth:`govern`), pausing what it flew."""
        paused: list[Leg] = []
        if self.script is not None:
            self.nav._emit(NavEvent.ERROR, "script stopped at the tether's reach")
        elif self.vel is not None:
            if not self.vel_limited:
                self.vel_limited = True
                self.nav._emit(NavEvent.WARNING, Notice(TextKind.VELOCITY_STOPPED,
                                                        "Guided velocity stopped at the reach"))
        elif self.leg is not None:
            # a circle resumes with the turns it has left (ArduCopter's circle continues
            # after a pause), not from its first again: a circle braked once a turn would
            # otherwise never end
            self.leg.item = self.leg.follower.remaining_item(self.leg_clock)
            paused = [self.leg, *self.legs]
        self.nav._emit(NavEvent.WARNING, Notice(
            TextKind.TETHER_BRAKING, f"Tether: braking at {lim:.2f} m from the winder"))
        self.script, self.vel, self.leg, self.legs = None, None, None, []
        self.paused = paused
        return self.nav.governor.start_brake(ref, dt)

    def braking(self, dt: float) -> RefSample | None:
        """The governor's stop, stepped; None once at rest (the plan goes on: a hold, a
        move in, or the paused legs)."""
        ref, stopped = self.nav.governor.step_brake(dt)
        if not stopped:
            return ref
        self.ref = ref
        paused = self.paused
        self.queue([Leg(self.follower(self.nav.speed_m_s), GotoItem(ref.pos_m, ref.yaw_rad),
                        tag=LegTag.HOLD)])
        self.paused = paused
        return None

    def at_rest(self, ref: RefSample, lim: float) -> RefSample:
        """A reference at rest: a paused leg resumes when the governor gives room again
        (:meth:`TetherGovernor.may_resume`); beyond the limit of a braked drum, the vehicle
        moves in (:meth:`TetherGovernor.move_in_target`)."""
        p = ref.pos_m
        leg = self.leg
        holding = leg is not None and leg.tag is LegTag.HOLD
        if (self.paused and holding and leg.follower.done
                and self.nav.governor.may_resume(p, self.nav.position_m, lim)):
            paused = self.paused
            self.nav._emit(NavEvent.WARNING, Notice(TextKind.TETHER_RESUMING,
                                                    "Tether: room again, resuming"))
            self.ref = ref
            self.queue(paused)
            return self.leg.follower.update(self.leg_clock, self.nav.position_m)
        target = (self.nav.governor.move_in_target(p, lim)
                  if holding and self.vel is None and self.script is None else None)
        if target is not None and math.dist(target, leg.follower.target_m or p) > 0.05:
            paused = self.paused
            self.nav._emit(NavEvent.WARNING, Notice(
                TextKind.TETHER_MOVING_IN, f"Tether: moving in within the braked {lim:.2f} m"))
            self.queue([Leg(self.follower(self.nav.speed_m_s), GotoItem(target, ref.yaw_rad),
                            tag=LegTag.HOLD)])
            self.paused = paused
        return ref

    def advance_plan(self, t: float, dt: float) -> RefSample:
        """The plan's own reference at ``t`` [s] after ``dt`` [s] (a script's sample, the
        velocity target stepped, or the current leg's sample; a leg that ends begins what
        follows it)."""
        if self.script is not None:
            # on the script's clock: the vehicle's, less what the slowing took since it began
            lag = self.nav.governor.clock_lag - self.script_lag
            ref = self.script(t - lag, self.nav.position_m)
            x, y, z = ref.pos_m
            reach = self.nav.reach_m
            if not (z >= 0.0 and x * x + y * y + z * z <= reach * reach):   # NaN too
                self.nav._emit(NavEvent.ERROR, f"script: {self.nav.check_target(ref.pos_m)}")
                self.hold()
                return self.advance_plan(t, dt)
            return ref
        if self.vel is not None:
            if t > self.vel_deadline:
                self.vel.cmd = _ZERO3
            self.nav.guided_mode.limit_velocity()
            if self.nav.governor.enabled:
                self.slow_velocity()
            return self.vel.step(dt)
        if self.leg is None:
            self.hold()
        leg = self.leg
        assert leg is not None
        follower = leg.follower
        ref = follower.update(self.leg_clock, self.nav.position_m)
        if follower.reached_t_s is not None and not leg.reported:
            leg.reported = True
            if leg.seq is not None and leg.tag is LegTag.MISSION:
                self.nav._emit(NavEvent.REACHED, leg.seq)
        if follower.done and not leg.landing and not leg.finished:
            leg.finished = True
            self.leg_done(leg)
        return ref

    def slow_velocity(self) -> None:
        """The tether governor's cap on a velocity target's speed
        (:meth:`TetherGovernor.velocity_cap`)."""
        v = self.vel
        assert v is not None
        v.cap, notice = self.nav.governor.velocity_cap(v.cmd, v.pos, self.nav.position_m,
                                                       self.nav.position_sigma_m)
        if notice is not None:
            self.nav._emit(NavEvent.WARNING, notice)

    def leg_done(self, leg: Leg) -> None:
        """A leg has ended: the next queued one, the landing after the way home or a
        landing's approach, the mission's next item, or a hold where it ended."""
        if leg.tag is LegTag.TAKEOFF:
            self.nav._emit(NavEvent.TAKEOFF_DONE)
        if self.legs:
            self.leg = self.legs.pop(0)
            self.start_leg(self.leg)
            return
        if leg.tag in (LegTag.RTL_HOME, LegTag.LAND_APPROACH):
            item = leg.item
            self.queue(self.nav.land_mode.legs((item.pos_m[0], item.pos_m[1]), leg.seq))
        elif leg.tag is LegTag.MISSION and self.nav.mission_running:
            self.nav.auto_mode.next_item()
        # otherwise the finished leg's reference rests at its target: a hold

    def current_ref(self) -> RefSample:
        """The last reference, or (none yet) the vehicle at rest where it is."""
        if self.ref is None:
            return RefSample(self.nav.position_m, _ZERO3, _ZERO3, _ZERO3, self.nav.yaw_rad, 0.0)
        return self.ref

    def follower(self, speed: float, accept: float | None = None, hold_s: float = 0.0
                 ) -> LegFollower:
        """A leg's follower at ``speed`` [m/s], reached within ``accept`` [m] (None: the
        acceptance radius), held ``hold_s`` [s] there."""
        p = self.nav.p
        return LegFollower(speed, p.acc_m_s2,
                           accept if accept is not None else p.acceptance_radius_m, hold_s)

    def start_leg(self, leg: Leg) -> None:
        """Begin ``leg`` from the current reference, its clock at the rate the governor's
        room allows."""
        ref = self.current_ref()
        leg.follower.start(self.leg_clock, ref.pos_m, ref.vel_m_s, leg.item,
                           current_yaw=ref.yaw_rad, current_acc=ref.acc_m_s2)
        self.leg = leg
        self.nav.governor.reset_clock()
        self.nominal = None
        v = ref.vel_m_s
        if (self.nav.governor.enabled and not (leg.landing or leg.takeoff)
                and v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < 1e-6):
            # a leg from rest starts on its clock at the rate the room allows (the
            # reference, at rest, is unchanged by it): from 1, the clock's slowing could
            # not follow the leg's first acceleration near the vertical, and the brake
            # stopped it at once (resumed, it began again: the chatter)
            self.nav.governor.s = self.nav.governor.slow_rate(
                leg.follower.trajectory.sample(self.leg_clock), 1.0,
                self.leg_velocity_ahead(), self.nav.position_m, self.nav.velocity_m_s,
                self.nav.position_sigma_m)[0]

    def queue(self, legs: list[Leg]) -> None:
        """Fly these legs in order, the first from the current reference (what the tether
        governor stopped is forgotten)."""
        self.script = None
        self.unpause()
        self.legs = legs[1:]
        self.start_leg(legs[0])

    def unpause(self) -> None:
        """Forget the governor's stop and what it paused."""
        self.nav.governor.brake, self.paused = None, []

    def hold(self) -> None:
        """Hold at the reference's stopping point."""
        ref = self.current_ref()
        self.vel = None
        self.queue([Leg(self.follower(self.nav.speed_m_s),
                        GotoItem(stop_point(ref, self.nav.p.acc_m_s2), ref.yaw_rad),
                        tag=LegTag.HOLD)])

    def fly_to(self, pos: Vec3, yaw: float | None) -> None:
        """Fly to ``pos`` [m] (turning to ``yaw`` [rad] if given) and hold there."""
        self.queue([Leg(self.follower(self.nav.speed_m_s), GotoItem(tuple(pos), yaw),
                        tag=LegTag.GOTO)])


def stop_point(ref: RefSample, acc: float) -> Vec3:
    """Where the reference comes to rest braking at ``acc`` [m/s^2] (ArduCopter's stopping
    point), so a hold begins without a jerk back."""
    v = ref.vel_m_s
    speed = math.sqrt(sum(x * x for x in v))
    if speed < 1e-6:
        return ref.pos_m
    d = speed * speed / (2.0 * acc)
    return tuple(ref.pos_m[i] + v[i] / speed * d for i in range(3))  # type: ignore


def wrap(a: float) -> float:
    """The angle ``a`` [rad] in [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi
