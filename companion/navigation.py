"""The vehicle's flight logic: arming, flight modes, take-off, landing, return, guided
targets and missions, as ArduCopter behaves; independent of MAVLink.

:class:`Navigator` turns what ground stations ask for into the reference the
:class:`companion.flight_controller.FlightController` tracks, at every control period, in
simulated time and the inertial z-up frame. The MAVLink layer (``companion/autopilot.py``)
translates messages into its calls and reports its events.

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
from dataclasses import dataclass
from enum import Enum, IntEnum

from companion.governor import GOVERNOR_LOOKAHEAD_S, TetherGovernor, Verdict, towards_winder
from companion.legs import CircleItem, GotoItem, LegFollower
from companion.reference import Circle, RefSample
from companion.statustext import Notice, TextKind, TextRateLimit
from tuavdefs.frames import quat_to_yaw
from tuavdefs.paramspec import Params, quantity

Vec3 = tuple[float, float, float]
_ZERO3: Vec3 = (0.0, 0.0, 0.0)


class FlightMode(IntEnum):
    """ArduCopter's custom mode numbers (HEARTBEAT.custom_mode)."""

    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    AVOID_ADSB = 19
    GUIDED_NOGPS = 20
    SMART_RTL = 21
    FLOWHOLD = 22
    FOLLOW = 23
    ZIGZAG = 24
    SYSTEMID = 25
    AUTOROTATE = 26
    AUTO_RTL = 27


#: Modes this vehicle flies; the others are refused.
SUPPORTED_MODES = frozenset({FlightMode.STABILIZE, FlightMode.ALT_HOLD, FlightMode.AUTO,
                             FlightMode.GUIDED, FlightMode.LOITER, FlightMode.RTL,
                             FlightMode.LAND, FlightMode.POSHOLD, FlightMode.BRAKE})
#: Modes that hold where they begin (no pilot input in a simulation).
HOLD_MODES = frozenset({FlightMode.STABILIZE, FlightMode.ALT_HOLD, FlightMode.LOITER,
                        FlightMode.POSHOLD, FlightMode.BRAKE})
#: Modes in which the vehicle may be armed (ArduCopter refuses RTL and LAND).
ARMABLE_MODES = frozenset({FlightMode.STABILIZE, FlightMode.ALT_HOLD, FlightMode.AUTO,
                           FlightMode.GUIDED, FlightMode.LOITER, FlightMode.POSHOLD})


@dataclass(frozen=True)
class NavigationParams(Params):
    """Speeds, altitudes and limits of the vehicle's flight logic (ground stations change
    them through the parameter protocol)."""

    speed_m_s: float = quantity(2.0, "m/s", "horizontal speed of waypoint and guided moves",
                                gt=0, le=20)
    speed_up_m_s: float = quantity(1.5, "m/s", "climb speed (take-off, RTL climb)", gt=0,
                                   le=10)
    speed_down_m_s: float = quantity(1.0, "m/s", "descent speed above land_alt_low_m", gt=0,
                                     le=10)
    acc_m_s2: float = quantity(1.5, "m/s^2", "acceleration limit of planned moves", gt=0,
                               le=10)
    land_speed_m_s: float = quantity(0.5, "m/s", "final descent speed", gt=0, le=5)
    land_alt_low_m: float = quantity(5.0, "m", "height below which LAND slows to "
                                     "land_speed_m_s", ge=0)
    rtl_alt_m: float = quantity(10.0, "m", "lowest altitude RTL returns at", ge=0)
    rtl_loiter_s: float = quantity(2.0, "s", "pause above home before RTL descends", ge=0)
    acceptance_radius_m: float = quantity(0.5, "m", "a waypoint is reached within this",
                                          gt=0)
    takeoff_accept_m: float = quantity(0.3, "m", "take-off is done within this of its "
                                       "altitude", gt=0)
    disarm_delay_s: float = quantity(10.0, "s", "armed on the ground this long without a "
                                     "take-off: disarm (0: never)", ge=0)
    land_detect_s: float = quantity(1.0, "s", "on the gear and still this long: landed",
                                    gt=0)
    land_stall_m: float = quantity(
        0.5, "m", "the land detector also takes a final descent whose reference has gone "
        "this far below the vehicle while it stays still (ArduCopter's: pushed down, not "
        "moving: on the ground, whatever the height estimate says)", gt=0)
    reach_fraction: float = quantity(0.95, "1", "share of the tether a target may need "
                                     "(straight-line distance + slack)", gt=0, le=1)
    reach_slack_m: float = quantity(0.5, "m", "slack added to a target's distance in the "
                                    "reach check (L-bar exceeds it by under 4 %)", ge=0)
    guided_velocity_timeout_s: float = quantity(3.0, "s", "a guided velocity target stops "
                                                "after this without an update "
                                                "(ArduCopter's GUID_TIMEOUT range)",
                                                ge=0.1, le=5.0)
    tension_limit_n: float = quantity(30.0, "N", "tether tension the winch reports above "
                                      "which the vehicle moves towards the winder", gt=0)
    tension_step_m: float = quantity(2.0, "m", "how far towards the winder each over-"
                                     "tension move goes", gt=0, le=10)
    tension_time_s: float = quantity(0.5, "s", "how long every winch report must say the "
                                     "tension is above the limit before the vehicle moves "
                                     "(a snap of the line is not an over-tension)",
                                     ge=0, le=10)
    tether_governor: int = quantity(1, "", "the tether governor (docs/control.md §3): 1 on "
                                    "(the default, with the winder's stop lead; near the "
                                    "vertical it slows moves to 0.3-1.4 m/s), 0 off",
                                    ge=0, le=1)
    tether_brake_acc_m_s2: float = quantity(
        3.0, "m/s^2", "tether governor: the deceleration it brakes at (reached at "
        "TETHER_BRAKE_JERK_M_S3) and assumes of the vehicle", gt=0, le=10)
    tether_latency_s: float = quantity(
        0.3, "s", "tether governor: how long the vehicle goes on at its speed before it "
        "follows a braking reference (its tracking lag)", ge=0, le=2)
    tether_margin_m: float = quantity(
        0.03, "m", "tether governor: length the stopping point keeps short of the last "
        "reported tether length", ge=0, le=1)
    tether_sigma_k: float = quantity(
        2.0, "1", "tether governor: multiples of the estimate's horizontal position "
        "standard deviation added to the margin", ge=0, le=5)


# ----- mission commands (the autopilot converts MAVLink items into these)

