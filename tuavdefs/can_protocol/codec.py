"""The winder bus's payloads: one decoded record, one encoder and one decoder per message.

Pure byte-level encoding with :mod:`struct` (little-endian, f32). Decoders accept a payload
from the bytes their signals occupy up to 8 bytes (ODrive's own examples send, for instance,
a 4-byte ``Set_Axis_State``); anything shorter or longer raises
:class:`~.ids.CanFrameError`. Float signals decode NaN and infinities as such: what to do
with them is the receiver's decision.

The identifiers are :mod:`.ids`, the table of messages :mod:`.messages`.
"""

from __future__ import annotations

import math
import struct
from typing import Any, NamedTuple

from tuavdefs.can_protocol.ids import MAX_DLC, CanFrameError, WinchFlags

__all__ = [
    "EXIT_ANGLE_LSB_RAD",
    "F32_MAX",
    "BusVoltageCurrent",
    "ControllerMode",
    "EncoderEstimates",
    "ErrorStatus",
    "Heartbeat",
    "Iq",
    "Limits",
    "Torques",
    "WinchExitAngle",
    "WinchHeartbeat",
    "WinchLength",
    "WinchTension",
    "decode_bus_voltage_current",
    "decode_clear_errors",
    "decode_encoder_estimates",
    "decode_estop",
    "decode_get_error",
    "decode_heartbeat",
    "decode_iq",
    "decode_set_axis_state",
    "decode_set_controller_mode",
    "decode_set_input_torque",
    "decode_set_limits",
    "decode_torques",
    "decode_winch_exit_angle",
    "decode_winch_heartbeat",
    "decode_winch_length",
    "decode_winch_tension",
    "encode_bus_voltage_current",
    "encode_clear_errors",
    "encode_encoder_estimates",
    "encode_estop",
    "encode_get_error",
    "encode_heartbeat",
    "encode_iq",
    "encode_set_axis_state",
    "encode_set_controller_mode",
    "encode_set_input_torque",
    "encode_set_limits",
    "encode_torques",
    "encode_winch_exit_angle",
    "encode_winch_heartbeat",
    "encode_winch_length",
    "encode_winch_tension",
    "is_finite_f32",
]

# ---------------------------------------------------------------------------------------------
# Packing helpers
# ---------------------------------------------------------------------------------------------


def _check_len(name: str, data: bytes, min_len: int) -> bytes:
    if type(data) is not bytes:         # (bytes itself as it is: every frame goes here)
        data = bytes(data)
    if not min_len <= len(data) <= MAX_DLC:
        raise CanFrameError(
            f"{name}: payload of {len(data)} bytes, expected {min_len}..{MAX_DLC}")
    return data


# payload layouts, compiled once
_S_B = struct.Struct("<B")
_S_BB = struct.Struct("<BB")
_S_I = struct.Struct("<I")
_S_I4X = struct.Struct("<I4x")
_S_IBBB = struct.Struct("<IBBB")
_S_IBBBX = struct.Struct("<IBBBx")
_S_II = struct.Struct("<II")
_S_F = struct.Struct("<f")
_S_F4X = struct.Struct("<f4x")
_S_FBH = struct.Struct("<fBH")
_S_FBHX = struct.Struct("<fBHx")
_S_FF = struct.Struct("<ff")
_S_HHHB = struct.Struct("<hhHB")
_S_HHHBX = struct.Struct("<hhHBx")


def _pack(name: str, layout: struct.Struct, *values: Any) -> bytes:
    """``layout.pack`` with ValueError (not struct.error/OverflowError) for out-of-range
    values."""
    try:
        return layout.pack(*values)
    except (struct.error, OverflowError) as exc:
        raise ValueError(f"{name}: cannot encode {values!r}: {exc}") from exc


def _u32(value: int) -> int:
    return int(value)


def _f32(value: float) -> float:
    return float(value)


# ---------------------------------------------------------------------------------------------
# Decoded payloads
# ---------------------------------------------------------------------------------------------


class Heartbeat(NamedTuple):
    """``Heartbeat`` (0x01): axis error bits (:class:`ODriveError`), state
    (:class:`AxisState`), last procedure result (:class:`ProcedureResult`), trajectory done."""

    axis_error: int
    axis_state: int
    procedure_result: int
    trajectory_done: bool


class ErrorStatus(NamedTuple):
    """``Get_Error`` (0x03): active error bits and the bits that caused the last disarm."""

    active_errors: int
    disarm_reason: int


class EncoderEstimates(NamedTuple):
    """``Get_Encoder_Estimates`` (0x09): position [rev] and velocity [rev/s]."""

    pos_rev: float
    vel_rev_s: float


