"""The companion as ground stations see it: an ArduCopter-compatible MAVLink vehicle.

System 1, component 1, HEARTBEAT autopilot ARDUPILOTMEGA, type QUADROTOR, copter custom
modes; MAVLink 2 out, MAVLink 1 accepted. What ArduCopter does and this does too:

- HEARTBEAT once a second of simulated time (and at least once a second of wall time),
  and right after a mode or arming change; base_mode with the custom-mode flag and the
  armed bit; system_status STANDBY on the ground, ACTIVE when armed.
- COMMAND_LONG and COMMAND_INT, each answered by one COMMAND_ACK to its sender at once
  (:meth:`Autopilot._command`); SET_MODE answered with the ACK of MAV_CMD_DO_SET_MODE.
- Missions (``companion.mission_protocol``), parameters (``companion.param_protocol``),
  SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT in GUIDED, REQUEST_DATA_STREAM,
  SET_MESSAGE_INTERVAL, REQUEST_MESSAGE, TIMESYNC, telemetry streams per link.
- The winch (component 169, the ground-station process, on the component link) is routed:
  what ground stations send it goes there, and everything it sends (its HEARTBEAT with
  autopilot INVALID, WINCH_STATUS, COMMAND_ACK, STATUSTEXT) reaches every ground station
  as it was sent. MAV_CMD_DO_WINCH addressed to the autopilot is forwarded to it too, and
  acknowledged from component 1 when the winch has answered.

Frames at this boundary: MAVLink's local NED has its origin at the winder (ArduPilot's EKF
origin), global positions come from ``home`` (the winder's latitude, longitude and ground
altitude AMSL; the ground is flat); relative altitudes are above that ground. Inside,
everything is the inertial z-up frame (``tuavdefs.frames`` converts).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import common as mavlink2

from companion.mavlink_io import MavlinkEndpoints, Peer
from companion.mission_items import ItemRefused, finite, mission_home, nav_command, nav_commands
from companion.mission_protocol import MissionItem, MissionProtocol
from companion.mission_protocol import from_message as mission_from_message
from companion.navigation import FlightMode, NavEvent, Navigator
from companion.param_protocol import ParamDef, ParamProtocol
from tuavdefs import component_link as cl
from tuavdefs.frames import (
    enu_to_ned,
    flu_to_frd,
    global_to_local_enu,
    local_enu_to_global,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    quat_to_euler,
    yaw_enu_to_ned,
    yaw_ned_to_enu,
)
from tuavdefs.mav_frames import GLOBAL_FRAMES, altitude_to_z, global_to_local

M = mavlink2
Vec3 = tuple[float, float, float]

#: ArduCopter 4.5.7 official, as AUTOPILOT_VERSION encodes it (major, minor, patch, type).
FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (7 << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)
FORCE_MAGIC = 21196.0
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces arming or disarming."""

_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
            | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
            | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
            | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | M.MAV_SYS_STATUS_AHRS
            | M.MAV_SYS_STATUS_SENSOR_BATTERY | M.MAV_SYS_STATUS_PREARM_CHECK)


#: Default telemetry: message name -> rate [Hz of simulated time].
DEFAULT_RATES_HZ: dict[str, float] = {
    "SYS_STATUS": 1.0, "EXTENDED_SYS_STATE": 1.0, "BATTERY_STATUS": 1.0,
    "GPS_RAW_INT": 2.0, "GLOBAL_POSITION_INT": 5.0, "LOCAL_POSITION_NED": 5.0,
    "ATTITUDE": 10.0, "VFR_HUD": 2.0, "HOME_POSITION": 0.2, "MISSION_CURRENT": 1.0,
    "SYSTEM_TIME": 0.5,
}
#: A message due within this [s] of a period's time is sent in that period: its due times
#: are sums of intervals in floating point, and without it messages due at the same instant
#: (a 5 Hz one on a 10 Hz one's grid) land a period apart as their rounding falls, and a
#: ground station wakes for each.
DUE_TOLERANCE_S = 1e-6
#: REQUEST_DATA_STREAM groups, as ArduPilot assigns messages to them.
STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT"),
    M.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    M.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    M.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    M.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "BATTERY_STATUS", "EXTENDED_SYS_STATE"),
}
_MSG_IDS = {name: getattr(M, f"MAVLINK_MSG_ID_{name}") for name in DEFAULT_RATES_HZ}
_MSG_NAMES = {v: k for k, v in _MSG_IDS.items()}

_WINCH_ACK_TIMEOUT_S = 0.4
_POS_IGNORE = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
               | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


class Telemetry(NamedTuple):
    """What the vehicle knows of itself at a control period (inertial z-up, body FLU)."""

    t_s: float
    pos_m: Vec3
    vel_m_s: Vec3
    quat: tuple[float, float, float, float]
    rates_rad_s: Vec3
    throttle: float
    """Mean rotor command in [0, 1]."""


