"""The ground station's winch: ``MAV_CMD_DO_WINCH``, the drum's length reference, the
brake, encoder-loss handling and ``WINCH_STATUS``, as pure logic.

No sockets and no clock. The process (``python -m groundstation``) hands every CAN frame it
receives to :meth:`Winch.on_frame`, calls :meth:`Winch.poll` on every turn of its loop,
passes each MAVLink command addressed to it to :meth:`Winch.command`, and keeps the UAV's
position current with :meth:`Winch.set_uav`; every call returns what to send (CAN frames,
``STATUSTEXT`` notices, a ``WINCH_STATUS`` report, a ``COMMAND_ACK``). Wall-clock times
[s] are passed in; simulated time is counted from the encoder frames.

Two clocks:

- **Simulated time** is the encoder frame counter times the control period
  (``WinderControlParams.rate_hz``, 10 ms): the axis sends ``Get_Encoder_Estimates`` every
  10 ms of its own time, so the n-th frame is at n x 10 ms (the plant's frames sit on its 4 ms
  control grid, 8 or 12 ms apart, 10 ms on average). The ramps of the length reference
  advance by one period per frame, and ``WINCH_STATUS`` goes out every
  ``round(1 / (status_rate_hz x period))`` frames (every 5th: 20 Hz). The drum's position
  cannot serve as a clock: it does not change while the drum holds still.
- **The time it is handed** (``wall_s`` of every call: the process's monotonic clock, or,
  with a plant in lockstep, the sensor node's clock :attr:`Winch.sensor_clock_s`; the
  offline runner's simulated time) decides that the encoder is lost (no frame for
  ``encoder_timeout_s``, 0.1 s), the notices' and re-arms' spacing, and sends
  ``WINCH_STATUS`` whenever ``status_wall_period_s`` (0.09 s) has passed without one (lost,
  or frames slower than about half real time), so that with the process's 10 ms loop no
  gap exceeds 0.1 s. The winch reads no clock of its own: given the same times it does
  the same.

Modes (the ``WINCH_ACTIONS`` value of the last accepted ``DO_WINCH``):

- ``WINCH_RELAXED`` (0, the default): the drum follows L-bar through
  :meth:`WinderHost.update` (slack, never taut). While the UAV's position is unknown, or it
  reports a height below ``ground_height_m`` and no climb of ``ground_climb_m_s`` (on the
  ground; a climb is a take-off, which keeps it only while L-bar would ask for more than
  ``ground_lbar_tension_ratio`` times its tension), the drum holds the line at
  ``ground_tension_n`` instead:
  a pre-tension, the line straight to the vehicle and readable by the guide arm; a loop on
  the load cell's tension, winding in slowly, paying out fast (holding instead while no
  position is known), never below the taut floor. Without a load-cell reading it holds
  the length it had.
  Line RELAXED pays out while nothing pulls it (the load cell below ``slack_tension_n``,
  no line leaving the exit above the ground) is counted; past ``slack_payout_max_m`` the
  drum holds and pays out only as it is pulled (the *slack guard*,
  :meth:`Winch._check_slack`): a vehicle on the ground after a failure whose reported
  position runs away does not get the tether paid out to it.
- ``WINCH_RELATIVE_LENGTH_CONTROL`` (1): from the measured length, pay out (+) or wind in
  (-) ``param3`` m at ``|param4|`` m/s (``default_rate_m_s`` if 0 or NaN), then hold: the
  backstepping law (the host's own :class:`WinderController`) tracks this ramped
  reference and its rate instead of L-bar.
- ``WINCH_RATE_CONTROL`` (2): the reference moves at ``param4`` m/s until the next command.
- ``WINCH_LOCK`` (3), ``WINCH_HOLD`` (5): the axis goes IDLE (``Set_Axis_State 1``), so
  the brake holds the drum; every encoder frame is answered with that request again (it
  reasserts the brake, and it is the answer a lockstep plant waits for). Any other action
  re-arms: ``Clear_Errors``, torque control, ``CLOSED_LOOP_CONTROL``.
- ``WINCH_RETRACT`` (6): wind in at ``|param4|`` m/s (``retract_rate_m_s`` if 0 or NaN) to
  the shortest length the geometry allows, the straight-line distance to the UAV plus
  L-bar's minimum slack (the *taut floor*), then hold that length.

Safety: in modes 1, 2 and 6 the reference never goes below the taut floor (it is raised
with it when the UAV moves away), nor above the drum's capacity less ``end_margin_m``, nor
below the drum's full stop; the first time a command meets a limit a ``STATUSTEXT`` says
so, and a command whose length is clamped is still ``ACCEPTED``. Rates above the law's speed
limit are clamped likewise. ``DELIVER``, ``LOAD_LINE``, ``ABANDON_LINE`` and
``LOAD_PAYLOAD`` are ``UNSUPPORTED``; a NaN where a value is required, an unknown action or
an instance other than 0 or 1 is ``DENIED`` with a ``STATUSTEXT``. LOCK and HOLD brake the
drum whatever the UAV does (a warning says when the UAV's distance reaches the held
length).

Encoder loss: after ``encoder_timeout_s`` of wall time without ``Get_Encoder_Estimates``
the axis is sent IDLE (the brake holds), a CRITICAL ``STATUSTEXT`` says so, and
``WINCH_STATUS`` drops HEALTHY and sets CLUTCH_ENGAGED. The first frame back re-arms the
axis (unless the mode is LOCK or HOLD), a ``STATUSTEXT`` says so, and the active mode
resumes where its reference stood (it did not advance without frames).

Another host commanding the axis (a host-to-axis frame this process did not send): said,
and the drum braked against it at once (IDLE, answered again to each of its frames that
could re-arm the axis), reported braked and not HEALTHY, until ``FOREIGN_NOTICE_S`` pass
without one or an operator's ``DO_WINCH`` (docs/protocols.md: what an unauthenticated bus
still allows).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.tether_fix import TetherFix, TetherFixer, TetherFixParams
from groundstation.winder_control import WinderCommand
from groundstation.winder_host import WinderHost
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl
from tuavdefs.params import TetherParams, WinderParams
from tuavdefs.paramspec import Params, quantity

Vec3 = tuple[float, float, float]
UavState = tuple[Vec3, Vec3]

#: Encoder silence after which the drum is braked and the stream reported lost [s, wall].
ENCODER_TIMEOUT_S = 0.1
#: WINCH_STATUS ``temperature`` when unknown (INT16_MAX, as the message defines).
TEMPERATURE_UNKNOWN = 32767
#: STATUSTEXT holds at most this many characters in one message.
STATUSTEXT_MAX_LEN = 50

_TWO_PI = 2.0 * math.pi


class WinchMode(enum.IntEnum):
    """The winch's mode: the ``WINCH_ACTIONS`` value of the last accepted action."""

    RELAXED = mavlink2.WINCH_RELAXED
    RELATIVE_LENGTH = mavlink2.WINCH_RELATIVE_LENGTH_CONTROL
    RATE = mavlink2.WINCH_RATE_CONTROL
    LOCK = mavlink2.WINCH_LOCK
    HOLD = mavlink2.WINCH_HOLD
    RETRACT = mavlink2.WINCH_RETRACT


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
#: The shortest wall time between two re-arms of an axis that disarmed itself [s].
REARM_S = 1.0
#: How long [s, wall] a frame from another host leaves the winch unhealthy and its drum
#: braked, and the shortest time between two STATUSTEXTs about it.
FOREIGN_NOTICE_S = 5.0
#: Another host's frames that can take the axis out of IDLE (or prepare it to be): each
#: is answered at once with ``Set_Axis_State`` IDLE while the drum is braked against it.
REARMING_COMMANDS = frozenset({cp.Cmd.SET_AXIS_STATE, cp.Cmd.SET_CONTROLLER_MODE,
                               cp.Cmd.CLEAR_ERRORS})
#: Host-to-axis commands: heard on the bus, another host sent them.
HOST_COMMANDS = (cp.Cmd.ESTOP, cp.Cmd.SET_AXIS_STATE, cp.Cmd.SET_CONTROLLER_MODE,
                 cp.Cmd.SET_INPUT_TORQUE, cp.Cmd.SET_LIMITS, cp.Cmd.CLEAR_ERRORS)
#: Modes in which the brake holds the drum (axis IDLE).
BRAKED_MODES = frozenset({WinchMode.LOCK, WinchMode.HOLD})
#: ``WINCH_ACTIONS`` this winch does not implement (ACK UNSUPPORTED).
UNSUPPORTED_ACTIONS = frozenset({mavlink2.WINCH_DELIVER, mavlink2.WINCH_LOAD_LINE,
                                 mavlink2.WINCH_ABANDON_LINE, mavlink2.WINCH_LOAD_PAYLOAD})