class ControllerMode(NamedTuple):
    """``Set_Controller_Mode`` (0x0B): :class:`ControlMode` and :class:`InputMode`."""

    control_mode: int
    input_mode: int


class Limits(NamedTuple):
    """``Set_Limits`` (0x0F): velocity limit [rev/s] and current limit [A]."""

    velocity_limit_rev_s: float
    current_limit_a: float


class Iq(NamedTuple):
    """``Get_Iq`` (0x14): q-axis current set-point and measurement [A]."""

    setpoint_a: float
    measured_a: float


class BusVoltageCurrent(NamedTuple):
    """``Get_Bus_Voltage_Current`` (0x17): DC bus voltage [V] and current [A]."""

    voltage_v: float
    current_a: float


class Torques(NamedTuple):
    """``Get_Torques`` (0x1C): torque target and estimate [N m]."""

    target_nm: float
    estimate_nm: float


class WinchHeartbeat(NamedTuple):
    """``Winch_Heartbeat`` (sensor node, 0x01): status flags and a rolling counter
    (0..255)."""

    brake_engaged: bool
    load_cell_healthy: bool
    at_full_stop: bool
    at_empty_stop: bool
    counter: int


class WinchLength(NamedTuple):
    """``Winch_Length`` (sensor node, 0x02): paid-out line [m] and line speed [m/s],
    positive paying out."""

    length_m: float
    speed_m_s: float


class WinchTension(NamedTuple):
    """``Winch_Tension`` (sensor node, 0x03): line tension at the drum [N] (load cell) and
    whether the brake is engaged."""

    tension_n: float
    brake_engaged: bool
    sample_time_ms: int = 0
    """The winch's clock when it sampled [ms], modulo 65536 (the simulator's time)."""


class WinchExitAngle(NamedTuple):
    """``Winch_Exit_Angle`` (sensor node, 0x04): the direction in which the tether leaves
    the fairlead, from the two encoders of its guide arm: azimuth [rad] (counter-clockwise
    from the winder frame's x axis, east, in -pi..pi), elevation [rad] (above the
    horizontal), the winch's clock when they were sampled [ms] modulo 65536, and whether
    the reading is valid (both encoders healthy)."""

    azimuth_rad: float
    elevation_rad: float
    sample_time_ms: int
    valid: bool


#: One count of ``Winch_Exit_Angle``'s angles [rad] (signed 16 bits: +-3.2767 rad).
EXIT_ANGLE_LSB_RAD = 1.0e-4


# ---------------------------------------------------------------------------------------------
# Encoders and decoders (one pair per message)
# ---------------------------------------------------------------------------------------------


def encode_heartbeat(axis_error: int, axis_state: int, procedure_result: int = 0,
                     trajectory_done: bool = True) -> bytes:
    """Heartbeat payload (8 bytes): u32 Axis_Error, u8 Axis_State @ byte 4, u8
    Procedure_Result @ byte 5, Trajectory_Done_Flag bit 48; the rest zero."""
    return _pack("Heartbeat", _S_IBBBX, _u32(axis_error), int(axis_state),
                 int(procedure_result), 1 if trajectory_done else 0)


def decode_heartbeat(data: bytes) -> Heartbeat:
    """Decode a Heartbeat payload (7..8 bytes)."""
    data = _check_len("Heartbeat", data, 7)
    err, state, result, flags = _S_IBBB.unpack_from(data)
    return Heartbeat(err, state, result, bool(flags & 0x01))


def encode_estop() -> bytes:
    """Estop payload: empty (DLC 0)."""
    return b""


def decode_estop(data: bytes) -> None:
    """Estop carries nothing; any payload up to 8 bytes is accepted (it is an emergency
    stop)."""
    _check_len("Estop", data, 0)
    return None


def encode_get_error(active_errors: int, disarm_reason: int) -> bytes:
    """Get_Error payload: u32 Active_Errors, u32 Disarm_Reason."""
    return _pack("Get_Error", _S_II, _u32(active_errors), _u32(disarm_reason))


def decode_get_error(data: bytes) -> ErrorStatus:
    """Decode a Get_Error payload."""
    data = _check_len("Get_Error", data, 8)
    return ErrorStatus(*_S_II.unpack_from(data))


def encode_set_axis_state(requested_state: int) -> bytes:
    """Set_Axis_State payload (8 bytes): u32 Axis_Requested_State, 4 zero bytes."""
    return _pack("Set_Axis_State", _S_I4X, _u32(requested_state))


