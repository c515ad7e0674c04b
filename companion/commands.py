"""Ground-station commands to the vehicle, as ArduCopter takes them: COMMAND_LONG and
COMMAND_INT (each answered by one COMMAND_ACK to its sender at once, whatever happens),
SET_MODE (answered with the ACK of MAV_CMD_DO_SET_MODE), MISSION_SET_CURRENT, and the
guided targets: SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT in GUIDED and the MISSION_ITEM
with current = 2 (go there) or 3 (change altitude) that MAVProxy's ``guided`` sends.

Every target is checked against the tether's reach and the ground (the navigator's
``check_target``) before it is flown; refusals are counted in ``counters
["rejected_targets"]`` and said in a STATUSTEXT. Positions arrive in MAVLink's frames
(local NED with its origin at the winder, global frames of :mod:`tuavdefs.mav_frames`) and
are turned into the inertial z-up frame here; headings in NED are turned into z-up yaw.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.mavlink_io import MavlinkEndpoints, Peer
from companion.mission_items import finite
from companion.mission_protocol import from_message as mission_from_message
from companion.navigation import FlightMode, Navigator, Reason, Refusal
from companion.telemetry import TelemetryStreams
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

__all__ = ["FORCE_MAGIC", "CommandHandler"]

FORCE_MAGIC = 21196.0
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces arming or disarming."""

_POS_IGNORE = (M.POSITION_TARGET_TYPEMASK_X_IGNORE | M.POSITION_TARGET_TYPEMASK_Y_IGNORE
               | M.POSITION_TARGET_TYPEMASK_Z_IGNORE)
_VEL_IGNORE = (M.POSITION_TARGET_TYPEMASK_VX_IGNORE | M.POSITION_TARGET_TYPEMASK_VY_IGNORE
               | M.POSITION_TARGET_TYPEMASK_VZ_IGNORE)


