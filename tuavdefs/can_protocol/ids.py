"""The winder's CAN bus, its identifiers and kinds: ODrive CAN Simple (firmware 0.6
generation) plus the winch sensors.

Shared by the plant (which *is* the ODrive axis and the winch sensors) and the ground
station (the CAN host); the payloads are :mod:`.codec`, the table of messages (with the DBC)
:mod:`.messages`. No bus access.

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
"""

from __future__ import annotations

import enum
from typing import NamedTuple

__all__ = [
    "AXIS_NODE_ID_DEFAULT",
    "CMD_ID_BITS",
    "MAX_CMD_ID",
    "MAX_DLC",
    "MAX_NODE_ID",
    "NODE_ID_BITS",
    "WINCH_SENSOR_NODE_ID_DEFAULT",
    "AxisState",
    "CanFrameError",
    "Cmd",
    "ControlMode",
    "Direction",
    "Frame",
    "InputMode",
    "NodeKind",
    "ODriveError",
    "ProcedureResult",
    "SensorCmd",
    "WinchFlags",
    "frame_id",
    "split_id",
]

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


class NodeKind(enum.StrEnum):
    """The kind of node a message belongs to: the ODrive axis, or the winch's sensors."""

    AXIS = "axis"
    SENSOR = "sensor"


class Direction(enum.StrEnum):
    """Who sends a message to whom."""

    HOST_TO_AXIS = "host->axis"
    AXIS_TO_HOST = "axis->host"
    SENSOR_TO_HOST = "sensor->host"


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