def decode_set_axis_state(data: bytes) -> int:
    """Decode Set_Axis_State (4..8 bytes) to the requested :class:`AxisState` value."""
    data = _check_len("Set_Axis_State", data, 4)
    return _S_I.unpack_from(data)[0]


def encode_encoder_estimates(pos_rev: float, vel_rev_s: float) -> bytes:
    """Get_Encoder_Estimates payload: f32 Pos_Estimate [rev], f32 Vel_Estimate [rev/s]."""
    return _pack("Get_Encoder_Estimates", _S_FF, _f32(pos_rev), _f32(vel_rev_s))


def decode_encoder_estimates(data: bytes) -> EncoderEstimates:
    """Decode Get_Encoder_Estimates to ``(pos_rev, vel_rev_s)``."""
    data = _check_len("Get_Encoder_Estimates", data, 8)
    return EncoderEstimates(*_S_FF.unpack_from(data))


def encode_set_controller_mode(control_mode: int, input_mode: int) -> bytes:
    """Set_Controller_Mode payload: u32 Control_Mode, u32 Input_Mode."""
    return _pack("Set_Controller_Mode", _S_II, _u32(control_mode), _u32(input_mode))


def decode_set_controller_mode(data: bytes) -> ControllerMode:
    """Decode Set_Controller_Mode."""
    data = _check_len("Set_Controller_Mode", data, 8)
    return ControllerMode(*_S_II.unpack_from(data))


def encode_set_input_torque(torque_nm: float) -> bytes:
    """Set_Input_Torque payload (8 bytes): f32 Input_Torque [N m], 4 zero bytes."""
    return _pack("Set_Input_Torque", _S_F4X, _f32(torque_nm))


def decode_set_input_torque(data: bytes) -> float:
    """Decode Set_Input_Torque (4..8 bytes) to the torque [N m] (NaN stays NaN)."""
    data = _check_len("Set_Input_Torque", data, 4)
    return _S_F.unpack_from(data)[0]


def encode_set_limits(velocity_limit_rev_s: float, current_limit_a: float) -> bytes:
    """Set_Limits payload: f32 Velocity_Limit [rev/s], f32 Current_Limit [A]."""
    return _pack("Set_Limits", _S_FF, _f32(velocity_limit_rev_s), _f32(current_limit_a))


def decode_set_limits(data: bytes) -> Limits:
    """Decode Set_Limits."""
    data = _check_len("Set_Limits", data, 8)
    return Limits(*_S_FF.unpack_from(data))


def encode_iq(setpoint_a: float, measured_a: float) -> bytes:
    """Get_Iq payload: f32 Iq_Setpoint [A], f32 Iq_Measured [A]."""
    return _pack("Get_Iq", _S_FF, _f32(setpoint_a), _f32(measured_a))


def decode_iq(data: bytes) -> Iq:
    """Decode Get_Iq."""
    data = _check_len("Get_Iq", data, 8)
    return Iq(*_S_FF.unpack_from(data))


def encode_bus_voltage_current(voltage_v: float, current_a: float) -> bytes:
    """Get_Bus_Voltage_Current payload: f32 Bus_Voltage [V], f32 Bus_Current [A]."""
    return _pack("Get_Bus_Voltage_Current", _S_FF, _f32(voltage_v), _f32(current_a))


def decode_bus_voltage_current(data: bytes) -> BusVoltageCurrent:
    """Decode Get_Bus_Voltage_Current."""
    data = _check_len("Get_Bus_Voltage_Current", data, 8)
    return BusVoltageCurrent(*_S_FF.unpack_from(data))


def encode_clear_errors(identify: bool = False) -> bytes:
    """Clear_Errors payload (DLC 1): u8 Identify (blink the LED)."""
    return _pack("Clear_Errors", _S_B, 1 if identify else 0)


def decode_clear_errors(data: bytes) -> bool:
    """Decode Clear_Errors (1..8 bytes) to the Identify flag."""
    data = _check_len("Clear_Errors", data, 1)
    return bool(data[0])


def encode_torques(target_nm: float, estimate_nm: float) -> bytes:
    """Get_Torques payload: f32 Torque_Target [N m], f32 Torque_Estimate [N m]."""
    return _pack("Get_Torques", _S_FF, _f32(target_nm), _f32(estimate_nm))


def decode_torques(data: bytes) -> Torques:
    """Decode Get_Torques."""
    data = _check_len("Get_Torques", data, 8)
    return Torques(*_S_FF.unpack_from(data))


