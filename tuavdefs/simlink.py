"""The simulator link: PX4's simulator MAVLink API between the plant and the companion.

The plant plays the part Gazebo plays for PX4 SITL: it listens on TCP (port
:data:`SIM_PORT_DEFAULT`, 127.0.0.1 only) and, once per control period, sends the sensor
readings and the truth state; the companion answers with the rotor commands. Both ends use
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
from MAVLink's NED/FRD here goes through :mod:`tuavdefs.frames`.

:class:`FrameParser` splits a TCP byte stream into MAVLink frames, dropping (and counting)
malformed, truncated and corrupted frames and resynchronising on the next valid one.
"""

from __future__ import annotations

import inspect
import math
import struct
from collections.abc import Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.airframe import ROTOR_LAYOUT
from tuavdefs.frames import (
    Quat,
    Vec3,
    enu_to_ned,
    flu_to_frd,
    frd_to_flu,
    global_to_local_enu,
    local_enu_to_global,
    ned_to_enu,
    quat_enu_flu_to_ned_frd,
    quat_ned_frd_to_enu_flu,
)

# ----- link constants
#: TCP port of PX4's simulator API (the plant listens, the companion connects).
SIM_PORT_DEFAULT = 4560
#: The only host the link binds to or connects to.
SIM_HOST_DEFAULT = "127.0.0.1"
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

_INT16 = 32767
_UINT16 = 65535


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


def _round_clamp(x: float, lo: int, hi: int) -> int:
    """``x`` rounded to the nearest integer and clamped to [lo, hi] (NaN -> 0)."""
    if math.isnan(x):
        return 0
    if x >= hi:
        return hi
    if x <= lo:
        return lo
    return round(x)


def _deg_e7(angle_deg: float) -> int:
    return round(angle_deg * 1e7)


def _wrap_lon(lon_deg: float) -> float:
    return (lon_deg + 180.0) % 360.0 - 180.0


def _global_fields(pos_enu_m: Vec3, home: tuple[float, float, float]) -> tuple[int, int, int]:
    """(lat degE7, lon degE7, alt mm AMSL) of an inertial position [m]."""
    lat, lon, alt = local_enu_to_global(pos_enu_m, home)
    return _deg_e7(lat), _deg_e7(_wrap_lon(lon)), round(alt * 1000.0)


def _local_from_global(msg: Any, home: tuple[float, float, float]) -> Vec3:
    return global_to_local_enu(_field(msg, "lat") * 1e-7, _field(msg, "lon") * 1e-7,
                               _field(msg, "alt") * 1e-3, home)


# ----- HIL_STATE_QUATERNION
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
    lat, lon, alt = _global_fields(pos_enu_m, home)
    v_ned = enu_to_ned(vel_enu_m_s)
    w_frd = flu_to_frd(rates_flu_rad_s)
    f_frd = flu_to_frd(specific_force_flu_m_s2)
    ias = true_airspeed_m_s if ind_airspeed_m_s is None else ind_airspeed_m_s
    return {
        "time_usec": int(time_us),
        "attitude_quaternion": list(quat_enu_flu_to_ned_frd(tuple(quat_enu_flu))),
        "rollspeed": float(w_frd[0]), "pitchspeed": float(w_frd[1]),
        "yawspeed": float(w_frd[2]),
        "lat": lat, "lon": lon, "alt": alt,
        "vx": _round_clamp(v_ned[0] * 100.0, -_INT16, _INT16),
        "vy": _round_clamp(v_ned[1] * 100.0, -_INT16, _INT16),
        "vz": _round_clamp(v_ned[2] * 100.0, -_INT16, _INT16),
        "ind_airspeed": _round_clamp(ias * 100.0, 0, _UINT16),
        "true_airspeed": _round_clamp(true_airspeed_m_s * 100.0, 0, _UINT16),
        "xacc": _round_clamp(f_frd[0] / MILLI_G_M_S2, -_INT16, _INT16),
        "yacc": _round_clamp(f_frd[1] / MILLI_G_M_S2, -_INT16, _INT16),
        "zacc": _round_clamp(f_frd[2] / MILLI_G_M_S2, -_INT16, _INT16),
    }