class NavKind(Enum):
    """What a mission step does (the MAV_CMD it comes from)."""

    TAKEOFF = "takeoff"              # NAV_TAKEOFF
    WAYPOINT = "waypoint"            # NAV_WAYPOINT, NAV_LOITER_TIME
    LOITER_TURNS = "loiter_turns"    # NAV_LOITER_TURNS
    LAND = "land"                    # NAV_LAND
    RTL = "rtl"                      # NAV_RETURN_TO_LAUNCH
    SPEED = "speed"                  # DO_CHANGE_SPEED
    WINCH = "winch"                  # DO_WINCH: handed to the winch as the item begins


#: Steps that move the vehicle (a mission of none has nothing to fly).
NAV_MOVES = frozenset({NavKind.TAKEOFF, NavKind.WAYPOINT, NavKind.LOITER_TURNS,
                       NavKind.LAND, NavKind.RTL})


@dataclass(frozen=True)
class NavCommand:
    """One mission step, inertial z-up frame.

    ``xy_m`` None means "where the vehicle is when the step begins".
    """

    seq: int
    kind: NavKind
    xy_m: tuple[float, float] | None = None
    z_m: float | None = None
    hold_s: float = 0.0
    accept_m: float | None = None
    turns: float = 1.0
    circle_radius_m: float = 0.0
    clockwise: bool = True
    speed_m_s: float | None = None
    winch: tuple[float, float, float, float] | None = None
    """DO_WINCH's (instance, action, length [m], rate [m/s]), as MAV_CMD_DO_WINCH's param1-4."""


class NavEvent(Enum):
    """Event kinds the navigator reports (:meth:`Navigator.pop_events`) and their value."""

    CURRENT = "current"          # a mission item became current (seq)
    REACHED = "reached"          # a mission item was reached (seq)
    MISSION_DONE = "mission_done"
    TAKEOFF_DONE = "takeoff_done"
    LANDED = "landed"            # (the landing item's seq, or None)
    DISARMED = "disarmed"
    ERROR = "error"              # a plan could not be flown; holding instead (text)
    WINCH = "winch"              # a DO_WINCH item began: (seq, (instance, action, length,
                                 # rate)) for the winch
    FAILSAFE = "failsafe"        # a failsafe took over (text)
    WARNING = "warning"          # a command was cut back to what is safe (text)


class MotorState(Enum):
    """What the rotors do this period."""

    OFF = "off"                  # disarmed: stopped
    IDLE = "idle"                # armed on the ground: idling
    FLY = "fly"                  # flying the reference


class LegTag(Enum):
    """Why a leg is flown (what happens when it ends)."""

    HOLD = "hold"
    GOTO = "goto"                # a guided target
    TAKEOFF = "takeoff"          # a guided take-off
    MISSION = "mission"          # a mission item
    LAND_APPROACH = "land_approach"   # to above a mission landing's point
    LAND_HIGH = "land_high"      # the descent to land_alt_low_m
    LAND = "land"                # the final descent
    RTL_CLIMB = "rtl_climb"
    RTL_HOME = "rtl_home"


class Reason(Enum):
    """Why the navigator refused a command."""

    NOT_A_NUMBER = "not a number"
    BELOW_GROUND = "below the ground"
    BEYOND_REACH = "beyond the tether's reach"
    MODE_NOT_ARMABLE = "mode not armable"
    MISSION_EMPTY = "mission empty"
    MISSING_TAKEOFF = "mission does not start with a take-off"
    FLYING = "flying"
    NOT_FLYING = "not flying"
    UNKNOWN_MODE = "unknown mode"
    UNSUPPORTED_MODE = "mode not supported"
    WRONG_MODE = "not in the mode the command needs"
    NOT_ARMED = "not armed"
    BAD_VALUE = "bad value"
    NO_SUCH_ITEM = "no such mission item"
    PREARM = "a pre-arm check failed"


@dataclass(frozen=True)
class Refusal:
    """A refused command: the reason (for logic) and the text (for STATUSTEXT)."""

    reason: Reason
    text: str

    def __str__(self) -> str:
        return self.text


# ----- legs: one planned movement each

class _Leg:
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


class _VelocityRef:
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
        self.yaw = _wrap(self.yaw + self.yaw_rate * dt)
        return RefSample(tuple(self.pos), tuple(self.vel), tuple(self.acc), tuple(jerk),
                         self.yaw, self.yaw_rate)




#: A vehicle whose first state (or, on its estimate, first GNSS fix) puts it more than
#: this above its gear's height, plus AIRBORNE_SIGMAS times the fix's vertical accuracy,
#: starts in the air [m] (a simulation started in hover); else on the ground, disarmed. A
#: consumer receiver's first fix is a metre off: taken at 0.3 m alone, three of ten such
#: starts on the ground took off.
AIRBORNE_MARGIN_M = 0.3
AIRBORNE_SIGMAS = 3.0


def air_start_threshold_m(gear_height_m: float, epv_m: float = 0.0) -> float:
    """The height [m] above which a first position of vertical accuracy ``epv_m`` [m] (0:
    the exact state) has the vehicle take itself to be in the air at boot."""
    return gear_height_m + AIRBORNE_MARGIN_M + AIRBORNE_SIGMAS * epv_m


def air_start_too_low_m(z_m: float, gear_height_m: float, epv_m: float) -> float | None:
    """For a simulation that starts the vehicle at height ``z_m`` [m] on its estimate with
    a receiver of vertical accuracy ``epv_m`` [m]: the least height [m] a start in the air
    needs (its first fix, as many standard deviations again below it, still above
    :func:`air_start_threshold_m`) when ``z_m`` is in the air but lower, else None."""
    need = air_start_threshold_m(gear_height_m, epv_m) + AIRBORNE_SIGMAS * epv_m
    return need if gear_height_m < z_m < need else None


