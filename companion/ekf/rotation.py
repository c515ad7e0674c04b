"""Quaternion kernels of the error-state filter (the attitude error a small rotation,
``R_true = Exp(dtheta) R``) and the TRIAD attitude of the alignment."""

from __future__ import annotations

import math

import numpy as np

from tuavdefs.frames import Quat, Vec3, euler_to_quat
from tuavdefs.jit import njit


@njit
def exp_rotvec(rx: float, ry: float, rz: float) -> tuple[float, float, float, float]:
    """The unit quaternion ``Exp(r)`` of a rotation vector ``r`` [rad]."""
    a = math.sqrt(rx * rx + ry * ry + rz * rz)
    if a < 1e-9:
        c, s = 1.0, 0.5
    else:
        c, s = math.cos(0.5 * a), math.sin(0.5 * a) / a
    return c, s * rx, s * ry, s * rz


@njit
def qmul_unit(aw: float, ax: float, ay: float, az: float, bw: float, bx: float,
               by: float, bz: float) -> tuple[float, float, float, float, float]:
    """The product ``a * b`` and the inverse of its norm."""
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    return w, x, y, z, 1.0 / math.sqrt(w * w + x * x + y * y + z * z)


@njit
def qmul_exp(qw: float, qx: float, qy: float, qz: float, rx: float, ry: float,
              rz: float) -> tuple[float, float, float, float]:
    """``q * Exp(r)`` for a rotation vector ``r`` [rad] (right: in the body frame),
    normalised."""
    ew, ex, ey, ez = exp_rotvec(rx, ry, rz)
    w, x, y, z, n = qmul_unit(qw, qx, qy, qz, ew, ex, ey, ez)
    return w * n, x * n, y * n, z * n


@njit
def expq_mul(rx: float, ry: float, rz: float, qw: float, qx: float, qy: float,
              qz: float) -> tuple[float, float, float, float]:
    """``Exp(r) * q`` for a rotation vector ``r`` [rad] (left: in the inertial frame),
    normalised, its scalar part kept non-negative."""
    ew, ex, ey, ez = exp_rotvec(rx, ry, rz)
    w, x, y, z, n = qmul_unit(ew, ex, ey, ez, qw, qx, qy, qz)
    if w < 0.0:
        n = -n
    return w * n, x * n, y * n, z * n



def triad(body1: Vec3, body2: Vec3, nav1: Vec3, nav2: Vec3) -> Quat:
    """The attitude (quaternion body FLU -> inertial ENU) that takes ``body1`` onto
    ``nav1`` exactly and ``body2`` as near ``nav2`` as that allows (TRIAD)."""
    def frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        t1 = a / np.linalg.norm(a)
        t2 = np.cross(a, b)
        t2 /= np.linalg.norm(t2)
        return np.column_stack((t1, t2, np.cross(t1, t2)))
    r = frame(np.array(nav1), np.array(nav2)) @ frame(np.array(body1), np.array(body2)).T
    roll = math.atan2(r[2, 1], r[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, r[2, 0])))
    yaw = math.atan2(r[1, 0], r[0, 0])
    return euler_to_quat(roll, pitch, yaw)