def encode_winch_heartbeat(brake_engaged: bool, load_cell_healthy: bool, at_full_stop: bool,
                           at_empty_stop: bool, counter: int) -> bytes:
    """Winch_Heartbeat payload (DLC 2): u8 flags (:class:`WinchFlags`), u8 counter."""
    flags = ((WinchFlags.BRAKE_ENGAGED if brake_engaged else 0)
             | (WinchFlags.LOAD_CELL_HEALTHY if load_cell_healthy else 0)
             | (WinchFlags.AT_FULL_STOP if at_full_stop else 0)
             | (WinchFlags.AT_EMPTY_STOP if at_empty_stop else 0))
    return _pack("Winch_Heartbeat", _S_BB, int(flags), int(counter))


def decode_winch_heartbeat(data: bytes) -> WinchHeartbeat:
    """Decode Winch_Heartbeat (2..8 bytes)."""
    data = _check_len("Winch_Heartbeat", data, 2)
    flags, counter = data[0], data[1]
    return WinchHeartbeat(bool(flags & WinchFlags.BRAKE_ENGAGED),
                          bool(flags & WinchFlags.LOAD_CELL_HEALTHY),
                          bool(flags & WinchFlags.AT_FULL_STOP),
                          bool(flags & WinchFlags.AT_EMPTY_STOP), counter)


def encode_winch_length(length_m: float, speed_m_s: float) -> bytes:
    """Winch_Length payload: f32 Line_Length [m] paid out, f32 Line_Speed [m/s] (positive
    paying out)."""
    return _pack("Winch_Length", _S_FF, _f32(length_m), _f32(speed_m_s))


def decode_winch_length(data: bytes) -> WinchLength:
    """Decode Winch_Length."""
    data = _check_len("Winch_Length", data, 8)
    return WinchLength(*_S_FF.unpack_from(data))


def encode_winch_tension(tension_n: float, brake_engaged: bool,
                         sample_time_ms: int = 0) -> bytes:
    """Winch_Tension payload (8 bytes): f32 Tension [N] at the drum, u8 Brake_Engaged,
    u16 Sample_Time [ms] (the winch's clock modulo 65536, so a host can tell how old other
    data are against it), 1 zero pad byte."""
    return _pack("Winch_Tension", _S_FBHX, _f32(tension_n), 1 if brake_engaged else 0,
                 int(sample_time_ms) & 0xFFFF)


def decode_winch_tension(data: bytes) -> WinchTension:
    """Decode Winch_Tension (7..8 bytes)."""
    data = _check_len("Winch_Tension", data, 7)
    tension, brake, stamp = _S_FBH.unpack_from(data)
    return WinchTension(tension, bool(brake), stamp)


def _angle_counts(name: str, angle_rad: float) -> int:
    """An angle [rad] as ``Winch_Exit_Angle`` counts (rounded; ValueError outside the
    signed 16 bits or not finite)."""
    if not math.isfinite(angle_rad):
        raise ValueError(f"{name}: cannot encode {angle_rad!r}")
    return round(float(angle_rad) / EXIT_ANGLE_LSB_RAD)


def encode_winch_exit_angle(azimuth_rad: float, elevation_rad: float,
                            sample_time_ms: int = 0, valid: bool = True) -> bytes:
    """Winch_Exit_Angle payload (8 bytes): i16 Azimuth and i16 Elevation in counts of
    :data:`EXIT_ANGLE_LSB_RAD`, u16 Sample_Time [ms] (the winch's clock modulo 65536), u8
    Valid, 1 zero pad byte. The azimuth is wrapped to -pi..pi first."""
    az = math.remainder(float(azimuth_rad), 2.0 * math.pi) if math.isfinite(
        azimuth_rad) else azimuth_rad
    return _pack("Winch_Exit_Angle", _S_HHHBX, _angle_counts("Winch_Exit_Angle", az),
                 _angle_counts("Winch_Exit_Angle", elevation_rad),
                 int(sample_time_ms) & 0xFFFF, 1 if valid else 0)


def decode_winch_exit_angle(data: bytes) -> WinchExitAngle:
    """Decode Winch_Exit_Angle (7..8 bytes) to radians."""
    data = _check_len("Winch_Exit_Angle", data, 7)
    az, el, stamp, valid = _S_HHHB.unpack_from(data)
    return WinchExitAngle(az * EXIT_ANGLE_LSB_RAD, el * EXIT_ANGLE_LSB_RAD, stamp,
                          bool(valid & 0x01))



#: The largest finite f32 (3.4028235e38).
F32_MAX = 3.4028234663852886e38


def is_finite_f32(value: float) -> bool:
    """True if ``value`` is a finite number that fits an f32 (|x| <= :data:`F32_MAX`)."""
    return math.isfinite(value) and abs(value) <= F32_MAX
