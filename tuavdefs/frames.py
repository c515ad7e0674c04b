"""Reference frames and the conversions between them.

Project frames (used everywhere inside the plant and the controllers):
- **inertial**: the paper's frame, z up, origin at the winder's tether exit point on the
  ground; x points east and y north (ENU), so that a geographic home maps onto it.
- **body**: origin at the UAV's centre of mass, x forward, y left, z up (FLU).

MAVLink frames (used only at the MAVLink boundary):
- **local NED**: x north, y east, z down, same origin.
- **body FRD**: x forward, y right, z down.

Quaternions are (w, x, y, z), Hamilton convention, and rotate vectors from the body frame
into the world frame: v_world = q * v_body * q^-1. Euler angles are the aerospace
Z-Y-X sequence R = Rz(yaw) Ry(pitch) Rx(roll) in both conventions, each in its own frame.

In the z-up/FLU convention a positive pitch puts the nose down; in NED/FRD a positive
pitch puts it up, and yaw is measured from north toward east rather than from east toward
north. The functions here handle that; nothing else in the project should.
"""

from __future__ import annotations

import math

import numpy as np

from tuavdefs.jit import njit

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

# WGS-84 semi-major axis and flattening, for the local tangent-plane mapping.
_WGS84_A_M = 6378137.0
_WGS84_F = 1.0 / 298.257223563
_WGS84_E2 = _WGS84_F * (2.0 - _WGS84_F)

_SQRT_HALF = math.sqrt(0.5)
# Rotation taking ENU vectors to NED vectors: x<->y swap and z flip. As a quaternion it is a
# 180 deg rotation about the axis (1, 1, 0)/sqrt(2).
Q_NED_FROM_ENU: Quat = (0.0, _SQRT_HALF, _SQRT_HALF, 0.0)
# Rotation taking FRD body vectors to FLU body vectors: 180 deg about body x.
Q_FLU_FROM_FRD: Quat = (0.0, 1.0, 0.0, 0.0)


def enu_to_ned(v: Vec3) -> Vec3:
    """A position or velocity from the z-up inertial frame (east, north, up) to NED."""
    return (v[1], v[0], -v[2])


def ned_to_enu(v: Vec3) -> Vec3:
    """A position or velocity from NED to the z-up inertial frame (east, north, up)."""
    return (v[1], v[0], -v[2])


def flu_to_frd(v: Vec3) -> Vec3:
    """A body-frame vector (rates, accelerations, forces) from FLU to FRD."""
    return (v[0], -v[1], -v[2])


def frd_to_flu(v: Vec3) -> Vec3:
    """A body-frame vector from FRD to FLU."""
    return (v[0], -v[1], -v[2])


def quat_multiply(a: Quat, b: Quat) -> Quat:
    """Hamilton product a * b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_conjugate(q: Quat) -> Quat:
    """The inverse of a unit quaternion."""
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalize(q: Quat) -> Quat:
    """q scaled to unit norm, with a non-negative scalar part."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n == 0.0 or not math.isfinite(n):
        raise ValueError(f"cannot normalise quaternion {q!r}")
    s = 1.0 / n if q[0] >= 0.0 else -1.0 / n
    return (q[0] * s, q[1] * s, q[2] * s, q[3] * s)


def quat_rotate(q: Quat, v: Vec3) -> Vec3:
    """Rotate v by unit quaternion q (body to world for an attitude quaternion)."""
    w, x, y, z = q
    # v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    cx = y * v[2] - z * v[1]
    cy = z * v[0] - x * v[2]
    cz = x * v[1] - y * v[0]
    return (v[0] + 2.0 * (w * cx + y * cz - z * cy),
            v[1] + 2.0 * (w * cy + z * cx - x * cz),
            v[2] + 2.0 * (w * cz + x * cy - y * cx))


def quat_to_matrix(q: Quat) -> tuple[Vec3, Vec3, Vec3]:
    """Rotation matrix (rows) of unit quaternion q."""
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def euler_to_quat(roll: float, pitch: float, yaw: float) -> Quat:
    """Unit quaternion of the Z-Y-X Euler angles [rad]: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return quat_normalize((cr * cp * cy + sr * sp * sy,
                           sr * cp * cy - cr * sp * sy,
                           cr * sp * cy + sr * cp * sy,
                           cr * cp * sy - sr * sp * cy))


def quat_to_yaw(q: Quat) -> float:
    """The yaw [rad] of unit quaternion q: ``quat_to_euler(q)[2]`` without roll and
    pitch."""
    w, x, y, z = q
    sinp = 2.0 * (w * y - z * x)
    if sinp >= 1.0 - 1e-12 or sinp <= -1.0 + 1e-12:
        return quat_to_euler(q)[2]      # gimbal lock
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quat_to_euler(q: Quat) -> Vec3:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad] of unit quaternion q.

    Pitch is in [-pi/2, pi/2]; at +-pi/2 (gimbal lock) roll is reported as 0.
    """
    w, x, y, z = q
    sinp = 2.0 * (w * y - z * x)
    if sinp >= 1.0 - 1e-12 or sinp <= -1.0 + 1e-12:
        pitch = math.copysign(math.pi / 2, sinp)
        roll = 0.0
        yaw = -2.0 * math.atan2(x, w) if sinp > 0 else 2.0 * math.atan2(x, w)
        return (roll, pitch, wrap_pi(yaw))
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(sinp)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


