"""The winder's CAN bus: ODrive CAN Simple (firmware 0.6 generation) plus the winch sensors.

Shared by the plant (which *is* the ODrive axis and the winch sensors) and the ground
station (the CAN host). Pure byte-level encoding with :mod:`struct`; no bus access.

Wire conventions (ODrive CAN Simple):

- Classic CAN, 11-bit identifiers: ``arbitration_id = node_id << 5 | cmd_id`` with a 6-bit
  node id (0..0x3F) and a 5-bit command id (0..0x1F).
- Little-endian payloads, IEEE-754 single-precision floats (``f32``), DLC 8 unless noted.
- A host asks an axis for one of its messages with a remote (RTR) frame carrying the same
  identifier; the axis answers with the data frame. Some messages are also sent cyclically.

The winch's own sensors (load cell, brake, paid-out length) sit on a node id of their own,
:data:`WINCH_SENSOR_NODE_ID_DEFAULT`, never in unused command ids of the axis's node: an
ODrive feeds its watchdog with every host frame addressed to its node id, so a sensor frame
sharing that node id could keep a disconnected host's last torque alive.

Frame representation: :class:`Frame` ``(arbitration_id, data, is_remote)``. For a remote
frame only ``len(data)`` matters (it is the DLC the request carries, normally 8); its bytes
are zeros.

Decoders accept a payload from the bytes their signals occupy up to 8 bytes (ODrive's own
examples send, for instance, a 4-byte ``Set_Axis_State``); anything shorter or longer raises
:class:`CanFrameError`. Float signals decode NaN and infinities as such: what to do with
them is the receiver's decision.

The DBC file describing every frame (axis node 0 and the sensor node 0x30) is at
:func:`dbc_path`.
"""

from __future__ import annotations

import enum
import importlib.resources
import math
import os
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

__all__ = [
    "AXIS_NODE_ID_DEFAULT",
    "WINCH_SENSOR_NODE_ID_DEFAULT",
    "MAX_NODE_ID",
    "MAX_CMD_ID",
    "MAX_DLC",
    "DBC_FILENAME",
    "Cmd",
    "SensorCmd",
    "AxisState",
    "ControlMode",
    "InputMode",
    "ProcedureResult",
    "ODriveError",
    "WinchFlags",
    "CanFrameError",
    "Frame",
    "MessageSpec",
    "MESSAGES",
    "MESSAGES_BY_NAME",
    "frame_id",
    "split_id",
    "message_spec",
    "spec_for_id",
    "dbc_path",
    "encode_signals",
    "decode_signals",
    "is_finite_f32",
    "F32_MAX",
    # decoded payloads
    "Heartbeat",
    "ErrorStatus",
    "EncoderEstimates",
    "ControllerMode",
    "Limits",
    "Iq",
    "BusVoltageCurrent",
    "Torques",
    "WinchHeartbeat",
    "WinchLength",
    "WinchTension",
    "WinchExitAngle",
    "EXIT_ANGLE_LSB_RAD",
    # encoders / decoders
    "encode_heartbeat",
    "decode_heartbeat",
    "encode_estop",
    "decode_estop",
    "encode_get_error",
    "decode_get_error",
    "encode_set_axis_state",
    "decode_set_axis_state",
    "encode_encoder_estimates",
    "decode_encoder_estimates",
    "encode_set_controller_mode",
    "decode_set_controller_mode",
    "encode_set_input_torque",
    "decode_set_input_torque",
    "encode_set_limits",
    "decode_set_limits",
    "encode_iq",
    "decode_iq",
    "encode_bus_voltage_current",
    "decode_bus_voltage_current",
    "encode_clear_errors",
    "decode_clear_errors",
    "encode_torques",
    "decode_torques",
    "encode_winch_heartbeat",
    "decode_winch_heartbeat",
    "encode_winch_length",
    "decode_winch_length",
    "encode_winch_tension",
    "decode_winch_tension",
    "encode_winch_exit_angle",
    "decode_winch_exit_angle",
]

# ---------------------------------------------------------------------------------------------
# Identifiers
# ---------------------------------------------------------------------------------------------

AXIS_NODE_ID_DEFAULT = 0
"""The winder motor's ODrive axis node id (ODrive's factory default)."""

WINCH_SENSOR_NODE_ID_DEFAULT = 0x30
"""Node id of the winch's own sensors: frame ids 0x600..0x61F, above every id an ODrive axis
on nodes 0..0x2F can use, and clear of ODrive's broadcast node 0x3F."""

NODE_ID_BITS = 6
CMD_ID_BITS = 5
MAX_NODE_ID = (1 << NODE_ID_BITS) - 1  # 0x3F
MAX_CMD_ID = (1 << CMD_ID_BITS) - 1  # 0x1F
MAX_DLC = 8
DBC_FILENAME = "tuav_winder.dbc"


