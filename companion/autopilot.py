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
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.mavlink_io import MavlinkEndpoints, Peer
from companion.mission_items import ItemRefused, finite, mission_home, nav_command, nav_commands
from companion.mission_protocol import MissionItem, MissionProtocol
from companion.mission_protocol import from_message as mission_from_message
from companion.navigation import FlightMode, NavEvent, Navigator
from companion.param_protocol import ParamDef, ParamProtocol
from companion.telemetry import DUE_TOLERANCE_S, Telemetry, TelemetryStreams
from tuavdefs import component_link as cl
from tuavdefs.frames import (
    enu_to_ned,
    global_to_local_enu,
    ned_to_enu,
    quat_to_euler,
    yaw_enu_to_ned,
    yaw_ned_to_enu,
)
from tuavdefs.mav_frames import GLOBAL_FRAMES, altitude_to_z, global_to_local

M = mavlink2
Vec3 = tuple[float, float, float]

FORCE_MAGIC = 21196.0
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces arming or disarming."""

_WINCH_ACK_TIMEOUT_S = 0.4
_POS_IGNORE = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
               | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


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
        self.streams = TelemetryStreams(endpoints, nav, self.origin, self.missions)
        # ground-station message type -> handler(peer, msg)
        self._handlers: dict[str, Callable[[Peer, Any], None]] = {
            name[4:].upper(): getattr(self, name) for name in dir(type(self))
            if name.startswith("_on_")}
        self._handlers.update(self.streams.handlers())
        self._boot_wall = time.monotonic()
        self._last_hb_sim = -math.inf
        self._last_hb_wall = -math.inf
        self._statustext_id = 0
        self._winch_pending: list[tuple[float, Peer, int, int, int]] = []
        self._winch_sink: Callable[[Any], None] | None = None
        self.counters = {"commands": 0, "unsupported": 0, "rejected_targets": 0}
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
        streams = self.streams
        if telem is not None:
            streams.telem = telem
        io = self.io
        if io.closed_pending:
            for peer in io.pop_closed():
                self.missions.peer_closed(peer)
                self.params.peer_closed(peer)
                streams.forget(peer)
        now_wall = time.monotonic()
        self.missions.tick(now_wall)
        self.params.tick(now_wall)
        if self._winch_pending:
            self._expire_winch(now_wall)
        if self.nav.has_events:
            for kind, value in self.nav.pop_events():
                self._nav_event(kind, value)
        tm = streams.telem
        t = tm.t_s if tm is not None else -math.inf
        if (now_wall - self._last_hb_wall >= 1.0
                or t - self._last_hb_sim >= 1.0 - DUE_TOLERANCE_S):
            self.send_heartbeat()
        if tm is not None and (t >= streams.due_s - DUE_TOLERANCE_S
                               or io.generation != streams.generation):
            streams.send_due(t)    # something is due on some link (otherwise nothing to do)
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
        if self.streams.telem is not None:
            self._last_hb_sim = self.streams.telem.t_s

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
        handler = self._handlers.get(mtype)
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
            here = self.streams.position()
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
                self.io.send(self.streams.home_position(), peer)
        elif cmd == M.MAV_CMD_DO_SET_HOME:
            why, result = self._set_home(p)
        elif cmd == M.MAV_CMD_REQUEST_MESSAGE:
            if finite(p[0]) and int(p[0]) == M.MAVLINK_MSG_ID_HEARTBEAT:
                self.send_heartbeat()
                result = M.MAV_RESULT_ACCEPTED
            else:
                result = self.streams.request_message(peer, p[0])
        elif cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self.streams.set_interval(peer, p[0], p[1])
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self.io.send(self.streams.autopilot_version(), peer)
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
            target = (target[0], target[1], ref.pos_m[2] if ref else self.streams.position()[2])
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
            yaw_now = quat_to_euler(self.streams.telem.quat)[2] if self.streams.telem else 0.0
            heading_ned = yaw_enu_to_ned(yaw_now) + direction * heading_ned
        why = self.nav.set_yaw(yaw_ned_to_enu(heading_ned))
        return why, (M.MAV_RESULT_ACCEPTED if why is None else M.MAV_RESULT_FAILED)

    def _set_home(self, p: list[float]) -> tuple[str | None, int]:
        if finite(p[0]) and p[0] >= 0.5:
            self.nav.home_m = self.streams.position()
        else:
            if not (finite(p[4]) and finite(p[5]) and finite(p[6])):
                return "Home: not a number", M.MAV_RESULT_DENIED
            home = global_to_local_enu(p[4], p[5], p[6], self.origin)
            why = self.nav.check_target((home[0], home[1], max(home[2], 0.0)))
            if why is not None:
                return f"Home: {why}", M.MAV_RESULT_DENIED
            self.nav.home_m = (home[0], home[1], self.nav.gear_height_m)
        self._update_mission_home()
        self.io.send(self.streams.home_position())
        return None, M.MAV_RESULT_ACCEPTED

    def _on_timesync(self, peer: Peer, msg: Any) -> None:
        if msg.tc1 == 0:
            self.io.send(M.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), peer)

    def _on_mission_set_current(self, peer: Peer, msg: Any) -> None:
        why = self.nav.set_current(msg.seq)
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING, why)
        self.io.send(self.streams.mission_current(), peer)

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
            here = ref.pos_m if ref is not None else self.streams.position()
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
        here = self.streams.position()
        yaw_now = quat_to_euler(self.streams.telem.quat)[2] if self.streams.telem else 0.0
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
                ahead = tuple(self.streams.position()[i] + 3.0 * vel[i] for i in range(3))
                if nav.check_target(ahead) is not None and nav.check_target(
                        self.streams.position()) is None:
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
            self.io.send(self.streams.mission_current())
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
        self.io.send(self.streams.home_position())
        self.send_heartbeat()

    # ----- telemetry