#: ArduCopter's RTL_CONE_SLOPE default: RTL climbs to at most this many times its
#: horizontal distance from home (0.5 and more; ArduCopter's 0 switches the cone off).
RTL_CONE_SLOPE = 3.0
#: ArduCopter's RTL_ALT_MIN: the least height [m] above home RTL returns at.
RTL_ALT_MIN_M = 2.0


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class Navigator:
    """Modes, arming and the reference, stepped at every control period.

    ``gear_height_m`` is the height of the centre of mass when the vehicle rests on its
    gear; ``tether_length_m`` the length on the full drum (reach check);
    ``on_event(kind, value)`` hears what happens (also queued for :meth:`pop_events`).
    """

    def __init__(self, params: NavigationParams, gear_height_m: float,
                 tether_length_m: float,
                 on_event: Callable[[NavEvent, object], None] | None = None) -> None:
        #: the tether governor (companion/governor.py): the winch's reports, the slowing
        #: of legs and velocity targets, the brake
        self.governor = TetherGovernor(params, tether_length_m, gear_height_m)
        self.p = params
        self.gear_height_m = gear_height_m
        self.tether_length_m = tether_length_m
        self.on_event = on_event
        self.mode = FlightMode.STABILIZE
        self.armed = False
        self.landed = True
        self.home_m: Vec3 | None = None
        #: Rally points [m] (uploaded as the rally mission type): RTL may end at one.
        self.rally_m: tuple[Vec3, ...] = ()
        """Launch point [m] (set at arming on the ground, or at the first state)."""
        self.mission: list[NavCommand] = []
        self.mission_index = 0
        """Index into :attr:`mission` of the current item."""
        self.mission_running = False
        self._events: list[tuple[NavEvent, object]] = []
        self._leg: _Leg | None = None
        self._legs: list[_Leg] = []
        self._vel: _VelocityRef | None = None
        self._script: Callable[[float, Vec3], RefSample] | None = None
        self._vel_deadline = math.inf      # a velocity target stops after this [s]
        self._ref: RefSample | None = None
        self._t = 0.0
        self._armed_on_ground_since: float | None = None
        self._still_since: float | None = None
        self._speed_override: float | None = None
        self._pos: Vec3 = _ZERO3
        self._vel_now: Vec3 = _ZERO3
        self._quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
        self._auto_takeoff_pending = False
        self._vel_limited = False                    # a velocity target cut at the reach
        self._paused: list[_Leg] = []                # the legs the governor stopped
        # the governor's slowing of legs runs the leg clock behind the vehicle's
        # (governor.clock_lag); ``_nominal`` the leg's unscaled sample
        self._script_lag = 0.0                       # clock_lag when a script began [s]
        self._nominal: RefSample | None = None
        #: The estimate's position standard deviation [m] (largest axis; 0 on the
        #: truth), which the tether governor keeps as margin (set by the onboard step).
        self.position_sigma_m = 0.0
        #: the pre-arm checks of the rest of the vehicle (the estimator's), or None
        self.prearm: Callable[[], Refusal | None] | None = None
        #: the rate limit of repeating texts (the navigator's events and the autopilot's
        #: STATUSTEXTs of a kind), in simulated time
        self.texts = TextRateLimit()

    def reboot(self) -> None:
        """Back to the power-on state (disarmed, STABILIZE, on the ground, no home, no
        reference), keeping what a reboot keeps: the parameters and the stored mission (and
        the pre-arm check and the event listener it is wired to)."""
        mission, prearm = self.mission, self.prearm
        self.__init__(self.p, self.gear_height_m, self.tether_length_m, self.on_event)
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

    @property
    def _yaw(self) -> float:
        """The vehicle's heading now [rad] (from its attitude quaternion, when needed)."""
        return quat_to_yaw(self._quat)

    @property
    def flying(self) -> bool:
        """Armed and off the ground."""
        return self.armed and not self.landed

    @property
    def reach_m(self) -> float:
        """Largest straight-line distance [m] from the winder a target may have: of the
        whole tether, or of the length paid out while the winch's drum is braked
        (LOCK, HOLD, a lost winder: it pays out no more)."""
        return self.p.reach_fraction * self.governor.reach_length_m - self.p.reach_slack_m

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
        if not self.governor.over_tension(
                self._t, tension_n,
                # in flight, and not on the way in already
                self.flying and self.mode not in (FlightMode.RTL, FlightMode.LAND)):
            return
        x, y, z = self._current_ref().pos_m
        d = math.sqrt(x * x + y * y + z * z)
        # towards the winder, but no lower than 1 m above the gear unless already lower
        target = towards_winder((x, y, z), d - self.p.tension_step_m, self.gear_height_m + 1.0)
        self._emit(NavEvent.FAILSAFE, Notice(
            TextKind.OVER_TENSION, f"Tether over-tension ({tension_n:.0f} N > "
            f"{self.p.tension_limit_n:.0f} N): moving towards the winder"))
        self.mode = FlightMode.GUIDED
        self.mission_running = False
        self._vel = None
        self._fly_to(target, None)

    @property
    def speed_m_s(self) -> float:
        """Horizontal speed of planned moves now [m/s] (DO_CHANGE_SPEED overrides)."""
        return self._speed_override if self._speed_override is not None else self.p.speed_m_s

    @property
    def landing(self) -> bool:
        """A landing descent is under way."""
        return self._leg is not None and self._leg.landing

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
        leg = self._leg
        if leg is None:
            return None
        item = leg.item
        if isinstance(item, GotoItem):
            return item.pos_m
        return (item.centre_xy_m[0], item.centre_xy_m[1], item.altitude_m)

    def reference(self) -> RefSample | None:
        """The last reference produced (None before the first flying step)."""
        return self._ref

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
        if self.on_event is not None:
            self.on_event(kind, value)

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
        self._t, self._pos, self._vel_now, self._quat = t, pos, vel, quat
        yaw = self._yaw
        self.landed = (not airborne if airborne is not None
                       else pos[2] <= air_start_threshold_m(self.gear_height_m))
        self.home_m = (pos[0], pos[1], self.gear_height_m)
        if not self.landed:
            self.armed = True
            self.mode = FlightMode.GUIDED
            self._ref = RefSample(pos, _ZERO3, _ZERO3, _ZERO3, yaw, 0.0)
            self._hold()

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
        if not force and self.mode == FlightMode.AUTO and not self._mission_has_items():
            return Refusal(Reason.MISSION_EMPTY, "Arm: mission is empty")
        self.armed = True
        if self.landed:
            self.home_m = self._pos
            self._armed_on_ground_since = self._t
            if self.mode == FlightMode.AUTO:
                self._auto_takeoff_pending = True
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
        self._leg, self._legs, self._vel, self._script = None, [], None, None
        self._unpause()
        self.mission_running = False
        self._armed_on_ground_since = None
        self._auto_takeoff_pending = False
        self._emit(NavEvent.DISARMED)

    def set_mode(self, mode: int) -> Refusal | None:
        """Change the flight mode."""
        try:
            m = FlightMode(int(mode))
        except ValueError:
            return Refusal(Reason.UNKNOWN_MODE, f"unknown mode {mode}")
        if m not in SUPPORTED_MODES:
            return Refusal(Reason.UNSUPPORTED_MODE, f"mode {m.name} not supported")
        if m == FlightMode.AUTO and not self._mission_has_items():
            return Refusal(Reason.MISSION_EMPTY, "Auto: mission is empty")
        if (m == FlightMode.AUTO and self.landed and self.armed
                and self._first_nav().kind is not NavKind.TAKEOFF):
            return Refusal(Reason.MISSING_TAKEOFF, "Auto: Missing Takeoff Cmd")
        self.mode = m
        self._vel = None
        if m == FlightMode.AUTO:
            if self.flying:
                self._start_mission(self.mission_index if self.mission_running else 0)
            elif self.armed:
                self._auto_takeoff_pending = True
        elif m == FlightMode.RTL:
            self.mission_running = False
            if self.flying:
                self._rtl()
        elif m == FlightMode.LAND:
            self.mission_running = False
            if self.flying:
                self._land_here()
        else:
            self.mission_running = False
            if self.flying:
                self._hold()
        return None

    def failsafe_land(self, text: str) -> None:
        """A failsafe's action: LAND where it is (ArduCopter's FS_EKF_ACTION 1), said as a
        NavEvent.FAILSAFE."""
        self.failsafe(FlightMode.LAND, text)

    def failsafe(self, mode: FlightMode, text: str) -> None:
        """A failsafe's action: ``mode`` (RTL or LAND; a vehicle already landing keeps
        landing), said as a NavEvent.FAILSAFE."""
        self._emit(NavEvent.FAILSAFE, text)
        if self.mode != FlightMode.LAND and self.mode != mode:
            self.set_mode(mode)

    def takeoff(self, alt_m: float) -> Refusal | None:
        """GUIDED take-off to ``alt_m`` [m above the ground]."""
        if not math.isfinite(alt_m) or alt_m <= 0.0:
            return Refusal(Reason.BAD_VALUE, f"Takeoff: bad altitude {alt_m}")
        if self.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "Takeoff: not in GUIDED")
        if not self.armed:
            return Refusal(Reason.NOT_ARMED, "Takeoff: not armed")
        if not self.landed:
            return Refusal(Reason.FLYING, "Takeoff: already flying")
        target = (self._pos[0], self._pos[1], alt_m)
        why = self.check_target(target)
        if why is not None:
            return why
        self._takeoff(target)
        return None

    def goto(self, pos_m: Vec3, yaw_rad: float | None = None,
             speed_m_s: float | None = None) -> Refusal | None:
        """GUIDED: fly to ``pos_m`` [m] (``yaw_rad`` there if given)."""
        why = self.check_target(pos_m)
        if why is not None:
            return why
        if self.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "not in GUIDED")
        if not self.flying:
            return Refusal(Reason.NOT_FLYING, "not flying (take off first)")
        if speed_m_s is not None and speed_m_s > 0 and math.isfinite(speed_m_s):
            self._speed_override = float(speed_m_s)
        self._vel = None
        self._fly_to(pos_m, yaw_rad)
        return None

    def set_velocity(self, vel_m_s: Vec3, yaw_rad: float | None = None,
                     yaw_rate_rad_s: float | None = None) -> Refusal | None:
        """GUIDED: fly at ``vel_m_s`` [m/s] until a new target, or a stop after
        ``guided_velocity_timeout_s`` without an update."""
        if not all(math.isfinite(v) for v in vel_m_s):
            return Refusal(Reason.NOT_A_NUMBER, "velocity is not a number")
        if self.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "not in GUIDED")
        if not self.flying:
            return Refusal(Reason.NOT_FLYING, "not flying (take off first)")
        ref = self._current_ref()
        if self._vel is None:
            self._vel = _VelocityRef(ref, self.p.acc_m_s2)
            self._leg, self._legs, self._script = None, [], None
            self._unpause()
        self._vel.cmd = tuple(float(v) for v in vel_m_s)
        if yaw_rad is not None and math.isfinite(yaw_rad):
            self._vel.yaw = yaw_rad
        self._vel.yaw_rate = yaw_rate_rad_s if (yaw_rate_rad_s is not None
                                                and math.isfinite(yaw_rate_rad_s)) else 0.0
        self._vel_deadline = self._t + self.p.guided_velocity_timeout_s
        self._vel_limited = False
        return None

    def follow(self, source: Callable[[float, Vec3], RefSample]) -> Refusal | None:
        """GUIDED: fly, at every control period, the reference ``source(t, pos)`` gives
        for time ``t`` [s] with the vehicle at ``pos`` [m]: position, velocity,
        acceleration and yaw together, as a script streaming full set-points at the control
        rate does (ArduCopter's GUIDED with position, velocity and acceleration targets).
        Any other command or mode ends it; a sample beyond the tether's reach or below the
        ground ends it with a hold (a NavEvent.ERROR)."""
        if self.mode != FlightMode.GUIDED:
            return Refusal(Reason.WRONG_MODE, "not in GUIDED")
        if not self.flying:
            return Refusal(Reason.NOT_FLYING, "not flying (take off first)")
        self._leg, self._legs, self._vel = None, [], None
        self._unpause()
        self._script = source
        self._script_lag = self.governor.clock_lag
        self.governor.reset_clock()
        self._nominal = None
        return None

    def set_yaw(self, yaw_rad: float) -> Refusal | None:
        """Turn to ``yaw_rad`` [rad] where it is (CONDITION_YAW)."""
        if not math.isfinite(yaw_rad):
            return Refusal(Reason.NOT_A_NUMBER, "yaw is not a number")
        if not self.flying:
            return Refusal(Reason.NOT_FLYING, "not flying")
        ref = self._current_ref()
        if self._vel is not None:
            self._vel.yaw = yaw_rad
            return None
        target = self._leg.follower.target_m if self._leg is not None else None
        self._fly_to(target if target is not None else ref.pos_m, yaw_rad)
        return None

    def change_speed(self, speed_m_s: float) -> Refusal | None:
        """DO_CHANGE_SPEED: the horizontal speed of planned moves from now on [m/s]."""
        if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
            return Refusal(Reason.BAD_VALUE, f"bad speed {speed_m_s}")
        self._speed_override = min(float(speed_m_s), 20.0)
        if self.flying and self._leg is not None and not self._leg.landing \
                and self._leg.tag in (LegTag.GOTO, LegTag.MISSION):
            target = self._leg.follower.target_m
            if target is not None and self._leg.tag is LegTag.GOTO:
                self._fly_to(target, None)
        return None

    def set_mission(self, commands: list[NavCommand]) -> None:
        """A new mission (items from seq 1 on); the current item returns to the first."""
        self.mission = list(commands)
        self.mission_index = 0
        if self.mission_running and self.mode == FlightMode.AUTO and self.flying:
            if self.mission:
                self._start_mission(0)
            else:
                self.mission_running = False
                self._hold()

    def set_current(self, seq: int) -> Refusal | None:
        """MISSION_SET_CURRENT: fly item ``seq`` next."""
        for i, c in enumerate(self.mission):
            if c.seq == seq:
                if self.mission_running and self.flying:
                    self._start_mission(i)
                else:
                    self.mission_index = i
                    self._emit(NavEvent.CURRENT, c.seq)
                return None
        return Refusal(Reason.NO_SUCH_ITEM, f"no mission item {seq}")

    def start_mission(self, first_seq: int = 0) -> Refusal | None:
        """MISSION_START: AUTO, from ``first_seq`` (0: from the start)."""
        if not self._mission_has_items():
            return Refusal(Reason.MISSION_EMPTY, "Auto: mission is empty")
        if not self.armed:
            return Refusal(Reason.NOT_ARMED, "MISSION_START: not armed")
        index = 0
        if first_seq > 0:
            for i, c in enumerate(self.mission):
                if c.seq == first_seq:
                    index = i
                    break
        if self.landed and self.mission[index].kind is not NavKind.TAKEOFF:
            return Refusal(Reason.MISSING_TAKEOFF, "Auto: Missing Takeoff Cmd")
        self.mode = FlightMode.AUTO
        self._vel = None
        self._start_mission(index)
        return None

    # ----- stepping

    def step(self, t: float, pos: Vec3, vel: Vec3, quat: tuple[float, ...], dt: float
             ) -> tuple[RefSample | None, MotorState]:
        """Advance to ``t`` [s] with the vehicle at ``pos`` [m], ``vel`` [m/s], attitude
        ``quat`` (body to inertial, w x y z). Returns (the reference, or None when not
        flying, and the motors' state)."""
        self._t, self._pos, self._vel_now, self._quat = t, pos, vel, quat
        if not self.armed:
            self._ref = None
            if not self.landed and pos[2] <= self.gear_height_m + 0.05:
                self.landed = True
            return None, MotorState.OFF
        if self.landed:
            if self._auto_takeoff_pending and self.mode == FlightMode.AUTO:
                self._auto_takeoff_pending = False
                if self._mission_has_items() and self._first_nav().kind is NavKind.TAKEOFF:
                    self._start_mission(0)
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
            ref = self._advance(t, dt)
        except ValueError as exc:
            # a plan the limits cannot fly (e.g. limits changed mid-mission): hold instead
            self._emit(NavEvent.ERROR, str(exc))
            self.mission_running = False
            self._leg, self._legs, self._vel = None, [], None
            self._hold()
            ref = self._leg.follower.update(self._leg_clock, self._pos)
        self._ref = ref
        self._land_detector(t, pos, vel)
        if not self.armed:
            return None, MotorState.OFF
        return ref, MotorState.FLY

    def _advance(self, t: float, dt: float) -> RefSample:
        """The period's reference: the tether governor's stop while it brakes, else the
        plan's (script, velocity target or legs), governed."""
        gov = self.governor
        if gov.brake is not None:
            ref = self._braking(dt)
            if ref is not None:
                return ref
        if not gov.enabled:
            return self._advance_plan(t, dt)
        leg, script = self._leg, self._script
        slow = self._vel is None and (script is not None or (
            leg is not None and not (leg.landing or leg.takeoff)))
        if slow:
            notice = gov.slow_clock(self._nominal, self._pos, self._vel_now,
                                    self.position_sigma_m, dt)
            if notice is not None:
                self._emit(NavEvent.WARNING, notice)
        elif gov.s != 1.0 or gov.sd != 0.0:
            gov.reset_clock()
        ref = self._advance_plan(t, dt)
        if slow and self._leg is leg and self._script is script:
            self._nominal = ref
            ref = gov.scaled(ref)
        else:
            self._nominal = None
        return self._govern(ref, dt)

    @property
    def _leg_clock(self) -> float:
        """The legs' clock [s]: the vehicle's, less what the governor's slowing took."""
        return self._t - self.governor.clock_lag

    def _leg_velocity_ahead(self) -> Vec3 | None:
        """The velocity [m/s] the current leg's plan has :data:`GOVERNOR_LOOKAHEAD_S` on
        its own clock (None: no leg, or a streamed script, whose future is unknown)."""
        leg = self._leg
        if leg is None or self._script is not None:
            return None
        return leg.follower.trajectory.sample(self._leg_clock + GOVERNOR_LOOKAHEAD_S).vel_m_s

    # ----- the tether governor's decisions carried out on the plan

    def _govern(self, ref: RefSample, dt: float) -> RefSample:
        """The tether governor, in every mode (:meth:`TetherGovernor.check`): a reference
        whose stopping point would pass its limit brakes now (what it was doing is
        paused: a leg is resumed once the drum has paid out room again, a script or a
        velocity target ends); at rest, a paused leg resumes or the vehicle moves in
        (:meth:`_at_rest`)."""
        leg = self._leg
        if leg is not None and (leg.landing or leg.takeoff):
            # the final descent: the ground stops it; the take-off: the winch pays out on
            # its ground pre-tension as the climb pulls (no reported length to keep
            # within until it follows L-bar), and a snag there stops a climb, not a run
            return ref
        decision = self.governor.check(ref, self._pos, self._vel_now, self.position_sigma_m)
        if decision.verdict is Verdict.AT_REST:
            return self._at_rest(ref, decision.limit_m)
        if decision.verdict is Verdict.BRAKE:
            return self._start_brake(ref, decision.limit_m, dt)
        return ref

    def _start_brake(self, ref: RefSample, lim: float, dt: float) -> RefSample:
        """Brake the reference (:meth:`_govern`), pausing what it flew."""
        paused: list[_Leg] = []
        if self._script is not None:
            self._emit(NavEvent.ERROR, "script stopped at the tether's reach")
        elif self._vel is not None:
            if not self._vel_limited:
                self._vel_limited = True
                self._emit(NavEvent.WARNING, Notice(TextKind.VELOCITY_STOPPED,
                                                    "Guided velocity stopped at the reach"))
        elif self._leg is not None:
            # a circle resumes with the turns it has left (ArduCopter's circle continues
            # after a pause), not from its first again: a circle braked once a turn would
            # otherwise never end
            self._leg.item = self._leg.follower.remaining_item(self._leg_clock)
            paused = [self._leg, *self._legs]
        self._emit(NavEvent.WARNING, Notice(TextKind.TETHER_BRAKING,
                                            f"Tether: braking at {lim:.2f} m from the winder"))
        self._script, self._vel, self._leg, self._legs = None, None, None, []
        self._paused = paused
        return self.governor.start_brake(ref, dt)

    def _braking(self, dt: float) -> RefSample | None:
        """The governor's stop, stepped; None once at rest (the plan goes on: a hold, a
        move in, or the paused legs)."""
        ref, stopped = self.governor.step_brake(dt)
        if not stopped:
            return ref
        self._ref = ref
        paused = self._paused
        self._queue([_Leg(self._follower(self.speed_m_s), GotoItem(ref.pos_m, ref.yaw_rad),
                          tag=LegTag.HOLD)])
        self._paused = paused
        return None

    def _at_rest(self, ref: RefSample, lim: float) -> RefSample:
        """A reference at rest: a paused leg resumes when the governor gives room again
        (:meth:`TetherGovernor.may_resume`); beyond the limit of a braked drum, the vehicle
        moves in (:meth:`TetherGovernor.move_in_target`)."""
        p = ref.pos_m
        leg = self._leg
        holding = leg is not None and leg.tag is LegTag.HOLD
        if (self._paused and holding and leg.follower.done
                and self.governor.may_resume(p, self._pos, lim)):
            paused = self._paused
            self._emit(NavEvent.WARNING, Notice(TextKind.TETHER_RESUMING,
                                                "Tether: room again, resuming"))
            self._ref = ref
            self._queue(paused)
            return self._leg.follower.update(self._leg_clock, self._pos)
        target = (self.governor.move_in_target(p, lim)
                  if holding and self._vel is None and self._script is None else None)
        if target is not None and math.dist(target, leg.follower.target_m or p) > 0.05:
            paused = self._paused
            self._emit(NavEvent.WARNING, Notice(
                TextKind.TETHER_MOVING_IN, f"Tether: moving in within the braked {lim:.2f} m"))
            self._queue([_Leg(self._follower(self.speed_m_s), GotoItem(target, ref.yaw_rad),
                              tag=LegTag.HOLD)])
            self._paused = paused
        return ref

    def _advance_plan(self, t: float, dt: float) -> RefSample:
        if self._script is not None:
            # on the script's clock: the vehicle's, less what the slowing took since it began
            ref = self._script(t - (self.governor.clock_lag - self._script_lag), self._pos)
            x, y, z = ref.pos_m
            reach = self.reach_m
            if not (z >= 0.0 and x * x + y * y + z * z <= reach * reach):   # NaN too
                self._emit(NavEvent.ERROR, f"script: {self.check_target(ref.pos_m)}")
                self._hold()
                return self._advance_plan(t, dt)
            return ref
        if self._vel is not None:
            if t > self._vel_deadline:
                self._vel.cmd = _ZERO3
            self._limit_velocity()
            if self.governor.enabled:
                self._slow_velocity()
            return self._vel.step(dt)
        if self._leg is None:
            self._hold()
        leg = self._leg
        assert leg is not None
        follower = leg.follower
        ref = follower.update(self._leg_clock, self._pos)
        if follower.reached_t_s is not None and not leg.reported:
            leg.reported = True
            if leg.seq is not None and leg.tag is LegTag.MISSION:
                self._emit(NavEvent.REACHED, leg.seq)
        if follower.done and not leg.landing and not leg.finished:
            leg.finished = True
            self._leg_done(t, leg)
        return ref

    def _limit_velocity(self) -> None:
        """A velocity target whose stopping point (with margin) leaves the tether's reach
        or goes below the ground loses its outward (downward) part, said once."""
        v = self._vel
        assert v is not None
        speed = math.sqrt(sum(c * c for c in v.vel))
        margin = 1.5 * speed * speed / (2.0 * self.p.acc_m_s2) + 0.2
        pos = v.pos
        d = math.sqrt(sum(c * c for c in pos))
        cmd = list(v.cmd)
        cut = False
        if d > 0 and d + margin > self.reach_m:
            out = sum(cmd[i] * pos[i] for i in range(3)) / d
            if out > 0:
                cmd = [cmd[i] - out * pos[i] / d for i in range(3)]
                cut = True
        if pos[2] - margin < self.gear_height_m and cmd[2] < 0:
            cmd[2] = 0.0
            cut = True
        if cut:
            v.cmd = (cmd[0], cmd[1], cmd[2])
            if not self._vel_limited:
                self._vel_limited = True
                self._emit(NavEvent.WARNING, Notice(TextKind.VELOCITY_STOPPED,
                                                    "Guided velocity stopped at the reach"))

    def _slow_velocity(self) -> None:
        """The tether governor's cap on a velocity target's speed
        (:meth:`TetherGovernor.velocity_cap`)."""
        v = self._vel
        assert v is not None
        v.cap, notice = self.governor.velocity_cap(v.cmd, v.pos, self._pos,
                                                   self.position_sigma_m)
        if notice is not None:
            self._emit(NavEvent.WARNING, notice)

    def _leg_done(self, t: float, leg: _Leg) -> None:
        if leg.tag is LegTag.TAKEOFF:
            self._emit(NavEvent.TAKEOFF_DONE)
        if self._legs:
            self._leg = self._legs.pop(0)
            self._start_leg(self._leg)
            return
        if leg.tag in (LegTag.RTL_HOME, LegTag.LAND_APPROACH):
            item = leg.item
            self._queue(self._landing_legs((item.pos_m[0], item.pos_m[1]), leg.seq))
        elif leg.tag is LegTag.MISSION and self.mission_running:
            self._next_mission_item(t)
        # otherwise the finished leg's reference rests at its target: a hold

    def _land_detector(self, t: float, pos: Vec3, vel: Vec3) -> None:
        leg = self._leg
        ref = self._ref
        down = (pos[2] <= self.gear_height_m + 0.05
                or (ref is not None and ref.pos_m[2] <= pos[2] - self.p.land_stall_m))
        if (leg is not None and leg.landing and down
                and math.sqrt(vel[0] * vel[0] + vel[1] * vel[1] + vel[2] * vel[2]) < 0.3):
            if self._still_since is None:
                self._still_since = t
            elif t - self._still_since >= self.p.land_detect_s:
                self._still_since = None
                self.landed = True
                was_mission = self.mission_running
                self._emit(NavEvent.LANDED, self._leg.seq if self._leg else None)
                if was_mission and self._leg is not None and self._leg.seq is not None:
                    self._emit(NavEvent.REACHED, self._leg.seq)
                    self._emit(NavEvent.MISSION_DONE, None)
                self._disarm()
        else:
            self._still_since = None

    # ----- planning

    def _current_ref(self) -> RefSample:
        if self._ref is None:
            return RefSample(self._pos, _ZERO3, _ZERO3, _ZERO3, self._yaw, 0.0)
        return self._ref

    def _follower(self, speed: float, accept: float | None = None, hold_s: float = 0.0
                  ) -> LegFollower:
        return LegFollower(speed, self.p.acc_m_s2,
                           accept if accept is not None else self.p.acceptance_radius_m, hold_s)

    def _start_leg(self, leg: _Leg) -> None:
        ref = self._current_ref()
        leg.follower.start(self._leg_clock, ref.pos_m, ref.vel_m_s, leg.item,
                           current_yaw=ref.yaw_rad, current_acc=ref.acc_m_s2)
        self._leg = leg
        self.governor.reset_clock()
        self._nominal = None
        v = ref.vel_m_s
        if (self.governor.enabled and not (leg.landing or leg.takeoff)
                and v[0] * v[0] + v[1] * v[1] + v[2] * v[2] < 1e-6):
            # a leg from rest starts on its clock at the rate the room allows (the
            # reference, at rest, is unchanged by it): from 1, the clock's slowing could
            # not follow the leg's first acceleration near the vertical, and the brake
            # stopped it at once (resumed, it began again: the chatter)
            self.governor.s = self.governor.slow_rate(
                leg.follower.trajectory.sample(self._leg_clock), 1.0,
                self._leg_velocity_ahead(), self._pos, self._vel_now,
                self.position_sigma_m)[0]

    def _queue(self, legs: list[_Leg]) -> None:
        """Fly these legs in order, the first from the current reference (what the tether
        governor stopped is forgotten)."""
        self._script = None
        self._unpause()
        self._legs = legs[1:]
        self._start_leg(legs[0])

    def _unpause(self) -> None:
        """Forget the governor's stop and what it paused."""
        self.governor.brake, self._paused = None, []

    def _hold(self) -> None:
        ref = self._current_ref()
        self._vel = None
        self._queue([_Leg(self._follower(self.speed_m_s),
                          GotoItem(_stop_point(ref, self.p.acc_m_s2), ref.yaw_rad),
                          tag=LegTag.HOLD)])

    def _fly_to(self, pos: Vec3, yaw: float | None) -> None:
        self._queue([_Leg(self._follower(self.speed_m_s), GotoItem(tuple(pos), yaw),
                          tag=LegTag.GOTO)])

    def _takeoff(self, target: Vec3, seq: int | None = None) -> None:
        self.landed = False
        self._armed_on_ground_since = None
        self._ref = RefSample(self._pos, _ZERO3, _ZERO3, _ZERO3, self._yaw, 0.0)
        tag = LegTag.MISSION if seq is not None else LegTag.TAKEOFF
        self._queue([_Leg(self._follower(self.p.speed_up_m_s, self.p.takeoff_accept_m),
                          GotoItem(target, None), seq=seq, tag=tag, takeoff=True)])

    def _landing_legs(self, xy: tuple[float, float], seq: int | None = None
                      ) -> list[_Leg]:
        ref = self._current_ref()
        legs: list[_Leg] = []
        low = self.gear_height_m + self.p.land_alt_low_m
        if ref.pos_m[2] > low + 0.5:
            legs.append(_Leg(self._follower(self.p.speed_down_m_s, 1.0),
                             GotoItem((xy[0], xy[1], low), None), seq=seq, tag=LegTag.LAND_HIGH))
        # the final descent aims below the ground: the land detector ends it
        legs.append(_Leg(self._follower(self.p.land_speed_m_s),
                         GotoItem((xy[0], xy[1], -1.0), None), landing=True, seq=seq,
                         tag=LegTag.LAND))
        return legs

    def _land_here(self, seq: int | None = None) -> None:
        ref = self._current_ref()
        stop = _stop_point(ref, self.p.acc_m_s2)
        self._vel = None
        self._queue(self._landing_legs((stop[0], stop[1]), seq))

    def rtl_destination(self, stop: Vec3) -> Vec3:
        """Where RTL goes from ``stop`` [m]: home, or the nearest rally point (as
        ArduCopter with RALLY_INCL_HOME 1: home counts as one) that is within the reach."""
        home = self.home_m if self.home_m is not None else (0.0, 0.0, 0.0)
        best, best_d = home, math.hypot(home[0] - stop[0], home[1] - stop[1])
        for r in self.rally_m:
            d = math.hypot(r[0] - stop[0], r[1] - stop[1])
            if d < best_d and self.check_target((r[0], r[1], max(r[2], 0.0))) is None:
                best, best_d = r, d
        return best

    def rtl_altitude_m(self, stop: Vec3, home: Vec3) -> float:
        """The height [m] RTL returns at from ``stop`` [m] to ``home`` [m], as ArduCopter
        computes it (ModeRTL's return target, its default RTL_CONE_SLOPE and RTL_CLIMB_MIN
        0): ``rtl_alt_m`` above home, at least :data:`RTL_ALT_MIN_M`, but within a cone
        of :data:`RTL_CONE_SLOPE` above home (a vehicle near home climbs little or not
        at all), and never below where it is. The tether's reach bounds it after."""
        base = self.gear_height_m
        here = stop[2] - base
        least = max(RTL_ALT_MIN_M, here)
        target = max(self.p.rtl_alt_m, least)
        cone = RTL_CONE_SLOPE * math.hypot(home[0] - stop[0], home[1] - stop[1])
        target = min(target, max(cone, least))
        return base + max(target, here)

    def _rtl(self, seq: int | None = None) -> None:
        ref = self._current_ref()
        legs: list[_Leg] = []
        stop = _stop_point(ref, self.p.acc_m_s2)
        home = self.rtl_destination(stop)
        alt = self.rtl_altitude_m(stop, home)
        # the climb and the way home stay within the tether's reach, whatever RTL_ALT says
        # (a level line's farthest point from the winder is one of its ends)
        reach = self.reach_m
        far_h = max(math.hypot(stop[0], stop[1]), math.hypot(home[0], home[1]))
        cap = math.sqrt(max(reach * reach - far_h * far_h, 0.0))
        if alt > cap:
            self._emit(NavEvent.WARNING, Notice(
                TextKind.RTL_ALT_LIMITED, f"RTL: altitude {alt:.1f} m cut to {cap:.1f} m by "
                "the tether"))
            alt = max(cap, self.gear_height_m)
        if alt > stop[2] + 0.5:
            legs.append(_Leg(self._follower(self.p.speed_up_m_s),
                             GotoItem((stop[0], stop[1], alt), None), seq=seq,
                             tag=LegTag.RTL_CLIMB))
        legs.append(_Leg(self._follower(self.speed_m_s, hold_s=self.p.rtl_loiter_s),
                         GotoItem((home[0], home[1], alt), None), seq=seq, tag=LegTag.RTL_HOME))
        self._vel = None
        self._queue(legs)

    # ----- missions

    def _mission_has_items(self) -> bool:
        return any(c.kind in NAV_MOVES for c in self.mission)

    def _first_nav(self) -> NavCommand:
        for c in self.mission[self.mission_index:] or self.mission:
            if c.kind in NAV_MOVES:
                return c
        return self.mission[0]

    def _start_mission(self, index: int) -> None:
        self.mission_running = True
        self.mission_index = max(0, min(index, len(self.mission)))
        self._begin_item(self._t)

    def _next_mission_item(self, t: float) -> None:
        self.mission_index += 1
        self._begin_item(t)

    def _begin_item(self, t: float) -> None:
        while self.mission_index < len(self.mission):
            c = self.mission[self.mission_index]
            self._emit(NavEvent.CURRENT, c.seq)
            if c.kind is NavKind.SPEED:
                if c.speed_m_s is not None and c.speed_m_s > 0:
                    self._speed_override = c.speed_m_s
                self.mission_index += 1
                continue
            if c.kind is NavKind.WINCH:
                # as ArduPilot's DO_ commands: run as the item begins, then the next item
                self._emit(NavEvent.WINCH, (c.seq, c.winch))
                self.mission_index += 1
                continue
            self._fly_item(c)
            return
        # past the last item: ArduCopter holds where it is (the mission is complete)
        self.mission_running = False
        self._emit(NavEvent.MISSION_DONE, None)
        if self.flying:
            self._hold()

    def _check_item_here(self, c: NavCommand, xy: tuple[float, float]) -> Refusal | None:
        """Why an item without a position of its own cannot be flown from ``xy``."""
        ref_z = self._current_ref().pos_m[2]
        z = c.z_m if c.z_m is not None else (self.p.rtl_alt_m if c.kind is NavKind.TAKEOFF
                                             else ref_z)
        if c.kind is NavKind.TAKEOFF:
            z = max(z, ref_z)
        return self.check_target(_far_point(c, xy, z))

    def _item_xy(self, c: NavCommand) -> tuple[float, float]:
        if c.xy_m is not None:
            return c.xy_m
        ref = self._current_ref()
        return (ref.pos_m[0], ref.pos_m[1])

    def _fly_item(self, c: NavCommand) -> None:
        xy = self._item_xy(c)
        if c.xy_m is None and c.kind in (NavKind.WAYPOINT, NavKind.LOITER_TURNS,
                                         NavKind.TAKEOFF):
            # checked at the upload at the winder; flown from here: checked here
            why = self._check_item_here(c, xy)
            if why is not None:
                self._emit(NavEvent.ERROR, f"Mission: item {c.seq} {why}; holding")
                self.mission_running = False
                self._hold()
                return
        if c.kind is NavKind.TAKEOFF:
            z = c.z_m if c.z_m is not None else self.p.rtl_alt_m
            if self.landed:
                self._takeoff((self._pos[0], self._pos[1], z), seq=c.seq)
            else:
                # already flying: ArduCopter climbs to the altitude if below it
                ref = self._current_ref()
                self._queue([_Leg(self._follower(self.p.speed_up_m_s,
                                                 self.p.takeoff_accept_m),
                                  GotoItem((ref.pos_m[0], ref.pos_m[1], max(z, ref.pos_m[2])),
                                           None), seq=c.seq, tag=LegTag.MISSION)])
        elif c.kind is NavKind.WAYPOINT:
            z = c.z_m if c.z_m is not None else self._current_ref().pos_m[2]
            self._queue([_Leg(self._follower(self.speed_m_s, c.accept_m, c.hold_s),
                              GotoItem((xy[0], xy[1], z), None), seq=c.seq, tag=LegTag.MISSION)])
        elif c.kind is NavKind.LOITER_TURNS:
            z = c.z_m if c.z_m is not None else self._current_ref().pos_m[2]
            radius = abs(c.circle_radius_m)
            # as ArduCopter's circle does, the speed is cut to what the acceleration limit
            # allows on this radius (centripetal acceleration v^2/r, with margin)
            speed = min(self.speed_m_s, 0.95 * math.sqrt(self.p.acc_m_s2 * radius))
            lead_in = max(5.0, 1.01 * Circle.min_lead_in_s(radius, speed, self.p.acc_m_s2))
            item = CircleItem(xy, radius, z, speed, turns=c.turns, clockwise=c.clockwise,
                              lead_in_s=lead_in)
            self._queue([_Leg(self._follower(speed, c.accept_m), item, seq=c.seq,
                              tag=LegTag.MISSION)])
        elif c.kind is NavKind.LAND:
            if c.xy_m is None:
                self._land_here(seq=c.seq)
            else:
                ref = self._current_ref()
                self._queue([_Leg(self._follower(self.speed_m_s),
                                  GotoItem((xy[0], xy[1], ref.pos_m[2]), None), seq=c.seq,
                                  tag=LegTag.LAND_APPROACH)])
        elif c.kind is NavKind.RTL:
            self._rtl(seq=c.seq)


def _far_point(c: NavCommand, xy: tuple[float, float], z: float) -> Vec3:
    """The point of item ``c`` flown around ``xy`` at ``z`` farthest from the winder."""
    if c.kind is not NavKind.LOITER_TURNS:
        return (xy[0], xy[1], z)
    h = math.hypot(xy[0], xy[1]) + abs(c.circle_radius_m)
    return (h, 0.0, z)


def _stop_point(ref: RefSample, acc: float) -> Vec3:
    """Where the reference comes to rest braking at ``acc`` [m/s^2] (ArduCopter's stopping
    point), so a hold begins without a jerk back."""
    v = ref.vel_m_s
    speed = math.sqrt(sum(x * x for x in v))
    if speed < 1e-6:
        return ref.pos_m
    d = speed * speed / (2.0 * acc)
    return tuple(ref.pos_m[i] + v[i] / speed * d for i in range(3))  # type: ignore
