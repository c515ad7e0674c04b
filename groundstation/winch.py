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

Modes (the ``WINCH_ACTIONS`` value of the last accepted ``DO_WINCH``), one class each
behind one interface (:class:`groundstation.winch_modes.ModeLogic`), the winch holding one
of each and dispatching to the active one:

- ``WINCH_RELAXED`` (0, the default): the drum follows L-bar, holds a ground pre-tension
  while the UAV is on the ground or unknown, rejoins or joins L-bar from another length,
  and guards against paying out slack (:class:`groundstation.winch_relaxed.Relaxed`).
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

The shared parts have rooms of their own: the axis's CAN talk (arming, IDLE, re-arms,
another host: ``groundstation/winch_axis.py``), the sensor node's readings, the tether
fix and the tension's source, the load cell or the motor's current
(``groundstation/winch_sensors.py``, ``groundstation/winch_current.py``), the bus's health
(``groundstation/winch_bus.py``), what the winch says and is asked
(``groundstation/winch_report.py``), its settings (``groundstation/winch_params.py``).

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

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.tension_law import Z_STARTED, hold_speed
from groundstation.tether_fix import TetherFix, TetherFixer, TetherFixParams
from groundstation.winch_axis import (
    FOREIGN_NOTICE_S,
    HOST_COMMANDS,
    REARM_S,
    REARMING_COMMANDS,
    AxisLink,
)
from groundstation.winch_bus import BusHealth
from groundstation.winch_current import CurrentTension
from groundstation.winch_modes import (
    BRAKED_MODES,
    JOIN_MARGIN_M,
    REJOIN_ACC_M_S2,
    REJOIN_MARGIN_M,
    Braked,
    ModeLogic,
    Rate,
    RelativeLength,
    Retract,
    WinchMode,
)
from groundstation.winch_params import ENCODER_TIMEOUT_S, WinchParams
from groundstation.winch_relaxed import Relaxed
from groundstation.winch_report import (
    FLAG_CLUTCH_ENGAGED,
    FLAG_FULLY_RETRACTED,
    FLAG_HEALTHY,
    FLAG_LOCKED,
    FLAG_MOVING,
    FLAG_RETRACTING,
    STATUSTEXT_MAX_LEN,
    TEMPERATURE_UNKNOWN,
    CommandReply,
    CommandRequest,
    Notice,
    WinchOutput,
    WinchStatusReport,
    notice,
)
from groundstation.winch_sensors import WinchSensors
from groundstation.winder_control import WinderCommand
from groundstation.winder_host import WinderHost
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl
from tuavdefs.params import TetherParams, WinderParams

__all__ = [
    "BRAKED_MODES", "ENCODER_TIMEOUT_S", "FLAG_CLUTCH_ENGAGED", "FLAG_FULLY_RETRACTED",
    "FLAG_HEALTHY", "FLAG_LOCKED", "FLAG_MOVING", "FLAG_RETRACTING", "FOREIGN_NOTICE_S",
    "HOST_COMMANDS", "JOIN_MARGIN_M", "REARMING_COMMANDS", "REARM_S", "REJOIN_ACC_M_S2",
    "REJOIN_MARGIN_M", "STATUSTEXT_MAX_LEN", "TEMPERATURE_UNKNOWN", "UNSUPPORTED_ACTIONS",
    "CommandReply", "CommandRequest", "Notice", "Winch", "WinchMode", "WinchOutput",
    "WinchParams", "WinchStatusReport",
]

Vec3 = tuple[float, float, float]
UavState = tuple[Vec3, Vec3]

_TWO_PI = 2.0 * math.pi