# MAV_WINCH_STATUS_FLAG bits; 0 for those the installed dialect does not define
FLAG_HEALTHY = cl.winch_status_flag("HEALTHY")
FLAG_FULLY_RETRACTED = cl.winch_status_flag("FULLY_RETRACTED")
FLAG_MOVING = cl.winch_status_flag("MOVING")
FLAG_CLUTCH_ENGAGED = cl.winch_status_flag("CLUTCH_ENGAGED")
FLAG_LOCKED = cl.winch_status_flag("LOCKED")
FLAG_RETRACTING = cl.winch_status_flag("RETRACTING")


@dataclass(frozen=True)
class WinchParams(Params):
    """Settings of the winch component (rates, limits, reporting)."""

    default_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of RELATIVE_LENGTH_CONTROL when param4 is 0 or NaN", gt=0)
    retract_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of RETRACT when param4 is 0 or NaN", gt=0)
    rejoin_rate_m_s: float = quantity(
        1.0, "m/s", "fastest wind-in of RELAXED back to L-bar from a longer line (after "
        "a pay-out: no jerk of the UAV)", gt=0)
    status_rate_hz: float = quantity(
        20.0, "Hz", "WINCH_STATUS rate in simulated time (encoder frames)", gt=0)
    status_wall_period_s: float = quantity(
        0.09, "s", "WINCH_STATUS after this much wall time without one (a process polling "
        "every 10 ms then never leaves a gap over 0.1 s)", gt=0)
    encoder_timeout_s: float = quantity(
        ENCODER_TIMEOUT_S, "s", "wall-clock encoder silence that brakes the drum", gt=0)
    moving_speed_m_s: float = quantity(
        0.01, "m/s", "line speed above which WINCH_STATUS says MOVING", ge=0)
    retracted_tolerance_m: float = quantity(
        0.02, "m", "FULLY_RETRACTED within this of the taut floor", ge=0)
    end_margin_m: float = quantity(
        0.5, "m", "tether always left on the drum below its capacity", ge=0)
    duplicate_window_s: float = quantity(
        3.0, "s", "a retransmitted COMMAND_LONG within this [wall] is acknowledged again, "
        "not executed again", ge=0)
    tension_limit_n: float = quantity(
        30.0, "N", "load-cell tension above which the winch pays out (the over-tension "
        "failsafe), whatever the active mode but LOCK and HOLD", gt=0)
    overtension_s: float = quantity(
        0.1, "s", "the tension above its limit this long (simulated time) starts the "
        "pay-out; it ends below 90 % of the limit", ge=0)
    overtension_rate_m_s: float = quantity(
        0.5, "m/s", "line speed of the over-tension pay-out", gt=0)
    stuck_error_m: float = quantity(
        0.1, "m", "the length this far behind a reference that pays out (the law tracks "
        "within 2 cm) for stuck_s: the drum is stuck", gt=0)
    sensor_rate_hz: float = quantity(
        100.0, "Hz", "rate of the load cell's frames (Winch_Tension)", gt=0)
    bus_window_s: float = quantity(
        0.1, "s", "the CAN bus is judged over windows this long (of the load cell's "
        "stamps)", gt=0)
    bus_lost_max: float = quantity(
        0.3, "1", "a window with more of the load cell's frames lost: the bus is degraded",
        gt=0, le=1)
    bus_late_max_s: float = quantity(
        0.05, "s", "a window whose frames all came later than this (against the UAV's "
        "position): the bus is degraded", gt=0)
    bus_good_windows: int = quantity(
        10, "1", "good windows in a row that end a degraded bus", ge=1)
    stuck_speed_m_s: float = quantity(
        0.05, "m/s", "a drum paying out slower than this while it lags may be stuck", gt=0)
    stuck_s: float = quantity(
        0.1, "s", "how long (simulated time) the drum lags stuck_error_m before it counts "
        "as stuck", ge=0)
    max_extrapolation_s: float = quantity(
        0.1, "s", "the UAV's reported position is carried forward by its velocity to the "
        "winch's sample time over gaps up to this", ge=0)
    ground_tension_n: float = quantity(
        0.3, "N", "RELAXED with the UAV on the ground (or its position unknown): the drum "
        "holds this tension on the line (a pre-tension: the line lies straight, the guide "
        "arm follows it and the tether fix stays readable); 0: it holds its length", ge=0)
    ground_height_m: float = quantity(
        0.6, "m", "the UAV counts as on the ground while it reports a height below this "
        "(at rest on its gear it reports about its gear height)", ge=0)
    ground_tension_gain_m_s_n: float = quantity(
        1.0, "m/(s*N)", "the pre-tension's loop: line speed of the length reference per "
        "newton of tension off the target (paid out above it, wound in below it)", gt=0)
    ground_tension_rate_m_s: float = quantity(
        0.05, "m/s", "the pre-tension's loop: its fastest wind-in (it pays out as fast as "
        "the law allows); slow, since a line lying straight on the ground is stiff (EA/L: "
        "55 kN/m at 2 m) and the drum's overshoot when the slack runs out is all stretch",
        gt=0)
    ground_lbar_tension_ratio: float = quantity(
        2.0, "1", "a take-off goes on holding the pre-tension while L-bar at the reported "
        "position asks for more than this times its target horizontal tension", gt=1)
    ground_climb_m_s: float = quantity(
        0.3, "m/s", "the UAV counts as on the ground only while it also reports climbing "
        "slower than this (a take-off ends the pre-tension at once; a landing's descent "
        "does not delay it)", gt=0)
    slack_tension_n: float = quantity(
        0.05, "N", "the line counts as slack (nothing pulls it) while the load cell reads "
        "less than this and the guide arm reads no line leaving the exit above the ground "
        "(the load cell's noise: less is nothing it can tell)", ge=0)
    slack_payout_max_m: float = quantity(
        4.0, "m", "RELAXED pays out at most this much line while it stays slack: more "
        "lies on the ground, where no vehicle pulls it (one on the ground after a failure, "
        "its reported position run away); then the drum holds and pays out only as the "
        "line is pulled. A real climb with the line's bottom lying at the exit (near the "
        "vertical, on a line whose ground friction takes the pull) pays out up to 2.6 m "
        "so between two pulls", gt=0)


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


def _notice(severity: int, text: str) -> Notice:
    return Notice(severity, text[:STATUSTEXT_MAX_LEN])


def _identity(req: CommandRequest) -> tuple:
    """What makes two requests the same command (NaN parameters compare equal)."""
    return tuple(None if isinstance(v, float) and math.isnan(v) else v
                 for v in req._replace(confirmation=0))


def _finite(*values: float) -> bool:
    """Whether every value is a finite int or float (a plain loop: this runs for every
    UAV position)."""
    for v in values:  # noqa: SIM110 - all() over a generator costs twice as much
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            return False
    return True


