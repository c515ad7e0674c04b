"""The companion's component link: MAVLink between the flight computer and onboard-style
components, here the ground station's winch.

The companion listens on TCP 127.0.0.1:5762 (ArduPilot SITL's second serial port) and sends
the UAV's ``LOCAL_POSITION_NED`` (100 Hz of simulated time); the winch component (system 1,
component 169 ``MAV_COMP_ID_WINCH``) sends ``WINCH_STATUS`` and a ``HEARTBEAT`` with
autopilot ``MAV_AUTOPILOT_INVALID`` and type ``MAV_TYPE_WINCH`` so that ground stations do
not take it for a second vehicle. MAVLink 2, signed with the vehicle's key when it has
one (the companion hands the winch a new key with ``SETUP_SIGNING`` from component 1).
The winch also sends its tether fix of the UAV's position as ``ODOMETRY``
(:func:`odometry_message`, :func:`external_position`) at :data:`TETHER_FIX_RATE_HZ`, and
with each fix the raw reading it was made of as ``DEBUG_FLOAT_ARRAY`` "TETHER"
(:func:`tether_reading_message`, :func:`tether_reading`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.signing import SigningMavlink

COMPONENT_PORT_DEFAULT = 5762
SYSTEM_ID = 1
AUTOPILOT_COMPONENT_ID = 1
WINCH_COMPONENT_ID = mavlink2.MAV_COMP_ID_WINCH          # 169
POSITION_RATE_HZ = 100.0
#: How often the companion sends the winch its wind estimate (``WIND``) [Hz, simulated].
WIND_RATE_HZ = 1.0


def winch_status_flags(brake_engaged: bool, moving: bool, healthy: bool = True) -> int:
    """``MAV_WINCH_STATUS_FLAG`` bits of the winch's state."""
    flags = mavlink2.MAV_WINCH_STATUS_HEALTHY if healthy else 0
    if moving:
        flags |= mavlink2.MAV_WINCH_STATUS_MOVING
    if brake_engaged:
        flags |= mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    return flags


def new_mavlink(component_id: int) -> mavlink2.MAVLink:
    """A MAVLink 2 packer/parser for system 1 and ``component_id`` (signing as
    ``tuavdefs.signing`` checks it, once a key is set on its ``signing``)."""
    mav = SigningMavlink(None, srcSystem=SYSTEM_ID, srcComponent=component_id)
    mav.robust_parsing = True
    return mav


#: ``MAV_CMD_DO_WINCH`` is taken when addressed to the winch, to the autopilot (which
#: forwards it to the winch) or to every component.
DO_WINCH_TARGET_COMPONENTS = (WINCH_COMPONENT_ID, AUTOPILOT_COMPONENT_ID, 0)
#: Winch instance numbers (``param1``) the winch answers to.
WINCH_INSTANCES = (0, 1)


def winch_status_flag(name: str) -> int:
    """The ``MAV_WINCH_STATUS_<name>`` bit, or 0 where the installed common dialect does not
    define it (pymavlink 2.4.x knows HEALTHY, FULLY_RETRACTED, MOVING, CLUTCH_ENGAGED; newer
    common.xml adds LOCKED, RETRACTING, ...)."""
    return int(getattr(mavlink2, f"MAV_WINCH_STATUS_{name}", 0))


#: How often the winch sends its tether fix (groundstation.tether_fix) [Hz, simulated].
TETHER_FIX_RATE_HZ = 10.0
#: ``pose_covariance`` indices (row-major upper triangle of the 6x6 x, y, z, roll, pitch,
#: yaw matrix, as ODOMETRY defines it) of the position block (i, j) for i <= j < 3.
_POSE_COV_INDEX = {(0, 0): 0, (0, 1): 1, (0, 2): 2, (1, 1): 6, (1, 2): 7, (2, 2): 11}
#: ENU <-> NED axis permutation and signs: NED_i = sign_i * ENU_perm_i.
_NED_FROM_ENU = ((1, 1.0), (0, 1.0), (2, -1.0))