class CommandHandler:
    """The commands and guided targets of ground stations, on the navigator ``nav``.

    ``io`` sends the answers; ``origin`` is the winder's (latitude deg, longitude deg,
    ground altitude m AMSL); ``streams`` has the vehicle's latest telemetry and builds the
    messages a command asks for; ``counters`` (``commands``, ``unsupported``,
    ``rejected_targets``) is counted in place. The vehicle's side of what a command changes:
    ``statustext(severity, text)`` says why a command was refused or what it did,
    ``send_heartbeat()`` announces a mode or arming change, ``home_changed()`` announces a
    new home (the mission's item 0, HOME_POSITION), ``forward_winch(peer, msg)`` hands a
    MAV_CMD_DO_WINCH to the winch and answers it when the winch does (False: no winch),
    ``log(text)`` the process log.
    """

    def __init__(self, io: MavlinkEndpoints, nav: Navigator, origin: Vec3,
                 streams: TelemetryStreams, counters: dict[str, int],
                 statustext: Callable[[int, str], None], send_heartbeat: Callable[[], None],
                 home_changed: Callable[[], None],
                 forward_winch: Callable[[Peer, Any], bool],
                 log: Callable[[str], None]) -> None:
        self.io = io
        self.nav = nav
        self.origin = origin
        self.streams = streams
        self.counters = counters
        self.statustext = statustext
        self.send_heartbeat = send_heartbeat
        self.home_changed = home_changed
        self.forward_winch = forward_winch
        self.log = log
        self.reboot: Callable[[], None] | None = None
        """Restarts the onboard state (PREFLIGHT_REBOOT_SHUTDOWN); None: not offered."""

    def handlers(self) -> dict[str, Callable[[Peer, Any], None]]:
        """Handlers of the ground-station messages this takes: type -> ``f(peer, msg)``."""
        return {
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_MODE": self._on_set_mode,
            "MISSION_SET_CURRENT": self._on_mission_set_current,
            "MISSION_ITEM_INT": self._guided_item,
            "MISSION_ITEM": self._guided_item,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_set_position_target_local_ned,
            "SET_POSITION_TARGET_GLOBAL_INT": self._on_set_position_target_global_int,
        }

    def _ack(self, peer: Peer, msg: Any, command: int, result: int) -> None:
        self.io.send(M.MAVLink_command_ack_message(
            command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), peer)

    # ----- COMMAND_LONG, COMMAND_INT, SET_MODE

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
        why: str | Refusal | None = None
        send_hb = False
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            force = finite(p[1]) and abs(p[1] - FORCE_MAGIC) < 0.5
            if finite(p[0]) and p[0] >= 0.5:
                why = nav.arm(force)
            elif finite(p[0]):
                why = nav.disarm(force)
            else:
                why = "Arm: param1 is not a number"
            result = (M.MAV_RESULT_ACCEPTED if why is None
                      else M.MAV_RESULT_DENIED
                      if isinstance(why, Refusal) and why.reason is Reason.PREARM
                      else M.MAV_RESULT_FAILED)
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
            if not self.streams.home_set():
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
        elif cmd == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            result = self.streams.get_interval(peer, p[0])
        elif cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self.io.send(self.streams.autopilot_version(), peer)
        elif cmd == M.MAV_CMD_REQUEST_PROTOCOL_VERSION:
            result = M.MAV_RESULT_UNSUPPORTED
        elif cmd == M.MAV_CMD_DO_WINCH:
            if self.forward_winch(peer, msg):
                return   # acknowledged when the winch answers
            why, result = "Winch: not connected", M.MAV_RESULT_FAILED
        elif cmd == M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
            why, result = self._reboot(p)
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

    def _reboot(self, p: list[float]) -> tuple[str | None, int]:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN for the autopilot (p1), as ArduPilot answers
        it: 1 (and 3, to the bootloader) reboots, refused while armed; 0 does nothing;
        shutting down (2) is not offered."""
        action = round(p[0]) if finite(p[0]) else -1
        if action == 0:
            return None, M.MAV_RESULT_ACCEPTED
        if action not in (1, 3) or self.reboot is None:
            return None, M.MAV_RESULT_UNSUPPORTED
        if self.nav.armed:
            return "Reboot: disarm first", M.MAV_RESULT_FAILED
        self.reboot()
        return "Rebooting: disarmed, on the ground, the EKF aligning", M.MAV_RESULT_ACCEPTED

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
        self.home_changed()
        return None, M.MAV_RESULT_ACCEPTED

    def _on_mission_set_current(self, peer: Peer, msg: Any) -> None:
        why = self.nav.set_current(msg.seq)
        if why is not None:
            self.statustext(M.MAV_SEVERITY_WARNING, why)
        self.io.send(self.streams.mission_current(), peer)

    # ----- guided targets as mission items (current = 2: go there; 3: change altitude)

    def _guided_item(self, peer: Peer, msg: Any) -> None:
        """What MAVProxy's ``guided`` and older ground stations send, as ArduCopter takes
        it: answered with a MISSION_ACK."""
        if msg.current not in (2, 3):
            return
        result = M.MAV_MISSION_ACCEPTED
        why: str | Refusal | None = None
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
                result = (M.MAV_MISSION_INVALID_PARAM7 if why.reason is Reason.BELOW_GROUND
                          else M.MAV_MISSION_INVALID_PARAM5_X
                          if why.reason is Reason.BEYOND_REACH else M.MAV_MISSION_INVALID)
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
        why: Refusal | str | None
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
                    why = f"Guided: velocity leads {nav.check_target(ahead)}"
        else:
            why = "Guided: acceleration-only targets not supported"
        if isinstance(why, Refusal):
            self._reject_target(f"Guided: {why}")
        elif why is not None:
            self._reject_target(why)

    def _reject_target(self, why: str, count: bool = True) -> None:
        if count:
            self.counters["rejected_targets"] += 1
        self.statustext(M.MAV_SEVERITY_WARNING, why)
