"""The winch's talk with the winder's ODrive axis on CAN: the frames it sends (arm, IDLE,
torque, the bus voltage request), what the axis's heartbeat says (its errors, a self-disarm
re-armed at most every :data:`REARM_S`, an Estop only the operator re-arms) and another
host commanding the axis (the drum braked against it)."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch_report import WinchOutput, notice
from tuavdefs import can_protocol as cp

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


class AxisLink:
    """The axis on node ``node`` as this host sees and commands it."""

    def __init__(self, node: int) -> None:
        self.node = node
        valid = 0 <= node <= cp.MAX_NODE_ID
        # the answers' ids, worked out once (None for a node id no frame can carry: then no
        # encoder frame is ever handled, and nothing is sent to it)
        self.torque_id = cp.frame_id(node, cp.Cmd.SET_INPUT_TORQUE) if valid else None
        self.bus_request = (cp.Frame(cp.frame_id(node, cp.Cmd.GET_BUS_VOLTAGE_CURRENT),
                                     bytes(8), True) if valid else None)
        self.axis_error: int | None = None
        self.axis_state: int | None = None
        #: Whether the next closed-loop frame re-arms the axis first.
        self.arm_pending = False
        self._rearm_wall = -math.inf        # the last re-arm of a self-disarmed axis [s]
        self._estop_noticed = False
        self.rearms = 0
        """Times the axis was re-armed after it had disarmed itself."""
        self.foreign_commands = 0
        """Host-to-axis frames on the axis's ids this process did not send."""
        self.foreign_wall = -math.inf       # the last one [s]
        self._foreign_said_wall = -math.inf
        #: Whether the drum is braked against another host commanding the axis (from its
        #: first frame until FOREIGN_NOTICE_S without one, or an operator's DO_WINCH).
        self.foreign_brake = False

    @property
    def estopped(self) -> bool:
        """Whether the axis reports an Estop (someone's act: only DO_WINCH re-arms)."""
        return bool((self.axis_error or 0) & cp.ODriveError.ESTOP_REQUESTED)

    @property
    def disarmed(self) -> bool:
        """Whether the axis reported a state other than closed-loop control."""
        return (self.axis_state is not None
                and self.axis_state != cp.AxisState.CLOSED_LOOP_CONTROL)

    def arm_frames(self) -> list[cp.Frame]:
        """Clear_Errors, torque control (passthrough), CLOSED_LOOP_CONTROL."""
        n = self.node
        return [
            cp.Frame(cp.frame_id(n, cp.Cmd.CLEAR_ERRORS), cp.encode_clear_errors()),
            cp.Frame(cp.frame_id(n, cp.Cmd.SET_CONTROLLER_MODE), cp.encode_set_controller_mode(
                cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH)),
            cp.Frame(cp.frame_id(n, cp.Cmd.SET_AXIS_STATE),
                     cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL)),
        ]

    def idle_frame(self) -> cp.Frame:
        """``Set_Axis_State`` IDLE: the brake holds the drum."""
        return cp.Frame(cp.frame_id(self.node, cp.Cmd.SET_AXIS_STATE),
                        cp.encode_set_axis_state(cp.AxisState.IDLE))

    def torque_frame(self, torque_n_m: float) -> cp.Frame:
        """``Set_Input_Torque`` of ``torque_n_m`` [N m]."""
        return cp.Frame(self.torque_id, cp.encode_set_input_torque(torque_n_m))

    def on_heartbeat(self, hb: cp.Heartbeat, wall_s: float, needed: bool) -> WinchOutput:
        """The axis's heartbeat at ``wall_s`` [s]: an error said as it appears; an axis
        that disarmed itself (watchdog after a stall, an error) while the winch needs it
        (``needed``: not braked, encoder frames seen) is re-armed with the next encoder
        frame, at most every :data:`REARM_S`; an Estop is someone's act, and only a
        ``DO_WINCH`` (the operator's) re-arms it."""
        out = WinchOutput()
        if hb.axis_error and hb.axis_error != self.axis_error:
            out.notices.append(notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                      f"winch: axis error 0x{hb.axis_error:08X}"))
        self.axis_error, self.axis_state = hb.axis_error, hb.axis_state
        if hb.axis_state == cp.AxisState.CLOSED_LOOP_CONTROL:
            self._estop_noticed = False
        elif needed and not self.arm_pending:
            if hb.axis_error & cp.ODriveError.ESTOP_REQUESTED:
                if not self._estop_noticed:
                    self._estop_noticed = True
                    out.notices.append(notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                              "winch: axis estopped; DO_WINCH re-arms"))
            elif wall_s - self._rearm_wall >= REARM_S:
                self._rearm_wall = wall_s
                self.arm_pending = True
                self.rearms += 1
                out.notices.append(notice(mavlink2.MAV_SEVERITY_WARNING,
                                          f"winch: axis disarmed (0x{hb.axis_error:08X}), "
                                          "re-arming"))
        return out

    def on_foreign(self, wall_s: float, cmd: cp.Cmd) -> WinchOutput | None:
        """A host-to-axis frame another host sent: counted, said at most every
        :data:`FOREIGN_NOTICE_S`, and the winch unhealthy for as long. The drum is braked
        at once (``Set_Axis_State`` IDLE: the axis applies no torque, whoever sends it)
        and stays braked until :data:`FOREIGN_NOTICE_S` pass without such a frame
        (:meth:`foreign_quiet`) or an operator's ``DO_WINCH`` re-arms it; a frame that
        could take the axis out of IDLE is answered with IDLE at once."""
        self.foreign_commands += 1
        self.foreign_wall = wall_s
        out = None
        if not self.foreign_brake or cmd in REARMING_COMMANDS:
            out = WinchOutput(frames=[self.idle_frame()])
        if not self.foreign_brake:
            self.foreign_brake = True
            out.notices.append(notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                      "winch: drum braked against another CAN host"))
        if wall_s - self._foreign_said_wall < FOREIGN_NOTICE_S:
            return out
        self._foreign_said_wall = wall_s
        out = out or WinchOutput()
        out.notices.insert(0, notice(mavlink2.MAV_SEVERITY_CRITICAL,
                                     f"winch: another CAN host sends {cmd.name}"))
        return out

    def foreign_quiet(self, wall_s: float) -> bool:
        """Whether the brake against another host ends now: it has sent nothing to the
        axis for :data:`FOREIGN_NOTICE_S`."""
        return self.foreign_brake and wall_s - self.foreign_wall >= FOREIGN_NOTICE_S

    def foreign_recent(self, wall_s: float | None) -> bool:
        """Whether another host commanded the axis within :data:`FOREIGN_NOTICE_S` before
        ``wall_s`` [s] (None: never asked)."""
        return wall_s is not None and wall_s - self.foreign_wall < FOREIGN_NOTICE_S