class Winch:
    """The winch component's behaviour (module docstring): mode state machine, length
    reference, brake, encoder-loss handling and status, around a :class:`WinderHost`.

    ``winder``/``tether`` give the drum's limits (full stop ``min_paid_out_m``, capacity
    ``total_length_m``), ``gravity_m_s2`` turns the load cell's newtons into the kilograms
    ``WINCH_STATUS`` carries.
    """

    def __init__(self, host: WinderHost, winder: WinderParams, tether: TetherParams,
                 gravity_m_s2: float, params: WinchParams | None = None,
                 axis_node_id: int = cp.AXIS_NODE_ID_DEFAULT,
                 sensor_node_id: int = cp.WINCH_SENSOR_NODE_ID_DEFAULT,
                 fix_params: TetherFixParams | None = None) -> None:
        self.host = host
        self.p = params or WinchParams()
        fp = fix_params or TetherFixParams()
        #: the tether fix (groundstation.tether_fix), on this station's own tether beliefs
        self.fixer = (TetherFixer(fp, tether.linear_density_kg_m * gravity_m_s2,
                                  tether.youngs_modulus_pa * tether.section_area_m2,
                                  tether.diameter_m) if fp.enabled else None)
        self.fix_every = max(1, round(1.0 / (fp.rate_hz * host.dt_s)))
        self._frames_since_fix = 0
        #: the last Winch_Exit_Angle: (azimuth [rad], elevation [rad], sample time [ms]
        #: modulo 65536, valid), or None
        self.exit_angle: tuple[float, float, int, bool] | None = None
        self._clock_ms: int | None = None     # the winch's clock, unwrapped [ms]
        self.fixes = 0
        """Tether fixes computed."""
        self.g = gravity_m_s2
        self.node = axis_node_id
        self.sensor_node = sensor_node_id
        self.dt_s = host.dt_s
        self.r_w = winder.drum_radius_m
        self.min_slack_m = host.lbar.p.min_slack_m
        #: fastest line speed a command may ask for [m/s]: the law's own speed limit
        self.max_rate_m_s = host.controller.omega_max * self.r_w
        self.length_min_m = winder.min_paid_out_m
        self.length_max_m = max(tether.total_length_m - self.p.end_margin_m, self.length_min_m)
        self.status_every = max(1, round(1.0 / (self.p.status_rate_hz * self.dt_s)))

        self.mode = WinchMode.RELAXED
        self.encoder_frames = 0
        self.torque_commands = 0
        self.bad_frames = 0
        self.lost = False
        self._last_encoder_wall: float | None = None
        # measurements
        self.length_m = math.nan            # from the encoder [m]
        self.omega_rad_s = 0.0
        self.sensor_length_m = math.nan     # Winch_Length
        self.sensor_speed_m_s = math.nan
        self.tension_n = math.nan           # last finite Winch_Tension [N]
        self.sensor_brake: bool | None = None
        self.load_cell_healthy: bool | None = None
        self.at_full_stop = False
        self.axis_error: int | None = None
        self.axis_state: int | None = None
        self.voltage_v = math.nan
        self.current_a = math.nan
        self.uav: UavState | None = None
        self.uav_time_ms: int | None = None
        self.sample_time_ms: int | None = None
        self._sensor_clock_ms: int | None = None   # Sample_Time unwrapped [ms]
        # reference of modes 1, 2, 6 and of RELAXED without a UAV position
        self.ref_m = math.nan
        self.ref_rate_m_s = 0.0
        self._target_m = math.nan
        self._speed_m_s = 0.0               # |ramp rate| (1, 6) or signed rate (2)
        self._retract_reached = False
        self._hold_m = math.nan
        self._rejoin_m = math.nan           # RELAXED's reference while rejoining L-bar
        self._rejoin_rate = 0.0             # its wind-in speed [m/s]
        self._join_gap_m = 0.0              # how far short of L-bar's law a join still is
        self._join_rate = 0.0               # how fast that closes [m/s]
        self._ground = False                # RELAXED holding the ground pre-tension
        self._ground_low = False            # ... since the UAV reported itself on the ground
        #: Line paid out (net) by RELAXED since the line was last pulled [m].
        self.slack_paid_m = 0.0
        self._slack_length_m = math.nan     # the length at the last slack count [m]
        #: Whether RELAXED holds the line against a pay-out nothing pulls (the slack guard,
        #: :meth:`_check_slack`): the pre-tension's loop, paid out only as it is pulled.
        self.slack_hold = False
        self._limit_noticed = False
        self._lock_noticed = False
        self._over_frames = 0               # encoder frames in a row above the limit
        self._stuck_frames = 0              # encoder frames in a row behind the reference
        self._stuck_length_m = math.nan     # the length at which the drum was found stuck
        #: Whether the CAN bus loses or delays too much (:meth:`_check_bus`): drum braked.
        self.bus_degraded = False
        self._bus_window_start = 0
        self._bus_expected = 0
        self._bus_lost = 0
        self._bus_late_ms = 0x10000          # the least lateness of the window [ms]
        self._bus_good = 0
        self._bus_min_step = 0xFFFF              # the shortest step between stamps [ms]
        self._bus_said: tuple[float, float] | None = None
        self._bus_noticed = False
        #: Whether the drum does not pay out as asked (a snag: :meth:`_check_stuck`).
        self.drum_stuck = False
        #: Whether the over-tension pay-out is on.
        self.over_tension = False
        #: the torque law's last output (torque, Lyapunov function, ...), for diagnostics
        self.last_command: WinderCommand | None = None
        # axis
        self._arm_pending = False
        self._rearm_wall = -math.inf        # the last re-arm of a self-disarmed axis [s]
        self._estop_noticed = False
        self.rearms = 0
        """Times the axis was re-armed after it had disarmed itself."""
        # another host on the bus commanding the axis
        self.foreign_commands = 0
        """Host-to-axis frames on the axis's ids this process did not send."""
        self._foreign_wall = -math.inf      # the last one [s]
        self._foreign_said_wall = -math.inf
        #: Whether the drum is braked against another host commanding the axis (from its
        #: first frame until FOREIGN_NOTICE_S without one, or an operator's DO_WINCH).
        self.foreign_brake = False
        # reporting
        self._frames_since_status = 0
        self._last_status_wall: float | None = None
        self._last_command: tuple[tuple, float, CommandReply] | None = None
        # the frames this winch reads, by 11-bit id (a sensor node sharing the axis's node
        # id takes all of that node's frames)
        handlers: dict[int, Callable[[float, bytes], WinchOutput | None]] = {}
        if 0 <= self.node <= cp.MAX_NODE_ID and self.node != self.sensor_node:
            handlers[cp.frame_id(self.node, cp.Cmd.GET_ENCODER_ESTIMATES)] = self._encoder_frame
            handlers[cp.frame_id(self.node, cp.Cmd.HEARTBEAT)] = self._axis_heartbeat_frame
            handlers[cp.frame_id(self.node, cp.Cmd.GET_BUS_VOLTAGE_CURRENT)] = (
                self._bus_voltage_current_frame)
            # what only a host sends: this process never hears its own frames, so these
            # come from a second host on the bus
            for cmd in HOST_COMMANDS:
                handlers[cp.frame_id(self.node, cmd)] = (
                    lambda wall_s, data, cmd=cmd: self._foreign_command(wall_s, cmd))
        if 0 <= self.sensor_node <= cp.MAX_NODE_ID:
            handlers[cp.frame_id(self.sensor_node, cp.SensorCmd.WINCH_LENGTH)] = (
                self._winch_length_frame)
            handlers[cp.frame_id(self.sensor_node, cp.SensorCmd.WINCH_TENSION)] = (
                self._winch_tension_frame)
            handlers[cp.frame_id(self.sensor_node, cp.SensorCmd.WINCH_HEARTBEAT)] = (
                self._winch_heartbeat_frame)
            handlers[cp.frame_id(self.sensor_node, cp.SensorCmd.WINCH_EXIT_ANGLE)] = (
                self._winch_exit_angle_frame)
        self._handlers = handlers
        # the answers' ids, worked out once (None for a node id no frame can carry: then no
        # encoder frame is ever handled, and nothing is sent to it)
        valid = 0 <= self.node <= cp.MAX_NODE_ID
        self._torque_id = cp.frame_id(self.node, cp.Cmd.SET_INPUT_TORQUE) if valid else None
        self._bus_request = (cp.Frame(cp.frame_id(self.node, cp.Cmd.GET_BUS_VOLTAGE_CURRENT),
                                      bytes(8), True) if valid else None)

    # ------------------------------------------------------------------------ inputs

    def set_uav(self, state: UavState | None, time_ms: int | None = None) -> None:
        """The UAV's latest (position [m], velocity [m/s]), z-up frame with the origin at
        the winder's exit, and the vehicle's time of it [ms] if known; ignored if None or
        not finite."""
        if state is None:
            return
        (px, py, pz), (vx, vy, vz) = state
        if _finite(px, py, pz, vx, vy, vz):
            self.uav = ((px, py, pz), (vx, vy, vz))
            self.uav_time_ms = time_ms

    def uav_now(self) -> UavState | None:
        """The UAV's state carried forward by its velocity to the winch's sample time
        (Winch_Tension's Sample_Time, the same clock as the vehicle's time_boot_ms in the
        simulator), when both times are known and the gap is between 0 and
        ``max_extrapolation_s``; otherwise as last reported."""
        if self.uav is None or self.uav_time_ms is None or self.sample_time_ms is None:
            return self.uav
        gap_ms = (self.sample_time_ms - self.uav_time_ms) & 0xFFFF
        if gap_ms >= 0x8000:
            gap_ms -= 0x10000                 # modulo 65.536 s: the nearer of the two
        gap = gap_ms * 1e-3
        if not 0.0 < gap <= self.p.max_extrapolation_s:
            return self.uav
        (px, py, pz), (vx, vy, vz) = self.uav
        return ((px + vx * gap, py + vy * gap, pz + vz * gap), (vx, vy, vz))

    @property
    def sensor_clock_s(self) -> float | None:
        """The winch sensor node's clock [s]: the last ``Winch_Tension`` Sample_Time,
        unwrapped from its 16 bits (the plant's simulated time), None before one came. A
        process in lockstep with the plant hands the winch this as its time
        (``python -m groundstation --clock frames``)."""
        c = self._sensor_clock_ms
        return None if c is None else c * 1e-3

    @property
    def braked(self) -> bool:
        """The winch keeps the axis IDLE (brake engaged): LOCK, HOLD, encoder lost, the
        bus degraded, or another host commanding the axis."""
        return self.mode in BRAKED_MODES or self.lost or self.bus_degraded or self.foreign_brake

    def taut_floor(self) -> tuple[float, float]:
        """(shortest safe length [m], its rate [m/s]): the straight-line distance to the
        UAV plus L-bar's minimum slack, at least the drum's full stop; (NaN, 0) while the
        UAV's position is unknown."""
        if self.uav is None:
            return math.nan, 0.0
        (px, py, pz), (vx, vy, vz) = self.uav
        d = math.sqrt(px * px + py * py + pz * pz)
        rate = (px * vx + py * vy + pz * vz) / d if d > 1e-9 else 0.0
        floor = d + self.min_slack_m
        if floor < self.length_min_m:
            return self.length_min_m, 0.0
        return floor, rate

    def reference(self) -> tuple[float, float]:
        """(length reference [m], its rate [m/s]) of the last control step."""
        return self.ref_m, self.ref_rate_m_s

    # --------------------------------------------------------------------- CAN frames

    def on_frame(self, wall_s: float, arbitration_id: int, data: bytes,
                 is_remote: bool = False) -> WinchOutput:
        """Handle one received CAN frame at wall time ``wall_s`` [s]."""
        out = self.handle_frame(wall_s, arbitration_id, data, is_remote)
        return WinchOutput() if out is None else out

    def handle_frame(self, wall_s: float, arbitration_id: int, data: bytes,
                     is_remote: bool = False) -> WinchOutput | None:
        """:meth:`on_frame`, None when there is nothing to send (most frames: the sensors',
        heartbeats, frames for other nodes)."""
        if is_remote:
            return None
        handler = self._handlers.get(arbitration_id)
        if handler is None:
            return None
        try:
            return handler(wall_s, data)
        except cp.CanFrameError:
            self.bad_frames += 1
            return None

    def _encoder_frame(self, wall_s: float, data: bytes) -> WinchOutput:
        pos_rev, vel_rev_s = cp.decode_encoder_estimates(data)
        return self._on_encoder(wall_s, pos_rev, vel_rev_s)

    def _axis_heartbeat_frame(self, wall_s: float, data: bytes) -> WinchOutput:
        return self._on_axis_heartbeat(cp.decode_heartbeat(data), wall_s)

    def _foreign_command(self, wall_s: float, cmd: cp.Cmd) -> WinchOutput | None:
        """A host-to-axis frame another host sent: counted, said at most every
        :data:`FOREIGN_NOTICE_S`, and the winch unhealthy for as long. The drum is braked
        at once (``Set_Axis_State`` IDLE: the axis applies no torque, whoever sends it)
        and stays braked until :data:`FOREIGN_NOTICE_S` pass without such a frame
        (:meth:`_foreign_quiet`) or an operator's ``DO_WINCH`` re-arms it; a frame that
        could take the axis out of IDLE is answered with IDLE at once."""
        self.foreign_commands += 1
        self._foreign_wall = wall_s
        out = None
        if not self.foreign_brake or cmd in REARMING_COMMANDS:
            out = WinchOutput(frames=[self._idle_frame()])
        if not self.foreign_brake:
            self.foreign_brake = True
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                       "winch: drum braked against another CAN host"))
        if wall_s - self._foreign_said_wall < FOREIGN_NOTICE_S:
            return out
        self._foreign_said_wall = wall_s
        out = out or WinchOutput()
        out.notices.insert(0, _notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                      f"winch: another CAN host sends {cmd.name}"))
        return out

    def _foreign_quiet(self, wall_s: float, out: WinchOutput) -> None:
        """End the brake against another host once it has sent nothing to the axis for
        :data:`FOREIGN_NOTICE_S`: the axis is re-armed and the mode resumes from the length
        the drum holds (RELAXED rejoins L-bar as after a pay-out)."""
        if self.foreign_brake and wall_s - self._foreign_wall >= FOREIGN_NOTICE_S:
            text = f"winch: no other CAN host for {FOREIGN_NOTICE_S:.0f} s"
            if self._end_foreign_brake():
                text += ", re-armed"
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE, text))

    def _end_foreign_brake(self) -> bool:
        """The drum released after the brake against another host: re-armed unless the
        winch brakes it for another reason or the axis was estopped (the operator's
        DO_WINCH re-arms that), the reference from the measured length. Returns whether
        it re-arms."""
        self.foreign_brake = False
        if (self.braked or not math.isfinite(self.length_m)
                or (self.axis_error or 0) & cp.ODriveError.ESTOP_REQUESTED):
            return False
        self._arm_pending = True
        self._resume_from(self.length_m)
        return True

    def _resume_from(self, length_m: float) -> None:
        """The active mode's reference taken up from ``length_m`` [m] after the drum was
        held: RELAXED rejoins L-bar (wound in on a trapezoid, or joined with a gap), the
        others ramp on from there."""
        if self.mode == WinchMode.RELAXED:
            self._hold_m = length_m
            self._ground = False
            uav = self.uav_now()
            lbar_m = self.host.lbar.length(uav[0])[0] if uav is not None else math.nan
            self._start_rejoin(length_m, lbar_m)
        else:
            self.ref_m, self.ref_rate_m_s = length_m, 0.0

    def _bus_voltage_current_frame(self, wall_s: float, data: bytes) -> None:
        self.voltage_v, self.current_a = cp.decode_bus_voltage_current(data)

    def _winch_length_frame(self, wall_s: float, data: bytes) -> None:
        length_m, speed_m_s = cp.decode_winch_length(data)
        if math.isfinite(length_m) and math.isfinite(speed_m_s):
            self.sensor_length_m, self.sensor_speed_m_s = length_m, speed_m_s

    def _winch_tension_frame(self, wall_s: float, data: bytes) -> None:
        last = self.sample_time_ms
        tension_n, self.sensor_brake, self.sample_time_ms = cp.decode_winch_tension(data)
        prev = self._sensor_clock_ms
        if prev is None:
            self._sensor_clock_ms = self.sample_time_ms
        else:
            d = (self.sample_time_ms - prev) & 0xFFFF
            self._sensor_clock_ms = prev + (d - 0x10000 if d >= 0x8000 else d)
        if math.isfinite(tension_n):
            self.tension_n = tension_n
        self._check_bus(last, self.sample_time_ms)

    def _check_bus(self, last_ms: int | None, stamp_ms: int) -> None:
        """The bus's health from the load cell's frames (100 Hz, stamped with the sample's
        time): the share lost (from the gaps between stamps) and how late they come (the
        UAV's latest position, which the component link brings, against the sample's
        stamp: the least of a window, so that a busy machine's lags do not count). Judged
        once a window of ``bus_window_s`` of stamps; a window with more than
        ``bus_lost_max`` lost or later than ``bus_late_max_s`` makes the bus degraded (the
        drum brakes, said in :meth:`_bus_notice`), ``bus_good_windows`` good ones in a row
        make it good again."""
        if last_ms is None:
            self._bus_window_start = stamp_ms
            return
        step = (stamp_ms - last_ms) & 0xFFFF
        if step == 0 or step >= 0x8000:
            return                                   # repeated or out of order
        # the frames' period: the nominal one, or the shortest step seen if longer (a plant
        # whose control period is longer than the sensors' sends them on its own grid)
        self._bus_min_step = min(self._bus_min_step, step)
        period_ms = max(1e3 / self.p.sensor_rate_hz, self._bus_min_step)
        frames = max(1, round(step / period_ms))
        self._bus_expected += frames
        self._bus_lost += frames - 1
        if self.uav_time_ms is not None:
            late = (self.uav_time_ms - stamp_ms) & 0xFFFF
            if late < 0x8000:
                self._bus_late_ms = min(self._bus_late_ms, late)
            else:
                self._bus_late_ms = min(self._bus_late_ms, 0)
        if ((stamp_ms - self._bus_window_start) & 0xFFFF) < self.p.bus_window_s * 1e3:
            return
        lost = self._bus_lost / self._bus_expected
        late_s = self._bus_late_ms * 1e-3 if self._bus_late_ms < 0x10000 else 0.0
        bad = lost > self.p.bus_lost_max or late_s > self.p.bus_late_max_s
        self._bus_window_start = stamp_ms
        self._bus_expected = self._bus_lost = 0
        self._bus_late_ms = 0x10000
        if bad:
            self._bus_good = 0
            if not self.bus_degraded:
                self.bus_degraded = True
                self._bus_said = (lost, late_s)
        elif self.bus_degraded:
            self._bus_good += 1
            if self._bus_good >= self.p.bus_good_windows:
                self.bus_degraded = False
                self._bus_said = None
                if self.mode not in BRAKED_MODES and not self.lost:
                    self._arm_pending = True

    def _bus_notice(self, out: WinchOutput) -> None:
        """Say a change of the bus's health (once each)."""
        if self.bus_degraded and self._bus_said is not None and not self._bus_noticed:
            lost, late_s = self._bus_said
            self._bus_noticed = True
            out.notices.append(_notice(
                mavlink2.MAV_SEVERITY_CRITICAL,
                f"winch: CAN bad ({lost:.0%} lost, {late_s * 1e3:.0f} ms), braked"))
        elif not self.bus_degraded and self._bus_noticed:
            self._bus_noticed = False
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE,
                                       "winch: CAN bus good again"))

    def _winch_exit_angle_frame(self, wall_s: float, data: bytes) -> None:
        az, el, stamp, valid = cp.decode_winch_exit_angle(data)
        # a direction no guide arm can read (below the ground, beyond the vertical, an
        # azimuth off the circle) is a bad frame: no fix from it
        if not (-math.pi <= az <= math.pi and -0.1 <= el <= 0.5 * math.pi):
            self.bad_frames += 1
            valid = False
        self.exit_angle = (az, el, stamp, valid)

    def _unwrap_ms(self, stamp_ms: int) -> int:
        """The winch's 16-bit clock [ms] as a full time: the nearest to the vehicle's
        time of its last position (the same clock in the simulator), else carried on from
        the last one unwrapped."""
        ref = self.uav_time_ms if self.uav_time_ms is not None else self._clock_ms
        if ref is None:
            full = stamp_ms
        else:
            d = (stamp_ms - ref) & 0xFFFF
            full = ref + (d - 0x10000 if d >= 0x8000 else d)
        self._clock_ms = full
        return full

    def _fix_inputs_valid(self) -> bool:
        """Whether length, tension and a valid exit angle no older than ``max_age_s``
        against the tension's sample are at hand for the tether fix."""
        fixer, ea = self.fixer, self.exit_angle
        if (fixer is None or ea is None or not ea[3] or self.sample_time_ms is None
                or not (math.isfinite(self.length_m) and math.isfinite(self.tension_n))
                or self.load_cell_healthy is False):
            return False
        gap_ms = (self.sample_time_ms - ea[2]) & 0xFFFF
        if gap_ms >= 0x8000:
            gap_ms -= 0x10000
        return abs(gap_ms) * 1e-3 <= fixer.p.max_age_s

    def _floor_need_m(self) -> float:
        """The least length [m] the slack floor asks at the winder's own fix now
        (:func:`groundstation.lbar.floor_length_m`; -inf without a fix or with the floor
        off): a rejoin of L-bar from a longer line stops there, since L-bar comes from the
        reported position (an in-air start 0.9 m low on its first fixes wound a 36 m line
        in taut before L-bar's law, which has the floor, took over)."""
        need = self.host.lbar.floor_need_m(self.measured_position_m())
        return need if math.isfinite(need) else -math.inf

    def measured_position_m(self) -> tuple[float, float, float] | None:
        """The UAV's position [m] as the winder itself measures it (its tether fix's mean
        from length, tension and exit angles, the line taken as hanging from the exit),
        None when the fix has no valid inputs: the slack floor's input
        (docs/control.md §3), whatever the vehicle reports or fuses."""
        if not self._fix_inputs_valid():
            return None
        fixer, ea = self.fixer, self.exit_angle
        assert fixer is not None and ea is not None
        # the tension as the trim low-passes it: a dynamic line's axial waves and snaps
        # (0-20 N at 20-25 Hz) would otherwise swing the fix, and the floor, which pays
        # out fast and takes back slowly, would ratchet the line out onto the ground
        lb = self.host.lbar
        return fixer.suspended_end(self.length_m, lb.drum_tension_n(self.tension_n), ea[0],
                                   ea[1], lb.weight_n_m())

    def tether_fix(self) -> TetherFix | None:
        """The UAV's position from length, tension and exit angles now, or None when one
        is missing, invalid or older than ``max_age_s`` against the tension's sample."""
        fixer, ea = self.fixer, self.exit_angle
        if not self._fix_inputs_valid():
            return None
        assert fixer is not None and ea is not None
        az, el, stamp, _ = ea
        if not fixer.readable(self.tension_n, el):
            return None
        reported = self.uav[0] if self.uav is not None else None
        pos, cov, ground = fixer.position(self.length_m, self.tension_n, az, el, reported,
                                          self.host.lbar.weight_n_m())
        self.fixes += 1
        return TetherFix(pos, cov, self._unwrap_ms(stamp), ground)

    def _winch_heartbeat_frame(self, wall_s: float, data: bytes) -> None:
        hb = cp.decode_winch_heartbeat(data)
        self.load_cell_healthy = hb.load_cell_healthy
        self.at_full_stop = hb.at_full_stop
        self.sensor_brake = hb.brake_engaged

    def _on_axis_heartbeat(self, hb: cp.Heartbeat, wall_s: float) -> WinchOutput:
        out = WinchOutput()
        if hb.axis_error and hb.axis_error != self.axis_error:
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                       f"winch: axis error 0x{hb.axis_error:08X}"))
        self.axis_error, self.axis_state = hb.axis_error, hb.axis_state
        closed = hb.axis_state == cp.AxisState.CLOSED_LOOP_CONTROL
        if closed:
            self._estop_noticed = False
        elif not self.braked and self.encoder_frames and not self._arm_pending:
            # the axis disarmed itself (watchdog after a stall, an error) while the winch
            # needs it: re-armed with the next encoder frame, at most every REARM_S; an
            # Estop is someone's act, and only a DO_WINCH (the operator's) re-arms it
            if hb.axis_error & cp.ODriveError.ESTOP_REQUESTED:
                if not self._estop_noticed:
                    self._estop_noticed = True
                    out.notices.append(_notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                               "winch: axis estopped; DO_WINCH re-arms"))
            elif wall_s - self._rearm_wall >= REARM_S:
                self._rearm_wall = wall_s
                self._arm_pending = True
                self.rearms += 1
                out.notices.append(_notice(mavlink2.MAV_SEVERITY_WARNING,
                                           f"winch: axis disarmed (0x{hb.axis_error:08X}), "
                                           "re-arming"))
        return out

    def _arm_frames(self) -> list[cp.Frame]:
        """Clear_Errors, torque control (passthrough), CLOSED_LOOP_CONTROL."""
        n = self.node
        return [
            cp.Frame(cp.frame_id(n, cp.Cmd.CLEAR_ERRORS), cp.encode_clear_errors()),
            cp.Frame(cp.frame_id(n, cp.Cmd.SET_CONTROLLER_MODE), cp.encode_set_controller_mode(
                cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH)),
            cp.Frame(cp.frame_id(n, cp.Cmd.SET_AXIS_STATE),
                     cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL)),
        ]

    def _idle_frame(self) -> cp.Frame:
        return cp.Frame(cp.frame_id(self.node, cp.Cmd.SET_AXIS_STATE),
                        cp.encode_set_axis_state(cp.AxisState.IDLE))

    def _on_encoder(self, wall_s: float, pos_rev: float, vel_rev_s: float) -> WinchOutput:
        out = WinchOutput()
        if not (math.isfinite(pos_rev) and math.isfinite(vel_rev_s)):
            self.bad_frames += 1
            return out
        self.encoder_frames += 1
        self._last_encoder_wall = wall_s
        self.length_m = pos_rev * _TWO_PI * self.r_w
        self.omega_rad_s = vel_rev_s * _TWO_PI
        if self.encoder_frames == 1:
            self._hold_m = self.length_m
            self._arm_pending = True
        if self.lost:
            self.lost = False
            self._arm_pending = True
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE, "winch: encoder back"))
        self._bus_notice(out)
        self._foreign_quiet(wall_s, out)
        if self.mode in BRAKED_MODES or self.bus_degraded or self.foreign_brake:
            out.frames.append(self._idle_frame())
            self._check_locked(out)
        else:
            if self._arm_pending:
                out.frames.extend(self._arm_frames())
                self.host.controller.reset()
                self._arm_pending = False
            torque = self._control(out)
            out.frames.append(cp.Frame(self._torque_id, cp.encode_set_input_torque(torque)))
            self.torque_commands += 1
        self._frames_since_fix += 1
        if self._frames_since_fix >= self.fix_every and self.fixer is not None:
            self._frames_since_fix = 0
            out.fix = self.tether_fix()
        self._frames_since_status += 1
        if self._frames_since_status >= self.status_every:
            out.status = self._status(wall_s)
            out.frames.append(self._bus_request)
        return out

    def _check_locked(self, out: WinchOutput) -> None:
        floor, _ = self.taut_floor()
        if (not self._lock_noticed and math.isfinite(floor)
                and self.length_m <= floor + self.p.retracted_tolerance_m):
            self._lock_noticed = True
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_WARNING,
                                       "winch: held drum, tether near taut"))

    # ------------------------------------------------------------------------- control

    def _check_tension(self, out: WinchOutput) -> bool:
        """Whether the over-tension pay-out acts for this encoder frame (said as it begins
        and ends)."""
        limit = self.p.tension_limit_n
        tension = self.tension_n
        if not self.over_tension:
            self._over_frames = self._over_frames + 1 if tension > limit else 0
            if self._over_frames * self.dt_s > self.p.overtension_s - 1e-9:
                self.over_tension = True
                out.notices.append(_notice(
                    mavlink2.MAV_SEVERITY_WARNING,
                    f"winch: over-tension {tension:.0f} N > {limit:.0f} N, paying out"))
        elif not tension >= 0.9 * limit:       # (NaN: the load cell silent ends it too)
            self.over_tension = False
            self._over_frames = 0
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE,
                                       f"winch: tension back below {limit:.0f} N"))
        return self.over_tension

    def _pay_out(self, length: float) -> None:
        """One period of the over-tension pay-out: the reference moves out from where it
        stands (at least the measured length) at ``overtension_rate_m_s``, and the active
        mode takes it from there afterwards (RELAXED winds back to L-bar as after any
        pay-out, the others hold it)."""
        rate = self.p.overtension_rate_m_s
        base = self.ref_m if math.isfinite(self.ref_m) else length
        if math.isfinite(length):
            base = max(base, length)
        self.ref_m = min(base + rate * self.dt_s, self.length_max_m)
        self.ref_rate_m_s = rate if self.ref_m < self.length_max_m else 0.0
        if self.mode == WinchMode.RELAXED:
            self._rejoin_m, self._rejoin_rate = self.ref_m, 0.0
            self._join_gap_m = self._join_rate = 0.0
            self._hold_m = self.ref_m
        else:
            self._target_m = self.ref_m
            if self.mode == WinchMode.RATE:
                self._speed_m_s = max(self._speed_m_s, 0.0)
            elif self.mode == WinchMode.RETRACT:
                self._retract_reached = True

    def _control(self, out: WinchOutput) -> float:
        """Torque [N m] for this encoder frame in the active (closed-loop) mode."""
        tension = self.tension_n if math.isfinite(self.tension_n) else 0.0
        length, omega = self.length_m, self.omega_rad_s
        if self._check_tension(out):
            self._pay_out(length)
            command = self.host.controller.update(self.dt_s, length, omega, tension,
                                                  self.ref_m, self.ref_rate_m_s)
        elif self.mode == WinchMode.RELAXED:
            uav = self.uav_now()
            if uav is not None and math.isfinite(self._rejoin_m):
                # rejoining L-bar from a longer line: wound in at rejoin_rate_m_s at most
                # a trapezoid: speeding up and slowing down at REJOIN_ACC_M_S2
                lbar_m = max(self.host.lbar.length(uav[0])[0], self._floor_need_m())
                dt = self.dt_s
                left = self._rejoin_m - lbar_m
                rate = self._trapezoid_speed(self._rejoin_rate, max(left, 0.0))
                if left <= max(rate * dt, 1e-3):
                    self._rejoin_m = math.nan      # there: L-bar's own law from now on
                else:
                    self._rejoin_rate = rate
                    self._rejoin_m -= rate * dt
                    self.ref_m, self.ref_rate_m_s = self._rejoin_m, -rate
            if self._check_slack(out, uav) or self._on_ground(uav):
                self._ground_reference()
                command = self.host.controller.update(self.dt_s, length, omega, tension,
                                                      self.ref_m, self.ref_rate_m_s)
            elif uav is not None and math.isfinite(self._rejoin_m):
                command = self.host.controller.update(self.dt_s, length, omega, tension,
                                                      self.ref_m, self.ref_rate_m_s)
            elif uav is not None:
                pos, vel = uav
                ea = self.exit_angle
                gap, closing = self._join_step()
                step = self.host.update(length, omega, tension, pos, vel,
                                        ea[1] if ea is not None and ea[3] else math.nan,
                                        self.measured_position_m(), -gap, closing)
                self.ref_m, self.ref_rate_m_s = step.lbar_m, step.lbar_rate_m_s
                if gap > 0.0:       # what the step left of it (less, where L-bar fell into it)
                    self._join_gap_m = self.host.lbar.join_gap_m
                command = step.command
            else:
                self.ref_m, self.ref_rate_m_s = self._hold_m, 0.0
                command = self.host.controller.update(self.dt_s, length, omega, tension,
                                                      self._hold_m, 0.0)
        else:
            self._advance_reference(out)
            command = self.host.controller.update(self.dt_s, length, omega, tension,
                                                  self.ref_m, self.ref_rate_m_s)
        self.last_command = command
        self._check_stuck(out, length)
        torque = command.torque_n_m
        return torque if math.isfinite(torque) else 0.0

    def _start_rejoin(self, start_m: float, lbar_m: float) -> None:
        """RELAXED's reference begins at the length ``start_m`` [m]: a line longer than
        L-bar (``lbar_m`` [m], NaN: unknown) by more than :data:`REJOIN_MARGIN_M` is wound
        in to it on a trapezoid; one shorter by more than :data:`JOIN_MARGIN_M` follows
        L-bar's law less a gap that closes on a trapezoid (:meth:`_join_step`); else L-bar's
        law takes it from there."""
        self._rejoin_m, self._rejoin_rate = math.nan, 0.0
        self._join_gap_m = self._join_rate = 0.0
        if not (math.isfinite(start_m) and math.isfinite(lbar_m)):
            return
        if start_m > lbar_m + REJOIN_MARGIN_M:
            self._rejoin_m = start_m
        elif start_m < lbar_m - JOIN_MARGIN_M:
            self._join_gap_m = lbar_m - start_m

    def _trapezoid_speed(self, speed_m_s: float, left_m: float) -> float:
        """This period's speed [m/s] of a rejoin or a join moving at ``speed_m_s`` with
        ``left_m`` [m] to go: at most ``rejoin_rate_m_s``, speeding up at
        :data:`REJOIN_ACC_M_S2`, and no faster than stops in what is left at it."""
        return min(self.p.rejoin_rate_m_s, speed_m_s + REJOIN_ACC_M_S2 * self.dt_s,
                   math.sqrt(2.0 * REJOIN_ACC_M_S2 * left_m))

    @property
    def join_gap_m(self) -> float:
        """How far short of L-bar's law the reference still is while it joins L-bar from a
        shorter line [m] (0: not joining)."""
        return self._join_gap_m

    def _join_step(self) -> tuple[float, float]:
        """This period's (gap [m], its closing speed [m/s]) of a join from a line shorter
        than L-bar: the gap closes at ``rejoin_rate_m_s`` at most, speeding up and slowing
        down at :data:`REJOIN_ACC_M_S2`, while L-bar's law moves the reference with the
        UAV (a climb away is paid out for at once); (0, 0) once closed. The gap defers a
        pay-out and never winds the line in: where the law's reference falls below the
        measured length plus the gap, it takes the gap with it (:func:`winder_step
        <groundstation.winder_host.winder_step>`)."""
        gap = self._join_gap_m
        if gap <= 0.0:
            return 0.0, 0.0
        dt = self.dt_s
        rate = self._trapezoid_speed(self._join_rate, gap)
        if gap <= max(rate * dt, 1e-4):
            gap, rate = 0.0, 0.0        # closed (the last step's at most this speed)
        else:
            gap -= rate * dt
        self._join_gap_m, self._join_rate = gap, rate
        return gap, rate

    def _check_slack(self, out: WinchOutput, uav: UavState | None) -> bool:
        """The slack guard of RELAXED; returns whether it holds the line now.

        The line counts as slack while the load cell reads below ``slack_tension_n`` and
        the guide arm reads no line leaving the exit above the ground: nothing pulls it.
        The line RELAXED pays out (net) while it stays slack is counted
        (:attr:`slack_paid_m`, back to 0 at any pull); beyond ``slack_payout_max_m`` it
        lies on the ground, where the vehicle is not taking it (a vehicle on the ground
        after a failure, flipped or landed, whose reported position runs away with a
        diverged estimate: the law followed it and paid out the whole tether). From then
        the drum holds the length and runs the ground pre-tension's loop, which pays out
        only as the line is pulled and winds in slowly to the pre-tension, its floor from
        the reported position stopping a wind-in but paying nothing out; said once. It
        ends when the line is pulled and the report agrees with what is out (L-bar within
        ``REJOIN_MARGIN_M`` of the length: a report still asking much more, or much less,
        which would wind the line in onto a vehicle elsewhere, is not followed), or with
        an operator's ``DO_WINCH``."""
        p = self.p
        length = self.length_m
        ea = self.exit_angle
        fixer = self.fixer
        ground_el = fixer.p.ground_elevation_rad if fixer is not None else 0.0
        leaves = (ea is not None and ea[3] and ea[1] >= ground_el
                  and self.sample_time_ms is not None
                  and ((self.sample_time_ms - ea[2] + 0x8000) & 0xFFFF) - 0x8000
                  <= 1e3 * p.bus_window_s)      # (a reading of this window, not a stale one)
        slack = self.tension_n < p.slack_tension_n and not leaves
        last, self._slack_length_m = self._slack_length_m, length
        if not slack:
            self.slack_paid_m = 0.0
        elif math.isfinite(last):
            self.slack_paid_m = max(0.0, self.slack_paid_m + length - last)
        if not self.slack_hold:
            if self.slack_paid_m > p.slack_payout_max_m:
                self.slack_hold = True
                self.ref_m, self.ref_rate_m_s = length, 0.0
                self._rejoin_m, self._rejoin_rate = math.nan, 0.0
                self._join_gap_m = self._join_rate = 0.0
                out.notices.append(_notice(
                    mavlink2.MAV_SEVERITY_CRITICAL,
                    f"winch: {self.slack_paid_m:.1f} m paid out slack, pay-out held"))
            return self.slack_hold
        if (not slack and uav is not None
                and abs(self.host.lbar.length(uav[0])[0] - length) <= REJOIN_MARGIN_M):
            self._end_slack_hold()
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE,
                                       "winch: line pulled, following L-bar again"))
        return self.slack_hold

    def _end_slack_hold(self) -> None:
        """The slack guard off: the law takes up from the measured length."""
        self.slack_hold = False
        self.slack_paid_m = 0.0
        if math.isfinite(self.length_m):
            self._resume_from(self.length_m)

    def _on_ground(self, uav: UavState | None) -> bool:
        """Whether RELAXED holds the ground pre-tension now (module docstring): the UAV on
        the ground by its report (or none yet), a load cell to hold it with. Leaving it, a
        line longer than L-bar rejoins it at ``rejoin_rate_m_s``."""
        p = self.p
        ground = p.ground_tension_n > 0.0 and math.isfinite(self.tension_n)
        if ground and uav is not None:
            pos = uav[0]
            low = pos[2] < p.ground_height_m and uav[1][2] < p.ground_climb_m_s
            # a take-off goes on holding it while L-bar would ask for a nearly straight
            # line (the UAV low and far: L-bar's horizontal tension a w far above its
            # target), which only an exact position keeps off taut
            if low:
                self._ground_low = True
            flat = (self._ground and self._ground_low and self.host.lbar.length(pos)[1]
                    > p.ground_lbar_tension_ratio * self.host.lbar.a_target)
            ground = low or flat
        if ground and not self._ground:
            self.ref_m, self.ref_rate_m_s = self.length_m, 0.0
            self._join_gap_m = self._join_rate = 0.0
        elif self._ground and not ground:
            lbar_m = self.host.lbar.length(uav[0])[0] if uav is not None else math.nan
            self._start_rejoin(self.length_m, lbar_m)
            self._hold_m = self.length_m
        self._ground = ground
        if not ground:
            self._ground_low = False
        return ground

    def _ground_reference(self) -> None:
        """One period of the pre-tension's length reference: paid out or wound in at a
        speed proportional to the tension's error (wound in at most at
        ``ground_tension_rate_m_s``, paid out at most at the law's speed limit, held
        instead while no UAV position is known), never below the taut floor while one is,
        nor past the drum's ends."""
        p, dt = self.p, self.dt_s
        rate = p.ground_tension_gain_m_s_n * (self.tension_n - p.ground_tension_n)
        # a pull above the pre-tension with no position known yet is held, as the drum
        # held its length before (a vehicle in the air the filter has not found)
        high = self.max_rate_m_s if self.uav is not None else 0.0
        rate = max(-p.ground_tension_rate_m_s, min(high, rate))
        ref = self.ref_m + rate * dt
        floor, _ = self.taut_floor()
        lower = max(floor, self.length_min_m) if math.isfinite(floor) else self.length_min_m
        if ref < lower:
            if not self.slack_hold:
                ref, rate = lower, 0.0
            elif rate < 0.0:
                # holding against a slack pay-out, the reported position is not to be
                # trusted: its floor stops a wind-in, it pays nothing out
                ref, rate = max(ref, min(self.ref_m, lower)), 0.0
        if ref > self.length_max_m:
            ref, rate = self.length_max_m, 0.0
        self.ref_m, self.ref_rate_m_s = ref, rate

    def _check_stuck(self, out: WinchOutput, length: float) -> None:
        """A drum that does not pay out as its reference asks (a snagged line, a jammed
        drum): the reference ``stuck_error_m`` ahead of the measured length, the line
        slower than ``stuck_speed_m_s`` (a drum catching up moves), for ``stuck_s`` of
        simulated time. While it is so the winch reports the drum braked
        (CLUTCH_ENGAGED: the vehicle bounds its reach by the length) and not HEALTHY (the
        vehicle's winder failsafe); said as it begins and ends. It ends when the reference
        is back within half of ``stuck_error_m`` and the drum has moved as far from where
        it stuck (it is free): a vehicle that stopped short of the snag (its tether
        governor) brings the reference back without freeing the drum."""
        behind = self.ref_m - length
        if not self.drum_stuck:
            lagging = (behind > self.p.stuck_error_m
                       and self.omega_rad_s * self.r_w < self.p.stuck_speed_m_s)
            self._stuck_frames = self._stuck_frames + 1 if lagging else 0
            if self._stuck_frames * self.dt_s > self.p.stuck_s - 1e-9:
                self.drum_stuck = True
                self._stuck_length_m = length
                out.notices.append(_notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                           f"winch: drum stuck at {length:.1f} m, no pay-out"))
        elif (behind < 0.5 * self.p.stuck_error_m
              and abs(length - self._stuck_length_m) > 0.5 * self.p.stuck_error_m):
            self.drum_stuck = False
            self._stuck_frames = 0
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_NOTICE,
                                       "winch: drum no longer behind its reference"))

    def _advance_reference(self, out: WinchOutput) -> None:
        """One period of the reference of modes 1, 2 and 6, then the safety limits."""
        dt = self.dt_s
        floor, floor_rate = self.taut_floor()
        if self.mode == WinchMode.RATE:
            self.ref_m += self._speed_m_s * dt
            self.ref_rate_m_s = self._speed_m_s
        else:
            if (self.mode == WinchMode.RETRACT and not self._retract_reached
                    and math.isfinite(floor)):
                self._target_m = floor
            diff = self._target_m - self.ref_m
            step = self._speed_m_s * dt
            if abs(diff) <= step:
                self.ref_m = self._target_m
                self.ref_rate_m_s = 0.0
                if self.mode == WinchMode.RETRACT:
                    self._retract_reached = True
            else:
                self.ref_m += math.copysign(step, diff)
                self.ref_rate_m_s = math.copysign(self._speed_m_s, diff)
        if math.isfinite(floor) and self.ref_m < floor:
            self.ref_m = floor
            self.ref_rate_m_s = max(self.ref_rate_m_s, floor_rate)
            if self.mode == WinchMode.RETRACT:
                self._retract_reached = True
                self._target_m = floor
            elif not self._limit_noticed:
                out.notices.append(_notice(mavlink2.MAV_SEVERITY_WARNING,
                                           f"winch: stopped at taut limit {floor:.2f} m"))
            self._limit_noticed = True
        if self.ref_m > self.length_max_m:
            self.ref_m = self.length_max_m
            self.ref_rate_m_s = min(self.ref_rate_m_s, 0.0)
            if not self._limit_noticed:
                out.notices.append(_notice(mavlink2.MAV_SEVERITY_WARNING,
                                           f"winch: stopped at drum end {self.length_max_m:.2f} m"))
            self._limit_noticed = True
        elif self.ref_m < self.length_min_m:
            self.ref_m = self.length_min_m
            self.ref_rate_m_s = max(self.ref_rate_m_s, 0.0)

    # ------------------------------------------------------------------------ the clock

    def poll(self, wall_s: float) -> WinchOutput:
        """Wall-clock duties at ``wall_s`` [s]: brake on encoder loss, and WINCH_STATUS
        when frames have not brought one for ``status_wall_period_s``."""
        out = WinchOutput()
        last = self._last_encoder_wall
        if (not self.lost and last is not None
                and wall_s - last > self.p.encoder_timeout_s):
            self.lost = True
            out.frames.append(self._idle_frame())
            out.notices.append(_notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                       "winch: encoder lost, drum braked"))
            out.status = self._status(wall_s)
        elif (self._last_status_wall is None
              or wall_s - self._last_status_wall >= self.p.status_wall_period_s):
            out.status = self._status(wall_s)
        return out

    def next_poll_s(self) -> float:
        """A wall time [s] before which :meth:`poll` has nothing to do (it may have nothing
        to do then either: it decides; -inf while a status is due at every call)."""
        last_status = self._last_status_wall
        if last_status is None:
            return -math.inf
        due = last_status + self.p.status_wall_period_s
        last = self._last_encoder_wall
        if not self.lost and last is not None:
            due = min(due, last + self.p.encoder_timeout_s)
        # a microsecond early: the sums above round, poll's differences decide
        return due - 1e-6

    # ------------------------------------------------------------------------- status

    def _foreign_recent(self) -> bool:
        """Whether another host commanded the axis within :data:`FOREIGN_NOTICE_S` of the
        last status."""
        last = self._last_status_wall
        return last is not None and last - self._foreign_wall < FOREIGN_NOTICE_S

    def status_flags(self) -> int:
        """``MAV_WINCH_STATUS_FLAG`` bits of the present state."""
        flags = 0
        axis_ok = self.braked or self.axis_state in (None, cp.AxisState.CLOSED_LOOP_CONTROL)
        if (self.encoder_frames and not self.lost and not self.axis_error and axis_ok
                and self.load_cell_healthy is not False and not self.drum_stuck
                and not self.bus_degraded
                and not self._foreign_recent()):
            flags |= FLAG_HEALTHY
        length = self._report_length()
        floor, _ = self.taut_floor()
        if self.at_full_stop or (math.isfinite(floor) and math.isfinite(length)
                                 and length <= floor + self.p.retracted_tolerance_m):
            flags |= FLAG_FULLY_RETRACTED
        if abs(self._report_speed()) > self.p.moving_speed_m_s:
            flags |= FLAG_MOVING
        if self.braked or self.sensor_brake or self.drum_stuck:
            flags |= FLAG_CLUTCH_ENGAGED
        if self.mode in BRAKED_MODES:
            flags |= FLAG_LOCKED
        if self.mode == WinchMode.RETRACT and not self._retract_reached:
            flags |= FLAG_RETRACTING
        return flags

    def _report_length(self) -> float:
        return self.sensor_length_m if math.isfinite(self.sensor_length_m) else self.length_m

    def _report_speed(self) -> float:
        if math.isfinite(self.sensor_speed_m_s):
            return self.sensor_speed_m_s
        return 0.0 if self.lost else self.omega_rad_s * self.r_w

    def _status(self, wall_s: float) -> WinchStatusReport | None:
        """The WINCH_STATUS to send now, or None while no length is known."""
        length = self._report_length()
        if not math.isfinite(length):
            return None
        self._frames_since_status = 0
        self._last_status_wall = wall_s
        return WinchStatusReport(length, self._report_speed(), self.tension_n / self.g,
                                 self.voltage_v, self.current_a, TEMPERATURE_UNKNOWN,
                                 self.status_flags())

    # ----------------------------------------------------------------------- commands

    def command(self, req: CommandRequest, wall_s: float) -> CommandReply | None:
        """Handle a COMMAND_LONG/COMMAND_INT; returns the COMMAND_ACK to send, or None when
        the command is not for this component (no ACK)."""
        if req.target_system not in (cl.SYSTEM_ID, 0):
            return None
        if req.command != mavlink2.MAV_CMD_DO_WINCH:
            if req.target_component == cl.WINCH_COMPONENT_ID:
                return self._reply(req, mavlink2.MAV_RESULT_UNSUPPORTED)
            return None
        if req.target_component not in cl.DO_WINCH_TARGET_COMPONENTS:
            return None
        last = self._last_command
        if (req.confirmation > 0 and last is not None and last[0] == _identity(req)
                and wall_s - last[1] <= self.p.duplicate_window_s):
            return last[2]._replace(notices=())
        reply = self._execute(req)
        self._last_command = (_identity(req), wall_s, reply)
        return reply

    def _reply(self, req: CommandRequest, result: int, *notices: Notice) -> CommandReply:
        return CommandReply(req.command, result, req.source_system, req.source_component,
                            tuple(notices))

    def _execute(self, req: CommandRequest) -> CommandReply:
        instance, action, length, rate = req.param1, req.param2, req.param3, req.param4
        sev_warn = mavlink2.MAV_SEVERITY_WARNING
        denied = mavlink2.MAV_RESULT_DENIED
        if not _finite(instance) or instance not in cl.WINCH_INSTANCES:
            return self._reply(req, denied, _notice(sev_warn, f"winch: no instance {instance}"))
        if not _finite(action) or action != int(action):
            return self._reply(req, denied, _notice(sev_warn, f"winch: bad action {action}"))
        action = int(action)
        if action in UNSUPPORTED_ACTIONS:
            name = mavlink2.enums["WINCH_ACTIONS"][action].name.removeprefix("WINCH_")
            return self._reply(req, mavlink2.MAV_RESULT_UNSUPPORTED,
                               _notice(mavlink2.MAV_SEVERITY_INFO, f"winch: {name} unsupported"))
        if action not in WinchMode._value2member_map_:
            return self._reply(req, denied, _notice(sev_warn, f"winch: bad action {action}"))
        mode = WinchMode(action)
        if mode == WinchMode.RELATIVE_LENGTH and not _finite(length):
            return self._reply(req, denied, _notice(sev_warn, "winch: length is NaN"))
        if mode == WinchMode.RATE and not _finite(rate):
            return self._reply(req, denied, _notice(sev_warn, "winch: rate is NaN"))
        moves = mode in (WinchMode.RELATIVE_LENGTH, WinchMode.RATE, WinchMode.RETRACT)
        if moves and (self.lost or not self.encoder_frames):
            return self._reply(req, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED,
                               _notice(sev_warn, "winch: no encoder, command rejected"))
        if mode == WinchMode.RETRACT and self.uav is None:
            return self._reply(req, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED,
                               _notice(sev_warn, "winch: no UAV position, cannot retract"))

        notices: list[Notice] = []
        if moves:
            if mode == WinchMode.RATE:
                speed = rate
            elif _finite(rate) and rate != 0.0:
                speed = abs(rate)
            else:
                speed = (self.p.retract_rate_m_s if mode == WinchMode.RETRACT
                         else self.p.default_rate_m_s)
            if abs(speed) > self.max_rate_m_s:
                speed = math.copysign(self.max_rate_m_s, speed)
                notices.append(_notice(sev_warn, f"winch: rate clamped to {speed:.2f} m/s"))
        self.slack_hold = False         # (the operator's act: RELAXED counts afresh)
        self.slack_paid_m = 0.0
        self._slack_length_m = math.nan
        if self.foreign_brake and mode not in BRAKED_MODES:
            # the operator's act releases the brake against another host (the next frame
            # of that host, if it goes on, brakes the drum again)
            self.foreign_brake = False
            self._arm_pending = not self.lost
        disarmed = (self.axis_state is not None
                    and self.axis_state != cp.AxisState.CLOSED_LOOP_CONTROL)
        if mode not in BRAKED_MODES and not self.lost and (self.mode in BRAKED_MODES
                                                           or disarmed):
            # leaving LOCK/HOLD, or the axis disarmed itself (watchdog, errors): re-arm
            self._arm_pending = True
        self.mode = mode
        self._limit_noticed = False
        self._lock_noticed = False
        self._retract_reached = False
        start = self.length_m
        if mode == WinchMode.RELAXED:
            self._hold_m = start
            self._ground = False
            # a line longer than L-bar (after a pay-out) is wound back in at a bounded rate
            uav = self.uav_now()
            lbar_m = self.host.lbar.length(uav[0])[0] if uav is not None else math.nan
            self._start_rejoin(start, lbar_m)
        elif mode == WinchMode.RELATIVE_LENGTH:
            self.ref_m, self._speed_m_s = start, speed
            target = start + length
            floor, _ = self.taut_floor()
            lower = max(floor, self.length_min_m) if math.isfinite(floor) else self.length_min_m
            if target < lower:
                target = lower
                self._limit_noticed = True
                notices.append(_notice(sev_warn, f"winch: length clamped to {target:.2f} m"))
            elif target > self.length_max_m:
                target = self.length_max_m
                self._limit_noticed = True
                notices.append(_notice(sev_warn, f"winch: length clamped to {target:.2f} m"))
            self._target_m = target
        elif mode == WinchMode.RATE:
            self.ref_m, self._speed_m_s = start, speed
        elif mode == WinchMode.RETRACT:
            self.ref_m, self._speed_m_s = start, speed
            self._target_m = self.taut_floor()[0]
            notices.append(_notice(mavlink2.MAV_SEVERITY_INFO,
                                   f"winch: retracting to {self._target_m:.2f} m"))
        return self._reply(req, mavlink2.MAV_RESULT_ACCEPTED, *notices)
