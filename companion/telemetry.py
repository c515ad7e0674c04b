"""The vehicle's telemetry to ground stations: what it knows of itself at a control period
(:class:`Telemetry`), the messages built from it, and each link's stream schedule as
ArduCopter keeps one (:class:`TelemetryStreams`).

Every ground-station link starts with :data:`DEFAULT_RATES_HZ` (in simulated time);
SET_MESSAGE_INTERVAL changes one message on the link that asked, REQUEST_DATA_STREAM a group
of them (:data:`STREAM_GROUPS`), GET_MESSAGE_INTERVAL answers with MESSAGE_INTERVAL,
REQUEST_MESSAGE sends one at once. The winch's WINCH_STATUS is scheduled the same way: each
link gets the winch's frames at most at its rate (:meth:`TelemetryStreams.forward`). The
messages due at a period go out in one write per link. Positions: MAVLink's local NED has
its origin at the winder, global positions come from ``origin`` (the winder's latitude deg,
longitude deg, ground altitude m AMSL); inside, the inertial z-up frame and body FLU.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from pymavlink.dialects.v20 import ardupilotmega
from pymavlink.dialects.v20 import common as mavlink2

from companion.ekf import EstimatorFlags, FilterHealth, FilterStatus
from companion.geofence import FenceStatus
from companion.mavlink_io import MavlinkEndpoints, Peer
from companion.mission_items import finite
from companion.mission_protocol import MissionProtocol
from companion.navigation import FlightMode, Navigator
from companion.simlink_client import GpsFix, ImuSample
from tuavdefs.frames import (
    enu_to_ned,
    flu_to_frd,
    local_enu_to_global,
    quat_enu_flu_to_ned_frd,
    quat_to_euler,
    yaw_enu_to_ned,
)

M = mavlink2
APM = ardupilotmega
Vec3 = tuple[float, float, float]

__all__ = ["CAPABILITIES", "DEFAULT_RATES_HZ", "DUE_TOLERANCE_S", "FLIGHT_SW_VERSION",
           "FORWARDED", "STREAM_GROUPS", "Telemetry", "TelemetryStreams"]

#: ArduCopter 4.5.7 official, as AUTOPILOT_VERSION encodes it (major, minor, patch, type).
FLIGHT_SW_VERSION = (4 << 24) | (5 << 16) | (7 << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
#: AUTOPILOT_VERSION's MAV_PROTOCOL_CAPABILITY flags.
CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
                | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)

#: Standard gravity: the milli-g of RAW_IMU / SCALED_IMU [m/s^2].
_G0_M_S2 = 9.80665
#: SYS_STATUS: the inertial sensors, the magnetometer and the barometer, present and
#: enabled always, healthy while their samples arrive (ArduPilot: calibrated, not
#: calibrating, healthy; MAVSDK's is_*_calibration_ok read them).
_INERTIAL = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
             | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE)
#: SYS_STATUS: the control loops, the motor outputs and the tether's supply, always
#: present, enabled and healthy.
_ALWAYS = (M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
           | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
           | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
           | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
           | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
           | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | M.MAV_SYS_STATUS_SENSOR_BATTERY)
#: SYS_STATUS: what says the vehicle is ready: the attitude and heading reference (the
#: estimate), the GNSS (MAVSDK's is_global_position_ok and is_local_position_ok) and the
#: pre-arm checks (MAVSDK's is_armable). Present and enabled always.
_READINESS = (M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_SENSOR_GPS
              | M.MAV_SYS_STATUS_PREARM_CHECK)


#: Default telemetry: message name -> rate [Hz of simulated time].
DEFAULT_RATES_HZ: dict[str, float] = {
    "SYS_STATUS": 1.0, "EXTENDED_SYS_STATE": 1.0, "BATTERY_STATUS": 1.0,
    "GPS_RAW_INT": 2.0, "GLOBAL_POSITION_INT": 5.0, "LOCAL_POSITION_NED": 5.0,
    "ATTITUDE": 10.0, "VFR_HUD": 2.0, "HOME_POSITION": 0.2, "MISSION_CURRENT": 1.0,
    "SYSTEM_TIME": 0.5, "EKF_STATUS_REPORT": 2.0, "RAW_IMU": 2.0, "SCALED_IMU": 2.0,
    "SCALED_PRESSURE": 2.0, "NAV_CONTROLLER_OUTPUT": 2.0, "RC_CHANNELS": 2.0,
    "SERVO_OUTPUT_RAW": 2.0, "WIND": 1.0, "WINCH_STATUS": 20.0,
    "LOCAL_POSITION_NED_COV": 2.0,
}
#: Messages another component sends that the autopilot forwards on each link's schedule
#: (as ArduPilot streams its winch's status).
FORWARDED = frozenset({"WINCH_STATUS"})
#: A message due within this [s] of a period's time is sent in that period: its due times
#: are sums of intervals in floating point, and without it messages due at the same instant
#: (a 5 Hz one on a 10 Hz one's grid) land a period apart as their rounding falls, and a
#: ground station wakes for each.
DUE_TOLERANCE_S = 1e-6
#: REQUEST_DATA_STREAM groups, as ArduPilot assigns messages to them.
STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT",
                                        "NAV_CONTROLLER_OUTPUT"),
    M.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED",
                                 "LOCAL_POSITION_NED_COV"),
    M.MAV_DATA_STREAM_RC_CHANNELS: ("RC_CHANNELS", "SERVO_OUTPUT_RAW"),
    M.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    M.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    M.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "BATTERY_STATUS", "EXTENDED_SYS_STATE",
                               "EKF_STATUS_REPORT", "WIND", "WINCH_STATUS"),
    M.MAV_DATA_STREAM_RAW_SENSORS: ("RAW_IMU", "SCALED_IMU", "SCALED_PRESSURE"),
}
_MSG_IDS = {name: getattr(APM, f"MAVLINK_MSG_ID_{name}") for name in DEFAULT_RATES_HZ}
#: EKF_STATUS_REPORT's flags (ArduPilot's EKF_STATUS_FLAGS) of the estimator's flags
#: (MAVLink's ESTIMATOR_STATUS_FLAGS): the same bits up to PRED_POS_HORIZ_ABS, each of
#: which EKF3 sets only while it is healthy (and so not in its first second).
_EKF_FLAG_BITS = 0x3FF
_MSG_NAMES = {v: k for k, v in _MSG_IDS.items()}


#: A receiver silent this long [s] is reported as no GPS (ArduPilot's AP_GPS timeout, 4 s).
GPS_TIMEOUT_S = 4.0


class Telemetry(NamedTuple):
    """What the vehicle knows of itself at a control period (inertial z-up, body FLU)."""

    t_s: float
    """Simulated time [s]."""
    pos_m: Vec3
    vel_m_s: Vec3
    quat: tuple[float, float, float, float]
    """Attitude, body FLU in the inertial frame (w, x, y, z)."""
    rates_rad_s: Vec3
    """Body rates (FLU) [rad/s]."""
    throttle: float
    """Mean rotor command in [0, 1]."""
    imu: ImuSample | None = None
    """The last IMU, magnetometer and barometer sample (RAW_IMU, SCALED_IMU,
    SCALED_PRESSURE)."""
    gps: GpsFix | None = None
    """The GNSS receiver's last fix (GPS_RAW_INT)."""
    ekf: FilterStatus | None = None
    """The navigation filter's status (EKF_STATUS_REPORT; None when flying on the
    simulator's state)."""
    motors: tuple[float, float, float, float] | None = None
    """The rotor commands in [0, 1], ArduPilot's quad-X order (SERVO_OUTPUT_RAW)."""