def state_from_hil_state_quaternion(msg_fields: Any, home: tuple[float, float, float]
                                    ) -> tuple[Vec3, Vec3, Quat, Vec3]:
    """(position ENU [m], velocity ENU [m/s], quaternion body FLU -> ENU, rates FLU [rad/s])
    from a HIL_STATE_QUATERNION (a pymavlink message or a mapping of its fields)."""
    pos = _local_from_global(msg_fields, home)
    vel = ned_to_enu((_field(msg_fields, "vx") * 0.01, _field(msg_fields, "vy") * 0.01,
                      _field(msg_fields, "vz") * 0.01))
    q_ned = tuple(float(c) for c in _field(msg_fields, "attitude_quaternion"))
    quat = quat_ned_frd_to_enu_flu(q_ned)  # type: ignore[arg-type]
    rates = frd_to_flu((float(_field(msg_fields, "rollspeed")),
                        float(_field(msg_fields, "pitchspeed")),
                        float(_field(msg_fields, "yawspeed"))))
    return pos, vel, quat, rates


def specific_force_from_hil_state_quaternion(msg_fields: Any) -> Vec3:
    """The truth specific force in body FLU [m/s^2] of a HIL_STATE_QUATERNION."""
    return frd_to_flu((_field(msg_fields, "xacc") * MILLI_G_M_S2,
                       _field(msg_fields, "yacc") * MILLI_G_M_S2,
                       _field(msg_fields, "zacc") * MILLI_G_M_S2))


def airspeeds_from_hil_state_quaternion(msg_fields: Any) -> tuple[float, float]:
    """(indicated, true) airspeed [m/s] of a HIL_STATE_QUATERNION."""
    return (_field(msg_fields, "ind_airspeed") * 0.01, _field(msg_fields, "true_airspeed") * 0.01)


# ----- HIL_GPS
def hil_gps_fields(time_us: int, pos_enu_m: Vec3, vel_enu_m_s: Vec3,
                   home: tuple[float, float, float], eph_m: float = 0.3, epv_m: float = 0.5,
                   satellites_visible: int = 10, fix_type: int = GPS_FIX_3D) -> dict[str, Any]:
    """The fields of HIL_GPS for a (measured) position [m] and velocity [m/s] in ENU.

    ``eph_m``/``epv_m`` are the claimed horizontal/vertical accuracies [m], sent in cm as
    PX4 reads them. Ground speed ``vel`` and ``vn/ve/vd`` in cm/s, course over ground
    ``cog`` in cdeg in [0, 36000) (unknown, 65535, when the ground speed rounds to 0).
    """
    lat, lon, alt = _global_fields(pos_enu_m, home)
    vn, ve, vd = enu_to_ned(vel_enu_m_s)
    ground = math.hypot(vn, ve)
    vel_cm = _round_clamp(ground * 100.0, 0, _UINT16 - 1)
    cog = (UINT16_UNKNOWN if vel_cm == 0
           else round(math.degrees(math.atan2(ve, vn)) * 100.0) % 36000)
    return {
        "time_usec": int(time_us), "fix_type": int(fix_type),
        "lat": lat, "lon": lon, "alt": alt,
        "eph": _round_clamp(eph_m * 100.0, 0, _UINT16 - 1),
        "epv": _round_clamp(epv_m * 100.0, 0, _UINT16 - 1),
        "vel": vel_cm,
        "vn": _round_clamp(vn * 100.0, -_INT16, _INT16),
        "ve": _round_clamp(ve * 100.0, -_INT16, _INT16),
        "vd": _round_clamp(vd * 100.0, -_INT16, _INT16),
        "cog": cog, "satellites_visible": int(satellites_visible), "id": 0, "yaw": 0,
    }