class ExternalPosition(NamedTuple):
    """A position of the UAV from outside its own sensors (the winch's tether fix), as the
    component link carries it: its time on the vehicle's clock [s] (time_boot), position
    [m] and covariance [m^2], inertial z-up frame with the origin at the winder."""

    t_s: float
    pos_m: tuple[float, float, float]
    cov_m2: tuple[tuple[float, float, float], ...]


def odometry_message(fix: ExternalPosition) -> mavlink2.MAVLink_odometry_message:
    """``ODOMETRY`` (331) as ArduPilot (ExternalNav) and PX4 (EKF2 external vision) take an
    external position: ``time_usec`` the sample's time, local NED (frame_id
    MAV_FRAME_LOCAL_NED) position, the position block of ``pose_covariance`` [m^2] (the
    orientation's entries and the velocity NaN: unknown), ``estimator_type`` NAIVE (a
    geometric fix, no filter behind it)."""
    n = tuple(sgn * fix.pos_m[k] for k, sgn in _NED_FROM_ENU)
    cov = [math.nan] * 21
    for (i, j), idx in _POSE_COV_INDEX.items():
        (ki, si), (kj, sj) = _NED_FROM_ENU[i], _NED_FROM_ENU[j]
        cov[idx] = si * sj * fix.cov_m2[ki][kj]
    nan = math.nan
    return mavlink2.MAVLink_odometry_message(
        max(int(round(fix.t_s * 1e6)), 0), mavlink2.MAV_FRAME_LOCAL_NED,
        mavlink2.MAV_FRAME_BODY_FRD, n[0], n[1], n[2], [nan, nan, nan, nan], nan, nan, nan,
        nan, nan, nan, cov, [nan] * 21, 0, mavlink2.MAV_ESTIMATOR_TYPE_NAIVE, 0)


def external_position(msg: mavlink2.MAVLink_odometry_message) -> ExternalPosition | None:
    """The position in an ``ODOMETRY`` message (local NED, its position covariance), or
    None when it is not one this vehicle can fuse (another frame, a position or its
    covariance not finite, the covariance not positive definite)."""
    if msg.frame_id != mavlink2.MAV_FRAME_LOCAL_NED:
        return None
    ned = (msg.x, msg.y, msg.z)
    cov_ned = [[0.0] * 3 for _ in range(3)]
    for (i, j), idx in _POSE_COV_INDEX.items():
        cov_ned[i][j] = cov_ned[j][i] = float(msg.pose_covariance[idx])
    values = [*ned, *(v for row in cov_ned for v in row)]
    if not all(math.isfinite(v) for v in values):
        return None
    # ENU_k = sign * NED_i where (k, sign) = _NED_FROM_ENU[i]
    pos = [0.0, 0.0, 0.0]
    cov = [[0.0] * 3 for _ in range(3)]
    for i, (k, si) in enumerate(_NED_FROM_ENU):
        pos[k] = si * ned[i]
        for j, (kk, sj) in enumerate(_NED_FROM_ENU):
            cov[k][kk] = si * sj * cov_ned[i][j]
    a, b, c = cov[0][0], cov[1][1], cov[2][2]
    det2 = a * b - cov[0][1] ** 2
    det3 = (a * (b * c - cov[1][2] ** 2) - cov[0][1] * (cov[0][1] * c - cov[1][2] * cov[0][2])
            + cov[0][2] * (cov[0][1] * cov[1][2] - b * cov[0][2]))
    if not (a > 0.0 and det2 > 0.0 and det3 > 0.0):
        return None
    return ExternalPosition(msg.time_usec * 1e-6, (pos[0], pos[1], pos[2]),
                            tuple(tuple(r) for r in cov))


#: ``DEBUG_FLOAT_ARRAY.name`` of the winch's raw tether reading.
TETHER_READING_NAME = "TETHER"