@dataclass
class _LinkState:
    """Per-link telemetry schedule: message name -> [interval s, next due s]."""

    schedule: dict[str, list[float]] = field(default_factory=dict)


class TelemetryStreams:
    """The telemetry of every ground-station link of ``io``: the latest :attr:`telem`, the
    schedule of each link, and the messages that describe the vehicle (home, mission state,
    version). ``nav`` gives the flight state, ``missions`` the stored mission, ``origin``
    the winder's (latitude deg, longitude deg, ground altitude m AMSL).

    The caller sets :attr:`telem` at every control period and calls :meth:`send_due` only
    when ``t >= due_s - DUE_TOLERANCE_S`` or the links changed (``io.generation !=
    generation``): most periods nothing is due, and that test is all they cost.
    """

    def __init__(self, io: MavlinkEndpoints, nav: Navigator, origin: Vec3,
                 missions: MissionProtocol) -> None:
        self.io = io
        self.nav = nav
        self.origin = origin
        self.missions = missions
        self.telem: Telemetry | None = None
        """The latest control period's telemetry (None before the first)."""
        self.due_s = -math.inf
        """Earliest time [s] a message is next due on any link."""
        self.generation = -1
        """The endpoints' ``generation`` (their set of links) :attr:`due_s` was found for."""
        self._links: dict[Peer, _LinkState] = {}
        self.mission_started = False
        """The stored mission has begun an item since it was uploaded."""
        self.mission_complete = False
        """The stored mission ran to its end (until it begins again or is replaced)."""
        self.wind_source: Any = None
        """``f()`` -> the onboard wind estimate (velocity the air moves with, z-up [m/s]),
        asked only when WIND is due; None: no estimate (zero wind reported)."""
        self._forwarded: dict[str, bytes] = {}     # the last frame of each forwarded message
        self.fence_status: FenceStatus | None = None
        """SYS_STATUS's geofence bits (None: no geofence; the autopilot sets them)."""
        self.estimator_ready: Callable[[], bool] | None = None
        """``f()`` -> whether the estimate is ready to arm on now (the onboard step's
        :meth:`~companion.onboard.Companion.estimator_ready`, which the pre-arm check asks
        too), asked whenever readiness is reported; None: the last filter status's
        health."""
        self._home_reported = False   # HOME_POSITION was reportable at the last send_due

    def position(self) -> Vec3:
        """The latest position [m] (the winder's exit before the first period)."""
        return self.telem.pos_m if self.telem is not None else (0.0, 0.0, 0.0)

    def ready(self) -> bool:
        """Whether the estimate is ready to arm on now (:attr:`estimator_ready`); always
        when flying on the simulator's state, never before the first period."""
        if self.estimator_ready is not None:
            return self.estimator_ready()
        tm = self.telem
        return tm is not None and (tm.ekf is None or tm.ekf.healthy)

    def home_set(self) -> bool:
        """Whether home is set as ArduPilot reports it (HOME_POSITION sent, streamed and
        on request): the navigator has one and the estimate it came from is ready to arm
        on. ArduCopter sets home from its EKF's position, which EKF3 gives only once it is
        healthy, and then sends HOME_POSITION at once (:meth:`send_due`)."""
        return self.nav.home_m is not None and self.ready()

    def forget(self, peer: Peer) -> None:
        """Drop the schedule of a link that closed."""
        self._links.pop(peer, None)

    def handlers(self) -> dict[str, Any]:
        """Handlers of the ground-station messages this takes: type -> ``f(peer, msg)``."""
        return {"REQUEST_DATA_STREAM": self.on_request_data_stream}

    # ----- the schedule

    def _link(self, peer: Peer) -> _LinkState:
        st = self._links.get(peer)
        if st is None:
            st = self._links[peer] = _LinkState()
            t = self.telem.t_s if self.telem is not None else 0.0
            for name, rate in DEFAULT_RATES_HZ.items():
                st.schedule[name] = [1.0 / rate, t]
        return st

    def send_due(self, t: float) -> None:
        """Send the telemetry due at ``t`` [s] on each link; note when the next is due."""
        io = self.io
        gen = io.generation
        links = io.links()
        built: dict[str, bytes] = {}
        next_due = math.inf
        ready, home = self.ready(), self.home_set()
        newly_home, self._home_reported = home and not self._home_reported, home
        # what is not sent yet (ArduPilot has no local position before its EKF gives one)
        withheld = {"HOME_POSITION": not home, "LOCAL_POSITION_NED": not ready,
                    "LOCAL_POSITION_NED_COV": not ready}
        for peer in links:
            st = self._link(peer)
            frames: list[bytes] = []
            if newly_home and st.schedule["HOME_POSITION"][0] > 0.0:
                st.schedule["HOME_POSITION"][1] = t    # home just set: said at once
            for name, entry in st.schedule.items():
                interval, due = entry
                if interval <= 0.0 or name in FORWARDED:
                    continue
                if t >= due - DUE_TOLERANCE_S:
                    entry[1] = max(due + interval, t) if t - due < interval else t + interval
                    if not withheld.get(name, False):
                        data = built.get(name)
                        if data is None:
                            data = built[name] = io.pack(self.build(name, self.telem))
                        frames.append(data)
                next_due = min(next_due, entry[1])
            if frames:
                # in one write: a station wakes once for the period's telemetry
                io.send_frames(frames, peer)
        for gone in [p for p in self._links if p not in links]:
            del self._links[gone]
        self.due_s, self.generation = next_due, gen

    def forward(self, name: str, data: bytes) -> None:
        """Another component's frame ``data`` of message ``name`` (in :data:`FORWARDED`) to
        every link whose schedule has it due (the rest drop it)."""
        self._forwarded[name] = data
        t = self.telem.t_s if self.telem is not None else 0.0
        io = self.io
        for peer in io.links():
            entry = self._link(peer).schedule[name]
            interval, due = entry
            if interval <= 0.0 or t < due - DUE_TOLERANCE_S:
                continue
            entry[1] = max(due + interval, t) if t - due < interval else t + interval
            io.send_bytes(data, peer)

    def get_interval(self, peer: Peer, msg_id: float) -> int:
        """MAV_CMD_GET_MESSAGE_INTERVAL: MESSAGE_INTERVAL of ``msg_id`` on ``peer``'s link
        to it (interval [us]; -1 stopped; 0 a message this vehicle does not stream); the
        MAV_RESULT."""
        if not finite(msg_id) or not 0 <= msg_id <= 0xFFFFFF:
            return M.MAV_RESULT_DENIED
        mid = int(msg_id)
        name = _MSG_NAMES.get(mid)
        if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            interval_us = 1_000_000
        elif name is None:
            interval_us = 0
        else:
            interval = self._link(peer).schedule[name][0]
            interval_us = round(interval * 1e6) if interval > 0 else -1
        self.io.send(M.MAVLink_message_interval_message(mid, interval_us), peer)
        return M.MAV_RESULT_ACCEPTED

    def set_interval(self, peer: Peer, msg_id: float, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL on ``peer``'s link: ``interval_us`` [us] between
        messages ``msg_id``, 0 for the default rate, negative to stop it. The
        MAV_RESULT."""
        if not (finite(msg_id) and finite(interval_us)):
            return M.MAV_RESULT_DENIED
        name = _MSG_NAMES.get(int(msg_id))
        if name is None:
            return M.MAV_RESULT_UNSUPPORTED if int(msg_id) != M.MAVLINK_MSG_ID_HEARTBEAT \
                else M.MAV_RESULT_ACCEPTED
        if interval_us < 0:
            interval = 0.0
        else:
            interval = (1.0 / DEFAULT_RATES_HZ[name] if interval_us == 0
                        else max(interval_us * 1e-6, 0.002))
        self._set_rate(self._link(peer).schedule, name, interval)
        return M.MAV_RESULT_ACCEPTED

    def _set_rate(self, sched: dict[str, list[float]], name: str, interval: float) -> None:
        """Message ``name`` every ``interval`` [s] (0: stopped) on the link of ``sched``.
        A message that was stopped starts at once; one already streaming keeps its phase
        (due at the earlier of its due time and one new interval from now), and a request
        for the rate it has changes nothing: a ground station repeating its requests (a
        flood of them) costs their decoding, not a burst of every stream in every
        period."""
        entry = sched[name]
        old_interval, due = entry
        if interval <= 0.0:
            entry[0], entry[1] = 0.0, math.inf
            return
        if interval == old_interval:
            return
        t = self.telem.t_s if self.telem else 0.0
        due = t if old_interval <= 0.0 else min(due, t + interval)
        entry[0], entry[1] = interval, due
        self.due_s = min(self.due_s, due)

    def on_request_data_stream(self, peer: Peer, msg: Any) -> None:
        """REQUEST_DATA_STREAM: a group's messages at ``req_message_rate`` [Hz] on
        ``peer``'s link, or stopped."""
        groups = (list(STREAM_GROUPS) if msg.req_stream_id == M.MAV_DATA_STREAM_ALL
                  else [msg.req_stream_id])
        rate = msg.req_message_rate if msg.start_stop else 0
        sched = self._link(peer).schedule
        for g in groups:
            for name in STREAM_GROUPS.get(g, ()):
                self._set_rate(sched, name, 1.0 / rate if rate > 0 else 0.0)

    def request_message(self, peer: Peer, msg_id: float) -> int:
        """MAV_CMD_REQUEST_MESSAGE of message ``msg_id`` (not HEARTBEAT, which the caller
        sends): sent to ``peer`` now; the MAV_RESULT."""
        if not finite(msg_id):
            return M.MAV_RESULT_DENIED
        mid = int(msg_id)
        if mid == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self.io.send(self.autopilot_version(), peer)
        elif mid == M.MAVLINK_MSG_ID_HOME_POSITION:
            if not self.home_set():
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            self.io.send(self.home_position(), peer)
        elif mid in (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                     M.MAVLINK_MSG_ID_LOCAL_POSITION_NED_COV) and not self.ready():
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        elif _MSG_NAMES.get(mid) in FORWARDED:
            data = self._forwarded.get(_MSG_NAMES[mid])
            if data is None:
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            self.io.send_bytes(data, peer)
        elif mid in _MSG_NAMES and self.telem is not None:
            self.io.send(self.build(_MSG_NAMES[mid], self.telem), peer)
        else:
            return M.MAV_RESULT_UNSUPPORTED
        return M.MAV_RESULT_ACCEPTED

    # ----- the messages

    def build(self, name: str, tm: Telemetry) -> Any:
        """Message ``name`` (a key of :data:`DEFAULT_RATES_HZ`) of telemetry ``tm``."""
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
        if name == "LOCAL_POSITION_NED_COV":
            return self._local_position_cov(tm)
        if name == "GLOBAL_POSITION_INT":
            lat, lon, alt = local_enu_to_global(tm.pos_m, self.origin)
            vn = enu_to_ned(tm.vel_m_s)
            hdg = math.degrees(yaw_enu_to_ned(quat_to_euler(tm.quat)[2])) % 360.0
            return M.MAVLink_global_position_int_message(
                boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                round(tm.pos_m[2] * 1000), _i16(vn[0] * 100), _i16(vn[1] * 100),
                _i16(vn[2] * 100), round(hdg * 100) % 36000)
        if name == "GPS_RAW_INT":
            return self._gps_raw(tm)
        if name == "EKF_STATUS_REPORT":
            return self._ekf_status(tm)
        if name in ("RAW_IMU", "SCALED_IMU"):
            return self._imu(name, tm, boot_ms)
        if name == "SCALED_PRESSURE":
            imu = tm.imu
            if imu is None:
                return M.MAVLink_scaled_pressure_message(boot_ms, 0.0, 0.0, 0, 0)
            return M.MAVLink_scaled_pressure_message(
                boot_ms, imu.abs_pressure_hpa, 0.0, round(imu.temperature_c * 100), 0)
        if name == "VFR_HUD":
            vn = enu_to_ned(tm.vel_m_s)
            gs = math.hypot(vn[0], vn[1])
            hdg = math.degrees(yaw_enu_to_ned(quat_to_euler(tm.quat)[2])) % 360.0
            return M.MAVLink_vfr_hud_message(gs, gs, round(hdg) % 360,
                                              round(100 * tm.throttle),
                                              self.origin[2] + tm.pos_m[2], -vn[2])
        if name == "SYS_STATUS":
            return self._sys_status(tm)
        if name == "BATTERY_STATUS":
            # powered through the tether: a steady supply, never discharging
            cells = [48000] + [65535] * 9
            return M.MAVLink_battery_status_message(
                0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_UNKNOWN, 32767, cells,
                round(100 * 100 * tm.throttle), -1, -1, 100)
        if name == "EXTENDED_SYS_STATE":
            return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED,
                                                        self.landed_state())
        if name == "HOME_POSITION":
            return self.home_position()
        if name == "MISSION_CURRENT":
            return self.mission_current()
        if name == "SYSTEM_TIME":
            return M.MAVLink_system_time_message(int(time.time() * 1e6), boot_ms)
        if name == "NAV_CONTROLLER_OUTPUT":
            return self._nav_output(tm)
        if name == "RC_CHANNELS":
            # no RC receiver: no channels, every value "unused", RSSI unknown
            return M.MAVLink_rc_channels_message(boot_ms, 0, *([65535] * 18), 255)
        if name == "SERVO_OUTPUT_RAW":
            # the rotor commands as PWM [us]: 1000 stopped .. 2000 full (ArduPilot's
            # MOT_PWM_MIN, MOT_PWM_MAX defaults), motors 1-4 on outputs 1-4
            pwm = [1000 + round(1000 * min(max(c, 0.0), 1.0)) for c in tm.motors or ()]
            pwm += [0] * (8 - len(pwm))
            return M.MAVLink_servo_output_raw_message(int(tm.t_s * 1e6) & 0xFFFFFFFF, 0,
                                                      *pwm[:8])
        if name == "WIND":
            w = self.wind_source() if self.wind_source is not None else (0.0, 0.0, 0.0)
            speed = math.hypot(w[0], w[1])
            # the direction the wind comes from, clockwise from north [deg]
            frm = math.degrees(math.atan2(-w[0], -w[1])) % 360.0 if speed > 0 else 0.0
            return APM.MAVLink_wind_message(frm, speed, w[2])
        raise KeyError(name)

    @staticmethod
    def _local_position_cov(tm: Telemetry) -> Any:
        """LOCAL_POSITION_NED_COV: the estimate (NED) with the filter's position and
        velocity variances [m^2, m^2/s^2] on the covariance's diagonal; the entries the
        filter does not report NaN (the whole first entry NaN, "unknown", when flying on
        the simulator's state)."""
        x, y, z = enu_to_ned(tm.pos_m)
        vx, vy, vz = enu_to_ned(tm.vel_m_s)
        cov = [math.nan] * 45
        e = tm.ekf
        if e is not None:
            # the upper triangle of the 9x9 (x y z vx vy vz ax ay az) row by row: the
            # diagonal's k-th entry is at 9k - k(k-1)/2; NED from (east, north, up)
            sig = (*enu_to_ned(e.pos_sigma_m), *enu_to_ned(e.vel_sigma_m_s))
            for k, s in enumerate(sig):
                cov[9 * k - k * (k - 1) // 2] = s * s
        return M.MAVLink_local_position_ned_cov_message(
            int(tm.t_s * 1e6), M.MAV_ESTIMATOR_TYPE_AUTOPILOT, x, y, z, vx, vy, vz,
            math.nan, math.nan, math.nan, cov)

    def _nav_output(self, tm: Telemetry) -> Any:
        """NAV_CONTROLLER_OUTPUT: the attitude flown (roll, pitch, yaw [deg]; this
        controller has no separate attitude target to show), the bearing [deg] and
        horizontal distance [m] to the current target, the altitude error [m] (target
        above the vehicle: positive) and the horizontal distance to the reference [m]
        (the cross-track error)."""
        roll, pitch, yaw = quat_to_euler(quat_enu_flu_to_ned_frd(tm.quat))
        target = self.nav.target_m
        ref = self.nav.reference()
        p = tm.pos_m
        if target is None:
            bearing, dist, alt_err = round(math.degrees(yaw)) % 360, 0, 0.0
        else:
            dx, dy = target[0] - p[0], target[1] - p[1]
            bearing = round(math.degrees(math.atan2(dx, dy))) % 360
            dist = min(round(math.hypot(dx, dy)), 65535)
            alt_err = target[2] - p[2]
        xtrack = 0.0 if ref is None else math.hypot(ref.pos_m[0] - p[0], ref.pos_m[1] - p[1])
        b = bearing - 360 if bearing > 180 else bearing
        return M.MAVLink_nav_controller_output_message(
            math.degrees(roll), math.degrees(pitch), b, b, dist, alt_err, 0.0, xtrack)

    def _sys_status(self, tm: Telemetry) -> Any:
        """SYS_STATUS, its bits as ArduPilot sets them (GCS::update_sensor_status_flags):
        the inertial sensors healthy while their samples arrive; the AHRS healthy while
        the estimate is ready to arm on (EKF3 is not healthy until it has settled); the
        GNSS present once the receiver has spoken, healthy with a 3D fix that the
        estimate is ready to fly on; the pre-arm bit healthy when armed or when the
        pre-arm checks pass (the same check arming runs); the fence's as ArduCopter sets
        them (:attr:`fence_status`)."""
        nav = self.nav
        fence = M.MAV_SYS_STATUS_GEOFENCE
        fs = self.fence_status
        present = _INERTIAL | _ALWAYS | _READINESS | (fence if fs and fs.present else 0)
        enabled = _INERTIAL | _ALWAYS | _READINESS | (fence if fs and fs.enabled else 0)
        health = _ALWAYS | (fence if fs is None or fs.healthy else 0)
        if tm.imu is not None:
            health |= _INERTIAL
        ready = self.ready()
        if ready:
            health |= M.MAV_SYS_STATUS_AHRS
        if tm.gps is None:
            present &= ~M.MAV_SYS_STATUS_SENSOR_GPS
            enabled &= ~M.MAV_SYS_STATUS_SENSOR_GPS
        elif ready and self._fix_current(tm) and tm.gps.fix_type >= M.GPS_FIX_TYPE_3D_FIX:
            health |= M.MAV_SYS_STATUS_SENSOR_GPS
        prearm = nav.prearm
        if nav.armed or prearm is None or prearm() is None:
            health |= M.MAV_SYS_STATUS_PREARM_CHECK
        return M.MAVLink_sys_status_message(present, enabled, health, 100, 48000,
                                            round(100 * 100 * tm.throttle), 100, 0, 0, 0,
                                            0, 0, 0)

    @staticmethod
    def _fix_current(tm: Telemetry) -> bool:
        """The receiver's last fix is younger than ``GPS_TIMEOUT_S``."""
        g = tm.gps
        return g is not None and int(tm.t_s * 1e6) - g.time_usec <= GPS_TIMEOUT_S * 1e6

    def _gps_raw(self, tm: Telemetry) -> Any:
        """GPS_RAW_INT of the receiver's last fix (no fix before the first; no GPS once
        the last is ``GPS_TIMEOUT_S`` old, as ArduPilot's driver times out)."""
        g = tm.gps
        t_us = int(tm.t_s * 1e6)
        if g is None or not self._fix_current(tm):
            fix = M.GPS_FIX_TYPE_NO_FIX if g is None else M.GPS_FIX_TYPE_NO_GPS
            return M.MAVLink_gps_raw_int_message(t_us, fix, 0, 0, 0, 65535,
                                                 65535, 65535, 65535, 0)
        vn = enu_to_ned(g.velocity_enu_m_s)
        gs = math.hypot(vn[0], vn[1])
        cog = math.degrees(math.atan2(vn[1], vn[0])) % 360.0 if gs > 0.1 else 0.0
        eph, epv = (min(round(v * 100), 65534) for v in (g.eph_m, g.epv_m))
        return M.MAVLink_gps_raw_int_message(
            t_us, g.fix_type, round(g.lat_deg * 1e7), round(g.lon_deg * 1e7),
            round(g.alt_amsl_m * 1000), eph, epv, round(gs * 100), round(cog * 100) % 36000,
            g.satellites_visible, 0, round(g.eph_m * 1000), round(g.epv_m * 1000))

    def _ekf_status(self, tm: Telemetry) -> Any:
        """EKF_STATUS_REPORT as ArduPilot fills it: flags, and each measurement's test
        ratio as its variance (1.0 at the gate). As EKF3 reports itself, every estimate
        flag is clear while the estimate is not ready to arm on (unhealthy, or not yet
        settled), and UNINITIALIZED is set until it first becomes ready (initialising,
        converging or settling): PRED_POS_HORIZ_ABS, which scripts wait for, says an arm
        would be accepted."""
        e = tm.ekf
        if e is None:   # flying on the simulator's state: everything good
            flags = (APM.EKF_ATTITUDE | APM.EKF_VELOCITY_HORIZ | APM.EKF_VELOCITY_VERT
                     | APM.EKF_POS_HORIZ_REL | APM.EKF_POS_HORIZ_ABS | APM.EKF_POS_VERT_ABS
                     | APM.EKF_PRED_POS_HORIZ_REL | APM.EKF_PRED_POS_HORIZ_ABS)
            return APM.MAVLink_ekf_status_report_message(flags, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        flags = int(e.flags) & _EKF_FLAG_BITS
        if not self.ready():
            flags = 0
            if e.health is not FilterHealth.UNHEALTHY:
                flags |= APM.EKF_UNINITIALIZED
        if e.flags & EstimatorFlags.GPS_GLITCH:
            flags |= APM.EKF_GPS_GLITCHING
        return APM.MAVLink_ekf_status_report_message(
            flags, e.velocity_variance, e.pos_horiz_variance, e.pos_vert_variance,
            e.compass_variance, e.terrain_alt_variance, 0.0)

    def _imu(self, name: str, tm: Telemetry, boot_ms: int) -> Any:
        """RAW_IMU or SCALED_IMU of the last sample: mG, mrad/s, mgauss in body FRD (as
        ArduPilot, RAW_IMU carries the same scaled values)."""
        imu = tm.imu
        if imu is None:
            a = w = m = (0.0, 0.0, 0.0)
            temp = 0
        else:
            a, w, m = (flu_to_frd(v) for v in (imu.accel_flu_m_s2, imu.gyro_flu_rad_s,
                                                  imu.mag_flu_gauss))
            temp = round(imu.temperature_c * 100)
        acc = [_i16(v / _G0_M_S2 * 1000.0) for v in a]
        gyr = [_i16(v * 1000.0) for v in w]
        mag = [_i16(v * 1000.0) for v in m]
        if name == "RAW_IMU":
            return M.MAVLink_raw_imu_message(int(tm.t_s * 1e6), *acc, *gyr, *mag, 0, temp)
        return M.MAVLink_scaled_imu_message(boot_ms, *acc, *gyr, *mag, temp)

    def landed_state(self) -> int:
        """EXTENDED_SYS_STATE's MAV_LANDED_STATE now."""
        nav = self.nav
        if not nav.armed or nav.landed:
            return M.MAV_LANDED_STATE_ON_GROUND
        if nav.landing:
            return M.MAV_LANDED_STATE_LANDING
        if self.telem is not None and self.telem.pos_m[2] < nav.gear_height_m + 1.0 \
                and self.telem.vel_m_s[2] > 0.1:
            return M.MAV_LANDED_STATE_TAKEOFF
        return M.MAV_LANDED_STATE_IN_AIR

    def home_position(self) -> Any:
        """HOME_POSITION: home on the ground below the navigator's ``home_m`` (the winder
        before it is set)."""
        home = self.nav.home_m or (0.0, 0.0, 0.0)
        ground = (home[0], home[1], 0.0)
        lat, lon, alt = local_enu_to_global(ground, self.origin)
        x, y, z = enu_to_ned(ground)
        return M.MAVLink_home_position_message(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000), x, y, z, [1.0, 0.0, 0.0, 0.0],
            0.0, 0.0, 0.0, int(self.telem.t_s * 1e6) if self.telem else 0)

    def mission_current(self) -> Any:
        """MISSION_CURRENT: the current item, the mission's size (without home), its state
        as ArduCopter reports it: NO_MISSION without items, ACTIVE while flown in AUTO,
        COMPLETE once it ran to its end, PAUSED when begun and left, else NOT_STARTED."""
        nav = self.nav
        total = len(self.missions.items) if hasattr(self.missions, "items") else 0
        if total <= 1:
            state = M.MISSION_STATE_NO_MISSION
        elif nav.mission_running:
            state = M.MISSION_STATE_ACTIVE
        elif self.mission_complete:
            state = M.MISSION_STATE_COMPLETE
        elif self.mission_started:
            state = M.MISSION_STATE_PAUSED
        else:
            state = M.MISSION_STATE_NOT_STARTED
        return M.MAVLink_mission_current_message(nav.current_seq, max(total - 1, 0), state,
                                                 1 if nav.mode == FlightMode.AUTO else 0)

    def autopilot_version(self) -> Any:
        """AUTOPILOT_VERSION: ArduCopter's version and :data:`CAPABILITIES`."""
        return M.MAVLink_autopilot_version_message(
            CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, list(b"tuavsitl"), [0] * 8, [0] * 8, 0,
            0, 0x7475617600000001)


def _i16(x: float) -> int:
    return max(-32768, min(32767, round(x)))
