"""The simulator link: PX4's simulator MAVLink API between the plant and the companion.

The plant plays the part Gazebo plays for PX4 SITL: it listens on TCP (port
:data:`SIM_PORT_DEFAULT`, 127.0.0.1 only), or on a Unix-domain socket (addresses in
:func:`parse_sim_address`), and, once per control period, sends the sensor readings and the
truth state; the companion answers with the rotor commands. Both ends use
this module for the wire conventions, so the frame and unit conversions exist once:

==================== ========================================================================
message              content (MAVLink frames and units)
==================== ========================================================================
HIL_SENSOR (107)     specific force [m/s^2] and rates [rad/s] in body FRD, magnetic field
                     [gauss] in body FRD, static pressure [hPa], pressure altitude [m],
                     temperature [degC]; ``fields_updated`` marks what is filled.
HIL_GPS (113)        lat/lon [degE7], altitude AMSL [mm], eph/epv [cm], ground speed and
                     vn/ve/vd [cm/s] NED, course over ground [cdeg], fix type 3.
HIL_STATE_QUATERNION truth: attitude (body FRD -> NED), body rates FRD [rad/s], lat/lon
(115)                [degE7], altitude AMSL [mm], vx/vy/vz NED [cm/s], airspeeds [cm/s],
                     specific force in body FRD [mG].
HIL_ACTUATOR_CONTROLS rotor commands 1..4 in [0, 1] (order of :mod:`tuavdefs.airframe`) in
(93)                 ``controls[0:4]``, ``mode`` 129 armed / 1 disarmed, ``flags`` bit 0
                     lockstep; ``time_usec`` echoes the HIL_SENSOR it answers.
==================== ========================================================================

Control-period convention (lockstep): simulated time is counted in integer microseconds.
The plant stamps the messages describing its state at time ``t`` with ``time_usec = t``
(``t`` a multiple of :func:`control_period_us` after the start), sends HIL_GPS (when due),
HIL_STATE_QUATERNION and last HIL_SENSOR, which closes the batch. The companion answers with
one HIL_ACTUATOR_CONTROLS whose ``time_usec`` is that same ``t``; the plant holds those
commands over ``[t, t + T)`` (:func:`physics_steps_per_period` physics steps) and sends the
batch for ``t + T``.

Inside the project positions are z-up ENU and the body frame FLU; every conversion to and
from MAVLink's NED/FRD here goes through :mod:`tuavdefs.frames` (the per-period decoders
write its axis swaps and sign changes out, ``tests/test_simlink.py`` checks them).

:class:`FrameParser` splits a TCP byte stream into MAVLink frames, dropping (and counting)
malformed, truncated and corrupted frames and resynchronising on the next valid one.

Two ways through: the ``*_fields`` builders and field-based decoders work on mappings and
pymavlink messages (general, for tools and tests); the link's ends, once every control
period, use the same conversions on *values*, a message's fields in wire order as its
``struct`` packs them (``*_values`` builders, :meth:`Encoder.pack_values`,
:meth:`FrameParser.feed_link` for the usual well-formed input, ``*_from_wire`` decoders),
which skip the dictionaries and message objects. ``tests/test_fast_paths.py`` checks that
both give the same bytes and values.
"""

from __future__ import annotations

import functools
import inspect
import math
import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.airframe import ROTOR_LAYOUT
from tuavdefs.frames import (
    Quat,
    Vec3,
    _radii_m,
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    quat_ned_frd_to_enu_flu,
)

# ----- link constants
#: TCP port of PX4's simulator API (the plant listens, the companion connects).
SIM_PORT_DEFAULT = 4560
#: The only host the link binds to or connects to.
SIM_HOST_DEFAULT = "127.0.0.1"
#: The scheme of a simulator link on a Unix-domain socket: ``unix:PATH``, or ``unix:@NAME``
#: for NAME in Linux's abstract namespace (no file; the name goes with the socket).
UNIX_SCHEME = "unix:"
#: The scheme of a simulator link on TCP: ``tcp:HOST:PORT`` (the scheme may be left out).
TCP_SCHEME = "tcp:"
#: Control (lockstep) rate [Hz]: one sensor batch and one actuator answer per period.
CONTROL_RATE_HZ_DEFAULT = 250.0
#: Rate of HIL_GPS [Hz].
GPS_RATE_HZ_DEFAULT = 10.0
#: Home (latitude deg, longitude deg, altitude m AMSL) of the inertial origin (the winder's
#: tether exit): PX4 SITL's default home.
HOME_DEFAULT: tuple[float, float, float] = (47.397742, 8.545594, 488.0)

#: System and component ids on the simulator link. The plant stamps its messages as the
#: sensor board (MAV_COMP_ID_IMU), the companion as the autopilot.
PLANT_SYSID = 1
PLANT_COMPID = mavlink2.MAV_COMP_ID_IMU
COMPANION_SYSID = 1
COMPANION_COMPID = mavlink2.MAV_COMP_ID_AUTOPILOT1

MSG_HIL_ACTUATOR_CONTROLS = mavlink2.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS  # 93
MSG_HIL_SENSOR = mavlink2.MAVLINK_MSG_ID_HIL_SENSOR  # 107
MSG_HIL_GPS = mavlink2.MAVLINK_MSG_ID_HIL_GPS  # 113
MSG_HIL_STATE_QUATERNION = mavlink2.MAVLINK_MSG_ID_HIL_STATE_QUATERNION  # 115
#: The simulator's run-time parameters (tuavdefs.sim_params) cross the link as these: the
#: companion sends PARAM_SET, the plant PARAM_VALUE (at the session's start, and after
#: each PARAM_SET, with the value it holds).
MSG_PARAM_SET = mavlink2.MAVLINK_MSG_ID_PARAM_SET  # 23
MSG_PARAM_VALUE = mavlink2.MAVLINK_MSG_ID_PARAM_VALUE  # 22