@njit
def wrap_pi(angle_rad: float) -> float:
    """An angle wrapped into [-pi, pi) [rad]."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


#: Compiled versions of the same functions, for the controllers' kernels.
quat_to_matrix_kernel = njit(quat_to_matrix)
quat_to_euler_kernel = njit(quat_to_euler)


@njit
def quat_rows_to_euler(quats: np.ndarray) -> np.ndarray:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad], (n, 3), of the (n, 4) unit quaternions
    (w, x, y, z): :func:`quat_to_euler` of each row (NaN rows give NaN)."""
    n = quats.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        out[i, 0], out[i, 1], out[i, 2] = quat_to_euler_kernel(
            (quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3]))
    return out


def quat_enu_flu_to_ned_frd(q: Quat) -> Quat:
    """Attitude from (body FLU -> inertial ENU) to MAVLink's (body FRD -> NED)."""
    return quat_normalize(quat_multiply(quat_multiply(Q_NED_FROM_ENU, q), Q_FLU_FROM_FRD))


def _quat_ned_frd_to_enu_flu_products(q: Quat) -> Quat:
    """Attitude from MAVLink's (body FRD -> NED) to (body FLU -> inertial ENU), through
    the generic products: the definition :func:`quat_ned_frd_to_enu_flu` follows."""
    return quat_normalize(quat_multiply(quat_multiply(quat_conjugate(Q_NED_FROM_ENU), q),
                                        quat_conjugate(Q_FLU_FROM_FRD)))


def quat_ned_frd_to_enu_flu(q: Quat) -> Quat:
    """Attitude from MAVLink's (body FRD -> NED) to (body FLU -> inertial ENU).

    The products of :func:`_quat_ned_frd_to_enu_flu_products` written out: their terms
    with a factor 0 add an exact (signed) zero, those with a factor +-1 are exact, so
    wherever the product's components are all non-zero and finite the few remaining
    terms give the same floats, bit for bit (``tests/test_frames.py``); elsewhere (a
    zero's sign would depend on the dropped terms) the generic products decide.
    """
    w, x, y, z = q
    s = _SQRT_HALF
    sw, sx, sy, sz = s * w, s * x, s * y, s * z
    rw = -sw - sz
    rx = -(sx + sy)
    ry = -(sx - sy)
    rz = sz - sw
    n = math.sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
    if not (rw and rx and ry and rz and 0.0 < n < math.inf):
        return _quat_ned_frd_to_enu_flu_products(q)
    k = 1.0 / n if rw >= 0.0 else -1.0 / n
    return (rw * k, rx * k, ry * k, rz * k)


def yaw_enu_to_ned(yaw_rad: float) -> float:
    """Heading from the z-up convention (from east, counter-clockwise) to NED (from north,
    clockwise) [rad], wrapped to [-pi, pi)."""
    return wrap_pi(math.pi / 2 - yaw_rad)


def yaw_ned_to_enu(yaw_rad: float) -> float:
    """Heading from NED (from north, clockwise) to the z-up convention [rad]."""
    return wrap_pi(math.pi / 2 - yaw_rad)


def local_enu_to_global(pos_enu_m: Vec3, home: tuple[float, float, float]
                        ) -> tuple[float, float, float]:
    """Inertial position [m] to (latitude deg, longitude deg, altitude m AMSL).

    ``home`` is (latitude deg, longitude deg, altitude m AMSL) of the inertial origin.
    Uses the local tangent plane with WGS-84 radii of curvature at home: accurate to
    centimetres over the tether's few hundred metres.
    """
    lat0, lon0, alt0 = home
    r_n, r_e = _radii_m(lat0)
    lat = lat0 + math.degrees(pos_enu_m[1] / r_n)
    lon = lon0 + math.degrees(pos_enu_m[0] / (r_e * math.cos(math.radians(lat0))))
    return (lat, lon, alt0 + pos_enu_m[2])


def global_to_local_enu(lat_deg: float, lon_deg: float, alt_m: float,
                        home: tuple[float, float, float]) -> Vec3:
    """(latitude deg, longitude deg, altitude m AMSL) to the inertial position [m]."""
    lat0, lon0, alt0 = home
    r_n, r_e = _radii_m(lat0)
    north = math.radians(lat_deg - lat0) * r_n
    east = math.radians(_wrap_deg(lon_deg - lon0)) * r_e * math.cos(math.radians(lat0))
    return (east, north, alt_m - alt0)


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def _radii_m(lat_deg: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii of curvature of WGS-84 at a latitude [m]."""
    s = math.sin(math.radians(lat_deg))
    d = 1.0 - _WGS84_E2 * s * s
    r_e = _WGS84_A_M / math.sqrt(d)
    r_n = _WGS84_A_M * (1.0 - _WGS84_E2) / (d * math.sqrt(d))
    return r_n, r_e
