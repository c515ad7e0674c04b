"""The prediction: the nominal state integrated with one IMU sample, the error-state
covariance propagated (``P <- F P F' + Q``), the state stored in the ring buffer of past
states (PX4 EKF2's ``covariance.cpp`` and ``predictState``; docs/estimation.md)."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.layout import (
    BUF_P,
    BUF_T,
    IDX_BA,
    IDX_BG,
    IDX_BH,
    IDX_BM,
    IDX_BP,
    IDX_TH,
    IDX_V,
    IDX_W,
    PRM_ACC_N,
    PRM_BA_W,
    PRM_BG_W,
    PRM_BH_W,
    PRM_BM_W,
    PRM_BP_TAU,
    PRM_BP_VAR_H,
    PRM_BP_VAR_V,
    PRM_GRAV,
    PRM_GYRO_N,
    PRM_WIND_HGT_SCALE,
    PRM_WIND_WALK,
    W_DRAG_SUM,
    W_PRM,
    W_RATES,
    W_X,
    X_BA,
    X_BG,
    X_BP,
    X_Q,
    X_V,
)
from companion.ekf.rotation import qmul_exp
from tuavdefs.frames import quat_to_matrix_kernel
from tuavdefs.jit import njit

#: Time constant of the low-passed acceleration and yaw rate that say whether the vehicle
#: manoeuvres (the magnetometer's 3-axis fusion) [s].
MANOEUVRE_TAU_S = 1.0


@njit
def predict_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                   t_s: float, dt_s: float, gx: float, gy: float, gz: float, ax: float,
                   ay: float, az: float) -> None:
    """One IMU step of ``dt_s`` [s] ending at ``t_s`` [s]: the nominal state (in the work
    array ``w``) integrated with the rates ``g*`` [rad/s] and specific force ``a*``
    [m/s^2] (body FLU), the covariance ``P`` propagated (``F P F' + Q``), the state stored
    in the ring buffer ``buf`` (``meta`` = next slot, entries); the rates block of ``w``:
    [0:3] the bias-corrected rates, [3:6] the inertial acceleration and [6] the yaw rate
    [rad/s], low-passed over :data:`MANOEUVRE_TAU_S` (whether the vehicle manoeuvres); the
    bias-corrected specific force's body x and y added to the drag fusion's sums."""
    x = w[W_X:]
    prm = w[W_PRM:]
    rates = w[W_RATES:]
    g = prm[PRM_GRAV]
    # bias-corrected measurements
    wx, wy, wz = gx - x[X_BG], gy - x[X_BG + 1], gz - x[X_BG + 2]
    fx, fy, fz = ax - x[X_BA], ay - x[X_BA + 1], az - x[X_BA + 2]
    rates[0], rates[1], rates[2] = wx, wy, wz
    qw, qx, qy, qz = x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]
    # the specific force rotated with the attitude at mid-step
    mw, mx, my, mz = qmul_exp(qw, qx, qy, qz, 0.5 * wx * dt_s, 0.5 * wy * dt_s,
                              0.5 * wz * dt_s)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(
        (mw, mx, my, mz))
    aix = r00 * fx + r01 * fy + r02 * fz
    aiy = r10 * fx + r11 * fy + r12 * fz
    aiz = r20 * fx + r21 * fy + r22 * fz - g
    lp = dt_s / (MANOEUVRE_TAU_S + dt_s)
    rates[3] += lp * (aix - rates[3])
    rates[4] += lp * (aiy - rates[4])
    rates[5] += lp * (aiz - rates[5])
    rates[6] += lp * (r20 * wx + r21 * wy + r22 * wz - rates[6])
    drag = w[W_DRAG_SUM:]
    drag[0] += fx
    drag[1] += fy
    drag[2] += 1.0
    for i, a in enumerate((aix, aiy, aiz)):
        x[i] += (x[X_V + i] + 0.5 * a * dt_s) * dt_s
        x[X_V + i] += a * dt_s
    nw, nx, ny, nz = qmul_exp(qw, qx, qy, qz, wx * dt_s, wy * dt_s, wz * dt_s)
    x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3] = nw, nx, ny, nz
    # F = I + A dt: dp <- dv dt; dv <- -[a_i]x dtheta dt - R db_a dt;
    # dtheta <- -R db_g dt (the attitude error in the inertial frame)
    sx, sy, sz = aix * dt_s, aiy * dt_s, (aiz + g) * dt_s     # a_i without gravity
    # A = -[s]x (3x3), B = C = -R dt
    A = ((0.0, sz, -sy), (-sz, 0.0, sx), (sy, -sx, 0.0))
    R = ((r00, r01, r02), (r10, r11, r12), (r20, r21, r22))
    n = P.shape[0]
    # FP = F P (rows)
    for j in range(n):
        for i in range(3):
            P[i, j] += dt_s * P[IDX_V + i, j]
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc += A[i][k] * P[IDX_TH + k, j] - R[i][k] * dt_s * P[IDX_BA + k, j]
            P[IDX_V + i, j] += acc
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc -= R[i][k] * dt_s * P[IDX_BG + k, j]
            P[IDX_TH + i, j] += acc
    # (F P) F' (columns)
    for j in range(n):
        for i in range(3):
            P[j, i] += dt_s * P[j, IDX_V + i]
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc += A[i][k] * P[j, IDX_TH + k] - R[i][k] * dt_s * P[j, IDX_BA + k]
            P[j, IDX_V + i] += acc
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc -= R[i][k] * dt_s * P[j, IDX_BG + k]
            P[j, IDX_TH + i] += acc
    # Q: white noise of the accelerometer (on dv) and gyro (on dtheta), bias random walks
    qv = prm[PRM_ACC_N] ** 2 * dt_s
    qt = prm[PRM_GYRO_N] ** 2 * dt_s
    qbg = prm[PRM_BG_W] ** 2 * dt_s
    qba = prm[PRM_BA_W] ** 2 * dt_s
    for i in range(3):
        P[i, i] += qv * dt_s * dt_s / 3.0
        P[i, IDX_V + i] += 0.5 * qv * dt_s
        P[IDX_V + i, i] += 0.5 * qv * dt_s
        P[IDX_V + i, IDX_V + i] += qv
        P[IDX_TH + i, IDX_TH + i] += qt
        P[IDX_BG + i, IDX_BG + i] += qbg
        P[IDX_BA + i, IDX_BA + i] += qba
    P[IDX_BH, IDX_BH] += prm[PRM_BH_W] ** 2 * dt_s
    qbm = prm[PRM_BM_W] ** 2 * dt_s
    for i in range(3):
        P[IDX_BM + i, IDX_BM + i] += qbm
    # the receiver's wander: b_p <- exp(-dt/tau) b_p, its stationary variance kept
    tau = prm[PRM_BP_TAU]
    if tau > 0.0:
        phi = math.exp(-dt_s / tau)
        for i in range(3):
            x[X_BP + i] *= phi
            for j in range(n):
                P[IDX_BP + i, j] *= phi
            for j in range(n):
                P[j, IDX_BP + i] *= phi
            var = prm[PRM_BP_VAR_H] if i < 2 else prm[PRM_BP_VAR_V]
            P[IDX_BP + i, IDX_BP + i] += var * (1.0 - phi * phi)
    # the wind: a random walk, faster while climbing or descending (EKF3's
    # EK3_WIND_PSCALE); none while its states are inhibited (walk 0)
    walk = prm[PRM_WIND_WALK]
    if walk > 0.0:
        qw = (walk * (1.0 + prm[PRM_WIND_HGT_SCALE] * abs(x[X_V + 2]))) ** 2 * dt_s
        P[IDX_W, IDX_W] += qw
        P[IDX_W + 1, IDX_W + 1] += qw
    symmetrise(P)
    # the ring buffer of (t, p, v)
    k = meta[0]
    buf[k, BUF_T] = t_s
    for i in range(6):
        buf[k, BUF_P + i] = x[i]
    meta[0] = (k + 1) % buf.shape[0]
    if meta[1] < buf.shape[0]:
        meta[1] += 1



@njit
def symmetrise(P: np.ndarray) -> None:
    """``P = (P + P') / 2`` in place."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m