#: HIL_SENSOR.fields_updated bits.
SENSOR_ACCEL = 0b111
SENSOR_GYRO = 0b111 << 3
SENSOR_MAG = 0b111 << 6
SENSOR_ABS_PRESSURE = mavlink2.HIL_SENSOR_UPDATED_ABS_PRESSURE
SENSOR_DIFF_PRESSURE = mavlink2.HIL_SENSOR_UPDATED_DIFF_PRESSURE
SENSOR_PRESSURE_ALT = mavlink2.HIL_SENSOR_UPDATED_PRESSURE_ALT
SENSOR_TEMPERATURE = mavlink2.HIL_SENSOR_UPDATED_TEMPERATURE
#: What the plant fills in every HIL_SENSOR (no airspeed sensor: diff_pressure is not).
SENSOR_FIELDS_FILLED = (SENSOR_ACCEL | SENSOR_GYRO | SENSOR_MAG | SENSOR_ABS_PRESSURE
                        | SENSOR_PRESSURE_ALT | SENSOR_TEMPERATURE)

#: HIL_ACTUATOR_CONTROLS.mode when armed / disarmed, and the flags' lockstep bit.
MODE_FLAG_ARMED = mavlink2.MAV_MODE_FLAG_SAFETY_ARMED  # 128
MODE_FLAG_CUSTOM = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED  # 1
MODE_ARMED = MODE_FLAG_ARMED | MODE_FLAG_CUSTOM
MODE_DISARMED = MODE_FLAG_CUSTOM
FLAG_LOCKSTEP = 1
#: Number of rotors, and of the HIL_ACTUATOR_CONTROLS controls they occupy (0..3).
N_ROTORS = len(ROTOR_LAYOUT)
N_CONTROLS = 16

#: One milli-g [m/s^2] (standard gravity), the unit of HIL_STATE_QUATERNION accelerations.
MILLI_G_M_S2 = 9.80665e-3
#: HIL_GPS fix type 3 (3-D fix) and the cog value that means "unknown".
GPS_FIX_3D = 3
UINT16_UNKNOWN = 65535
#: Satellites the simulated receiver reports in HIL_GPS.
GPS_SATELLITES_VISIBLE = 10

_INT16 = 32767
_UINT16 = 65535


# ----- sockets
_TIMEVAL = struct.Struct("@ll")


def parse_sim_address(text: str) -> tuple[str, int] | str:
    """A simulator-link address: ``HOST:PORT`` or ``tcp:HOST:PORT`` gives (host, port);
    ``unix:PATH`` or ``unix:@NAME`` gives the path as written (see :func:`unix_sockaddr`).
    ValueError says what is wrong."""
    if text.startswith(UNIX_SCHEME):
        path = text[len(UNIX_SCHEME):]
        if path in ("", "@"):
            raise ValueError(f"{text!r}: no path after {UNIX_SCHEME!r}")
        if "\0" in path:
            raise ValueError(f"{text!r}: a NUL in the path")
        return path
    rest = text[len(TCP_SCHEME):] if text.startswith(TCP_SCHEME) else text
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"{text!r} is not HOST:PORT, tcp:HOST:PORT or unix:PATH")
    return (host or SIM_HOST_DEFAULT, int(port))


def format_sim_address(address: tuple[str, int] | str) -> str:
    """The text of an address as :func:`parse_sim_address` reads it back, with its scheme."""
    if isinstance(address, str):
        return UNIX_SCHEME + address
    return f"{TCP_SCHEME}{address[0]}:{address[1]}"


def unix_sockaddr(path: str) -> str:
    """What ``bind`` and ``connect`` take for a Unix-domain path: the path itself, or for
    ``@NAME`` the abstract name (a leading NUL byte; Linux only)."""
    return "\0" + path[1:] if path.startswith("@") else path


