"""The simulator link's constants (:mod:`tuavdefs.simlink`): ports and addresses, ids,
message ids, flags and units, the control period in microseconds."""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.airframe import ROTOR_LAYOUT

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


