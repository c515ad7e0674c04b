"""The simulator link's field conversions (:mod:`tuavdefs.simlink`): project frames and SI
units to and from each message's fields, as *values* in wire order (the ``*_values``
builders, the ``*_from_wire`` decoders) and as mappings or pymavlink messages (the
``*_fields`` builders, the field-based decoders)."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

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
from tuavdefs.simlink.codec import (
    _CODECS,
    _field,
)
from tuavdefs.simlink.constants import (
    _INT16,
    _UINT16,
    FLAG_LOCKSTEP,
    GPS_FIX_3D,
    GPS_SATELLITES_VISIBLE,
    MILLI_G_M_S2,
    MODE_ARMED,
    MODE_DISARMED,
    MODE_FLAG_ARMED,
    MSG_HIL_ACTUATOR_CONTROLS,
    MSG_HIL_GPS,
    MSG_HIL_SENSOR,
    MSG_HIL_STATE_QUATERNION,
    N_CONTROLS,
    N_ROTORS,
    SENSOR_FIELDS_FILLED,
    UINT16_UNKNOWN,
)


# ----- integer packing
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


