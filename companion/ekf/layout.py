"""Where everything the filter's kernels work on lives: the one place its layout is set.

- the nominal state ``x`` (``X_*``) and the error state, the covariance's rows (``IDX_*``);
- the ring buffer of past states (``BUF_*``);
- the work array ``w`` (``W_*``): the nominal state, the error-state correction, the
  delayed state, the rates, the output predictor's lag, the parameters the kernels read
  (``PRM_*``) and one status row per aid source (``AID_*``), packed so that a kernel takes
  a few arrays rather than dozens of arguments.

A new state goes at the end of ``x`` and of the error state (adding to ``NX`` and
``N_ERR``); a new aid source to :class:`companion.ekf.aid_source.AidSourceKind` (its row
here follows); a new kernel parameter to the ``PRM_*`` list.
"""

from __future__ import annotations

from enum import IntEnum


class AidSourceKind(IntEnum):
    """The measurements the filter fuses, each with its status row and record
    (:class:`companion.ekf.aid_source.AidSourceStatus`); the value is the row."""

    GNSS_POS = 0
    """GNSS horizontal position (the 2 axes gated as one)."""
    GNSS_HGT = 1
    """GNSS height."""
    GNSS_VEL = 2
    """GNSS velocity (3 axes gated as one)."""
    BARO = 3
    """Barometric height."""
    MAG = 4
    """Magnetometer: the heading (1 axis) or the field's three axes [gauss]."""
    TETHER = 5
    """The winch's tether fix (3 axes gated as one on their Mahalanobis distance)."""
    ZERO_VEL = 6
    """The stationary constraint on the ground (zero velocity, the gear's height; ungated)."""
    CONST_POS = 7
    """Constant-position mode's held position (ungated)."""
    DRAG = 8
    """The drag's specific force: the accelerometer's body x and y against the vehicle's
    drag in the wind states' air and the tether's pull (2 axes gated as one)."""
    TETHER_LINE = 9
    """The winch's raw tether reading (length, tension, exit angles) against the line's
    model in the filter's wind and line states (3 axes gated as one on their Mahalanobis
    distance; tightly coupled, docs/estimation.md §11)."""


N_AID_SOURCES = len(AidSourceKind)

# ----- the nominal state x
#: position p [m] (ENU), velocity v [m/s], attitude q (w, x, y, z; body FLU -> inertial),
#: gyro bias b_g [rad/s], accelerometer bias b_a [m/s^2], baro offset b_h [m],
#: magnetometer bias b_m [gauss], GNSS receiver wander b_p [m], horizontal wind U [m/s]
#: (the velocity the air moves with, east and north), the line's states: its drag and weight
#: per metre as factors on the belief k_c, k_w, the guide arm's azimuth and elevation
#: biases b_psi, b_eps [rad].
X_P, X_V, X_Q, X_BG, X_BA, X_BH, X_BM, X_BP, X_W, X_LINE = (0, 3, 6, 10, 13, 16, 17, 20, 23,
                                                            25)
NX = 29
#: the line's states, in order (offsets from X_LINE and IDX_LINE): k_c first, so that
#: "k_c alone considered" and "all considered" are both one contiguous range
LINE_KC, LINE_KW, LINE_BPSI, LINE_BEPS = 0, 1, 2, 3
N_LINE = 4

# ----- the error state (the covariance's rows)
#: dp, dv, dtheta (a small rotation in the inertial frame), db_g, db_a, db_h, db_m, db_p,
#: dU (the wind's two horizontal axes), the line's states (dk_c, dk_w, db_psi, db_eps).
IDX_P, IDX_V, IDX_TH, IDX_BG, IDX_BA, IDX_BH, IDX_BM, IDX_BP, IDX_W, IDX_LINE = (
    0, 3, 6, 9, 12, 15, 16, 19, 22, 24)
N_ERR = 28

# ----- the ring buffer of past states: one row per IMU step
BUF_T, BUF_P, BUF_V = 0, 1, 4
#: its columns: t [s], p [m] (3), v [m/s] (3)
BUF_COLS = 7

