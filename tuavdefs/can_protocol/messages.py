"""The winder bus's table of messages: per message its id, node, direction, length, period,
DBC signal names and codec; lookup by name or by frame id, encoding and decoding by DBC
signal names (as cantools does), and the DBC file describing every frame.

The identifiers are :mod:`.ids`, the payloads :mod:`.codec`.
"""

from __future__ import annotations

import importlib.resources
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tuavdefs.can_protocol.codec import (
    decode_bus_voltage_current,
    decode_clear_errors,
    decode_encoder_estimates,
    decode_estop,
    decode_get_error,
    decode_heartbeat,
    decode_iq,
    decode_set_axis_state,
    decode_set_controller_mode,
    decode_set_input_torque,
    decode_set_limits,
    decode_torques,
    decode_winch_exit_angle,
    decode_winch_heartbeat,
    decode_winch_length,
    decode_winch_tension,
    encode_bus_voltage_current,
    encode_clear_errors,
    encode_encoder_estimates,
    encode_estop,
    encode_get_error,
    encode_heartbeat,
    encode_iq,
    encode_set_axis_state,
    encode_set_controller_mode,
    encode_set_input_torque,
    encode_set_limits,
    encode_torques,
    encode_winch_exit_angle,
    encode_winch_heartbeat,
    encode_winch_length,
    encode_winch_tension,
)
from tuavdefs.can_protocol.ids import (
    AXIS_NODE_ID_DEFAULT,
    WINCH_SENSOR_NODE_ID_DEFAULT,
    Cmd,
    Direction,
    NodeKind,
    SensorCmd,
    frame_id,
    split_id,
)

__all__ = [
    "DBC_FILENAME",
    "MESSAGES",
    "MESSAGES_BY_NAME",
    "MessageSpec",
    "dbc_path",
    "decode_signals",
    "encode_signals",
    "message_spec",
    "spec_for_id",
]

DBC_FILENAME = "tuav_winder.dbc"


def dbc_path() -> Path:
    """Path of the DBC file (``tuavdefs/data/tuav_winder.dbc``) describing every frame of
    the bus for the default node ids (axis 0, winch sensors 0x30)."""
    resource = importlib.resources.files("tuavdefs") / "data" / DBC_FILENAME
    return Path(os.fspath(resource))  # type: ignore[arg-type]


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
            node_id = (AXIS_NODE_ID_DEFAULT if self.node is NodeKind.AXIS
                       else WINCH_SENSOR_NODE_ID_DEFAULT)
        return frame_id(node_id, self.cmd_id)


def _spec(name: str, cmd_id: int, node: NodeKind, direction: Direction, dlc: int,
          period_s: float | None, rtr: bool, signals: Sequence[str], min_len: int,
          encode: Callable[..., bytes], decode: Callable[[bytes], Any]) -> MessageSpec:
    return MessageSpec(name, int(cmd_id), node, direction, dlc, period_s, rtr, tuple(signals),
                       min_len, encode, decode)


# the table's columns, short
_AXIS, _SENSOR = NodeKind.AXIS, NodeKind.SENSOR
_TO_AXIS, _FROM_AXIS = Direction.HOST_TO_AXIS, Direction.AXIS_TO_HOST
_FROM_SENSOR = Direction.SENSOR_TO_HOST