@dataclass
class _LinkState:
    """Per-link telemetry schedule: message name -> [interval s, next due s]."""

    schedule: dict[str, list[float]] = field(default_factory=dict)


class Autopilot:
    """The vehicle's MAVLink side: watch :meth:`selectables` in the control loop's
    ``select`` and hand what is readable to :meth:`receive`; call :meth:`service` at every
    control period (and after :meth:`receive` between periods).

    ``home`` is the winder's (latitude deg, longitude deg, ground altitude m AMSL);
    ``params`` the parameters ground stations may read and set; ``component`` the
    component link to the winch (or None).
    """

    def __init__(self, endpoints: MavlinkEndpoints, nav: Navigator,
                 home: tuple[float, float, float], params: list[ParamDef],
                 param_file: Any = None, component: Any = None,
                 log: Callable[[str], None] | None = None) -> None:
        self.io = endpoints
        self.nav = nav
        self.origin = tuple(float(v) for v in home)
        self.component = component
        self.log = log or (lambda text: print(f"companion: {text}", flush=True))
        self.missions = MissionProtocol(self._send_to, self.statustext,
                                        self._validate_item, self._mission_changed)
        self.params = ParamProtocol(params, self._send_to, self.statustext,
                                    persist_path=param_file)
        self._links: dict[Peer, _LinkState] = {}
        self._telem: Telemetry | None = None
        self._boot_wall = time.monotonic()
        self._last_hb_sim = -math.inf
        self._last_hb_wall = -math.inf
        self._statustext_id = 0
        self._winch_pending: list[tuple[float, Peer, int, int, int]] = []
        self._winch_sink: Callable[[Any], None] | None = None
        self.counters = {"commands": 0, "unsupported": 0, "rejected_targets": 0}
        self._streams_due = -math.inf     # earliest next message due on any link [s]
        self._streams_gen = -1            # the endpoints' links when it was computed
        self._watch: list[Any] = []
        self._watch_gen = -1
        self._watch_comp: Any = None

    # ----- sending helpers

    def _send_to(self, peer: Peer | None, msg: Any) -> None:
        self.io.send(msg, peer)

    def statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every link (chunked past 50 characters, as MAVLink 2 allows) and
        the process log."""
        self.log(text)
        data = text.encode("utf-8", "replace")
        if len(data) <= 50:
            self.io.send(M.MAVLink_statustext_message(severity, data, 0, 0))
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        for i in range(0, len(data), 50):
            self.io.send(M.MAVLink_statustext_message(severity, data[i:i + 50],
                                                      self._statustext_id, i // 50))

    def _ack(self, peer: Peer, msg: Any, command: int, result: int) -> None:
        self.io.send(M.MAVLink_command_ack_message(
            command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), peer)

    # ----- the loop

    def selectables(self) -> list[Any]:
        """The sockets whose input :meth:`receive` takes (the ground stations', the
        component link's), for the caller's ``select``: the same list object until they
        change (a client connects or goes); do not modify it."""
        gen = self.io.generation
        comp = self.component.selectable if self.component is not None else None
        if gen != self._watch_gen or comp is not self._watch_comp:
            self._watch = [*self.io.sockets(), *([comp] if comp is not None else [])]
            self._watch_gen, self._watch_comp = gen, comp
        return self._watch

    def receive(self, ready: Iterable[Any]) -> None:
        """Take the input of the sockets in ``ready`` (found readable by a ``select`` on
        :meth:`selectables`; other objects in it are ignored): ground-station messages are
        handled (commands answered) and the winch's routed at once; what they change in
        flight applies from the next control period. Call :meth:`service` after it."""
        for peer, msg in self.io.receive(ready):
            try:
                self.handle(peer, msg)
            except Exception as exc:  # noqa: BLE001 - one bad message must not stop flight
                self.log(f"error handling {msg.get_type()} from {peer}: {exc!r}")
        comp = self.component
        if comp is not None and comp.selectable in ready:
            self._from_winch(comp.poll())

    def service(self, telem: Telemetry | None) -> None:
        """Send what is due: at every control period with its telemetry, and (with None)
        after :meth:`receive` or when no period came for a while. Forgets links that
        closed, runs the protocols' timers and the navigator's events, sends heartbeats
        and streams, and writes out what slow TCP clients could not take before. Cheap
        when nothing is due (most periods)."""
        if telem is not None:
            self._telem = telem
        io = self.io
        if io.closed_pending:
            for peer in io.pop_closed():
                self.missions.peer_closed(peer)
                self.params.peer_closed(peer)
                self._links.pop(peer, None)
        now_wall = time.monotonic()
        self.missions.tick(now_wall)
        self.params.tick(now_wall)
        if self._winch_pending:
            self._expire_winch(now_wall)
        if self.nav.has_events:
            for kind, value in self.nav.pop_events():
                self._nav_event(kind, value)
        tm = self._telem
        t = tm.t_s if tm is not None else -math.inf
        if (now_wall - self._last_hb_wall >= 1.0
                or t - self._last_hb_sim >= 1.0 - DUE_TOLERANCE_S):
            self.send_heartbeat()
        if tm is not None and (t >= self._streams_due - DUE_TOLERANCE_S
                               or io.generation != self._streams_gen):
            self._streams(t)    # something is due on some link (otherwise nothing to do)
        if io.backlogged:
            io.flush()
        if self.component is not None and self.component.backlogged:
            self.component.flush()

    def send_heartbeat(self) -> None:
        """A HEARTBEAT now (after a mode or arming change)."""
        nav = self.nav
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if nav.mode in (FlightMode.GUIDED, FlightMode.AUTO, FlightMode.RTL,
                        FlightMode.LOITER, FlightMode.LAND):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if nav.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        status = M.MAV_STATE_ACTIVE if nav.armed else M.MAV_STATE_STANDBY
        self.io.send(M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(nav.mode), status,
            3))
        self._last_hb_wall = time.monotonic()
        if self._telem is not None:
            self._last_hb_sim = self._telem.t_s

    # ----- routing

    def handle(self, peer: Peer, msg: Any) -> None:
        """One message from a ground station."""
        mtype = msg.get_type()
        tsys = getattr(msg, "target_system", None)
        tcomp = getattr(msg, "target_component", None)
        if tsys is not None and tsys not in (0, cl.SYSTEM_ID):
            return
        if tcomp == cl.WINCH_COMPONENT_ID:
            self._to_winch(msg)
            return
        if self.missions.handle(peer, msg, time.monotonic()):
            return
        if self.params.handle(peer, msg, time.monotonic()):
            return
        if tcomp is not None and tcomp not in (0, cl.AUTOPILOT_COMPONENT_ID):
            return
        handler = getattr(self, f"_on_{mtype.lower()}", None)
        if handler is not None:
            handler(peer, msg)

    def _to_winch(self, msg: Any) -> bool:
        if self.component is None or not self.component.connected:
            return False
        self.component.send_bytes(msg.get_msgbuf())
        return True

    def _from_winch(self, msgs: list[Any]) -> None:
        """Route what the winch sent: to every ground station, WINCH_STATUS also to the
        sink; its answer to a DO_WINCH sent to the autopilot goes back as the
        autopilot's."""
        for msg in msgs:
            if msg.get_srcComponent() != cl.WINCH_COMPONENT_ID:
                continue
            if (msg.get_type() == "COMMAND_ACK" and msg.command == M.MAV_CMD_DO_WINCH
                    and self._winch_acked(msg)):
                continue   # answered from the autopilot, to whom it was sent
            self.io.send_bytes(msg.get_msgbuf())
            if msg.get_type() == "WINCH_STATUS" and self._winch_sink is not None:
                self._winch_sink(msg)

    def _expire_winch(self, now_wall: float) -> None:
        """Fail the DO_WINCH commands the winch has not answered in time."""
        keep = []
        for entry in self._winch_pending:
            t0, peer, sysid, compid, cmd = entry
            if now_wall - t0 > _WINCH_ACK_TIMEOUT_S:
                self.io.send(M.MAVLink_command_ack_message(cmd, M.MAV_RESULT_FAILED, 0, 0,
                                                           sysid, compid), peer)
                self.statustext(M.MAV_SEVERITY_WARNING, "Winch: no answer")
            else:
                keep.append(entry)
        self._winch_pending = keep

    def on_winch_status(self, sink: Callable[[Any], None]) -> None:
        """Call ``sink(msg)`` with every WINCH_STATUS the winch sends."""
        self._winch_sink = sink

    def _winch_acked(self, ack: Any) -> bool:
        """Answer a DO_WINCH that was sent to the autopilot with the winch's result;
        False if ``ack`` answers no such command."""
        for i, (_, peer, sysid, compid, cmd) in enumerate(self._winch_pending):
            if ack.target_system in (0, sysid) and ack.target_component in (0, compid):
                self.io.send(M.MAVLink_command_ack_message(cmd, ack.result, 0, 0, sysid,
                                                           compid), peer)
                del self._winch_pending[i]
                return True
        return False

    # ----- commands

    def _on_command_long(self, peer: Peer, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
             msg.param7]
        self._command(peer, msg, msg.command, p, None)

    def _on_command_int(self, peer: Peer, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7, msg.y * 1e-7,
             msg.z]
        self._command(peer, msg, msg.command, p, msg.frame)

    def _command(self, peer: Peer, msg: Any, cmd: int, p: list[float],
                 frame: int | None) -> None:
        """Run one command and answer it with one COMMAND_ACK, whatever happens."""
        try:
            self._run_command(peer, msg, cmd, p, frame)
        except Exception as exc:  # noqa: BLE001 - the sender still gets its answer
            self.log(f"command {cmd} failed: {exc!r}")
            self._ack(peer, msg, cmd, M.MAV_RESULT_FAILED)

    def _run_command(self, peer: Peer, msg: Any, cmd: int, p: list[float],
                     frame: int | None) -> None:
        self.counters["commands"] += 1
        nav = self.nav
        result = M.MAV_RESULT_ACCEPTED
        why: str | None = None
        send_hb = False
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            force = finite(p[1]) and abs(p[1] - FORCE_MAGIC) < 0.5
            if finite(p[0]) and p[0] >= 0.5:
                why = nav.arm(force)
            elif finite(p[0]):
                why = nav.disarm(force)
            else:
                why = "Arm: param1 is not a number"
            result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED
            send_hb = why is None
        elif cmd == M.MAV_CMD_DO_SET_MODE:
            if not finite(p[1]):
                why, result = "Mode: not a number", M.MAV_RESULT_DENIED
            else:
                why = nav.set_mode(int(p[1]))
                result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_DENIED
                send_hb = why is None
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            alt = p[6]
            if frame is not None and frame in GLOBAL_FRAMES:
                alt = altitude_to_z(alt, frame, self.origin)
            here = self._pos()
            if not (finite(alt) and alt > 0.0):
                why, result = f"Takeoff: bad altitude {alt}", M.MAV_RESULT_DENIED
            elif (bad := nav.check_target((here[0], here[1], alt))) is not None:
                why, result = f"Takeoff: {bad}", M.MAV_RESULT_DENIED
            else:
                # refused only for the vehicle's state (mode, arming, already flying)
                why = nav.takeoff(alt)
                result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED
        elif cmd == M.MAV_CMD_NAV_LAND:
            why = nav.set_mode(FlightMode.LAND)
            result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED
            send_hb = why is None
        elif cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            why = nav.set_mode(FlightMode.RTL)
            result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED
            send_hb = why is None
        elif cmd == M.MAV_CMD_MISSION_START:
            first = int(p[0]) if finite(p[0]) else 0
            why = nav.start_mission(first)
            result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED
            send_hb = why is None
        elif cmd == M.MAV_CMD_DO_REPOSITION:
            why, result = self._reposition(p, frame)
            send_hb = why is None
        elif cmd == M.MAV_CMD_DO_CHANGE_SPEED:
            why = nav.change_speed(p[1]) if finite(p[1]) and p[1] > 0 else None
            if finite(p[1]) and p[1] > 0 and why is not None:
                result = M.MAV_RESULT_DENIED
        elif cmd == M.MAV_CMD_CONDITION_YAW:
            why, result = self._condition_yaw(p)
        elif cmd == M.MAV_CMD_GET_HOME_POSITION:
            if nav.home_m is None:
                result = M.MAV_RESULT_TEMPORARILY_REJECTED
            else:
                self.io.send(self._home_position(), peer)
        elif cmd == M.MAV_CMD_DO_SET_HOME:
            why, result = self._set_home(p)
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            result = self._request_message(peer, p)
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(peer, p[0], p[1])
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self.io.send(self._autopilot_version(), peer)
        elif cmd == M.MAV_CMD_REQUEST_PROTOCOL_VERSION:
            result = M.MAV_RESULT_UNSUPPORTED
        elif cmd == M.MAV_CMD_DO_WINCH:
            if self._to_winch(msg):
                self._winch_pending.append((time.monotonic(), peer, msg.get_srcSystem(),
                                            msg.get_srcComponent(), cmd))
                return   # acknowledged when the winch answers
            why, result = "Winch: not connected", M.MAV_RESULT_FAILED
        elif cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            why = nav.set_current(int(p[0])) if finite(p[0]) else "bad mission item"
            result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_DENIED
        else:
            self.counters["unsupported"] += 1
            result = M.MAV_RESULT_UNSUPPORTED
        self._ack(peer, msg, cmd, result)
        if result == M.MAV_RESULT_DENIED and cmd in (M.MAV_CMD_DO_REPOSITION,
                                                     M.MAV_CMD_NAV_TAKEOFF):
            self.counters["rejected_targets"] += 1     # NaN, below ground, out of reach
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING if result != M.MAV_RESULT_ACCEPTED
                            else M.MAV_SEVERITY_INFO, why)
        if send_hb:
            self.send_heartbeat()

    def _on_set_mode(self, peer: Peer, msg: Any) -> None:
        why = self.nav.set_mode(msg.custom_mode)
        result = M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_DENIED
        self._ack(peer, msg, M.MAV_CMD_DO_SET_MODE, result)
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING, why)
        else:
            self.send_heartbeat()

    def _global_to_local(self, lat: float, lon: float, alt: float, frame: int | None) -> Vec3:
        return global_to_local(lat, lon, alt, frame, self.origin)

    def _reposition(self, p: list[float], frame: int | None) -> tuple[str | None, int]:
        nav = self.nav
        if frame is not None and frame not in GLOBAL_FRAMES:
            return "Reposition: unsupported frame", M.MAV_RESULT_DENIED
        lat, lon, alt = p[4], p[5], p[6]
        if not (finite(lat) and finite(lon)) or (lat == 0.0 and lon == 0.0):
            return "Reposition: position is not a number", M.MAV_RESULT_DENIED
        target = self._global_to_local(lat, lon, alt, frame)
        if not finite(alt):
            ref = nav.reference()
            target = (target[0], target[1], ref.pos_m[2] if ref else self._pos()[2])
        why = nav.check_target(target)
        if why is not None:
            return f"Reposition: {why}", M.MAV_RESULT_DENIED
        if not nav.flying:
            return "Reposition: not flying", M.MAV_RESULT_FAILED
        if nav.mode != FlightMode.GUIDED:
            nav.set_mode(FlightMode.GUIDED)
        yaw = yaw_ned_to_enu(math.radians(p[3])) if finite(p[3]) else None
        speed = p[0] if finite(p[0]) and p[0] > 0 else None
        why = nav.goto(target, yaw, speed)
        return why, (M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED)

    def _condition_yaw(self, p: list[float]) -> tuple[str | None, int]:
        if not finite(p[0]):
            return "Yaw: not a number", M.MAV_RESULT_DENIED
        heading_ned = math.radians(p[0])
        if finite(p[3]) and p[3] >= 0.5:   # relative to the current heading
            direction = -1.0 if finite(p[2]) and p[2] < 0 else 1.0
            yaw_now = quat_to_euler(self._telem.quat)[2] if self._telem else 0.0
            heading_ned = yaw_enu_to_ned(yaw_now) + direction * heading_ned
        why = self.nav.set_yaw(yaw_ned_to_enu(heading_ned))
        return why, (M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED)

    def _set_home(self, p: list[float]) -> tuple[str | None, int]:
        if finite(p[0]) and p[0] >= 0.5:
            self.nav.home_m = self._pos()
        else:
            if not (finite(p[4]) and finite(p[5]) and finite(p[6])):
                return "Home: not a number", M.MAV_RESULT_DENIED
            home = global_to_local_enu(p[4], p[5], p[6], self.origin)
            why = self.nav.check_target((home[0], home[1], max(home[2], 0.0)))
            if why is not None:
                return f"Home: {why}", M.MAV_RESULT_DENIED
            self.nav.home_m = (home[0], home[1], self.nav.gear_height_m)
        self._update_mission_home()
        self.io.send(self._home_position())
        return None, M.MAV_RESULT_ACCEPTED

    def _request_message(self, peer: Peer, p: list[float]) -> int:
        if not finite(p[0]):
            return M.MAV_RESULT_DENIED
        mid = int(p[0])
        if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self.io.send(self._autopilot_version(), peer)
        elif mid == M.MAVLINK_MSG_ID_HOME_POSITION:
            if self.nav.home_m is None:
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            self.io.send(self._home_position(), peer)
        elif mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            self.send_heartbeat()
        elif mid in _MSG_NAMES and self._telem is not None:
            self.io.send(self._build(_MSG_NAMES[mid], self._telem), peer)
        else:
            return M.MAV_RESULT_UNSUPPORTED
        return M.MAV_RESULT_ACCEPTED

    def _set_interval(self, peer: Peer, msg_id: float, interval_us: float) -> int:
        if not (finite(msg_id) and finite(interval_us)):
            return M.MAV_RESULT_DENIED
        name = _MSG_NAMES.get(int(msg_id))
        if name is None:
            return M.MAV_RESULT_UNSUPPORTED if int(msg_id) != M.MAVLINK_MSG_ID_HEARTBEAT \
                else M.MAV_RESULT_ACCEPTED
        sched = self._link(peer).schedule
        self._streams_due = -math.inf
        if interval_us < 0:
            sched[name] = [0.0, math.inf]
        else:
            interval = (1.0 / DEFAULT_RATES_HZ[name] if interval_us == 0
                        else max(interval_us * 1e-6, 0.002))
            sched[name] = [interval, self._telem.t_s if self._telem else 0.0]
        return M.MAV_RESULT_ACCEPTED

    def _on_request_data_stream(self, peer: Peer, msg: Any) -> None:
        groups = (list(STREAM_GROUPS) if msg.req_stream_id == M.MAV_DATA_STREAM_ALL
                  else [msg.req_stream_id])
        rate = msg.req_message_rate if msg.start_stop else 0
        sched = self._link(peer).schedule
        self._streams_due = -math.inf
        t = self._telem.t_s if self._telem else 0.0
        for g in groups:
            for name in STREAM_GROUPS.get(g, ()):
                sched[name] = [1.0 / rate, t] if rate > 0 else [0.0, math.inf]

    def _on_timesync(self, peer: Peer, msg: Any) -> None:
        if msg.tc1 == 0:
            self.io.send(M.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), peer)

    def _on_mission_set_current(self, peer: Peer, msg: Any) -> None:
        why = self.nav.set_current(msg.seq)
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING, why)
        self.io.send(self._mission_current(), peer)

    # ----- guided targets as mission items (current = 2: go there; 3: change altitude)

    def _on_mission_item_int(self, peer: Peer, msg: Any) -> None:
        self._guided_item(peer, msg)

    def _on_mission_item(self, peer: Peer, msg: Any) -> None:
        self._guided_item(peer, msg)

    def _guided_item(self, peer: Peer, msg: Any) -> None:
        """What MAVProxy's ``guided`` and older ground stations send, as ArduCopter takes
        it: answered with a MISSION_ACK."""
        if msg.current not in (2, 3):
            return
        result = M.MAV_MISSION_ACCEPTED
        why: str | None = None
        try:
            item = mission_from_message(msg)
        except ValueError:
            item = None
        if item is None or item.frame not in GLOBAL_FRAMES:
            result, why = M.MAV_MISSION_UNSUPPORTED_FRAME, "Guided: frame not supported"
        else:
            target = self._global_to_local(item.x * 1e-7, item.y * 1e-7, item.z, item.frame)
            ref = self.nav.reference()
            here = ref.pos_m if ref is not None else self._pos()
            if msg.current == 3:
                target = (here[0], here[1], target[2])
            why = self.nav.check_target(target)
            if why is not None:
                result = (M.MAV_MISSION_INVALID_PARAM7 if "ground" in why
                          else M.MAV_MISSION_INVALID_PARAM5_X if "reach" in why
                          else M.MAV_MISSION_INVALID)
                self.counters["rejected_targets"] += 1
            else:
                why = self.nav.goto(target)
                if why is not None:
                    result = M.MAV_MISSION_ERROR
        self.io.send(M.MAVLink_mission_ack_message(msg.get_srcSystem(),
                                                   msg.get_srcComponent(), result,
                                                   M.MAV_MISSION_TYPE_MISSION), peer)
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING, f"Guided: {why}")

    # ----- guided position targets

    def _on_set_position_target_local_ned(self, peer: Peer, msg: Any) -> None:
        frame, mask = msg.coordinate_frame, msg.type_mask
        here = self._pos()
        yaw_now = quat_to_euler(self._telem.quat)[2] if self._telem else 0.0
        pos_ned = (msg.x, msg.y, msg.z)
        vel_ned = (msg.vx, msg.vy, msg.vz)
        if frame == M.MAV_FRAME_LOCAL_NED:
            base = None
        elif frame == M.MAV_FRAME_LOCAL_OFFSET_NED:
            base = enu_to_ned(here)
        elif frame in (M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED):
            # offsets and velocities turned by the heading, as ArduCopter does
            c, s = math.cos(yaw_enu_to_ned(yaw_now)), math.sin(yaw_enu_to_ned(yaw_now))
            pos_ned = (c * msg.x - s * msg.y, s * msg.x + c * msg.y, msg.z)
            vel_ned = (c * msg.vx - s * msg.vy, s * msg.vx + c * msg.vy, msg.vz)
            base = enu_to_ned(here)
        else:
            self._reject_target(f"Guided: frame {frame} not supported")
            return
        if base is not None:
            pos_ned = (base[0] + pos_ned[0], base[1] + pos_ned[1], base[2] + pos_ned[2])
        self._guided_target(mask, ned_to_enu(pos_ned), ned_to_enu(vel_ned), msg.yaw,
                            msg.yaw_rate)

    def _on_set_position_target_global_int(self, peer: Peer, msg: Any) -> None:
        if msg.coordinate_frame not in GLOBAL_FRAMES:
            self._reject_target(f"Guided: frame {msg.coordinate_frame} not supported")
            return
        mask = msg.type_mask
        pos = (math.nan,) * 3
        if not mask & M.POSITION_TARGET_TYPEMASK_X_IGNORE:
            pos = self._global_to_local(msg.lat_int * 1e-7, msg.lon_int * 1e-7, msg.alt,
                                        msg.coordinate_frame)
        self._guided_target(mask, pos, ned_to_enu((msg.vx, msg.vy, msg.vz)), msg.yaw,
                            msg.yaw_rate)

    def _guided_target(self, mask: int, pos: Vec3, vel: Vec3, yaw_ned: float,
                       yaw_rate_ned: float) -> None:
        nav = self.nav
        pos_ignored = mask & _POS_IGNORE == _POS_IGNORE
        vel_ignored = mask & _VEL_IGNORE == _VEL_IGNORE
        yaw = None if mask & M.POSITION_TARGET_TYPEMASK_YAW_IGNORE or not finite(yaw_ned) \
            else yaw_ned_to_enu(yaw_ned)
        yaw_rate = None if mask & M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE \
            or not finite(yaw_rate_ned) else -yaw_rate_ned
        if nav.mode != FlightMode.GUIDED:
            self._reject_target("Guided: not in GUIDED", count=False)
            return
        if not pos_ignored:
            why = nav.goto(pos, yaw)
        elif not vel_ignored:
            why = nav.set_velocity(vel, yaw, yaw_rate)
            if why is None:
                # a velocity target must keep the vehicle within the tether's reach
                ahead = tuple(self._pos()[i] + 3.0 * vel[i] for i in range(3))
                if nav.check_target(ahead) is not None and nav.check_target(
                        self._pos()) is None:
                    nav.set_velocity((0.0, 0.0, 0.0))
                    why = f"velocity leads {nav.check_target(ahead)}"
        else:
            why = "Guided: acceleration-only targets not supported"
        if why is not None:
            self._reject_target(f"Guided: {why}" if not why.startswith("Guided") else why)

    def _reject_target(self, why: str, count: bool = True) -> None:
        if count:
            self.counters["rejected_targets"] += 1
        self.statustext(M.MAV_SEVERITY_WARNING, why)

    # ----- missions

    def _validate_item(self, seq: int, item: MissionItem) -> tuple[int, str] | None:
        try:
            nav_command(seq, item, self.origin, self.nav)
        except ItemRefused as exc:
            return exc.result, f"Mission: item {seq}: {exc}"
        return None

    def _mission_changed(self, items: list[MissionItem]) -> None:
        self.nav.set_mission(nav_commands(items, self.origin, self.nav))
        self.log(f"mission of {len(items) - 1} items accepted")

    def _update_mission_home(self) -> None:
        home = self.nav.home_m
        if home is None:
            return
        self.missions.set_home(mission_home(home, self.origin))

    # ----- navigator events

    def _nav_event(self, kind: str, value: object) -> None:
        if kind == NavEvent.CURRENT:
            self.io.send(self._mission_current())
        elif kind == NavEvent.REACHED:
            self.io.send(M.MAVLink_mission_item_reached_message(int(value)))
            self.statustext(M.MAV_SEVERITY_INFO, f"Reached command #{int(value)}")
        elif kind == NavEvent.MISSION_DONE:
            self.statustext(M.MAV_SEVERITY_INFO, "Mission: complete")
        elif kind == NavEvent.TAKEOFF_DONE:
            self.statustext(M.MAV_SEVERITY_INFO, "Takeoff complete")
        elif kind == NavEvent.LANDED:
            self.statustext(M.MAV_SEVERITY_INFO, "Landed")
        elif kind == NavEvent.ERROR:
            self.statustext(M.MAV_SEVERITY_ERROR, f"Nav: {value}"[:150])
        elif kind == NavEvent.DISARMED:
            self.statustext(M.MAV_SEVERITY_INFO, "Disarmed")
            self.send_heartbeat()

    def armed_changed(self) -> None:
        """Call after arming on the ground: home is set there, and announced."""
        self._update_mission_home()
        self.io.send(self._home_position())
        self.send_heartbeat()

    # ----- telemetry

    def _pos(self) -> Vec3:
        return self._telem.pos_m if self._telem is not None else (0.0, 0.0, 0.0)

    def _link(self, peer: Peer) -> _LinkState:
        st = self._links.get(peer)
        if st is None:
            st = self._links[peer] = _LinkState()
            t = self._telem.t_s if self._telem is not None else 0.0
            for name, rate in DEFAULT_RATES_HZ.items():
                st.schedule[name] = [1.0 / rate, t]
        return st

    def _streams(self, t: float) -> None:
        """Send the telemetry due at ``t`` [s] on each link; note when the next is due."""
        gen = self.io.generation
        links = self.io.links()
        built: dict[str, bytes] = {}
        next_due = math.inf
        for peer in links:
            st = self._link(peer)
            frames: list[bytes] = []
            for name, entry in st.schedule.items():
                interval, due = entry
                if interval <= 0.0:
                    continue
                if t >= due - DUE_TOLERANCE_S:
                    entry[1] = max(due + interval, t) if t - due < interval else t + interval
                    if not (name == "HOME_POSITION" and self.nav.home_m is None):
                        data = built.get(name)
                        if data is None:
                            data = built[name] = self.io.pack(self._build(name, self._telem))
                        frames.append(data)
                next_due = min(next_due, entry[1])
            if frames:
                # in one write: a station wakes once for the period's telemetry
                self.io.send_frames(frames, peer)
        for gone in [p for p in self._links if p not in links]:
            del self._links[gone]
        self._streams_due, self._streams_gen = next_due, gen

    def _build(self, name: str, tm: Telemetry) -> Any:
        boot_ms = int(tm.t_s * 1000) & 0xFFFFFFFF
        if name == "ATTITUDE":
            q = quat_enu_flu_to_ned_frd(tm.quat)
            roll, pitch, yaw = quat_to_euler(q)   # ZYX angles of body FRD in NED
            p, q_, r = flu_to_frd(tm.rates_rad_s)
            return M.MAVLink_attitude_message(boot_ms, roll, pitch, yaw, p, q_, r)
        if name == "LOCAL_POSITION_NED":
            x, y, z = enu_to_ned(tm.pos_m)
            vx, vy, vz = enu_to_ned(tm.vel_m_s)
            return M.MAVLink_local_position_ned_message(boot_ms, x, y, z, vx, vy, vz)
        if name == "GLOBAL_POSITION_INT":
            lat, lon, alt = local_enu_to_global(tm.pos_m, self.origin)
            vn = enu_to_ned(tm.vel_m_s)
            hdg = math.degrees(yaw_enu_to_ned(quat_to_euler(tm.quat)[2])) % 360.0
            return M.MAVLink_global_position_int_message(
                boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                round(tm.pos_m[2] * 1000), _i16(vn[0] * 100), _i16(vn[1] * 100),
                _i16(vn[2] * 100), round(hdg * 100) % 36000)
        if name == "GPS_RAW_INT":
            lat, lon, alt = local_enu_to_global(tm.pos_m, self.origin)
            vn = enu_to_ned(tm.vel_m_s)
            gs = math.hypot(vn[0], vn[1])
            cog = math.degrees(math.atan2(vn[1], vn[0])) % 360.0 if gs > 0.1 else 0.0
            return M.MAVLink_gps_raw_int_message(
                int(tm.t_s * 1e6), M.GPS_FIX_TYPE_3D_FIX, round(lat * 1e7), round(lon * 1e7),
                round(alt * 1000), 70, 100, round(gs * 100), round(cog * 100) % 36000, 16)
        if name == "VFR_HUD":
            vn = enu_to_ned(tm.vel_m_s)
            gs = math.hypot(vn[0], vn[1])
            hdg = math.degrees(yaw_enu_to_ned(quat_to_euler(tm.quat)[2])) % 360.0
            return M.MAVLink_vfr_hud_message(gs, gs, round(hdg) % 360,
                                              round(100 * tm.throttle),
                                              self.origin[2] + tm.pos_m[2], -vn[2])
        if name == "SYS_STATUS":
            # the fence's health bit is set as ArduPilot sets it while no fence is breached
            return M.MAVLink_sys_status_message(_SENSORS, _SENSORS,
                                                _SENSORS | M.MAV_SYS_STATUS_GEOFENCE, 100, 48000,
                                                round(100 * 100 * tm.throttle), 100, 0, 0, 0,
                                                0, 0, 0)
        if name == "BATTERY_STATUS":
            # powered through the tether: a steady supply, never discharging
            cells = [48000] + [65535] * 9
            return M.MAVLink_battery_status_message(
                0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_UNKNOWN, 32767, cells,
                round(100 * 100 * tm.throttle), -1, -1, 100)
        if name == "EXTENDED_SYS_STATE":
            return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED,
                                                        self._landed_state())
        if name == "HOME_POSITION":
            return self._home_position()
        if name == "MISSION_CURRENT":
            return self._mission_current()
        if name == "SYSTEM_TIME":
            return M.MAVLink_system_time_message(int(time.time() * 1e6), boot_ms)
        raise KeyError(name)

    def _landed_state(self) -> int:
        nav = self.nav
        if not nav.armed or nav.landed:
            return M.MAV_LANDED_STATE_ON_GROUND
        if nav.landing:
            return M.MAV_LANDED_STATE_LANDING
        if self._telem is not None and self._telem.pos_m[2] < nav.gear_height_m + 1.0 \
                and self._telem.vel_m_s[2] > 0.1:
            return M.MAV_LANDED_STATE_TAKEOFF
        return M.MAV_LANDED_STATE_IN_AIR

    def _home_position(self) -> Any:
        home = self.nav.home_m or (0.0, 0.0, 0.0)
        ground = (home[0], home[1], 0.0)
        lat, lon, alt = local_enu_to_global(ground, self.origin)
        x, y, z = enu_to_ned(ground)
        return M.MAVLink_home_position_message(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000), x, y, z, [1.0, 0.0, 0.0, 0.0],
            0.0, 0.0, 0.0, int(self._telem.t_s * 1e6) if self._telem else 0)

    def _mission_current(self) -> Any:
        nav = self.nav
        total = len(self.missions.items) if hasattr(self.missions, "items") else 0
        if nav.mission_running:
            state = M.MISSION_STATE_ACTIVE
        elif total <= 1:
            state = M.MISSION_STATE_NO_MISSION
        else:
            state = M.MISSION_STATE_NOT_STARTED
        return M.MAVLink_mission_current_message(nav.current_seq, max(total - 1, 0), state,
                                                 1 if nav.mode == FlightMode.AUTO else 0)

    def _autopilot_version(self) -> Any:
        return M.MAVLink_autopilot_version_message(
            CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, list(b"tuavsitl"), [0] * 8, [0] * 8, 0,
            0, 0x7475617600000001)


def _i16(x: float) -> int:
    return max(-32768, min(32767, round(x)))