def gps_from_hil_gps(msg_fields: Any, home: tuple[float, float, float]
                     ) -> tuple[Vec3, Vec3, float, float]:
    """(position ENU [m], velocity ENU [m/s], eph [m], epv [m]) of a HIL_GPS."""
    pos = _local_from_global(msg_fields, home)
    vel = ned_to_enu((_field(msg_fields, "vn") * 0.01, _field(msg_fields, "ve") * 0.01,
                      _field(msg_fields, "vd") * 0.01))
    return pos, vel, _field(msg_fields, "eph") * 0.01, _field(msg_fields, "epv") * 0.01


# ----- HIL_SENSOR
def hil_sensor_fields(time_us: int, accel_flu_m_s2: Vec3, gyro_flu_rad_s: Vec3,
                      mag_flu_gauss: Vec3, abs_pressure_hpa: float, pressure_alt_m: float,
                      temperature_c: float) -> dict[str, Any]:
    """The fields of HIL_SENSOR for readings in body FLU: specific force [m/s^2], rates
    [rad/s], magnetic field [gauss]; static pressure [hPa], pressure altitude [m],
    temperature [degC]. Vectors go out in body FRD; ``fields_updated`` is
    :data:`SENSOR_FIELDS_FILLED` (diff_pressure 0: no airspeed sensor)."""
    a = flu_to_frd(accel_flu_m_s2)
    g = flu_to_frd(gyro_flu_rad_s)
    m = flu_to_frd(mag_flu_gauss)
    return {
        "time_usec": int(time_us),
        "xacc": float(a[0]), "yacc": float(a[1]), "zacc": float(a[2]),
        "xgyro": float(g[0]), "ygyro": float(g[1]), "zgyro": float(g[2]),
        "xmag": float(m[0]), "ymag": float(m[1]), "zmag": float(m[2]),
        "abs_pressure": float(abs_pressure_hpa), "diff_pressure": 0.0,
        "pressure_alt": float(pressure_alt_m), "temperature": float(temperature_c),
        "fields_updated": SENSOR_FIELDS_FILLED, "id": 0,
    }


def imu_from_hil_sensor(msg_fields: Any) -> tuple[Vec3, Vec3, Vec3, float, float, float]:
    """(specific force FLU [m/s^2], rates FLU [rad/s], field FLU [gauss], static pressure
    [hPa], pressure altitude [m], temperature [degC]) of a HIL_SENSOR."""
    def vec(a: str, b: str, c: str) -> Vec3:
        return frd_to_flu((float(_field(msg_fields, a)), float(_field(msg_fields, b)),
                           float(_field(msg_fields, c))))

    return (vec("xacc", "yacc", "zacc"), vec("xgyro", "ygyro", "zgyro"),
            vec("xmag", "ymag", "zmag"), float(_field(msg_fields, "abs_pressure")),
            float(_field(msg_fields, "pressure_alt")), float(_field(msg_fields, "temperature")))


# ----- HIL_ACTUATOR_CONTROLS
def _clean_command(c: float) -> float:
    c = float(c)
    if math.isnan(c):
        return 0.0
    return min(max(c, 0.0), 1.0)


def actuator_controls_fields(rotor_commands: Sequence[float], armed: bool,
                             lockstep: bool = True) -> dict[str, Any]:
    """``controls``, ``mode`` and ``flags`` of HIL_ACTUATOR_CONTROLS (``time_usec`` is the
    caller's: the HIL_SENSOR time being answered). ``rotor_commands`` are the four
    normalised commands in [0, 1] (rotor order of :mod:`tuavdefs.airframe`), clamped, NaN
    sent as 0; the other 12 controls are 0."""
    if len(rotor_commands) != N_ROTORS:
        raise ValueError(f"need {N_ROTORS} rotor commands, got {len(rotor_commands)}")
    controls = [_clean_command(c) for c in rotor_commands] + [0.0] * (N_CONTROLS - N_ROTORS)
    return {"controls": controls, "mode": MODE_ARMED if armed else MODE_DISARMED,
            "flags": FLAG_LOCKSTEP if lockstep else 0}