def timeval(seconds: float) -> bytes:
    """A ``struct timeval`` of ``seconds`` [s], at least 1 us (0 would mean no timeout),
    for the socket options SO_RCVTIMEO and SO_SNDTIMEO: timeouts the kernel keeps, so that
    a blocking recv or send stays one system call (a Python-level socket timeout polls
    before each)."""
    us = max(round(seconds * 1e6), 1)
    return _TIMEVAL.pack(us // 1_000_000, us % 1_000_000)


# ----- the control period
def control_period_us(control_rate_hz: float) -> int:
    """Control period [us] of ``control_rate_hz`` [Hz]; it must be a whole number of us."""
    if not control_rate_hz > 0.0:
        raise ValueError(f"control rate must be positive, got {control_rate_hz!r}")
    period = 1e6 / control_rate_hz
    if abs(period - round(period)) > 1e-6 or round(period) < 1:
        raise ValueError(f"{control_rate_hz} Hz is not a whole number of microseconds")
    return round(period)


def physics_steps_per_period(control_rate_hz: float, physics_dt_s: float) -> int:
    """N, the plant's physics steps of ``physics_dt_s`` [s] in one control period."""
    period_s = control_period_us(control_rate_hz) * 1e-6
    n = round(period_s / physics_dt_s)
    if n < 1 or abs(n * physics_dt_s - period_s) > 1e-9:
        raise ValueError(f"control period {period_s} s is not a multiple of the physics "
                         f"step {physics_dt_s} s")
    return n


def time_usec(sim_time_s: float) -> int:
    """A simulated time [s] as MAVLink's integer microseconds."""
    return round(sim_time_s * 1e6)


# ----- field access and integer packing
def _field(msg: Any, name: str) -> Any:
    """Field ``name`` of a pymavlink message or of a mapping of field names."""
    if isinstance(msg, mavlink2.MAVLink_message):   # (a plain class check: fast)
        return getattr(msg, name)
    if isinstance(msg, Mapping):
        return msg[name]
    return getattr(msg, name)


def round_clamp(x: float, lo: int, hi: int) -> int:
    """``x`` rounded to the nearest integer and clamped to [lo, hi] (NaN -> 0)."""
    if lo < x < hi:     # the usual case first (NaN fails every comparison)
        return round(x)
    if x >= hi:
        return hi
    if x <= lo:
        return lo
    return 0


def _deg_e7(angle_deg: float) -> int:
    return round(angle_deg * 1e7)


def wrap_lon(lon_deg: float) -> float:
    """A longitude [deg] wrapped to [-180, 180)."""
    return (lon_deg + 180.0) % 360.0 - 180.0


class HomeMap:
    """The local tangent plane at ``home`` (lat deg, lon deg, alt m AMSL) in the link's
    integer units: inertial ENU [m] <-> (lat degE7, lon degE7, alt mm AMSL).

    The same arithmetic as :func:`tuavdefs.frames.local_enu_to_global` and
    :func:`tuavdefs.frames.global_to_local_enu` (bit for bit: ``tests/test_fast_paths.py``),
    with the home's radii of curvature computed once instead of at every call.
    ``lat0_deg``, ``lon0_deg``, ``alt0_m``: the home; ``r_n_m``: the meridian radius of
    curvature there [m]; ``r_e_cos_m``: the prime-vertical radius times cos(latitude) [m]
    (metres per radian of longitude).
    """

    def __init__(self, home: tuple[float, float, float]) -> None:
        self.home = home
        self.lat0_deg, self.lon0_deg, self.alt0_m = home
        self.r_n_m, self._r_e = _radii_m(self.lat0_deg)
        self._cos_lat0 = math.cos(math.radians(self.lat0_deg))
        self.r_e_cos_m = self._r_e * self._cos_lat0

    def global_fields(self, pos_enu_m: Sequence[float]) -> tuple[int, int, int]:
        """(lat degE7, lon degE7 wrapped to [-180, 180), alt mm AMSL) of an inertial
        position [m]."""
        lat = self.lat0_deg + math.degrees(pos_enu_m[1] / self.r_n_m)
        lon = self.lon0_deg + math.degrees(pos_enu_m[0] / self.r_e_cos_m)
        alt = self.alt0_m + pos_enu_m[2]
        return _deg_e7(lat), _deg_e7(wrap_lon(lon)), round(alt * 1000.0)

    def local(self, lat_e7: int, lon_e7: int, alt_mm: int) -> Vec3:
        """The inertial position [m] of (lat degE7, lon degE7, alt mm AMSL)."""
        north = math.radians(lat_e7 * 1e-7 - self.lat0_deg) * self.r_n_m
        east = (math.radians(wrap_lon(lon_e7 * 1e-7 - self.lon0_deg)) * self._r_e
                * self._cos_lat0)
        return (east, north, alt_mm * 1e-3 - self.alt0_m)


def home_map(home: Sequence[float]) -> HomeMap:
    """The :class:`HomeMap` of ``home`` (lat deg, lon deg, alt m AMSL), made once."""
    return _home_map(tuple(float(v) for v in home))  # type: ignore[arg-type]


_home_map = functools.lru_cache(maxsize=16)(HomeMap)


# ----- HIL_STATE_QUATERNION
def hil_state_quaternion_values(time_us: int, pos_enu_m: Vec3, vel_enu_m_s: Vec3,
                                quat_enu_flu: Quat, rates_flu_rad_s: Vec3,
                                specific_force_flu_m_s2: Vec3, home: HomeMap,
                                true_airspeed_m_s: float, ind_airspeed_m_s: float) -> tuple:
    """HIL_STATE_QUATERNION's field values in wire order (``attitude_quaternion`` spread
    over four) for a truth state: what :func:`hil_state_quaternion_fields` describes,
    ready for :meth:`Encoder.pack_values`."""
    lat, lon, alt = home.global_fields(pos_enu_m)
    vn, ve, vd = enu_to_ned(vel_enu_m_s)
    wx, wy, wz = flu_to_frd(rates_flu_rad_s)
    fx, fy, fz = flu_to_frd(specific_force_flu_m_s2)
    return (int(time_us), *quat_enu_flu_to_ned_frd(tuple(quat_enu_flu)),
            float(wx), float(wy), float(wz), lat, lon, alt,
            round_clamp(vn * 100.0, -_INT16, _INT16),
            round_clamp(ve * 100.0, -_INT16, _INT16),
            round_clamp(vd * 100.0, -_INT16, _INT16),
            round_clamp(ind_airspeed_m_s * 100.0, 0, _UINT16),
            round_clamp(true_airspeed_m_s * 100.0, 0, _UINT16),
            round_clamp(fx / MILLI_G_M_S2, -_INT16, _INT16),
            round_clamp(fy / MILLI_G_M_S2, -_INT16, _INT16),
            round_clamp(fz / MILLI_G_M_S2, -_INT16, _INT16))


def hil_state_quaternion_fields(time_us: int, pos_enu_m: Vec3, vel_enu_m_s: Vec3,
                                quat_enu_flu: Quat, rates_flu_rad_s: Vec3,
                                specific_force_flu_m_s2: Vec3,
                                home: tuple[float, float, float],
                                true_airspeed_m_s: float = 0.0,
                                ind_airspeed_m_s: float | None = None) -> dict[str, Any]:
    """The fields of HIL_STATE_QUATERNION for a truth state.

    Inputs in project frames and SI units: position [m] and velocity [m/s] in the inertial
    ENU frame, attitude quaternion (w, x, y, z) body FLU -> ENU, body rates FLU [rad/s],
    specific force (what an ideal accelerometer reads) in body FLU [m/s^2], airspeeds
    [m/s] (indicated defaults to true). ``home`` is (lat deg, lon deg, alt m AMSL) of the
    inertial origin. Out: quaternion body FRD -> NED, rates FRD, lat/lon [degE7],
    alt [mm AMSL], vx/vy/vz NED [cm/s], airspeeds [cm/s], xacc/yacc/zacc FRD [mG]; the
    integer fields are rounded to the nearest unit and clamped to their type's range.
    """
    ias = true_airspeed_m_s if ind_airspeed_m_s is None else ind_airspeed_m_s
    return _CODECS[MSG_HIL_STATE_QUATERNION].fields(hil_state_quaternion_values(
        time_us, pos_enu_m, vel_enu_m_s, quat_enu_flu, rates_flu_rad_s,
        specific_force_flu_m_s2, home_map(home), true_airspeed_m_s, ias))


def truth_from_wire(values: Sequence[Any], home: HomeMap
                    ) -> tuple[Vec3, Vec3, Quat, Vec3, Vec3, float, float]:
    """(position ENU [m], velocity ENU [m/s], quaternion body FLU -> ENU, rates FLU
    [rad/s], specific force FLU [m/s^2], true airspeed [m/s], indicated airspeed [m/s]) of
    HIL_STATE_QUATERNION's field values in wire order."""
    # (ned_to_enu and frd_to_flu written out: swaps and sign changes, exact)
    _, qw, qx, qy, qz, wx, wy, wz, lat, lon, alt, vn, ve, vd, ias, tas, fx, fy, fz = values
    return (home.local(lat, lon, alt), (ve * 0.01, vn * 0.01, -(vd * 0.01)),
            quat_ned_frd_to_enu_flu((float(qw), float(qx), float(qy), float(qz))),
            (float(wx), -float(wy), -float(wz)),
            (fx * MILLI_G_M_S2, -(fy * MILLI_G_M_S2), -(fz * MILLI_G_M_S2)),
            tas * 0.01, ias * 0.01)


def state_from_hil_state_quaternion(msg_fields: Any, home: tuple[float, float, float]
                                    ) -> tuple[Vec3, Vec3, Quat, Vec3]:
    """(position ENU [m], velocity ENU [m/s], quaternion body FLU -> ENU, rates FLU [rad/s])
    from a HIL_STATE_QUATERNION (a pymavlink message or a mapping of its fields)."""
    values = _CODECS[MSG_HIL_STATE_QUATERNION].wire_of(msg_fields)
    return truth_from_wire(values, home_map(home))[:4]  # type: ignore[return-value]


def specific_force_from_hil_state_quaternion(msg_fields: Any) -> Vec3:
    """The truth specific force in body FLU [m/s^2] of a HIL_STATE_QUATERNION."""
    return frd_to_flu((_field(msg_fields, "xacc") * MILLI_G_M_S2,
                       _field(msg_fields, "yacc") * MILLI_G_M_S2,
                       _field(msg_fields, "zacc") * MILLI_G_M_S2))


def airspeeds_from_hil_state_quaternion(msg_fields: Any) -> tuple[float, float]:
    """(indicated, true) airspeed [m/s] of a HIL_STATE_QUATERNION."""
    return (_field(msg_fields, "ind_airspeed") * 0.01, _field(msg_fields, "true_airspeed") * 0.01)


# ----- HIL_GPS
def hil_gps_values(time_us: int, pos_enu_m: Vec3, vel_enu_m_s: Vec3, home: HomeMap,
                   eph_m: float = 0.3, epv_m: float = 0.5,
                   satellites_visible: int = GPS_SATELLITES_VISIBLE,
                   fix_type: int = GPS_FIX_3D) -> tuple:
    """HIL_GPS's field values in wire order: what :func:`hil_gps_fields` describes, ready
    for :meth:`Encoder.pack_values`."""
    lat, lon, alt = home.global_fields(pos_enu_m)
    vn, ve, vd = enu_to_ned(vel_enu_m_s)
    vel_cm = round_clamp(math.hypot(vn, ve) * 100.0, 0, _UINT16 - 1)
    cog = (UINT16_UNKNOWN if vel_cm == 0
           else round(math.degrees(math.atan2(ve, vn)) * 100.0) % 36000)
    return (int(time_us), lat, lon, alt,
            round_clamp(eph_m * 100.0, 0, _UINT16 - 1),
            round_clamp(epv_m * 100.0, 0, _UINT16 - 1), vel_cm,
            round_clamp(vn * 100.0, -_INT16, _INT16),
            round_clamp(ve * 100.0, -_INT16, _INT16),
            round_clamp(vd * 100.0, -_INT16, _INT16),
            cog, int(fix_type), int(satellites_visible), 0, 0)


def hil_gps_fields(time_us: int, pos_enu_m: Vec3, vel_enu_m_s: Vec3,
                   home: tuple[float, float, float], eph_m: float = 0.3, epv_m: float = 0.5,
                   satellites_visible: int = GPS_SATELLITES_VISIBLE, fix_type: int = GPS_FIX_3D
                   ) -> dict[str, Any]:
    """The fields of HIL_GPS for a (measured) position [m] and velocity [m/s] in ENU.

    ``eph_m``/``epv_m`` are the claimed horizontal/vertical accuracies [m], sent in cm as
    PX4 reads them. Ground speed ``vel`` and ``vn/ve/vd`` in cm/s, course over ground
    ``cog`` in cdeg in [0, 36000) (unknown, 65535, when the ground speed rounds to 0).
    """
    return _CODECS[MSG_HIL_GPS].fields(hil_gps_values(
        time_us, pos_enu_m, vel_enu_m_s, home_map(home), eph_m, epv_m, satellites_visible,
        fix_type))


def gps_from_wire(values: Sequence[Any], home: HomeMap) -> tuple[Vec3, Vec3, float, float]:
    """(position ENU [m], velocity ENU [m/s], eph [m], epv [m]) of HIL_GPS's field values
    in wire order."""
    v = values
    vel = ned_to_enu((v[7] * 0.01, v[8] * 0.01, v[9] * 0.01))
    return home.local(v[1], v[2], v[3]), vel, v[4] * 0.01, v[5] * 0.01


def gps_from_hil_gps(msg_fields: Any, home: tuple[float, float, float]
                     ) -> tuple[Vec3, Vec3, float, float]:
    """(position ENU [m], velocity ENU [m/s], eph [m], epv [m]) of a HIL_GPS."""
    return gps_from_wire(_CODECS[MSG_HIL_GPS].wire_of(msg_fields), home_map(home))


# ----- HIL_SENSOR
def hil_sensor_values(time_us: int, accel_flu_m_s2: Vec3, gyro_flu_rad_s: Vec3,
                      mag_flu_gauss: Vec3, abs_pressure_hpa: float, pressure_alt_m: float,
                      temperature_c: float) -> tuple:
    """HIL_SENSOR's field values in wire order: what :func:`hil_sensor_fields` describes,
    ready for :meth:`Encoder.pack_values`."""
    ax, ay, az = flu_to_frd(accel_flu_m_s2)
    gx, gy, gz = flu_to_frd(gyro_flu_rad_s)
    mx, my, mz = flu_to_frd(mag_flu_gauss)
    return (int(time_us), float(ax), float(ay), float(az), float(gx), float(gy), float(gz),
            float(mx), float(my), float(mz), float(abs_pressure_hpa), 0.0,
            float(pressure_alt_m), float(temperature_c), SENSOR_FIELDS_FILLED, 0)


def hil_sensor_fields(time_us: int, accel_flu_m_s2: Vec3, gyro_flu_rad_s: Vec3,
                      mag_flu_gauss: Vec3, abs_pressure_hpa: float, pressure_alt_m: float,
                      temperature_c: float) -> dict[str, Any]:
    """The fields of HIL_SENSOR for readings in body FLU: specific force [m/s^2], rates
    [rad/s], magnetic field [gauss]; static pressure [hPa], pressure altitude [m],
    temperature [degC]. Vectors go out in body FRD; ``fields_updated`` is
    :data:`SENSOR_FIELDS_FILLED` (diff_pressure 0: no airspeed sensor)."""
    return _CODECS[MSG_HIL_SENSOR].fields(hil_sensor_values(
        time_us, accel_flu_m_s2, gyro_flu_rad_s, mag_flu_gauss, abs_pressure_hpa,
        pressure_alt_m, temperature_c))


def imu_from_wire(values: Sequence[Any]) -> tuple[Vec3, Vec3, Vec3, float, float, float]:
    """(specific force FLU [m/s^2], rates FLU [rad/s], field FLU [gauss], static pressure
    [hPa], pressure altitude [m], temperature [degC]) of HIL_SENSOR's field values in wire
    order."""
    # (frd_to_flu written out: sign changes, exact)
    _, ax, ay, az, gx, gy, gz, mx, my, mz, p, _, alt, temp = values[:14]
    return ((float(ax), -float(ay), -float(az)), (float(gx), -float(gy), -float(gz)),
            (float(mx), -float(my), -float(mz)), float(p), float(alt), float(temp))


def imu_from_hil_sensor(msg_fields: Any) -> tuple[Vec3, Vec3, Vec3, float, float, float]:
    """(specific force FLU [m/s^2], rates FLU [rad/s], field FLU [gauss], static pressure
    [hPa], pressure altitude [m], temperature [degC]) of a HIL_SENSOR."""
    return imu_from_wire(_CODECS[MSG_HIL_SENSOR].wire_of(msg_fields))


# ----- HIL_ACTUATOR_CONTROLS
def _clean_command(c: float) -> float:
    c = float(c)
    if 0.0 <= c <= 1.0:     # the usual case first (NaN fails it)
        return c
    if math.isnan(c):
        return 0.0
    return min(max(c, 0.0), 1.0)


_UNUSED_CONTROLS = (0.0,) * (N_CONTROLS - N_ROTORS)


def actuator_controls_values(time_us: int, rotor_commands: Sequence[float], armed: bool,
                             lockstep: bool = True) -> tuple:
    """HIL_ACTUATOR_CONTROLS' field values in wire order (``controls`` spread over 16) for
    :func:`actuator_controls_fields`' inputs and the ``time_usec`` answered [us], ready for
    :meth:`Encoder.pack_values`."""
    if len(rotor_commands) != N_ROTORS:
        raise ValueError(f"need {N_ROTORS} rotor commands, got {len(rotor_commands)}")
    return (int(time_us), FLAG_LOCKSTEP if lockstep else 0,
            *map(_clean_command, rotor_commands), *_UNUSED_CONTROLS,
            MODE_ARMED if armed else MODE_DISARMED)


def actuator_controls_fields(rotor_commands: Sequence[float], armed: bool,
                             lockstep: bool = True) -> dict[str, Any]:
    """``controls``, ``mode`` and ``flags`` of HIL_ACTUATOR_CONTROLS (``time_usec`` is the
    caller's: the HIL_SENSOR time being answered). ``rotor_commands`` are the four
    normalised commands in [0, 1] (rotor order of :mod:`tuavdefs.airframe`), clamped, NaN
    sent as 0; the other 12 controls are 0."""
    fields = _CODECS[MSG_HIL_ACTUATOR_CONTROLS].fields(
        actuator_controls_values(0, rotor_commands, armed, lockstep))
    del fields["time_usec"]
    return fields


def rotor_commands_from_controls(controls: Sequence[float], mode: int
                                 ) -> tuple[tuple[float, float, float, float], bool]:
    """(rotor commands 1..4 in [0, 1], armed) of HIL_ACTUATOR_CONTROLS' ``controls`` and
    ``mode``. Commands are clamped to [0, 1] and NaN read as 0; armed is the
    MAV_MODE_FLAG_SAFETY_ARMED bit."""
    if len(controls) < N_ROTORS:
        raise ValueError(f"need at least {N_ROTORS} controls, got {len(controls)}")
    cmds = tuple(map(_clean_command, controls[:N_ROTORS]))
    return cmds, bool(int(mode) & MODE_FLAG_ARMED)  # type: ignore[return-value]


def answer_from_wire(values: Sequence[Any]
                     ) -> tuple[int, tuple[float, float, float, float], bool, bool]:
    """(time_usec answered [us], rotor commands in [0, 1], armed, lockstep) of
    HIL_ACTUATOR_CONTROLS' field values in wire order (as
    :func:`rotor_commands_from_controls` and :func:`lockstep_flag` read them)."""
    ts, flags, c0, c1, c2, c3 = values[:2 + N_ROTORS]
    if 0.0 <= c0 <= 1.0 and 0.0 <= c1 <= 1.0 and 0.0 <= c2 <= 1.0 and 0.0 <= c3 <= 1.0:
        # the usual case (once a period in the plant): nothing to clamp, NaN fails it
        return (int(ts), (float(c0), float(c1), float(c2), float(c3)),
                bool(int(values[18]) & MODE_FLAG_ARMED), bool(int(flags) & FLAG_LOCKSTEP))
    cmds, armed = rotor_commands_from_controls(values[2:2 + N_ROTORS], values[18])
    return int(ts), cmds, armed, lockstep_flag(flags)


def lockstep_flag(flags: int) -> bool:
    """Whether HIL_ACTUATOR_CONTROLS' ``flags`` announce lockstep."""
    return bool(int(flags) & FLAG_LOCKSTEP)


# ----- framing
_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD
_HEADER_V1 = 6
_HEADER_V2 = 10
_SIGNATURE_LEN = 13
_IFLAG_SIGNED = 0x01


class _Sink:
    """A file-like object collecting what pymavlink writes."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.chunks.append(bytes(data))

    def take(self) -> bytes:
        out = b"".join(self.chunks)
        self.chunks.clear()
        return out


#: pymavlink's C helper for the checksum (``mcrf4xx(data, 0xFFFF)``), None if not installed
_MCRF4XX: Callable[[bytes, int], int] | None = getattr(mavlink2, "mcrf4xx", None)


def mavlink_crc(data: bytes) -> int:
    """MAVLink's checksum (CRC-16/MCRF4XX) of ``data`` (a frame after its magic byte, then
    the message's CRC extra), as pymavlink computes it: its C helper where installed."""
    if _MCRF4XX is not None:
        return int(_MCRF4XX(data, 0xFFFF))
    return int(mavlink2.x25crc(data).crc)


_HEADER_V2_STRUCT = struct.Struct("<BBBBBBBHB")
_CRC_STRUCT = struct.Struct("<H")


def count_sent(mav: mavlink2.MAVLink, frames: int, nbytes: int) -> None:
    """Account ``frames`` frames of ``nbytes`` bytes in all, packed here with ``mav``'s
    ids from its current sequence number, as ``MAVLink.send`` does: the sequence advances
    (modulo 256) and the sent counters grow."""
    mav.seq = (mav.seq + frames) % 256
    mav.total_packets_sent += frames
    mav.total_bytes_sent += nbytes


class _Codec:
    """MAVLink 2 packing and unpacking of one message type, without pymavlink's generic
    per-message machinery: the same bytes as ``MAVLink.send`` writes and the same message
    objects as ``MAVLink.decode`` returns (``tests/test_simlink.py`` compares them), about
    three times faster. For messages without strings, unsigned (the simulator link's own,
    and the component link's LOCAL_POSITION_NED through :func:`whole_frames`).

    A message's *values* are its fields in wire order with the arrays spread out: what its
    ``struct`` packs (``cls.unpacker``)."""

    def __init__(self, cls: type) -> None:
        self.cls = cls
        self.msg_id = int(cls.id)
        self.crc_extra = bytes((cls.crc_extra,))
        self.unpacker: struct.Struct = cls.unpacker
        arrays = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
        if "char" in cls.fieldtypes or 1 in arrays.values():
            raise ValueError(f"{cls.__name__}: strings and 1-element arrays are pymavlink's")
        self.wire = [(name, arrays[name]) for name in cls.ordered_fieldnames]
        init = inspect.signature(cls.__init__).parameters
        self.defaults = {n: p.default for n, p in init.items()
                         if p.default is not inspect.Parameter.empty}
        # where each constructor argument lies in the unpacked tuple (wire order)
        starts, pos = {}, 0
        for name, n in self.wire:
            starts[name] = pos
            pos += max(n, 1)
        self.plan = [(starts[name], arrays[name]) for name in cls.fieldnames]

    def _spread(self, get: Callable[[str], Any]) -> list[Any]:
        """The values of the fields ``get`` returns by name."""
        values: list[Any] = []
        for name, n in self.wire:
            v = get(name)
            if n:
                values.extend(v[k] for k in range(n))
            else:
                values.append(v)
        return values

    def values(self, fields: Mapping[str, Any]) -> list[Any]:
        """The values of ``fields`` (missing ones take pymavlink's defaults)."""
        defaults = self.defaults
        return self._spread(lambda name: fields[name] if name in fields else defaults[name])

    def wire_of(self, msg_fields: Any) -> tuple:
        """The values of a pymavlink message or of a mapping of all its fields."""
        return tuple(self._spread(lambda name: _field(msg_fields, name)))

    def fields(self, values: Sequence[Any]) -> dict[str, Any]:
        """The mapping of field names (arrays as lists) of ``values``."""
        out: dict[str, Any] = {}
        i = 0
        for name, n in self.wire:
            if n:
                out[name] = list(values[i:i + n])
                i += n
            else:
                out[name] = values[i]
                i += 1
        return out

    def pack(self, mav: mavlink2.MAVLink, fields: Mapping[str, Any]) -> bytes:
        """The frame of a message with ``fields`` from ``mav`` (its ids and sequence)."""
        return self.pack_values(mav, self.values(fields))

    def pack_values(self, mav: mavlink2.MAVLink, values: Sequence[Any]) -> bytes:
        """The frame of a message with ``values`` from ``mav`` (its ids and sequence)."""
        payload = self.unpacker.pack(*values).rstrip(b"\0") or b"\0"
        mid = self.msg_id
        seq = mav.seq
        body = _HEADER_V2_STRUCT.pack(_MAGIC_V2, len(payload), 0, 0, seq, mav.srcSystem,
                                      mav.srcComponent, mid & 0xFFFF, mid >> 16) + payload
        frame = body + _CRC_STRUCT.pack(mavlink_crc(body[1:] + self.crc_extra))
        count_sent(mav, 1, len(frame))
        return frame

    def unpack(self, payload: bytes) -> tuple:
        """The values of a MAVLink 2 payload (which drops its trailing zeros)."""
        size = self.unpacker.size
        if len(payload) != size:
            payload = payload[:size] + bytes(size - len(payload))
        return self.unpacker.unpack(payload)

    def decode(self, frame: bytearray) -> mavlink2.MAVLink_message | None:
        """The message of an unsigned MAVLink 2 ``frame`` of this type (None: bad CRC)."""
        (_, mlen, incompat, compat, seq, sysid, compid, _, _) = _HEADER_V2_STRUCT.unpack_from(
            frame)
        crc = frame[-2] | (frame[-1] << 8)
        if crc != mavlink_crc(bytes(frame[1:-2]) + self.crc_extra):
            return None
        t = self.unpack(bytes(frame[_HEADER_V2:-2]))
        m = self.cls(*[t[a] if n == 0 else list(t[a:a + n]) for a, n in self.plan])
        m._signed = False
        m._msgbuf = frame
        m._payload = frame[6:-2]
        m._crc = crc
        m._header = mavlink2.MAVLink_header(self.msg_id, incompat, compat, mlen, seq, sysid,
                                            compid)
        return m


def frame_codecs(*classes: type) -> dict[int, _Codec]:
    """Codecs for :func:`whole_frames` of pymavlink message classes (without strings or
    one-element arrays), by message id."""
    return {c.msg_id: c for c in map(_Codec, classes)}


#: The simulator link's messages, packed and parsed by :class:`_Codec`.
_CODECS = frame_codecs(
    mavlink2.MAVLink_hil_sensor_message, mavlink2.MAVLink_hil_gps_message,
    mavlink2.MAVLink_hil_state_quaternion_message,
    mavlink2.MAVLink_hil_actuator_controls_message)
#: The same, by the name :func:`whole_frames`' callers outside this module use.
LINK_CODECS = _CODECS

#: A whole HIL_ACTUATOR_CONTROLS frame but its checksum: header, then the payload.
_ACTUATOR_FRAME = struct.Struct(
    _HEADER_V2_STRUCT.format + _CODECS[MSG_HIL_ACTUATOR_CONTROLS].unpacker.format[1:])
_ACTUATOR_PAYLOAD = _CODECS[MSG_HIL_ACTUATOR_CONTROLS].unpacker.size
_ACTUATOR_CRC_EXTRA = _CODECS[MSG_HIL_ACTUATOR_CONTROLS].crc_extra


def link_values(msg: mavlink2.MAVLink_message) -> tuple[int, tuple] | None:
    """(message id, values in wire order) of one of the link's messages (None for any
    other message): what :meth:`FrameParser.feed_link` returns for it. PARAM_SET and
    PARAM_VALUE give (name, value) instead."""
    mid = msg.get_msgId()
    codec = _CODECS.get(mid)
    if codec is None:
        if mid in (MSG_PARAM_SET, MSG_PARAM_VALUE):
            name = msg.param_id
            if isinstance(name, bytes):
                name = name.decode("ascii", "replace")
            return mid, (str(name).split("\0", 1)[0], float(msg.param_value))
        return None
    return (codec.msg_id, codec.wire_of(msg))


def param_set_frame(encoder: Encoder, target: tuple[int, int], name: str,
                    value: float) -> bytes:
    """A PARAM_SET of a simulator parameter (a REAL32 on the wire) for ``target``
    (system, component)."""
    return encoder.pack(mavlink2.MAVLink_param_set_message(
        target[0], target[1], name.encode("ascii"), float(value),
        mavlink2.MAV_PARAM_TYPE_REAL32))


def param_value_frame(encoder: Encoder, name: str, value: float, index: int,
                      count: int) -> bytes:
    """A PARAM_VALUE of a simulator parameter (a REAL32 on the wire)."""
    return encoder.pack(mavlink2.MAVLink_param_value_message(
        name.encode("ascii"), float(value), mavlink2.MAV_PARAM_TYPE_REAL32, count, index))


class Encoder:
    """Packs MAVLink 2 messages into bytes, with this end's ids and a running sequence."""

    def __init__(self, sysid: int, compid: int) -> None:
        self._sink = _Sink()
        self.mav = mavlink2.MAVLink(self._sink, srcSystem=sysid, srcComponent=compid)

    def pack(self, msg: mavlink2.MAVLink_message) -> bytes:
        """The frame of one message (advances the sequence number)."""
        self.mav.send(msg)
        return self._sink.take()

    def _fast(self, msg_id: int, fields: Mapping[str, Any]) -> bytes:
        return self.pack_values(msg_id, _CODECS[msg_id].values(fields))

    def pack_values(self, msg_id: int, values: Sequence[Any]) -> bytes:
        """The frame of one of the link's messages from its values in wire order (the
        ``*_values`` functions here), advancing the sequence number."""
        codec = _CODECS[msg_id]
        if self.mav.signing.sign_outgoing:   # pymavlink signs: let it pack
            cls = mavlink2.mavlink_map[msg_id]
            return self.pack(cls(**codec.fields(values)))
        return codec.pack_values(self.mav, values)

    def actuator_controls(self, time_us: int, rotor_commands: Sequence[float], armed: bool,
                          lockstep: bool = True) -> bytes:
        """The HIL_ACTUATOR_CONTROLS frame answering ``time_us`` [us] with four rotor
        commands in [0, 1] and the armed flag: the bytes of :meth:`pack_values` of
        :func:`actuator_controls_values`, packed in one go (its payload never ends in a
        zero: ``mode`` is never 0)."""
        mav = self.mav
        if len(rotor_commands) != N_ROTORS or mav.signing.sign_outgoing:
            return self.pack_values(MSG_HIL_ACTUATOR_CONTROLS, actuator_controls_values(
                time_us, rotor_commands, armed, lockstep))
        c0, c1, c2, c3 = rotor_commands
        seq = mav.seq
        frame = _ACTUATOR_FRAME.pack(
            _MAGIC_V2, _ACTUATOR_PAYLOAD, 0, 0, seq, mav.srcSystem, mav.srcComponent,
            MSG_HIL_ACTUATOR_CONTROLS, 0, int(time_us), FLAG_LOCKSTEP if lockstep else 0,
            c0 if 0.0 <= c0 <= 1.0 else _clean_command(c0),
            c1 if 0.0 <= c1 <= 1.0 else _clean_command(c1),
            c2 if 0.0 <= c2 <= 1.0 else _clean_command(c2),
            c3 if 0.0 <= c3 <= 1.0 else _clean_command(c3),
            *_UNUSED_CONTROLS, MODE_ARMED if armed else MODE_DISARMED)
        frame += _CRC_STRUCT.pack(mavlink_crc(frame[1:] + _ACTUATOR_CRC_EXTRA))
        count_sent(mav, 1, len(frame))
        return frame

    def hil_sensor(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_SENSOR frame from :func:`hil_sensor_fields`' output."""
        return self._fast(MSG_HIL_SENSOR, fields)

    def hil_gps(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_GPS frame from :func:`hil_gps_fields`' output."""
        return self._fast(MSG_HIL_GPS, fields)

    def hil_state_quaternion(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_STATE_QUATERNION frame from :func:`hil_state_quaternion_fields`' output."""
        return self._fast(MSG_HIL_STATE_QUATERNION, fields)

    def hil_actuator_controls(self, time_us: int, fields: Mapping[str, Any]) -> bytes:
        """A HIL_ACTUATOR_CONTROLS frame from :func:`actuator_controls_fields`' output."""
        return self._fast(MSG_HIL_ACTUATOR_CONTROLS, {**fields, "time_usec": int(time_us)})


def whole_frames(data: bytes, codecs: Mapping[int, _Codec], check_crc: bool = True
                 ) -> list[tuple[int, tuple]] | None:
    """(message id, values in wire order) of each frame of ``data`` when it is nothing but
    whole, unsigned MAVLink 2 frames of the ``codecs``' messages with valid CRCs (what a
    parser holding no partial frame decodes from it); None for anything else, which is
    then a general parser's to read. ``check_crc`` False skips the checksums: only for
    bytes that never crossed a wire (a batch built in the same process, offline)."""
    out = []
    i, n = 0, len(data)
    mcrf = _MCRF4XX
    while i < n:
        if data[i] != _MAGIC_V2 or n - i < _HEADER_V2 + 2 or data[i + 2]:
            return None   # not a frame start, short, signed or impossible flags
        size = data[i + 1]
        end = i + _HEADER_V2 + size + 2
        codec = codecs.get(data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16))
        if codec is None or end > n:
            return None
        if check_crc:
            body = data[i + 1:end - 2] + codec.crc_extra
            if ((mcrf(body, 0xFFFF) if mcrf is not None else mavlink_crc(body))
                    != data[end - 2] | (data[end - 1] << 8)):
                return None
        # a whole payload straight from the stream; one short of its trailing zeros
        # through unpack
        out.append((codec.msg_id, codec.unpacker.unpack_from(data, i + _HEADER_V2)
                    if size == codec.unpacker.size
                    else codec.unpack(data[i + _HEADER_V2:end - 2])))
        i = end
    return out


class FrameParser:
    """Splits a byte stream into MAVLink (1 or 2) messages of the common dialect.

    A frame is accepted only if its message id is known and its CRC (with the id's
    CRC_EXTRA) checks. Anything else is dropped: bytes before a start marker, frames with
    a bad CRC, unknown ids or invalid flags (dropped one byte at a time so that a valid
    frame hidden behind a false start is still found), and truncated frames, recognised
    when a complete valid frame starts inside the span a partial frame claims. Each run of
    dropped bytes between two accepted frames counts as one bad frame (``bad_frames``;
    ``bad_bytes`` counts the bytes), so the counts do not depend on how TCP splits the
    stream. Never raises on content.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._mav = mavlink2.MAVLink(None)
        self._in_bad_run = False
        self.frames = 0
        self.bad_frames = 0
        self.bad_bytes = 0

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[mavlink2.MAVLink_message]:
        """Add received bytes; return the messages completed by them, in order."""
        buf = self._buf
        buf += data
        out: list[mavlink2.MAVLink_message] = []
        while buf:
            start = _find_magic(buf, 0)
            if start < 0:
                self._drop(len(buf))
                break
            if start > 0:
                self._drop(start)
            n = _frame_length(buf, 0)
            if n == 0:            # impossible header (flags): not a frame start
                self._drop(1)
                continue
            if n is not None and len(buf) >= n:
                msg = self._decode(buf, 0, n)
                if msg is None:
                    self._drop(1)
                    continue
                del buf[:n]
                self._accept(msg, out)
                continue
            # a partial frame at the head: wait, unless a complete valid frame starts
            # inside it, which shows the partial frame was truncated
            found = self._valid_frame_after(buf, 1)
            if found is None:
                break
            j, m, msg = found
            self._drop(j)
            del buf[:m]
            self._accept(msg, out)
        return out

    def feed_link(self, data: bytes) -> list[tuple[int, tuple]] | None:
        """The usual case of :meth:`feed`, fast: when nothing is pending and ``data`` is
        whole unsigned MAVLink 2 frames of the link's own messages with valid CRCs, their
        (message id, values in wire order), counted as :meth:`feed` counts them. Anything
        else returns None and changes nothing: pass ``data`` to :meth:`feed` then."""
        if self._buf:
            return None
        out = whole_frames(data, _CODECS)
        if out:
            self.frames += len(out)
            self._in_bad_run = False
        return out

    def _accept(self, msg: mavlink2.MAVLink_message, out: list) -> None:
        self.frames += 1
        self._in_bad_run = False
        out.append(msg)

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.bad_bytes += n
        if not self._in_bad_run:
            self.bad_frames += 1
            self._in_bad_run = True

    def _valid_frame_after(self, buf: bytearray, start: int
                           ) -> tuple[int, int, mavlink2.MAVLink_message] | None:
        j = _find_magic(buf, start)
        while j >= 0:
            n = _frame_length(buf, j)
            if n and len(buf) - j >= n:
                msg = self._decode(buf, j, n)
                if msg is not None:
                    return j, n, msg
            j = _find_magic(buf, j + 1)
        return None

    def _decode(self, buf: bytearray, i: int, n: int) -> mavlink2.MAVLink_message | None:
        frame = buf[i:i + n]
        if buf[i] == _MAGIC_V2:
            msg_id = buf[i + 7] | (buf[i + 8] << 8) | (buf[i + 9] << 16)
        else:
            msg_id = buf[i + 5]
        if msg_id not in mavlink2.mavlink_map:
            return None     # its CRC cannot be checked: not trusted
        codec = _CODECS.get(msg_id)
        if codec is not None and buf[i] == _MAGIC_V2 and not buf[i + 2] & _IFLAG_SIGNED:
            try:
                return codec.decode(frame)
            except Exception:   # noqa: BLE001 - any decoding failure is a bad frame
                return None
        try:
            msg = self._mav.decode(frame)
        except Exception:   # noqa: BLE001 - any decoding failure is a bad frame
            return None
        if isinstance(msg, (mavlink2.MAVLink_bad_data, mavlink2.MAVLink_unknown)):
            return None
        return msg


def _find_magic(buf: bytearray, start: int) -> int:
    """Index of the first MAVLink start marker at or after ``start`` (-1 if none)."""
    a = buf.find(_MAGIC_V2, start)
    b = buf.find(_MAGIC_V1, start)
    if a < 0:
        return b
    if b < 0:
        return a
    return min(a, b)


def _frame_length(buf: bytearray, i: int) -> int | None:
    """Total length [bytes] of the frame starting at ``buf[i]``; None when its header is
    not all there yet, 0 when the header is impossible (unknown incompatibility flags)."""
    if buf[i] == _MAGIC_V2:
        if len(buf) - i < 3:
            return None
        flags = buf[i + 2]
        if flags & ~_IFLAG_SIGNED:
            return 0
        return (_HEADER_V2 + buf[i + 1] + 2
                + (_SIGNATURE_LEN if flags & _IFLAG_SIGNED else 0))
    if len(buf) - i < 2:
        return None
    return _HEADER_V1 + buf[i + 1] + 2