MESSAGES: tuple[MessageSpec, ...] = (
    _spec("Heartbeat", Cmd.HEARTBEAT, _AXIS, _FROM_AXIS, 8, 0.1, True,
          ("Axis_Error", "Axis_State", "Procedure_Result", "Trajectory_Done_Flag"), 7,
          encode_heartbeat, decode_heartbeat),
    _spec("Estop", Cmd.ESTOP, _AXIS, _TO_AXIS, 0, None, False, (), 0,
          encode_estop, decode_estop),
    _spec("Get_Error", Cmd.GET_ERROR, _AXIS, _FROM_AXIS, 8, None, True,
          ("Active_Errors", "Disarm_Reason"), 8, encode_get_error, decode_get_error),
    _spec("Set_Axis_State", Cmd.SET_AXIS_STATE, _AXIS, _TO_AXIS, 8, None, False,
          ("Axis_Requested_State",), 4, encode_set_axis_state, decode_set_axis_state),
    _spec("Get_Encoder_Estimates", Cmd.GET_ENCODER_ESTIMATES, _AXIS, _FROM_AXIS, 8, 0.01,
          True, ("Pos_Estimate", "Vel_Estimate"), 8,
          encode_encoder_estimates, decode_encoder_estimates),
    _spec("Set_Controller_Mode", Cmd.SET_CONTROLLER_MODE, _AXIS, _TO_AXIS, 8, None, False,
          ("Control_Mode", "Input_Mode"), 8,
          encode_set_controller_mode, decode_set_controller_mode),
    _spec("Set_Input_Torque", Cmd.SET_INPUT_TORQUE, _AXIS, _TO_AXIS, 8, None, False,
          ("Input_Torque",), 4, encode_set_input_torque, decode_set_input_torque),
    _spec("Set_Limits", Cmd.SET_LIMITS, _AXIS, _TO_AXIS, 8, None, False,
          ("Velocity_Limit", "Current_Limit"), 8, encode_set_limits, decode_set_limits),
    _spec("Get_Iq", Cmd.GET_IQ, _AXIS, _FROM_AXIS, 8, 0.05, True,
          ("Iq_Setpoint", "Iq_Measured"), 8, encode_iq, decode_iq),
    _spec("Get_Bus_Voltage_Current", Cmd.GET_BUS_VOLTAGE_CURRENT, _AXIS, _FROM_AXIS, 8,
          None, True, ("Bus_Voltage", "Bus_Current"), 8,
          encode_bus_voltage_current, decode_bus_voltage_current),
    _spec("Clear_Errors", Cmd.CLEAR_ERRORS, _AXIS, _TO_AXIS, 1, None, False,
          ("Identify",), 1, encode_clear_errors, decode_clear_errors),
    _spec("Get_Torques", Cmd.GET_TORQUES, _AXIS, _FROM_AXIS, 8, None, True,
          ("Torque_Target", "Torque_Estimate"), 8, encode_torques, decode_torques),
    _spec("Winch_Heartbeat", SensorCmd.WINCH_HEARTBEAT, _SENSOR, _FROM_SENSOR, 2, 0.1,
          False, ("Brake_Engaged", "Load_Cell_Healthy", "At_Full_Stop", "At_Empty_Stop",
                  "Counter"), 2, encode_winch_heartbeat, decode_winch_heartbeat),
    _spec("Winch_Length", SensorCmd.WINCH_LENGTH, _SENSOR, _FROM_SENSOR, 8, 0.01, False,
          ("Line_Length", "Line_Speed"), 8, encode_winch_length, decode_winch_length),
    _spec("Winch_Tension", SensorCmd.WINCH_TENSION, _SENSOR, _FROM_SENSOR, 8, 0.01, False,
          ("Tension", "Brake_Engaged", "Sample_Time"), 7, encode_winch_tension,
          decode_winch_tension),
    _spec("Winch_Exit_Angle", SensorCmd.WINCH_EXIT_ANGLE, _SENSOR, _FROM_SENSOR, 8, 0.02,
          False, ("Azimuth", "Elevation", "Sample_Time", "Valid"), 7,
          encode_winch_exit_angle, decode_winch_exit_angle),
)
"""Every frame on the winder bus. Axis frames are ``frame_id(axis_node, cmd_id)``, sensor
frames ``frame_id(sensor_node, cmd_id)``."""

MESSAGES_BY_NAME: Mapping[str, MessageSpec] = {m.name: m for m in MESSAGES}
_AXIS_BY_CMD: Mapping[int, MessageSpec] = {m.cmd_id: m for m in MESSAGES if m.node is _AXIS}
_SENSOR_BY_CMD: Mapping[int, MessageSpec] = {
    m.cmd_id: m for m in MESSAGES if m.node is _SENSOR}


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
