"""The winder motor as an ODrive axis (CAN Simple, 0.6 generation) and the winch's sensors.

Pure logic driven by *simulated* time: no bus, no clock. The plant process feeds received
frames to :meth:`OdriveAxis.handle`, calls :meth:`OdriveAxis.tick` and
:meth:`WinchSensors.tick` every plant step, and sends the frames they return. The plant
reads :attr:`OdriveAxis.enabled` (closed loop: motor powered, brake released) and
:attr:`OdriveAxis.torque_command_nm` and applies them to the drum itself, including the
torque cut-back near :attr:`OdriveAxis.vel_limit_rev_s`.

Behaviour modelled on ODrive's:

- **States.** The axis starts IDLE (brake engaged). ``Set_Axis_State 8`` enters
  CLOSED_LOOP_CONTROL only when no error is active, otherwise the axis stays IDLE with
  Procedure_Result DISARMED; ``Set_Axis_State 1`` returns to IDLE. Other requested states
  (calibrations, homing, ...) are not simulated: the frame is dropped and counted.
- **Torque.** ``Set_Input_Torque`` stores the input torque whatever the state; it reaches the
  motor only in closed loop with control mode TORQUE and input mode PASSTHROUGH (at once) or
  TORQUE_RAMP (slewed at ``torque_ramp_rate_nm_s`` by :meth:`tick`). The command is clamped to
  the torque limit (``Set_Limits``' current limit times the torque constant). In any other
  control or input mode the simulated axis commands zero torque: only torque control is
  modelled. A NaN or infinite input torque is dropped and counted; the set-point is
  unchanged.
- **Estop** latches ESTOP_REQUESTED and disarms to IDLE. **Clear_Errors** clears the errors
  and the disarm reason; the axis stays IDLE until a new ``Set_Axis_State 8``.
- **Watchdog.** Every data frame a host addresses to this node id feeds it (any command id,
  or even a frame then dropped as malformed, as an ODrive's CAN handler feeds before it
  parses). Remote requests (polls for the axis's telemetry, which any bystander on the bus
  may send) do not: only a host that commands the axis keeps it armed. Frames for other
  node ids, the winch sensor node's frames, and data frames on the axis's own transmit ids
  (its echoes on a loop-back bus such as ``udp_multicast``) do not either. If
  ``watchdog_timeout_s`` passes without a feed while in closed
  loop, the axis latches WATCHDOG_TIMER_EXPIRED, disarms to IDLE (brake holds), and stays
  there until Clear_Errors and a new closed-loop request. ``watchdog_timeout_s <= 0``
  disables it. The time check runs at the start of :meth:`handle` and :meth:`tick`, so a
  late frame cannot revive an axis whose watchdog already expired.
- **Requests.** A remote frame (any DLC) on a requestable id, or a zero-length data frame on
  it (ODrive's firmware accepts both), is answered with the data frame.

Reported values (what the replies carry):

- Heartbeat ``Axis_Error`` = active errors | disarm reason; ``Get_Error`` both separately.
- ``Get_Encoder_Estimates``: the drum position [rev] and velocity [rev/s] the plant passed to
  the last :meth:`tick` (the motor drives the drum directly, positive paying out).
- ``Get_Torques``: target = :attr:`torque_command_nm` (after ramp and clamp, 0 when not
  enabled), estimate = the applied torque the plant passed to the last :meth:`tick` (which
  includes its speed cut-back).
- ``Get_Iq``: the same two torques divided by the torque constant ``kt`` [N m/A]; cyclic
  every ``iq_period_s`` (50 ms, each before the encoder frame of its instant: the winder is
  configured so, as ODrive's ``iq_msg_rate_ms``), the ground station's second, cruder
  tension source (``groundstation/winch_current.py``).
- ``Get_Bus_Voltage_Current``: the bus voltage from the last :meth:`tick` and the DC bus
  current of a lossless drive by power balance, ``I_bus = (tau_applied * omega +
  R_loss * Iq^2) / V_bus`` with ``omega = 2 pi vel`` [rad/s] and the copper-loss resistance
  ``loss_resistance_ohm`` (default 0): negative while the drum brakes the paying-out line
  (regeneration). Zero when the bus voltage is not positive.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping

from tuavdefs.can_protocol import (
    AXIS_NODE_ID_DEFAULT,
    F32_MAX,
    MAX_DLC,
    MESSAGES,
    WINCH_SENSOR_NODE_ID_DEFAULT,
    AxisState,
    CanFrameError,
    Cmd,
    ControlMode,
    Direction,
    Frame,
    InputMode,
    MessageSpec,
    NodeKind,
    ODriveError,
    ProcedureResult,
    SensorCmd,
    decode_clear_errors,
    decode_set_axis_state,
    decode_set_controller_mode,
    decode_set_input_torque,
    decode_set_limits,
    encode_bus_voltage_current,
    encode_encoder_estimates,
    encode_get_error,
    encode_heartbeat,
    encode_iq,
    encode_torques,
    encode_winch_exit_angle,
    encode_winch_heartbeat,
    encode_winch_length,
    encode_winch_tension,
    frame_id,
)

__all__ = ["Frame", "OdriveAxis", "WinchSensors", "CyclicSchedule", "DROP_REASONS"]

DROP_REASONS = (
    "bad_dlc",  # payload shorter than the command's signals (or longer than 8)
    "unknown_cmd",  # a command id this simulated axis does not implement
    "non_finite",  # NaN or infinite float (torque, limits)
    "bad_value",  # a value outside what the command allows (negative limit, unknown mode)
    "unsupported_state",  # a requested axis state the simulator does not model
    "not_requestable",  # a remote frame on a command that cannot be requested
    "wrong_direction",  # a data frame on one of the axis's own transmit ids
)
"""Reasons under which :attr:`OdriveAxis.counters` counts dropped frames."""

_AXIS_SPECS: Mapping[int, MessageSpec] = {m.cmd_id: m for m in MESSAGES if m.node is NodeKind.AXIS}
_TIME_EPS_S = 1e-9
_TWO_PI = 2.0 * math.pi


class CyclicSchedule:
    """Fixed-rate schedule in simulated time: due at ``t0, t0 + T, t0 + 2T, ...`` where ``t0``
    is the first time it is polled. Missed slots are skipped, not sent in a burst."""

    def __init__(self, period_s: float) -> None:
        if not period_s > 0.0:
            raise ValueError(f"period must be positive, got {period_s!r} s")
        self.period_s = float(period_s)
        self._t0: float | None = None
        self._n = 0
        self.next_s = -math.inf
        """The next slot [s] (-inf until the first poll): :meth:`due` is False before
        ``next_s - 1 ns``."""

    def due(self, t_s: float) -> bool:
        """True (once) when a slot at or before ``t_s`` [s] has not been served yet."""
        if t_s + _TIME_EPS_S < self.next_s:
            return False
        if self._t0 is None:
            self._t0 = t_s
            self._n = 1
        else:
            # serve this slot and skip any slots that were missed
            self._n = max(self._n + 1,
                          math.floor((t_s + _TIME_EPS_S - self._t0) / self.period_s) + 1)
        self.next_s = self._t0 + self._n * self.period_s
        return True


class OdriveAxis:
    """A simulated ODrive axis (0.6 CAN Simple) on node ``node_id``.

    Parameters: ``watchdog_timeout_s`` [s] (<= 0 disables), ``torque_limit_nm`` [N m] initial
    torque limit, ``vel_limit_rev_s`` [rev/s] initial velocity limit (stored for the plant),
    ``torque_constant_nm_a`` [N m/A] maps currents to torques, ``heartbeat_period_s``,
    ``iq_period_s`` and ``encoder_period_s`` [s] the default cyclic periods (<= 0 or None:
    not cyclic),
    ``cyclic`` extra or overriding periods by command id (any requestable message, e.g.
    ``{Cmd.GET_TORQUES: 0.01}``), ``control_mode``/``input_mode`` the modes at power-up,
    ``torque_ramp_rate_nm_s`` [N m/s] for input mode TORQUE_RAMP, ``loss_resistance_ohm``
    [ohm] for the bus-current model.
    """

    def __init__(self, node_id: int = AXIS_NODE_ID_DEFAULT, *, watchdog_timeout_s: float = 0.1,
                 torque_limit_nm: float = 5.0, vel_limit_rev_s: float = 20.0,
                 torque_constant_nm_a: float = 0.1, heartbeat_period_s: float | None = 0.1,
                 encoder_period_s: float | None = 0.01,
                 iq_period_s: float | None = 0.05,
                 cyclic: Mapping[int, float | None] | None = None,
                 control_mode: int = ControlMode.POSITION,
                 input_mode: int = InputMode.PASSTHROUGH,
                 torque_ramp_rate_nm_s: float = 10.0,
                 loss_resistance_ohm: float = 0.0) -> None:
        frame_id(node_id, 0)  # validates the node id
        if not torque_constant_nm_a > 0.0:
            raise ValueError("torque constant must be positive [N m/A]")
        if not torque_limit_nm >= 0.0 or not vel_limit_rev_s >= 0.0:
            raise ValueError("limits must be non-negative")
        self.node_id = int(node_id)
        self.watchdog_timeout_s = float(watchdog_timeout_s)
        self.torque_constant_nm_a = float(torque_constant_nm_a)
        self.torque_limit_nm = float(torque_limit_nm)
        self.vel_limit_rev_s = float(vel_limit_rev_s)
        self.torque_ramp_rate_nm_s = float(torque_ramp_rate_nm_s)
        self.loss_resistance_ohm = float(loss_resistance_ohm)

        self.state = AxisState.IDLE
        self.procedure_result = ProcedureResult.SUCCESS
        self.control_mode = ControlMode(control_mode)
        self.input_mode = InputMode(input_mode)
        self.errors = ODriveError.NONE  # latched active errors
        self.disarm_reason = ODriveError.NONE
        self.input_torque_nm = 0.0  # last accepted Set_Input_Torque
        self._ramped_torque_nm = 0.0  # TORQUE_RAMP's slewed value
        self.identify = False

        # measurements from the plant, for replies
        self.pos_rev = 0.0
        self.vel_rev_s = 0.0
        self.applied_torque_nm = 0.0
        self.bus_voltage_v = 0.0

        self.counters: Counter[str] = Counter()
        """Dropped frames by reason (see :data:`DROP_REASONS`)."""
        self.rx_frames = 0  # frames addressed to this node, dropped or not

        self._last_feed_s: float | None = None
        self._last_tick_s: float | None = None

        # (an instant's Get_Iq before its encoder frame: the host has the current of the
        # instant when it answers the encoder frame)
        periods: dict[int, float | None] = {Cmd.HEARTBEAT: heartbeat_period_s,
                                            Cmd.GET_IQ: iq_period_s,
                                            Cmd.GET_ENCODER_ESTIMATES: encoder_period_s}
        periods.update(cyclic or {})
        self._schedules: dict[int, CyclicSchedule] = {}
        for cmd, period in periods.items():
            spec = _AXIS_SPECS.get(int(cmd))
            if spec is None or spec.direction is not Direction.AXIS_TO_HOST:
                raise ValueError(f"command {cmd!r} is not an axis->host message")
            if period is not None and period > 0.0:
                self._schedules[int(cmd)] = CyclicSchedule(period)
        self._next_cyclic_s = -math.inf if self._schedules else math.inf

    # ----------------------------------------------------------------------------- outputs

    @property
    def enabled(self) -> bool:
        """Closed loop: the motor is powered and the brake released."""
        return self.state == AxisState.CLOSED_LOOP_CONTROL

    @property
    def active_errors(self) -> int:
        """Latched :class:`ODriveError` bits."""
        return int(self.errors)

    @property
    def current_limit_a(self) -> float:
        """Current limit [A] = torque limit / torque constant."""
        return self.torque_limit_nm / self.torque_constant_nm_a

    @property
    def torque_command_nm(self) -> float:
        """Torque the motor is asked for [N m]: the (ramped) set-point clamped to the torque
        limit in closed loop with torque control, 0 otherwise."""
        if not self.enabled or self.control_mode != ControlMode.TORQUE:
            return 0.0
        if self.input_mode == InputMode.PASSTHROUGH:
            tau = self.input_torque_nm
        elif self.input_mode == InputMode.TORQUE_RAMP:
            tau = self._ramped_torque_nm
        else:
            return 0.0
        lim = self.torque_limit_nm
        return min(max(tau, -lim), lim)

    # ------------------------------------------------------------------------ bus input

    def handle(self, t_s: float, arbitration_id: int, data: bytes, is_remote: bool = False,
               is_extended: bool = False) -> list[Frame]:
        """Process one received frame at simulated time ``t_s`` [s]; return the replies.

        For a remote frame ``data`` is ignored except for its length.
        """
        self._check_watchdog(t_s)
        if is_extended or not 0 <= arbitration_id <= 0x7FF:
            return []  # not an 11-bit CAN Simple frame: not for this axis
        node, cmd = arbitration_id >> 5, arbitration_id & 0x1F
        if node != self.node_id:
            return []
        data = bytes(data)
        self.rx_frames += 1
        spec = _AXIS_SPECS.get(cmd)

        # the axis's own transmit ids: requests are host frames, data frames are not
        if spec is not None and spec.direction is Direction.AXIS_TO_HOST:
            if is_remote or len(data) == 0:
                return [self._reply(cmd)]     # a poll: answered, not a feed
            self.counters["wrong_direction"] += 1
            return []
        if is_remote:
            self.counters["unknown_cmd" if spec is None else "not_requestable"] += 1
            return []
        self._feed(t_s)
        if spec is None:
            self.counters["unknown_cmd"] += 1
            return []
        if not spec.min_len <= len(data) <= MAX_DLC:
            self.counters["bad_dlc"] += 1
            return []
        try:
            self._command(t_s, cmd, data)
        except CanFrameError:  # pragma: no cover - lengths checked above
            self.counters["bad_dlc"] += 1
        return []

    def _command(self, t_s: float, cmd: int, data: bytes) -> None:
        if cmd == Cmd.ESTOP:
            self._disarm(ODriveError.ESTOP_REQUESTED)
        elif cmd == Cmd.SET_AXIS_STATE:
            self._request_state(decode_set_axis_state(data))
        elif cmd == Cmd.SET_CONTROLLER_MODE:
            control, inp = decode_set_controller_mode(data)
            try:
                self.control_mode, self.input_mode = ControlMode(control), InputMode(inp)
            except ValueError:
                self.counters["bad_value"] += 1
        elif cmd == Cmd.SET_INPUT_TORQUE:
            tau = decode_set_input_torque(data)
            if not math.isfinite(tau):
                self.counters["non_finite"] += 1
                return
            self.input_torque_nm = tau
        elif cmd == Cmd.SET_LIMITS:
            vel, cur = decode_set_limits(data)
            if not (math.isfinite(vel) and math.isfinite(cur)):
                self.counters["non_finite"] += 1
                return
            if vel < 0.0 or cur < 0.0:
                self.counters["bad_value"] += 1
                return
            self.vel_limit_rev_s = vel
            self.torque_limit_nm = cur * self.torque_constant_nm_a
        elif cmd == Cmd.CLEAR_ERRORS:
            self.identify = decode_clear_errors(data)
            self.errors = ODriveError.NONE
            self.disarm_reason = ODriveError.NONE
        else:  # pragma: no cover - every host->axis command is handled above
            self.counters["unknown_cmd"] += 1

    def _request_state(self, requested: int) -> None:
        if requested == AxisState.CLOSED_LOOP_CONTROL:
            if self.errors or self.disarm_reason:
                self.state = AxisState.IDLE
                self.procedure_result = ProcedureResult.DISARMED
                return
            if self.state != AxisState.CLOSED_LOOP_CONTROL:
                self.state = AxisState.CLOSED_LOOP_CONTROL
                self.procedure_result = ProcedureResult.BUSY
                self._ramped_torque_nm = 0.0
        elif requested == AxisState.IDLE:
            if self.state == AxisState.CLOSED_LOOP_CONTROL:
                self.procedure_result = ProcedureResult.SUCCESS
            self.state = AxisState.IDLE
        else:
            self.counters["unsupported_state"] += 1

    def _disarm(self, reason: ODriveError) -> None:
        self.errors |= reason
        self.disarm_reason |= reason
        self.state = AxisState.IDLE
        self.procedure_result = ProcedureResult.DISARMED
        self._ramped_torque_nm = 0.0

    def _feed(self, t_s: float) -> None:
        self._last_feed_s = t_s

    def _check_watchdog(self, t_s: float) -> None:
        if self.watchdog_timeout_s <= 0.0 or not self.enabled:
            return
        last = self._last_feed_s
        if last is None or t_s - last > self.watchdog_timeout_s + _TIME_EPS_S:
            self._disarm(ODriveError.WATCHDOG_TIMER_EXPIRED)

    # ----------------------------------------------------------------------- periodic output

    def tick(self, t_s: float, drum_pos_rev: float, drum_vel_rev_s: float,
             applied_torque_nm: float, bus_voltage_v: float) -> list[Frame]:
        """Advance to simulated time ``t_s`` [s] with the plant's drum position [rev] and
        velocity [rev/s] (positive paying out), the torque the motor applied [N m] and the
        bus voltage [V]; return the cyclic frames that are due."""
        self._check_watchdog(t_s)
        dt = 0.0 if self._last_tick_s is None else max(0.0, t_s - self._last_tick_s)
        self._last_tick_s = t_s
        self.pos_rev = float(drum_pos_rev)
        self.vel_rev_s = float(drum_vel_rev_s)
        self.applied_torque_nm = float(applied_torque_nm)
        self.bus_voltage_v = float(bus_voltage_v)
        if self.enabled:
            step = self.torque_ramp_rate_nm_s * dt
            err = self.input_torque_nm - self._ramped_torque_nm
            self._ramped_torque_nm += min(max(err, -step), step)
        else:
            self._ramped_torque_nm = 0.0
        if t_s + _TIME_EPS_S < self._next_cyclic_s:
            return []   # no schedule is due (the common case: they run at 10 and 100 Hz)
        frames = [self._reply(cmd) for cmd, sched in self._schedules.items() if sched.due(t_s)]
        self._next_cyclic_s = min(sched.next_s for sched in self._schedules.values())
        return frames

    # ----------------------------------------------------------------------------- replies

    def bus_current_a(self) -> float:
        """DC bus current [A] by power balance (see the module docstring)."""
        if not self.bus_voltage_v > 0.0:
            return 0.0
        iq = self.applied_torque_nm / self.torque_constant_nm_a
        power_w = (self.applied_torque_nm * _TWO_PI * self.vel_rev_s
                   + self.loss_resistance_ohm * iq * iq)
        return power_w / self.bus_voltage_v

    def _reply(self, cmd: int) -> Frame:
        if cmd == Cmd.HEARTBEAT:
            data = encode_heartbeat(int(self.errors | self.disarm_reason), int(self.state),
                                    int(self.procedure_result), True)
        elif cmd == Cmd.GET_ERROR:
            data = encode_get_error(int(self.errors), int(self.disarm_reason))
        elif cmd == Cmd.GET_ENCODER_ESTIMATES:
            data = encode_encoder_estimates(_to_f32(self.pos_rev),
                                            _to_f32(self.vel_rev_s))
        elif cmd == Cmd.GET_IQ:
            kt = self.torque_constant_nm_a
            data = encode_iq(_to_f32(self.torque_command_nm / kt),
                             _to_f32(self.applied_torque_nm / kt))
        elif cmd == Cmd.GET_BUS_VOLTAGE_CURRENT:
            data = encode_bus_voltage_current(_to_f32(self.bus_voltage_v),
                                              _to_f32(self.bus_current_a()))
        elif cmd == Cmd.GET_TORQUES:
            data = encode_torques(_to_f32(self.torque_command_nm),
                                  _to_f32(self.applied_torque_nm))
        else:  # pragma: no cover - only requestable ids reach here
            raise ValueError(f"command {cmd:#x} has no reply")
        return Frame(frame_id(self.node_id, cmd), data, False)


def _to_f32(value: float) -> float:
    """Magnitudes beyond the f32 range become +-inf, as an IEEE conversion rounds them, rather
    than failing to encode; NaN and infinities pass through."""
    if abs(value) <= F32_MAX or not math.isfinite(value):
        return value
    return math.copysign(math.inf, value)


class WinchSensors:
    """The winch's own sensors on node ``node_id`` (default 0x30): ``Winch_Length`` and
    ``Winch_Tension`` every ``period_s`` [s], ``Winch_Heartbeat`` every
    ``heartbeat_period_s`` [s] with a counter that wraps at 255.

    ``load_cell_healthy`` can be cleared to inject a load-cell fault; a non-finite tension
    also reports the load cell unhealthy (the NaN is sent as is).
    """

    def __init__(self, node_id: int = WINCH_SENSOR_NODE_ID_DEFAULT, period_s: float = 0.01,
                 heartbeat_period_s: float = 0.1, exit_angle_period_s: float = 0.02) -> None:
        frame_id(node_id, 0)
        self.node_id = int(node_id)
        self.load_cell_healthy = True
        self.counter = 0
        self._data_schedule = CyclicSchedule(period_s)
        self._hb_schedule = CyclicSchedule(heartbeat_period_s)
        self._length_id = frame_id(self.node_id, SensorCmd.WINCH_LENGTH)
        self._tension_id = frame_id(self.node_id, SensorCmd.WINCH_TENSION)
        self._heartbeat_id = frame_id(self.node_id, SensorCmd.WINCH_HEARTBEAT)
        self._exit_schedule = CyclicSchedule(exit_angle_period_s)
        self._exit_id = frame_id(self.node_id, SensorCmd.WINCH_EXIT_ANGLE)

    def exit_angle_frame(self, t_s: float, azimuth_rad: float, elevation_rad: float,
                         valid: bool) -> Frame:
        """The ``Winch_Exit_Angle`` frame of a reading [rad] sampled at ``t_s`` [s] (sent
        when :meth:`exit_angle_due`)."""
        return Frame(self._exit_id, encode_winch_exit_angle(
            azimuth_rad, elevation_rad, round(t_s * 1000.0) & 0xFFFF, valid), False)

    def exit_angle_due(self, t_s: float) -> bool:
        """True (once per slot) when a ``Winch_Exit_Angle`` is due at ``t_s`` [s]."""
        return self._exit_schedule.due(t_s)

    def due(self, t_s: float) -> bool:
        """Whether :meth:`tick` at ``t_s`` [s] has frames to send (it changes nothing: the
        caller can skip working out the measurements when not)."""
        return (t_s + _TIME_EPS_S >= self._data_schedule.next_s
                or t_s + _TIME_EPS_S >= self._hb_schedule.next_s)

    def tick(self, t_s: float, length_m: float, speed_m_s: float, tension_n: float,
             brake_engaged: bool, at_full_stop: bool, at_empty_stop: bool) -> list[Frame]:
        """Frames due at simulated time ``t_s`` [s] for the paid-out length [m], line speed
        [m/s] (positive paying out), drum tension [N] and the brake and stop flags."""
        frames: list[Frame] = []
        if self._data_schedule.due(t_s):
            frames.append(Frame(self._length_id,
                                encode_winch_length(_to_f32(length_m),
                                                    _to_f32(speed_m_s)), False))
            frames.append(Frame(self._tension_id,
                                encode_winch_tension(_to_f32(tension_n), brake_engaged,
                                                     round(t_s * 1000.0) & 0xFFFF),
                                False))
        if self._hb_schedule.due(t_s):
            healthy = self.load_cell_healthy and math.isfinite(tension_n)
            frames.append(Frame(self._heartbeat_id,
                                encode_winch_heartbeat(brake_engaged, healthy, at_full_stop,
                                                       at_empty_stop, self.counter), False))
            self.counter = (self.counter + 1) & 0xFF
        return frames