#: The line weights per metre [N/m] a reading may carry as the winder's estimate: a UAV's
#: tether, from a tenth of a gram to two kilograms a metre; outside, none.
LINE_WEIGHT_RANGE_N_M = (1e-3, 20.0)


class TetherReading(NamedTuple):
    """What the winch measured of the line at one sample (the readings its tether fix is
    made of): the sample's time on the vehicle's clock [s], the paid-out length [m], the
    load cell's tension [N], the guide arm's exit azimuth and elevation [rad] (as read:
    its biases in them; azimuth anticlockwise from east, elevation up from the
    horizontal, the project's z-up frame), and the line's weight per metre [N/m] as the
    winder estimates it (``groundstation.lbar.weight_estimate``; NaN: it has none yet)."""

    t_s: float
    length_m: float
    tension_n: float
    azimuth_rad: float
    elevation_rad: float
    weight_n_m: float = math.nan


def line_weight_n_m(value: float) -> float:
    """A line weight per metre [N/m] as a reading may carry it: ``value`` when finite and
    within :data:`LINE_WEIGHT_RANGE_N_M`, else NaN (none)."""
    lo, hi = LINE_WEIGHT_RANGE_N_M
    return float(value) if lo <= value <= hi else math.nan     # (False for NaN)


def tether_reading_message(r: TetherReading) -> mavlink2.MAVLink_debug_float_array_message:
    """``DEBUG_FLOAT_ARRAY`` (350) named :data:`TETHER_READING_NAME`: ``time_usec`` the
    sample's time, ``data[0:4]`` length [m], tension [N], exit azimuth and elevation [rad],
    ``data[4]`` the winder's estimate of the line's weight per metre [N/m] (NaN: none, or
    one out of :data:`LINE_WEIGHT_RANGE_N_M`), the rest 0. MAVLink has no message for a
    tether's raw reading; this one carries a named array of floats for a component's own
    data, which it is."""
    data = [0.0] * 58
    data[0:5] = (r.length_m, r.tension_n, r.azimuth_rad, r.elevation_rad,
                 line_weight_n_m(r.weight_n_m))
    return mavlink2.MAVLink_debug_float_array_message(
        max(int(round(r.t_s * 1e6)), 0), TETHER_READING_NAME.encode(), 0, data)


def tether_reading(msg: mavlink2.MAVLink_debug_float_array_message) -> TetherReading | None:
    """The reading in a ``DEBUG_FLOAT_ARRAY`` (:func:`tether_reading_message`), or None when
    the array is another or a measured value is not finite; a weight not finite or out of
    :data:`LINE_WEIGHT_RANGE_N_M` is read as none (NaN)."""
    name = msg.name
    if isinstance(name, bytes):
        name = name.decode(errors="replace")
    if name.rstrip("\x00") != TETHER_READING_NAME:
        return None
    vals = [float(v) for v in msg.data[0:4]]
    if not all(math.isfinite(v) for v in vals):
        return None
    return TetherReading(msg.time_usec * 1e-6, *vals, line_weight_n_m(float(msg.data[4])))


def wind_message(time_usec: int, wind_m_s: tuple[float, float, float]
                 ) -> mavlink2.MAVLink_wind_cov_message:
    """``WIND_COV`` of the vehicle's wind estimate ``wind_m_s`` [m/s] (the air's velocity,
    z-up, converted here to NED) at ``time_usec`` [us] (its time since boot); the
    variances, altitude and accuracies NaN (unknown)."""
    nan = math.nan
    return mavlink2.MAVLink_wind_cov_message(time_usec, wind_m_s[1], wind_m_s[0], -wind_m_s[2],
                                             nan, nan, nan, nan, nan)


def wind_of(m: mavlink2.MAVLink_wind_cov_message) -> tuple[float, float, float]:
    """The wind [m/s], z-up, of a ``WIND_COV`` (:func:`wind_message`)."""
    return (float(m.wind_y), float(m.wind_x), -float(m.wind_z))