class Cmd(enum.IntEnum):
    """ODrive CAN Simple command ids used here (0.6 numbering)."""

    HEARTBEAT = 0x01
    ESTOP = 0x02
    GET_ERROR = 0x03
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    GET_IQ = 0x14
    GET_BUS_VOLTAGE_CURRENT = 0x17
    CLEAR_ERRORS = 0x18
    GET_TORQUES = 0x1C


class SensorCmd(enum.IntEnum):
    """Command ids of the winch sensor node (this project's own messages)."""

    WINCH_HEARTBEAT = 0x01
    WINCH_LENGTH = 0x02
    WINCH_TENSION = 0x03
    WINCH_EXIT_ANGLE = 0x04


class AxisState(enum.IntEnum):
    """ODrive ``AxisState`` values (0.6)."""

    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8
    LOCKIN_SPIN = 9
    ENCODER_DIR_FIND = 10
    HOMING = 11
    ENCODER_HALL_POLARITY_CALIBRATION = 12
    ENCODER_HALL_PHASE_CALIBRATION = 13
    ANTICOGGING_CALIBRATION = 14


class ControlMode(enum.IntEnum):
    """ODrive ``Controller.ControlMode`` values."""

    VOLTAGE = 0
    TORQUE = 1
    VELOCITY = 2
    POSITION = 3


class InputMode(enum.IntEnum):
    """ODrive ``Controller.InputMode`` values."""

    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class ProcedureResult(enum.IntEnum):
    """ODrive ``ProcedureResult`` values (0.6), the heartbeat's ``Procedure_Result``."""

    SUCCESS = 0
    BUSY = 1
    CANCELLED = 2
    DISARMED = 3
    NO_RESPONSE = 4
    POLE_PAIR_CPR_MISMATCH = 5
    PHASE_RESISTANCE_OUT_OF_RANGE = 6
    PHASE_INDUCTANCE_OUT_OF_RANGE = 7
    UNBALANCED_PHASES = 8
    INVALID_MOTOR_TYPE = 9
    ILLEGAL_HALL_STATE = 10
    TIMEOUT = 11
    HOMING_WITHOUT_ENDSTOP = 12
    INVALID_STATE = 13
    NOT_CALIBRATED = 14
    NOT_CONVERGING = 15


class ODriveError(enum.IntFlag):
    """ODrive 0.6 ``ODriveError`` bits (``active_errors``, ``disarm_reason``, heartbeat
    ``Axis_Error``). These differ from the 0.5 generation's ``AxisError`` values."""

    NONE = 0
    INITIALIZING = 0x00000001
    SYSTEM_LEVEL = 0x00000002
    TIMING_ERROR = 0x00000004
    MISSING_ESTIMATE = 0x00000008
    BAD_CONFIG = 0x00000010
    DRV_FAULT = 0x00000020
    MISSING_INPUT = 0x00000040
    DC_BUS_OVER_VOLTAGE = 0x00000100
    DC_BUS_UNDER_VOLTAGE = 0x00000200
    DC_BUS_OVER_CURRENT = 0x00000400
    DC_BUS_OVER_REGEN_CURRENT = 0x00000800
    CURRENT_LIMIT_VIOLATION = 0x00001000
    MOTOR_OVER_TEMP = 0x00002000
    INVERTER_OVER_TEMP = 0x00004000
    VELOCITY_LIMIT_VIOLATION = 0x00008000
    POSITION_LIMIT_VIOLATION = 0x00010000
    WATCHDOG_TIMER_EXPIRED = 0x01000000
    ESTOP_REQUESTED = 0x02000000
    SPINOUT_DETECTED = 0x04000000
    BRAKE_RESISTOR_DISARMED = 0x08000000
    THERMISTOR_DISCONNECTED = 0x10000000
    CALIBRATION_ERROR = 0x40000000


class WinchFlags(enum.IntFlag):
    """Bits of the ``Winch_Heartbeat`` flags byte."""

    NONE = 0
    BRAKE_ENGAGED = 0x01
    LOAD_CELL_HEALTHY = 0x02
    AT_FULL_STOP = 0x04
    AT_EMPTY_STOP = 0x08


class CanFrameError(ValueError):
    """A payload that cannot be this message (wrong length)."""


class Frame(NamedTuple):
    """One classic CAN frame. For a remote (RTR) frame ``data`` is ``bytes(dlc)``: only its
    length (the requested DLC) carries information."""

    arbitration_id: int
    data: bytes
    is_remote: bool = False