#: ``WINCH_ACTIONS`` this winch does not implement (ACK UNSUPPORTED).
UNSUPPORTED_ACTIONS = frozenset({mavlink2.WINCH_DELIVER, mavlink2.WINCH_LOAD_LINE,
                                 mavlink2.WINCH_ABANDON_LINE, mavlink2.WINCH_LOAD_PAYLOAD})


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
    """The winch component's behaviour (module docstring): the active mode's length
    reference, the brake, encoder-loss handling, the safety checks and the status, around
    a :class:`WinderHost`.

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
        #: the sensor node's readings and the tether fix (groundstation.winch_sensors)
        self.sensors = WinchSensors(
            TetherFixer.for_tether(fp, tether, gravity_m_s2) if fp.enabled else None,
            CurrentTension(self.p.motor_torque_constant_nm_a, winder.drum_radius_m,
                           winder.viscous_friction_n_m_s_rad, host.controller.inertia_kg_m2,
                           self.p.current_filter_s, host.dt_s),
            self.p)
        self.fix_every = max(1, round(1.0 / (fp.rate_hz * host.dt_s)))
        self._frames_since_fix = 0
        #: the winder's axis as this host commands it (groundstation.winch_axis)
        self.axis = AxisLink(axis_node_id)
        #: the CAN bus's health (groundstation.winch_bus)
        self.bus = BusHealth(self.p)
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

        #: one object a mode, kept across switches (each mode's state its own)
        self.relaxed = Relaxed()
        self.modes: dict[WinchMode, ModeLogic] = {
            WinchMode.RELAXED: self.relaxed, WinchMode.RELATIVE_LENGTH: RelativeLength(),
            WinchMode.RATE: Rate(), WinchMode.RETRACT: Retract(),
            WinchMode.LOCK: Braked(WinchMode.LOCK), WinchMode.HOLD: Braked(WinchMode.HOLD)}
        #: the active mode
        self.active: ModeLogic = self.relaxed
        self.encoder_frames = 0
        self.torque_commands = 0
        self.bad_frames = 0
        self.lost = False
        self._last_encoder_wall: float | None = None
        # the encoder's measurements
        self.length_m = math.nan            # [m]
        self.omega_rad_s = 0.0
        self.uav: UavState | None = None
        self.uav_time_ms: int | None = None
        #: the length reference [m] and its rate [m/s] of the last control step
        self.ref_m = math.nan
        self.ref_rate_m_s = 0.0
        #: whether a limit of the reference (or the held drum's) was said for this command
        self.limit_noticed = False
        self.lock_noticed = False
        self._over_frames = 0               # encoder frames in a row above the limit
        self._stuck_frames = 0              # encoder frames in a row behind the reference
        self._stuck_length_m = math.nan     # the length at which the drum was found stuck
        #: Whether the drum does not pay out as asked (a snag: :meth:`_check_stuck`).
        self.drum_stuck = False
        #: Whether the over-tension pay-out is on.
        self.over_tension = False
        #: the torque law's last output (torque, Lyapunov function, ...), for diagnostics
        self.last_command: WinderCommand | None = None
        # reporting
        self._frames_since_status = 0
        self._last_status_wall: float | None = None
        self._last_command: tuple[tuple, float, CommandReply] | None = None
        self._handlers = self._frame_handlers()

    def _frame_handlers(self) -> dict[int, Callable[[float, bytes], WinchOutput | None]]:
        """The frames this winch reads, by 11-bit id (a sensor node sharing the axis's
        node id takes all of that node's frames)."""
        handlers: dict[int, Callable[[float, bytes], WinchOutput | None]] = {}
        node, sensors = self.node, self.sensors
        if 0 <= node <= cp.MAX_NODE_ID and node != self.sensor_node:
            handlers[cp.frame_id(node, cp.Cmd.GET_ENCODER_ESTIMATES)] = self._encoder_frame
            handlers[cp.frame_id(node, cp.Cmd.HEARTBEAT)] = self._axis_heartbeat_frame
            handlers[cp.frame_id(node, cp.Cmd.GET_BUS_VOLTAGE_CURRENT)] = (
                lambda wall_s, data: sensors.on_bus_voltage_current(data))
            handlers[cp.frame_id(node, cp.Cmd.GET_IQ)] = (
                lambda wall_s, data: sensors.on_iq(data))
            # what only a host sends: this process never hears its own frames, so these
            # come from a second host on the bus
            for cmd in HOST_COMMANDS:
                handlers[cp.frame_id(node, cmd)] = (
                    lambda wall_s, data, cmd=cmd: self.axis.on_foreign(wall_s, cmd))
        if 0 <= self.sensor_node <= cp.MAX_NODE_ID:
            sn = self.sensor_node
            handlers[cp.frame_id(sn, cp.SensorCmd.WINCH_LENGTH)] = (
                lambda wall_s, data: sensors.on_length(data))
            handlers[cp.frame_id(sn, cp.SensorCmd.WINCH_TENSION)] = self._winch_tension_frame
            handlers[cp.frame_id(sn, cp.SensorCmd.WINCH_HEARTBEAT)] = (
                lambda wall_s, data: sensors.on_heartbeat(data))
            handlers[cp.frame_id(sn, cp.SensorCmd.WINCH_EXIT_ANGLE)] = self._exit_angle_frame
        return handlers

    # ------------------------------------------------------------- what others read

    @property
    def mode(self) -> WinchMode:
        """The active mode."""
        return self.active.mode

    @property
    def tension_n(self) -> float:
        """The load cell's last finite tension [N] (NaN: none yet)."""
        return self.sensors.tension_n

    @property
    def exit_angle(self) -> tuple[float, float, int, bool] | None:
        """The guide arm's last reading (groundstation.winch_sensors)."""
        return self.sensors.exit_angle

    @property
    def fixer(self) -> TetherFixer | None:
        """The tether fix's solver, None when the fix is off."""
        return self.sensors.fixer

    @property
    def fixes(self) -> int:
        """Tether fixes computed."""
        return self.sensors.fixes

    @property
    def foreign_brake(self) -> bool:
        """Whether the drum is braked against another host commanding the axis."""
        return self.axis.foreign_brake

    @property
    def foreign_commands(self) -> int:
        """Host-to-axis frames on the axis's ids this process did not send."""
        return self.axis.foreign_commands

    @property
    def rearms(self) -> int:
        """Times the axis was re-armed after it had disarmed itself."""
        return self.axis.rearms

    @property
    def bus_degraded(self) -> bool:
        """Whether the CAN bus loses or delays too much (the drum braked)."""
        return self.bus.degraded

    @property
    def slack_hold(self) -> bool:
        """Whether RELAXED holds the line against a pay-out nothing pulls."""
        return self.relaxed.slack_hold

    @property
    def slack_paid_m(self) -> float:
        """Line paid out (net) by RELAXED since the line was last pulled [m]."""
        return self.relaxed.slack_paid_m

    @property
    def join_gap_m(self) -> float:
        """How far short of L-bar's law the reference still is while it joins L-bar from a
        shorter line [m] (0: not joining)."""
        return self.relaxed.join_gap_m

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
        sample = self.sensors.sample_time_ms
        if self.uav is None or self.uav_time_ms is None or sample is None:
            return self.uav
        gap_ms = (sample - self.uav_time_ms) & 0xFFFF
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
        return self.sensors.sensor_clock_s

    @property
    def braked(self) -> bool:
        """The winch keeps the axis IDLE (brake engaged): LOCK, HOLD, encoder lost, the
        bus degraded, or another host commanding the axis."""
        return (self.active.brakes or self.lost or self.bus.degraded
                or self.axis.foreign_brake)

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

    def law_tension_n(self) -> float:
        """The drum tension [N] the law takes: the load cell's, 0 before one came."""
        t = self.sensors.tension_n
        return t if math.isfinite(t) else 0.0

    def exit_elevation_rad(self) -> float:
        """The guide arm's valid exit elevation [rad], NaN without one."""
        ea = self.sensors.exit_angle
        return ea[1] if ea is not None and ea[3] else math.nan

    def track(self, ref_m: float, ref_rate_m_s: float) -> WinderCommand:
        """One step of the length law tracking ``ref_m`` [m] moving at ``ref_rate_m_s``
        [m/s] from the measured length, drum rate and tension."""
        return self.host.controller.update(self.dt_s, self.length_m, self.omega_rad_s,
                                           self.law_tension_n(), ref_m, ref_rate_m_s)

    def floor_need_m(self) -> float:
        """The least length [m] the slack floor asks at the winder's own fix now
        (:func:`groundstation.lbar.floor_length_m`; -inf without a fix or with the floor
        off): a rejoin of L-bar from a longer line stops there, since L-bar comes from the
        reported position (an in-air start 0.9 m low on its first fixes wound a 36 m line
        in taut before L-bar's law, which has the floor, took over)."""
        need = self.host.lbar.floor_need_m(self.measured_position_m())
        return need if math.isfinite(need) else -math.inf

    def measured_position_m(self) -> Vec3 | None:
        """The UAV's position [m] as the winder itself measures it (its tether fix's mean,
        :meth:`WinchSensors.measured_position_m
        <groundstation.winch_sensors.WinchSensors.measured_position_m>`), None when the
        fix has no valid inputs: the slack floor's input (docs/control.md §3)."""
        return self.sensors.measured_position_m(self.length_m, self.host.lbar)

    def tether_fix(self) -> TetherFix | None:
        """The UAV's position from length, tension and exit angles now, or None when one
        is missing, invalid or older than ``max_age_s`` against the tension's sample."""
        reported = self.uav[0] if self.uav is not None else None
        return self.sensors.tether_fix(self.length_m, reported, self.uav_time_ms,
                                       self.host.lbar)

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
        return self.axis.on_heartbeat(cp.decode_heartbeat(data), wall_s,
                                      not self.braked and bool(self.encoder_frames))

    def _winch_tension_frame(self, wall_s: float, data: bytes) -> None:
        last = self.sensors.on_tension(data)
        if (self.bus.on_stamp(last, self.sensors.sample_time_ms, self.uav_time_ms)
                and not self.active.brakes and not self.lost):
            self.axis.arm_pending = True

    def _exit_angle_frame(self, wall_s: float, data: bytes) -> None:
        if not self.sensors.on_exit_angle(data):
            self.bad_frames += 1

    def _foreign_quiet(self, wall_s: float, out: WinchOutput) -> None:
        """End the brake against another host once it has sent nothing to the axis for
        :data:`FOREIGN_NOTICE_S`: the axis is re-armed and the mode resumes from the length
        the drum holds (RELAXED rejoins L-bar as after a pay-out)."""
        if self.axis.foreign_quiet(wall_s):
            text = f"winch: no other CAN host for {FOREIGN_NOTICE_S:.0f} s"
            if self._end_foreign_brake():
                text += ", re-armed"
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE, text))

    def _end_foreign_brake(self) -> bool:
        """The drum released after the brake against another host: re-armed unless the
        winch brakes it for another reason or the axis was estopped (the operator's
        DO_WINCH re-arms that), the reference from the measured length. Returns whether
        it re-arms."""
        self.axis.foreign_brake = False
        if self.braked or not math.isfinite(self.length_m) or self.axis.estopped:
            return False
        self.axis.arm_pending = True
        self.active.resume_from(self, self.length_m)
        return True

    def _on_encoder(self, wall_s: float, pos_rev: float, vel_rev_s: float) -> WinchOutput:
        out = WinchOutput()
        if not (math.isfinite(pos_rev) and math.isfinite(vel_rev_s)):
            self.bad_frames += 1
            return out
        axis = self.axis
        self.encoder_frames += 1
        self._last_encoder_wall = wall_s
        self.length_m = pos_rev * _TWO_PI * self.r_w
        self.omega_rad_s = vel_rev_s * _TWO_PI
        said = self.sensors.on_encoder(self.length_m, self.omega_rad_s,
                                       not (self.braked or axis.disarmed or axis.arm_pending))
        if said is not None:
            out.notices.append(said)
        if self.encoder_frames == 1:
            self.relaxed.hold_m = self.length_m
            axis.arm_pending = True
        if self.lost:
            self.lost = False
            axis.arm_pending = True
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE, "winch: encoder back"))
        self.bus.notice(out)
        self._foreign_quiet(wall_s, out)
        if self.active.brakes or self.bus.degraded or axis.foreign_brake:
            out.frames.append(axis.idle_frame())
            self._check_locked(out)
        else:
            if axis.arm_pending:
                out.frames.extend(axis.arm_frames())
                self.host.controller.reset()
                axis.arm_pending = False
            torque = self._control(out)
            out.frames.append(axis.torque_frame(torque))
            self.torque_commands += 1
        self._frames_since_fix += 1
        if self._frames_since_fix >= self.fix_every and self.sensors.fixer is not None:
            self._frames_since_fix = 0
            out.fix = self.tether_fix()
        self._frames_since_status += 1
        if self._frames_since_status >= self.status_every:
            out.status = self._status(wall_s)
            out.frames.append(axis.bus_request)
        return out

    def _check_locked(self, out: WinchOutput) -> None:
        floor, _ = self.taut_floor()
        if (not self.lock_noticed and math.isfinite(floor)
                and self.length_m <= floor + self.p.retracted_tolerance_m):
            self.lock_noticed = True
            out.notices.append(notice(mavlink2.MAV_SEVERITY_WARNING,
                                      "winch: held drum, tether near taut"))

    # ------------------------------------------------------------------------- control

    def _check_tension(self, out: WinchOutput) -> bool:
        """Whether the over-tension pay-out acts for this encoder frame (said as it begins
        and ends)."""
        limit = self.p.tension_limit_n
        tension = self.sensors.tension_n
        if not self.over_tension:
            self._over_frames = self._over_frames + 1 if tension > limit else 0
            if self._over_frames * self.dt_s > self.p.overtension_s - 1e-9:
                self.over_tension = True
                out.notices.append(notice(
                    mavlink2.MAV_SEVERITY_WARNING,
                    f"winch: over-tension {tension:.0f} N > {limit:.0f} N, paying out"))
        elif not tension >= 0.9 * limit:       # (NaN: the load cell silent ends it too)
            self.over_tension = False
            self._over_frames = 0
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE,
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
        self.active.after_pay_out(self)

    def _control(self, out: WinchOutput) -> float:
        """Torque [N m] for this encoder frame in the active (closed-loop) mode."""
        length = self.length_m
        if self._check_tension(out):
            self._pay_out(length)
            command = self.track(self.ref_m, self.ref_rate_m_s)
        else:
            command = self.active.control(self, out)
        self.last_command = command
        self._check_stuck(out, length, command)
        torque = command.torque_n_m
        return torque if math.isfinite(torque) else 0.0

    def _check_stuck(self, out: WinchOutput, length: float, command: WinderCommand) -> None:
        """A drum that does not pay out as its law asks (a snag, a jam) for ``stuck_s``:
        the reference ``stuck_error_m`` ahead of the length with the drum standing (its
        line within ``stuck_speed_m_s`` either way); or, under the tension law, the drum
        standing while its law asks no wind-in and the pull is ``stuck_tension_n`` above
        the set-point (a free drum renders to it at once: docs/control.md §8.5). Reported
        braked (CLUTCH_ENGAGED) and not HEALTHY, said as it begins and ends, the tension
        law's speed set-point held at the drum's meanwhile (anti-windup). It ends with the reference
        within half of ``stuck_error_m`` and the drum moved as far from where it stuck."""
        behind, speed = self.ref_m - length, self.omega_rad_s * self.r_w
        ctl = self.host.controller
        tension_law = ctl.tension_state[Z_STARTED] > 0.0   # (the length law's step unsets it)
        if not self.drum_stuck:
            standing = abs(speed) < self.p.stuck_speed_m_s
            lagging = behind > self.p.stuck_error_m and standing
            if tension_law and not lagging:
                lagging = (standing and command.rate_cmd_rad_s >= 0.0
                           and command.e_length_m > self.p.stuck_tension_n)
            self._stuck_frames = self._stuck_frames + 1 if lagging else 0
            if self._stuck_frames * self.dt_s > self.p.stuck_s - 1e-9:
                self.drum_stuck = True
                self._stuck_length_m = length
                out.notices.append(notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                          f"winch: drum stuck at {length:.1f} m, no pay-out"))
        elif (behind < 0.5 * self.p.stuck_error_m
              and abs(length - self._stuck_length_m) > 0.5 * self.p.stuck_error_m):
            self.drum_stuck = False
            self._stuck_frames = 0
            out.notices.append(notice(mavlink2.MAV_SEVERITY_NOTICE,
                                      "winch: drum no longer behind its reference"))
        if self.drum_stuck and tension_law:
            hold_speed(ctl.tension_state, speed)

    # ------------------------------------------------------------------------ the clock

    def poll(self, wall_s: float) -> WinchOutput:
        """Wall-clock duties at ``wall_s`` [s]: brake on encoder loss, and WINCH_STATUS
        when frames have not brought one for ``status_wall_period_s``."""
        out = WinchOutput()
        last = self._last_encoder_wall
        if (not self.lost and last is not None
                and wall_s - last > self.p.encoder_timeout_s):
            self.lost = True
            out.frames.append(self.axis.idle_frame())
            out.notices.append(notice(mavlink2.MAV_SEVERITY_CRITICAL,
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

    def status_flags(self) -> int:
        """``MAV_WINCH_STATUS_FLAG`` bits of the present state."""
        flags = 0
        axis, sensors = self.axis, self.sensors
        axis_ok = self.braked or axis.axis_state in (None, cp.AxisState.CLOSED_LOOP_CONTROL)
        if (self.encoder_frames and not self.lost and not axis.axis_error and axis_ok
                and sensors.load_cell_healthy is not False and not self.drum_stuck
                and not self.bus.degraded
                and not axis.foreign_recent(self._last_status_wall)):
            flags |= FLAG_HEALTHY
        length = self._report_length()
        floor, _ = self.taut_floor()
        if sensors.at_full_stop or (math.isfinite(floor) and math.isfinite(length)
                                 and length <= floor + self.p.retracted_tolerance_m):
            flags |= FLAG_FULLY_RETRACTED
        if abs(self._report_speed()) > self.p.moving_speed_m_s:
            flags |= FLAG_MOVING
        if self.braked or sensors.sensor_brake or self.drum_stuck:
            flags |= FLAG_CLUTCH_ENGAGED
        if self.active.brakes:
            flags |= FLAG_LOCKED
        if self.active.retracting:
            flags |= FLAG_RETRACTING
        return flags

    def _report_length(self) -> float:
        length = self.sensors.sensor_length_m
        return length if math.isfinite(length) else self.length_m

    def _report_speed(self) -> float:
        speed = self.sensors.sensor_speed_m_s
        if math.isfinite(speed):
            return speed
        return 0.0 if self.lost else self.omega_rad_s * self.r_w

    def _status(self, wall_s: float) -> WinchStatusReport | None:
        """The WINCH_STATUS to send now, or None while no length is known."""
        length = self._report_length()
        if not math.isfinite(length):
            return None
        self._frames_since_status = 0
        self._last_status_wall = wall_s
        sensors = self.sensors
        return WinchStatusReport(length, self._report_speed(), sensors.tension_n / self.g,
                                 sensors.voltage_v, sensors.current_a, TEMPERATURE_UNKNOWN,
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
            return self._reply(req, denied, notice(sev_warn, f"winch: no instance {instance}"))
        if not _finite(action) or action != int(action):
            return self._reply(req, denied, notice(sev_warn, f"winch: bad action {action}"))
        action = int(action)
        if action in UNSUPPORTED_ACTIONS:
            name = mavlink2.enums["WINCH_ACTIONS"][action].name.removeprefix("WINCH_")
            return self._reply(req, mavlink2.MAV_RESULT_UNSUPPORTED,
                               notice(mavlink2.MAV_SEVERITY_INFO, f"winch: {name} unsupported"))
        if action not in WinchMode._value2member_map_:
            return self._reply(req, denied, notice(sev_warn, f"winch: bad action {action}"))
        mode = WinchMode(action)
        if mode == WinchMode.RELATIVE_LENGTH and not _finite(length):
            return self._reply(req, denied, notice(sev_warn, "winch: length is NaN"))
        if mode == WinchMode.RATE and not _finite(rate):
            return self._reply(req, denied, notice(sev_warn, "winch: rate is NaN"))
        moves = mode in (WinchMode.RELATIVE_LENGTH, WinchMode.RATE, WinchMode.RETRACT)
        if moves and (self.lost or not self.encoder_frames):
            return self._reply(req, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED,
                               notice(sev_warn, "winch: no encoder, command rejected"))
        if mode == WinchMode.RETRACT and self.uav is None:
            return self._reply(req, mavlink2.MAV_RESULT_TEMPORARILY_REJECTED,
                               notice(sev_warn, "winch: no UAV position, cannot retract"))

        notices: list[Notice] = []
        speed = 0.0
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
                notices.append(notice(sev_warn, f"winch: rate clamped to {speed:.2f} m/s"))
        self.relaxed.reset_slack()      # (the operator's act: RELAXED counts afresh)
        axis = self.axis
        if axis.foreign_brake and mode not in BRAKED_MODES:
            # the operator's act releases the brake against another host (the next frame
            # of that host, if it goes on, brakes the drum again)
            axis.foreign_brake = False
            axis.arm_pending = not self.lost
        if mode not in BRAKED_MODES and not self.lost and (self.active.brakes
                                                           or axis.disarmed):
            # leaving LOCK/HOLD, or the axis disarmed itself (watchdog, errors): re-arm
            axis.arm_pending = True
        self.active = self.modes[mode]
        self.limit_noticed = False
        self.lock_noticed = False
        notices.extend(self.active.start(self, length, speed))
        return self._reply(req, mavlink2.MAV_RESULT_ACCEPTED, *notices)