def rotor_commands_from_controls(controls: Sequence[float], mode: int
                                 ) -> tuple[tuple[float, float, float, float], bool]:
    """(rotor commands 1..4 in [0, 1], armed) of HIL_ACTUATOR_CONTROLS' ``controls`` and
    ``mode``. Commands are clamped to [0, 1] and NaN read as 0; armed is the
    MAV_MODE_FLAG_SAFETY_ARMED bit."""
    if len(controls) < N_ROTORS:
        raise ValueError(f"need at least {N_ROTORS} controls, got {len(controls)}")
    cmds = tuple(_clean_command(c) for c in controls[:N_ROTORS])
    return cmds, bool(int(mode) & MODE_FLAG_ARMED)  # type: ignore[return-value]


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


def _crc16(data: bytes) -> int:
    """MAVLink's checksum (CRC-16/MCRF4XX) of ``data``, as pymavlink computes it."""
    if mavlink2.mcrf4xx is not None:
        return int(mavlink2.mcrf4xx(data, 0xFFFF))
    return int(mavlink2.x25crc(data).crc)


_HEADER_V2_STRUCT = struct.Struct("<BBBBBBBHB")
_CRC_STRUCT = struct.Struct("<H")


class _Codec:
    """MAVLink 2 packing and unpacking of one message type, without pymavlink's generic
    per-message machinery: the same bytes as ``MAVLink.send`` writes and the same message
    objects as ``MAVLink.decode`` returns (``tests/test_simlink.py`` compares them), about
    three times faster. For the simulator link's own messages (no strings, no signing)."""

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

    def pack(self, mav: mavlink2.MAVLink, fields: Mapping[str, Any]) -> bytes:
        """The frame of a message with ``fields`` from ``mav`` (its ids and sequence)."""
        values: list[Any] = []
        defaults = self.defaults
        for name, n in self.wire:
            v = fields[name] if name in fields else defaults[name]
            if n:
                values.extend(v[k] for k in range(n))
            else:
                values.append(v)
        payload = self.unpacker.pack(*values).rstrip(b"\0") or b"\0"
        mid = self.msg_id
        header = _HEADER_V2_STRUCT.pack(_MAGIC_V2, len(payload), 0, 0, mav.seq, mav.srcSystem,
                                        mav.srcComponent, mid & 0xFFFF, mid >> 16)
        body = header + payload
        frame = body + _CRC_STRUCT.pack(_crc16(body[1:] + self.crc_extra))
        mav.seq = (mav.seq + 1) % 256
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(frame)
        return frame

    def decode(self, frame: bytearray) -> mavlink2.MAVLink_message | None:
        """The message of an unsigned MAVLink 2 ``frame`` of this type (None: bad CRC)."""
        (_, mlen, incompat, compat, seq, sysid, compid, _, _) = _HEADER_V2_STRUCT.unpack_from(
            frame)
        crc = frame[-2] | (frame[-1] << 8)
        if crc != _crc16(bytes(frame[1:-2]) + self.crc_extra):
            return None
        size = self.unpacker.size
        payload = bytes(frame[_HEADER_V2:-2])
        if len(payload) < size:   # MAVLink 2 drops the payload's trailing zeros
            payload += bytes(size - len(payload))
        t = self.unpacker.unpack(payload[:size])
        m = self.cls(*[t[a] if n == 0 else list(t[a:a + n]) for a, n in self.plan])
        m._signed = False
        m._msgbuf = frame
        m._payload = frame[6:-2]
        m._crc = crc
        m._header = mavlink2.MAVLink_header(self.msg_id, incompat, compat, mlen, seq, sysid,
                                            compid)
        return m


#: The simulator link's messages, packed and parsed by :class:`_Codec`.
_CODECS = {c.msg_id: c for c in map(_Codec, (
    mavlink2.MAVLink_hil_sensor_message, mavlink2.MAVLink_hil_gps_message,
    mavlink2.MAVLink_hil_state_quaternion_message,
    mavlink2.MAVLink_hil_actuator_controls_message))}


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
        if self.mav.signing.sign_outgoing:   # pymavlink signs: let it pack
            cls = mavlink2.mavlink_map[msg_id]
            return self.pack(cls(**{**_CODECS[msg_id].defaults, **fields}))
        return _CODECS[msg_id].pack(self.mav, fields)

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