def frame_id(node_id: int, cmd_id: int) -> int:
    """The 11-bit arbitration id ``node_id << 5 | cmd_id``."""
    if not 0 <= node_id <= MAX_NODE_ID:
        raise ValueError(f"node id {node_id!r} outside 0..{MAX_NODE_ID:#x}")
    if not 0 <= cmd_id <= MAX_CMD_ID:
        raise ValueError(f"command id {cmd_id!r} outside 0..{MAX_CMD_ID:#x}")
    return (node_id << CMD_ID_BITS) | cmd_id


def split_id(arbitration_id: int) -> tuple[int, int]:
    """``(node_id, cmd_id)`` of an 11-bit arbitration id."""
    if not 0 <= arbitration_id <= 0x7FF:
        raise ValueError(f"arbitration id {arbitration_id!r} is not an 11-bit id")
    return arbitration_id >> CMD_ID_BITS, arbitration_id & MAX_CMD_ID


def dbc_path() -> Path:
    """Path of the DBC file (``tuavdefs/data/tuav_winder.dbc``) describing every frame of
    the bus for the default node ids (axis 0, winch sensors 0x30)."""
    resource = importlib.resources.files(__package__ or "tuavdefs") / "data" / DBC_FILENAME
    return Path(os.fspath(resource))  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# Packing helpers
# ---------------------------------------------------------------------------------------------


def _check_len(name: str, data: bytes, min_len: int) -> bytes:
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


# ---------------------------------------------------------------------------------------------
# Message table
# ---------------------------------------------------------------------------------------------

NodeKind = Literal["axis", "sensor"]
Direction = Literal["host->axis", "axis->host", "sensor->host"]


@dataclass(frozen=True)
class MessageSpec:
    """One message of the bus.

    ``signals`` are the DBC signal names, in the order of the encoder's arguments and of the
    decoder's result; ``min_len`` is the shortest payload a decoder accepts (the bytes the
    signals occupy); ``period_s`` is the default cyclic period [s] (None: on request or on
    event only); ``rtr`` says whether a host may request it with a remote frame.
    """

    name: str
    cmd_id: int
    node: NodeKind
    direction: Direction
    dlc: int
    period_s: float | None
    rtr: bool
    signals: tuple[str, ...]
    min_len: int
    encode: Callable[..., bytes]
    decode: Callable[[bytes], Any]

    def frame_id(self, node_id: int | None = None) -> int:
        """Arbitration id for ``node_id`` (default: the node kind's default node id)."""
        if node_id is None:
            node_id = (AXIS_NODE_ID_DEFAULT if self.node == "axis"
                       else WINCH_SENSOR_NODE_ID_DEFAULT)
        return frame_id(node_id, self.cmd_id)


def _spec(name: str, cmd_id: int, node: NodeKind, direction: Direction, dlc: int,
          period_s: float | None, rtr: bool, signals: Sequence[str], min_len: int,
          encode: Callable[..., bytes], decode: Callable[[bytes], Any]) -> MessageSpec:
    return MessageSpec(name, int(cmd_id), node, direction, dlc, period_s, rtr, tuple(signals),
                       min_len, encode, decode)


