"""The vehicle's flight logic: arming, flight modes, take-off, landing, return, guided
targets and missions, as ArduCopter behaves; independent of MAVLink.

:class:`Navigator` turns what ground stations ask for into the reference the
:class:`companion.flight_controller.FlightController` tracks, at every control period, in
simulated time and the inertial z-up frame. The MAVLink layer (``companion/autopilot.py``)
translates messages into its calls and reports its events (:meth:`Navigator.pop_events`).

It is a dispatcher over rooms of one concern each:

- the vocabulary (modes, parameters, mission steps, events, refusals):
  :mod:`companion.nav_types`;
- the plans a reference comes from (a leg, a velocity target): :mod:`companion.plan`;
- the flight modes, one room each as ArduCopter's ``mode_*.cpp``: :mod:`companion.modes`
  (hold, GUIDED, AUTO, RTL, LAND);
- the tether governor, in every mode: :mod:`companion.governor`, whose decisions (slow a
  leg's clock, cap a velocity target, brake, resume, move in) this carries out on the plan.

What ArduCopter does and this follows:

- Disarmed: rotors stopped. Armed on the ground: rotors idle until a take-off; disarmed
  again after ``disarm_delay_s`` without one.
- Take-off (GUIDED ``NAV_TAKEOFF``, or the mission's take-off item) climbs straight up at
  ``speed_up_m_s`` to the altitude asked for.
- LAND descends where it is: at ``speed_down_m_s`` to ``land_alt_low_m``, then at
  ``land_speed_m_s``; the land detector (on the gear, or pushed ``land_stall_m`` below
  its reference, still, for ``land_detect_s``)
  disarms. RTL climbs to ``rtl_alt_m`` if lower, flies back above its launch point (home),
  and lands there, while the ground winds the tether in (the winder follows L-bar).
- LOITER, BRAKE, POSHOLD, ALT_HOLD and STABILIZE hold the position where they begin
  (there is no pilot stick input here); GUIDED flies to each new target; AUTO flies the
  mission.
- Missions: take-off, waypoints (hold time, acceptance radius), loiter-turns circles (the
  paper's circle), land, return to launch, change of speed; an item whose horizontal
  position is unset (latitude = longitude = 0) is flown from where the vehicle is.

Targets are checked against the tether (``reach_m``) and the ground before anything is
flown: :meth:`Navigator.check_target` says why one is refused.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

from companion.governor import TetherGovernor
from companion.legs import GotoItem
from companion.modes.auto import Auto
from companion.modes.guided import Guided
from companion.modes.hold import Hold
from companion.modes.land import Land
from companion.modes.rtl import RTL_ALT_MIN_M, RTL_CONE_SLOPE, Rtl
from companion.nav_types import (
    AIRBORNE_MARGIN_M,
    AIRBORNE_SIGMAS,
    ARMABLE_MODES,
    HOLD_MODES,
    NAV_MOVES,
    SUPPORTED_MODES,
    FlightMode,
    LegTag,
    MotorState,
    NavCommand,
    NavEvent,
    NavigationParams,
    NavKind,
    Reason,
    Refusal,
    air_start_threshold_m,
    air_start_too_low_m,
)
from companion.plan import Leg, Plan
from companion.reference import RefSample
from companion.statustext import Notice, TextKind, TextRateLimit
from tuavdefs.frames import quat_to_yaw

#: what importers of the navigator's vocabulary find here as before
__all__ = [
    "AIRBORNE_MARGIN_M", "AIRBORNE_SIGMAS", "ARMABLE_MODES", "HOLD_MODES", "NAV_MOVES",
    "RTL_ALT_MIN_M", "RTL_CONE_SLOPE", "SUPPORTED_MODES", "FlightMode", "LegTag",
    "MotorState", "NavCommand", "NavEvent", "NavKind", "NavigationParams", "Navigator",
    "Reason", "Refusal", "air_start_threshold_m", "air_start_too_low_m",
]

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)


class Navigator:
    """Modes, arming and the reference, stepped at every control period.

    ``gear_height_m`` is the height of the centre of mass when the vehicle rests on its
    gear; ``tether_length_m`` the length on the full drum (reach check). What happens is
    queued for :meth:`pop_events`.
    """

    def __init__(self, params: NavigationParams, gear_height_m: float,
                 tether_length_m: float) -> None:
        #: the tether governor (companion/governor.py): the winch's reports, the slowing
        #: of legs and velocity targets, the brake
        self.governor = TetherGovernor(params, tether_length_m, gear_height_m)
        self.p = params
        self.gear_height_m = gear_height_m
        self.tether_length_m = tether_length_m
        self.mode = FlightMode.STABILIZE
        self.armed = False
        self.landed = True
        self.home_m: Vec3 | None = None
        """Launch point [m] (set at arming on the ground, or at the first state)."""
        #: Rally points [m] (uploaded as the rally mission type): RTL may end at one.
        self.rally_m: tuple[Vec3, ...] = ()
        self.mission: list[NavCommand] = []
        self.mission_index = 0
        """Index into :attr:`mission` of the current item."""
        self.mission_running = False
        self._events: list[tuple[NavEvent, object]] = []
        #: what the vehicle flies now (legs, a velocity target or a script), governed
        self.plan = Plan(self)
        self._t = 0.0
        self._armed_on_ground_since: float | None = None
        #: the speed of planned moves set by DO_CHANGE_SPEED or a guided target [m/s]
        #: (None: ``speed_m_s``'s)
        self.speed_override_m_s: float | None = None
        #: The vehicle's position [m] and velocity [m/s] at the last step (its estimate).
        self.position_m: Vec3 = _ZERO3
        self.velocity_m_s: Vec3 = _ZERO3
        self._quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
        #: The estimate's position standard deviation [m] (largest axis; 0 on the
        #: truth), which the tether governor keeps as margin (set by the onboard step).
        self.position_sigma_m = 0.0
        #: the pre-arm checks of the rest of the vehicle (the estimator's), or None
        self.prearm: Callable[[], Refusal | None] | None = None
        #: the rate limit of repeating texts (the navigator's events and the autopilot's
        #: STATUSTEXTs of a kind), in simulated time
        self.texts = TextRateLimit()
        #: the modes' rooms (companion/modes/), which this dispatches to
        self.guided_mode = Guided(self)
        self.auto_mode = Auto(self)
        self.rtl_mode = Rtl(self)
        self.land_mode = Land(self)
        hold = Hold(self)
        self._modes: dict[FlightMode, Hold | Auto | Rtl | Land] = {
            m: hold for m in SUPPORTED_MODES}
        self._modes.update({FlightMode.AUTO: self.auto_mode, FlightMode.RTL: self.rtl_mode,
                            FlightMode.LAND: self.land_mode})

    def reboot(self) -> None:
        """Back to the power-on state (disarmed, STABILIZE, on the ground, no home, no
        reference), keeping what a reboot keeps: the parameters and the stored mission (and
        the pre-arm check it is wired to)."""
        mission, prearm = self.mission, self.prearm
        self.__init__(self.p, self.gear_height_m, self.tether_length_m)
        self.mission, self.prearm = mission, prearm

    # ----- state

    @property
    def p(self) -> NavigationParams:
        """The parameters (the tether governor reads the same)."""
        return self._p

    @p.setter
    def p(self, params: NavigationParams) -> None:
        self._p = params
        self.governor.p = params
        self._reach_m: float | None = None     # reach_m, or stale

    @property
    def _yaw(self) -> float:
        """The vehicle's heading now [rad] (from its attitude quaternion, when needed)."""
        return quat_to_yaw(self._quat)

    @property
    def yaw_rad(self) -> float:
        """The vehicle's heading at the last step [rad]."""
        return self._yaw

    @property
    def flying(self) -> bool:
        """Armed and off the ground."""
        return self.armed and not self.landed

    @property
    def reach_m(self) -> float:
        """Largest straight-line distance [m] from the winder a target may have: of the
        whole tether, or of the length paid out while the winch's drum is braked
        (LOCK, HOLD, a lost winder: it pays out no more)."""
        reach = self._reach_m
        if reach is None:   # made again after new parameters or a report of the winch
            p = self._p
            reach = self._reach_m = (p.reach_fraction * self.governor.reach_length_m
                                     - p.reach_slack_m)
        return reach

    @property
    def tether_limit_m(self) -> float:
        """Distance [m] from the winder beyond which the tether would be near taut (the
        always-on fence's): the whole tether, or the length a braked drum has paid out,
        less ``reach_slack_m``. Targets keep the margin of :attr:`reach_m` inside it."""
        return max(self.governor.reach_length_m - self.p.reach_slack_m, 0.0)

    def winch_report(self, length_m: float, tension_n: float | None,
                     braked: bool, speed_m_s: float | None = None) -> None:
        """The winch's report: paid-out length [m], drum tension [N] (None: unknown),
        whether its drum is braked, its line speed [m/s] (None: unchanged). A braked drum
        bounds the reach; the length bounds the tether governor's stopping point (the drum
        may stop at any moment); a tension above ``tension_limit_n`` in every report for
        ``tension_time_s`` moves the vehicle towards the winder, ``tension_step_m`` at a
        time (again every 2 s while it lasts), in GUIDED."""
        self.governor.report(length_m, braked, speed_m_s)
        self._reach_m = None
        target = self.governor.over_tension(
            self._t, tension_n,
            # in flight, and not on the way in already
            self.flying and self.mode not in (FlightMode.RTL, FlightMode.LAND),
            self.plan.current_ref().pos_m)
        if target is None:
            return
        self._emit(NavEvent.FAILSAFE, Notice(
            TextKind.OVER_TENSION, f"Tether over-tension ({tension_n:.0f} N > "
            f"{self.p.tension_limit_n:.0f} N): moving towards the winder"))
        self.mode = FlightMode.GUIDED
        self.mission_running = False
        self.plan.vel = None
        self.plan.fly_to(target, None)

    @property
    def speed_m_s(self) -> float:
        """Horizontal speed of planned moves now [m/s] (DO_CHANGE_SPEED overrides)."""
        override = self.speed_override_m_s
        return override if override is not None else self.p.speed_m_s

    @property
    def landing(self) -> bool:
        """A landing descent is under way."""
        return self.plan.leg is not None and self.plan.leg.landing

    @property
    def current_seq(self) -> int:
        """MAVLink sequence number of the current mission item (0 when none)."""
        if 0 <= self.mission_index < len(self.mission):
            return self.mission[self.mission_index].seq
        return 0

    @property
    def target_m(self) -> Vec3 | None:
        """Where the current leg goes [m] (a circle: its centre at its altitude); None
        without one."""
        leg = self.plan.leg
        if leg is None:
            return None
        item = leg.item
        if isinstance(item, GotoItem):
            return item.pos_m
        return (item.centre_xy_m[0], item.centre_xy_m[1], item.altitude_m)

    def reference(self) -> RefSample | None:
        """The last reference produced (None before the first flying step)."""
        return self.plan.ref

    @property
    def has_events(self) -> bool:
        """Whether :meth:`pop_events` has events to hand out."""
        return bool(self._events)

    def pop_events(self) -> list[tuple[NavEvent, object]]:
        """(kind, value) events since the last call."""
        out, self._events = self._events, []
        return out

    def notice(self, text: str) -> None:
        """A message of the onboard software for ground stations (a STATUSTEXT warning:
        the event WARNING)."""
        self._emit(NavEvent.WARNING, text)

    @property
    def time_s(self) -> float:
        """The time of the last step [s] (simulated)."""
        return self._t

    def _emit(self, kind: NavEvent, value: object = None) -> None:
        """Report an event; a :class:`Notice` (a repeating text) only if its kind has not
        been said within :data:`companion.statustext.TEXT_KIND_INTERVAL_S`."""
        if isinstance(value, Notice) and not self.texts.allow(value.kind, self._t):
            return
        self._events.append((kind, value))

    # ----- checks

    def check_target(self, pos_m: Iterable[float]) -> Refusal | None:
        """Why ``pos_m`` [m] cannot be flown to, or None if it can."""
        p = tuple(float(v) for v in pos_m)
        if len(p) != 3 or not all(math.isfinite(v) for v in p):
            return Refusal(Reason.NOT_A_NUMBER, "target is not a number")
        if p[2] < 0.0:
            return Refusal(Reason.BELOW_GROUND, f"target {p[2]:.1f} m below the ground")
        d = math.sqrt(p[0] ** 2 + p[1] ** 2 + p[2] ** 2)
        if d > self.reach_m:
            return Refusal(Reason.BEYOND_REACH,
                           f"beyond tether reach ({d:.1f} > {self.reach_m:.1f} m)")
        return None

    # ----- commands (return None when done, else the reason it was refused)

    def start(self, t: float, pos: Vec3, vel: Vec3, quat: tuple[float, ...],
              airborne: bool | None = None) -> None:
        """Initialise from the first state: on the ground (disarmed) or in the air (armed,
        GUIDED, holding where it is, as when a simulation starts airborne). ``airborne``
        says which (the onboard step's decision, which knows the state's accuracy); None:
        in the air above :func:`air_start_threshold_m` of an exact state."""
        self._t, self.position_m, self.velocity_m_s, self._quat = t, pos, vel, quat
        yaw = self._yaw
        self.landed = (not airborne if airborne is not None
                       else pos[2] <= air_start_threshold_m(self.gear_height_m))
        self.home_m = (pos[0], pos[1], self.gear_height_m)
        if not self.landed:
            self.armed = True
            self.mode = FlightMode.GUIDED
            self.plan.ref = RefSample(pos, _ZERO3, _ZERO3, _ZERO3, yaw, 0.0)
            self.plan.hold()

    def arm(self, force: bool = False) -> Refusal | None:
        """Arm (ArduCopter's checks: an armable mode; with force, any)."""
        if self.armed:
            return None
        if not force and self.prearm is not None:
            why = self.prearm()
            if why is not None:
                return why
        if not force and self.mode not in ARMABLE_MODES:
            return Refusal(Reason.MODE_NOT_ARMABLE, f"Arm: Mode not armable ({self.mode.name})")
        if not force and self.mode == FlightMode.AUTO and not self.auto_mode.has_items():
            return Refusal(Reason.MISSION_EMPTY, "Arm: mission is empty")
        self.armed = True
        if self.landed:
            self.home_m = self.position_m
            self._armed_on_ground_since = self._t
            if self.mode == FlightMode.AUTO:
                self.auto_mode.takeoff_pending = True
        return None

    def disarm(self, force: bool = False) -> Refusal | None:
        """Disarm; in flight only with force (the rotors stop and it falls)."""
        if not self.armed:
            return None
        if self.flying and not force:
            return Refusal(Reason.FLYING, "Disarm: vehicle is flying (use force)")
        self._disarm()
        return None

    def _disarm(self) -> None:
        self.armed = False
        self.plan.clear()
        self.mission_running = False
        self._armed_on_ground_since = None
        self.auto_mode.takeoff_pending = False
        self._emit(NavEvent.DISARMED)

    def set_mode(self, mode: int) -> Refusal | None:
        """Change the flight mode."""
        try:
            m = FlightMode(int(mode))
        except ValueError:
            return Refusal(Reason.UNKNOWN_MODE, f"unknown mode {mode}")
        if m not in SUPPORTED_MODES:
            return Refusal(Reason.UNSUPPORTED_MODE, f"mode {m.name} not supported")
        if m == FlightMode.AUTO:
            why = self.auto_mode.refuse()
            if why is not None:
                return why
        self.mode = m
        self.plan.vel = None
        self._modes[m].enter()
        return None

    def failsafe_land(self, text: str) -> None:
        """A failsafe's action: LAND where it is (ArduCopter's FS_EKF_ACTION 1), said as a
        NavEvent.FAILSAFE."""
        self.failsafe(FlightMode.LAND, text)

    def failsafe(self, mode: FlightMode, text: str) -> None:
        """A failsafe's action: ``mode`` (RTL or LAND; a vehicle already landing keeps
        landing), said as a NavEvent.FAILSAFE."""
        self._emit(NavEvent.FAILSAFE, text)
        if self.mode != FlightMode.LAND and self.mode != mode and not self.landing:
            self.set_mode(mode)

    def takeoff(self, alt_m: float) -> Refusal | None:
        """GUIDED take-off to ``alt_m`` [m above the ground]."""
        return self.guided_mode.takeoff(alt_m)

    def goto(self, pos_m: Vec3, yaw_rad: float | None = None,
             speed_m_s: float | None = None) -> Refusal | None:
        """GUIDED: fly to ``pos_m`` [m] (``yaw_rad`` there if given)."""
        return self.guided_mode.goto(pos_m, yaw_rad, speed_m_s)

    def set_velocity(self, vel_m_s: Vec3, yaw_rad: float | None = None,
                     yaw_rate_rad_s: float | None = None) -> Refusal | None:
        """GUIDED: fly at ``vel_m_s`` [m/s] until a new target, or a stop after
        ``guided_velocity_timeout_s`` without an update."""
        return self.guided_mode.set_velocity(vel_m_s, yaw_rad, yaw_rate_rad_s)

    def follow(self, source: Callable[[float, Vec3], RefSample]) -> Refusal | None:
        """GUIDED: fly, at every control period, the reference ``source(t, pos)`` gives
        for time ``t`` [s] with the vehicle at ``pos`` [m]: position, velocity,
        acceleration and yaw together, as a script streaming full set-points at the control
        rate does (ArduCopter's GUIDED with position, velocity and acceleration targets).
        Any other command or mode ends it; a sample beyond the tether's reach or below the
        ground ends it with a hold (a NavEvent.ERROR)."""
        return self.guided_mode.follow(source)

    def set_yaw(self, yaw_rad: float) -> Refusal | None:
        """Turn to ``yaw_rad`` [rad] where it is (CONDITION_YAW)."""
        return self.guided_mode.set_yaw(yaw_rad)

    def change_speed(self, speed_m_s: float) -> Refusal | None:
        """DO_CHANGE_SPEED: the horizontal speed of planned moves from now on [m/s]."""
        return self.guided_mode.change_speed(speed_m_s)

    def set_mission(self, commands: list[NavCommand]) -> None:
        """A new mission (items from seq 1 on); the current item returns to the first."""
        self.auto_mode.set_mission(commands)

    def set_current(self, seq: int) -> Refusal | None:
        """MISSION_SET_CURRENT: fly item ``seq`` next."""
        return self.auto_mode.set_current(seq)

    def start_mission(self, first_seq: int = 0) -> Refusal | None:
        """MISSION_START: AUTO, from ``first_seq`` (0: from the start)."""
        return self.auto_mode.start_mission(first_seq)

    # ----- stepping

    def step(self, t: float, pos: Vec3, vel: Vec3, quat: tuple[float, ...], dt: float
             ) -> tuple[RefSample | None, MotorState]:
        """Advance to ``t`` [s] with the vehicle at ``pos`` [m], ``vel`` [m/s], attitude
        ``quat`` (body to inertial, w x y z). Returns (the reference, or None when not
        flying, and the motors' state)."""
        self._t, self.position_m, self.velocity_m_s, self._quat = t, pos, vel, quat
        if not self.armed:
            self.plan.ref = None
            if not self.landed and pos[2] <= self.gear_height_m + 0.05:
                self.landed = True
            return None, MotorState.OFF
        if self.landed:
            self.auto_mode.start_pending()
            if self.landed:
                since = self._armed_on_ground_since
                if since is None:
                    self._armed_on_ground_since = since = t
                if self.p.disarm_delay_s > 0 and t - since >= self.p.disarm_delay_s:
                    self._disarm()
                    return None, MotorState.OFF
                return None, MotorState.IDLE
        self._armed_on_ground_since = None
        try:
            ref = self.plan.advance(t, dt)
        except ValueError as exc:
            # a plan the limits cannot fly (e.g. limits changed mid-mission): hold instead
            self._emit(NavEvent.ERROR, str(exc))
            self.mission_running = False
            self.plan.leg, self.plan.legs, self.plan.vel = None, [], None
            self.plan.hold()
            ref = self.plan.leg.follower.update(self.plan.leg_clock, self.position_m)
        self.plan.ref = ref
        self.land_mode.detect(t, pos, vel)
        if not self.armed:
            return None, MotorState.OFF
        return ref, MotorState.FLY

    def begin_takeoff(self, target: Vec3, seq: int | None = None) -> None:
        """Climb from the ground to ``target`` [m] (for mission item ``seq``)."""
        self.landed = False
        self._armed_on_ground_since = None
        self.plan.ref = RefSample(self.position_m, _ZERO3, _ZERO3, _ZERO3, self._yaw, 0.0)
        tag = LegTag.MISSION if seq is not None else LegTag.TAKEOFF
        self.plan.queue([Leg(self.plan.follower(self.p.speed_up_m_s, self.p.takeoff_accept_m),
                             GotoItem(target, None), seq=seq, tag=tag, takeoff=True)])

    def rtl_destination(self, stop: Vec3) -> Vec3:
        """Where RTL goes from ``stop`` [m] (:meth:`companion.modes.rtl.Rtl.destination`)."""
        return self.rtl_mode.destination(stop)

    def rtl_altitude_m(self, stop: Vec3, home: Vec3) -> float:
        """The height [m] RTL returns at from ``stop`` [m] to ``home`` [m]
        (:meth:`companion.modes.rtl.Rtl.altitude_m`)."""
        return self.rtl_mode.altitude_m(stop, home)

