"""The navigator's vocabulary: flight modes, its parameters, mission steps, events,
reasons for refusals, and what the rotors do (:mod:`companion.navigation` flies them; the
MAVLink layer converts messages into and out of them).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum

from tuavdefs.paramspec import Params, quantity


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
    tether_governor: int = quantity(2, "", "the tether governor (docs/control.md §3), what "
                                    "it counts on from the winder (GovernorMode): 2 the "
                                    "tension law (the default: a free drum pays out, the "
                                    "room is the whole tether or a braked drum's length), "
                                    "1 a length law (the paper's, with the winder's stop "
                                    "lead; near the vertical it slows moves to 0.3-1.4 "
                                    "m/s), 0 off",
                                    ge=0, le=2)
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
    """Event kinds the navigator reports
    (:meth:`companion.navigation.Navigator.pop_events`) and their value."""

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