# ----- the parameters the kernels read (the work array's PRM block)
(PRM_GRAV, PRM_GYRO_N, PRM_ACC_N, PRM_BG_W, PRM_BA_W, PRM_BH_W, PRM_DT_MAX, PRM_VAR_MIN,
 PRM_BM_W, PRM_BP_TAU, PRM_BP_VAR_H, PRM_BP_VAR_V, PRM_OUT_TAU, PRM_GNSS_GATE_POS,
 PRM_GNSS_GATE_VEL, PRM_GNSS_R_VEL, PRM_GNSS_FUSE_HGT, PRM_WANDER, PRM_BARO_R,
 PRM_BARO_GATE, PRM_MAG_GATE, PRM_MAG_R_HEADING, PRM_MAG_R_3D, PRM_MAG_TILT,
 PRM_MAG_COUPLE_X, PRM_MAG_COUPLE_Y, PRM_MAG_WITH_BIAS, PRM_EARTH_X, PRM_EARTH_Y,
 PRM_EARTH_Z, PRM_HEADING_EARTH, PRM_TETHER_GATE, PRM_WIND_WALK, PRM_WIND_HGT_SCALE,
 PRM_DRAG_QX, PRM_DRAG_QY, PRM_DRAG_MX, PRM_DRAG_MY, PRM_MASS_INV, PRM_DRAG_R,
 PRM_DRAG_GATE, PRM_LINE_GATE, PRM_LINE_W, PRM_LINE_C, PRM_LINE_EA, PRM_LINE_SHEAR,
 PRM_LINE_STEPS, PRM_ATTACH_X, PRM_ATTACH_Y, PRM_ATTACH_Z, PRM_LINE_SIG_L, PRM_LINE_SIG_T,
 PRM_LINE_SIG_T_FRAC, PRM_LINE_SIG_ANG, PRM_LINE_SIG_MIN, PRM_LINE_SIG_GUST,
 PRM_DRAG_MODEL_FRAC, PRM_DRAG_PULL_FRAC, PRM_DRAG_RESET, PRM_WIND_VAR0, PRM_DRAG_ALL
 ) = range(61)
N_PRM = 61

# ----- one aid source's status row (the AID block: a row per AidSourceKind)
#: innovation (up to 3 axes; measurement - predicted), its variance, the gate's test ratio
#: (innovation^2 / (gate^2 variance), or the Mahalanobis distance^2 / gate^2: 1 at the gate)
AID_INNOV, AID_INNOV_VAR, AID_TEST_RATIO = 0, 3, 6
AID_COLS = 7

# ----- the work array w
W_X = 0
W_DX = W_X + NX
#: the (p, v) of the delayed state a fusion compares with
W_DELAYED = W_DX + N_ERR
#: bias-corrected rates [rad/s] (3), low-passed inertial acceleration [m/s^2] (3) and yaw
#: rate [rad/s] (the prediction's; whether the vehicle manoeuvres)
W_RATES = W_DELAYED + 6
#: what the output still lags the filter by: position [m] (3), velocity [m/s] (3)
W_LAG = W_RATES + 7
#: the magnetometer's latest heading innovation [rad] (either fusion's; reported)
W_HEADING_INNOV = W_LAG + 6
#: the specific force's body x and y [m/s^2] (bias-corrected) summed over the IMU steps
#: since the last drag fusion, and their count (the drag fusion takes their mean)
W_DRAG_SUM = W_HEADING_INNOV + 1
W_PRM = W_DRAG_SUM + 3
W_AID = W_PRM + N_PRM
W_SIZE = W_AID + N_AID_SOURCES * AID_COLS

# ----- what a fusion kernel returns
FUSED, REJECTED, NUMERIC = 1, 0, 8
#: the GNSS kernel's bits: horizontal position, vertical position, velocity accepted
ACC_POS_H, ACC_POS_V, ACC_VEL = 1, 2, 4