MESSAGES: tuple[MessageSpec, ...] = (
    _spec("Heartbeat", Cmd.HEARTBEAT, "axis", "axis->host", 8, 0.1, True,
          ("Axis_Error", "Axis_State", "Procedure_Result", "Trajectory_Done_Flag"), 7,
          encode_heartbeat, decode_heartbeat),
    _spec("Estop", Cmd.ESTOP, "axis", "host->axis", 0, None, False, (), 0,
          encode_estop, decode_estop),
    _spec("Get_Error", Cmd.GET_ERROR, "axis", "axis->host", 8, None, True,
          ("Active_Errors", "Disarm_Reason"), 8, encode_get_error, decode_get_error),
    _spec("Set_Axis_State", Cmd.SET_AXIS_STATE, "axis", "host->axis", 8, None, False,
          ("Axis_Requested_State",), 4, encode_set_axis_state, decode_set_axis_state),
    _spec("Get_Encoder_Estimates", Cmd.GET_ENCODER_ESTIMATES, "axis", "axis->host", 8, 0.01,
          True, ("Pos_Estimate", "Vel_Estimate"), 8,
          encode_encoder_estimates, decode_encoder_estimates),
    _spec("Set_Controller_Mode", Cmd.SET_CONTROLLER_MODE, "axis", "host->axis", 8, None, False,
          ("Control_Mode", "Input_Mode"), 8,
          encode_set_controller_mode, decode_set_controller_mode),
    _spec("Set_Input_Torque", Cmd.SET_INPUT_TORQUE, "axis", "host->axis", 8, None, False,
          ("Input_Torque",), 4, encode_set_input_torque, decode_set_input_torque),
    _spec("Set_Limits", Cmd.SET_LIMITS, "axis", "host->axis", 8, None, False,
          ("Velocity_Limit", "Current_Limit"), 8, encode_set_limits, decode_set_limits),
    _spec("Get_Iq", Cmd.GET_IQ, "axis", "axis->host", 8, 0.05, True,
          ("Iq_Setpoint", "Iq_Measured"), 8, encode_iq, decode_iq),
    _spec("Get_Bus_Voltage_Current", Cmd.GET_BUS_VOLTAGE_CURRENT, "axis", "axis->host", 8,
          None, True, ("Bus_Voltage", "Bus_Current"), 8,
          encode_bus_voltage_current, decode_bus_voltage_current),
    _spec("Clear_Errors", Cmd.CLEAR_ERRORS, "axis", "host->axis", 1, None, False,
          ("Identify",), 1, encode_clear_errors, decode_clear_errors),
    _spec("Get_Torques", Cmd.GET_TORQUES, "axis", "axis->host", 8, None, True,
          ("Torque_Target", "Torque_Estimate"), 8, encode_torques, decode_torques),
    _spec("Winch_Heartbeat", SensorCmd.WINCH_HEARTBEAT, "sensor", "sensor->host", 2, 0.1,
          False, ("Brake_Engaged", "Load_Cell_Healthy", "At_Full_Stop", "At_Empty_Stop",
                  "Counter"), 2, encode_winch_heartbeat, decode_winch_heartbeat),
    _spec("Winch_Length", SensorCmd.WINCH_LENGTH, "sensor", "sensor->host", 8, 0.01, False,
          ("Line_Length", "Line_Speed"), 8, encode_winch_length, decode_winch_length),
    _spec("Winch_Tension", SensorCmd.WINCH_TENSION, "sensor", "sensor->host", 8, 0.01, False,
          ("Tension", "Brake_Engaged", "Sample_Time"), 7, encode_winch_tension,
          decode_winch_tension),
    _spec("Winch_Exit_Angle", SensorCmd.WINCH_EXIT_ANGLE, "sensor", "sensor->host", 8, 0.02,
          False, ("Azimuth", "Elevation", "Sample_Time", "Valid"), 7,
          encode_winch_exit_angle, decode_winch_exit_angle),
)
"""Every frame on the winder bus. Axis frames are ``frame_id(axis_node, cmd_id)``, sensor
frames ``frame_id(sensor_node, cmd_id)``."""

MESSAGES_BY_NAME: Mapping[str, MessageSpec] = {m.name: m for m in MESSAGES}
_AXIS_BY_CMD: Mapping[int, MessageSpec] = {m.cmd_id: m for m in MESSAGES if m.node == "axis"}
_SENSOR_BY_CMD: Mapping[int, MessageSpec] = {
    m.cmd_id: m for m in MESSAGES if m.node == "sensor"}


def message_spec(name: str) -> MessageSpec:
    """The :class:`MessageSpec` named ``name`` (KeyError if none)."""
    return MESSAGES_BY_NAME[name]


def spec_for_id(arbitration_id: int, axis_node_id: int = AXIS_NODE_ID_DEFAULT,
                sensor_node_id: int = WINCH_SENSOR_NODE_ID_DEFAULT) -> MessageSpec | None:
    """The message an 11-bit id carries on a bus with these node ids, or None."""
    node, cmd = split_id(arbitration_id)
    if node == axis_node_id:
        return _AXIS_BY_CMD.get(cmd)
    if node == sensor_node_id:
        return _SENSOR_BY_CMD.get(cmd)
    return None


def encode_signals(name: str, values: Mapping[str, Any]) -> bytes:
    """Encode a message from a ``{DBC signal name: value}`` mapping (as cantools takes)."""
    spec = MESSAGES_BY_NAME[name]
    missing = [s for s in spec.signals if s not in values]
    if missing:
        raise KeyError(f"{name}: missing signals {missing}")
    return spec.encode(*(values[s] for s in spec.signals))


def decode_signals(name: str, data: bytes) -> dict[str, Any]:
    """Decode a payload to ``{DBC signal name: value}`` (as cantools returns, booleans as
    bool)."""
    spec = MESSAGES_BY_NAME[name]
    result = spec.decode(data)
    if result is None:
        values: tuple[Any, ...] = ()
    elif isinstance(result, tuple):
        values = tuple(result)
    else:
        values = (result,)
    return dict(zip(spec.signals, values, strict=True))


#: The largest finite f32 (3.4028235e38).
F32_MAX = 3.4028234663852886e38


def is_finite_f32(value: float) -> bool:
    """True if ``value`` is a finite number that fits an f32 (|x| <= :data:`F32_MAX`)."""
    return math.isfinite(value) and abs(value) <= F32_MAX
