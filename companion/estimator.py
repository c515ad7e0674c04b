"""The onboard navigation filter: an error-state (multiplicative) extended Kalman filter.

What the companion knows of its own position, velocity and attitude from its sensors alone
(the IMU, GNSS, barometer and magnetometer the simulator link delivers), in the manner of
PX4's EKF2 and ArduPilot's EKF3 (docs/estimation.md has the equations):

- nominal state: position ``p`` [m] and velocity ``v`` [m/s] in the inertial frame (z up,
  x east, y north, origin at the winder), attitude ``q`` (body FLU -> inertial, (w, x, y,
  z)), gyro bias ``b_g`` [rad/s], accelerometer bias ``b_a`` [m/s^2], barometer offset
  ``b_h`` [m], magnetometer bias ``b_m`` [gauss] (body FLU), the GNSS receiver's position
  error ``b_p`` [m] (ENU; a Gauss-Markov wander, when its correlation time is set);
- error state (22): ``dp, dv, dtheta, db_g, db_a, db_h, db_m, db_p``; the attitude error is a
  small rotation in the inertial frame, ``R_true = Exp(dtheta) R``;
- predict with each IMU sample (:meth:`NavFilter.predict`); fuse GNSS position and velocity
  against the state at the measurement's time (a ring buffer of past states, the
  correction applied to the current state), barometric height and the magnetometer's
  three axes (or its heading alone), each gated on its normalised innovation;
- health (:class:`FilterHealth`, :class:`HealthReason`), MAVLink's
  ``ESTIMATOR_STATUS_FLAGS`` (:class:`EstimatorFlags`) and ArduPilot's
  ``EKF_STATUS_REPORT`` test ratios in :class:`FilterStatus`.

The arithmetic is compiled (numba kernels on the filter's arrays, through
:func:`tuavdefs.jit.entry_point`); the class is the thin Python wrapper around them.
Everything the filter assumes about its sensors is in :class:`EstimatorParams`: its own
numbers, never the plant's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import numpy as np

from companion.flight_controller import VehicleState
from tuavdefs.frames import Quat, Vec3, euler_to_quat
from tuavdefs.jit import entry_point, njit
from tuavdefs.paramspec import Params, quantity

# ----- layouts of the packed arrays
#: Nominal state x: p 0-2, v 3-5, q 6-9 (w, x, y, z), b_g 10-12, b_a 13-15, b_h 16,
#: b_m 17-19, b_p 20-22.
NX = 23
#: Error state (the covariance's rows): dp 0-2, dv 3-5, dtheta 6-8, db_g 9-11, db_a 12-14,
#: db_h 15, db_m 16-18, db_p 19-21.
N_ERR = 22
IDX_P, IDX_V, IDX_TH, IDX_BG, IDX_BA, IDX_BH, IDX_BM, IDX_BP = 0, 3, 6, 9, 12, 15, 16, 19
_X_Q, _X_BG, _X_BA, _X_BH, _X_BM, _X_BP = 6, 10, 13, 16, 17, 20
#: The ring buffer's columns: t [s], p [m] (3), v [m/s] (3).
_BUF_COLS = 7

# the packed parameter array (prm) of the kernels
(_P_GRAV, _P_GYRO_N, _P_ACC_N, _P_BG_W, _P_BA_W, _P_BH_W, _P_DT_MAX, _P_VAR_MIN, _P_BM_W,
 _P_BP_TAU, _P_BP_VAR_H, _P_BP_VAR_V) = range(12)
_N_PRM = 12

# diagnostics written by the fusion kernels (diag)
(_D_POS_INNOV, _D_VEL_INNOV, _D_POS_TR, _D_VEL_TR, _D_BARO_INNOV, _D_BARO_TR,
 _D_MAG_INNOV, _D_MAG_TR, _D_TETHER_INNOV, _D_TETHER_TR) = (0, 3, 6, 9, 12, 13, 14, 15, 16, 19)
_N_DIAG = 20

#: Time constant of the magnetometer's low-pass for the alignment [s].
_MAG_ALIGN_TAU_S = 0.1
#: Time constant of the low-passed acceleration and yaw rate that say whether the vehicle
#: manoeuvres (the magnetometer's 3-axis fusion) [s].
_MANOEUVRE_TAU_S = 1.0

# the GNSS kernel's result bits
_ACC_POS_H, _ACC_POS_V, _ACC_VEL, _NUMERIC = 1, 2, 4, 8


# ----- parameters
#: What the vehicle may fly on (EstimatorParams.kind).
ESTIMATOR_KINDS = ("ekf", "truth")
#: How the magnetometer is fused (EstimatorParams.mag_fusion): its three axes against the
#: Earth field with a bias state per axis (EKF2's 3-axis fusion, EKF3's MAG_CAL), or its
#: heading alone.
MAG_FUSIONS = ("3d", "heading")


@dataclass(frozen=True)
class EstimatorParams(Params):
    """The navigation filter's own model of its sensors, its gates and its health checks
    (docs/estimation.md). Noise densities are of continuous white noise; random walks are
    the rate at which a bias wanders."""

    kind: str = quantity(
        "ekf", "", "what the vehicle flies on: ekf (this filter, on the sensors) or truth "
        "(the simulator's state as HIL_STATE_QUATERNION sends it: for comparison, and the "
        "paper's experiments, which feed the state back; ArduPilot's AHRS_EKF_TYPE 10)",
        choices=ESTIMATOR_KINDS)
    earth_field_ned_gauss: tuple[float, ...] = quantity(
        (0.2, 0.0, 0.45), "gauss", "the Earth's magnetic field at home (north, east, down), "
        "as a world magnetic model gives it", length=3)
    accel_offsets_m_s2: tuple[float, ...] = quantity(
        (0.0, 0.0, 0.0), "m/s^2", "the accelerometer's offsets (body FLU) its calibration "
        "found, taken off every reading (ArduPilot's INS_ACCOFFS_X/Y/Z)", length=3)
    imu_rate_hz: float = quantity(
        250.0, "Hz", "nominal IMU rate: sizes the delay buffer; a gap longer than 5 "
        "periods is integrated as 5 periods", gt=0, le=2000)
    gyro_noise_rad_s_sqrt_hz: float = quantity(
        3.0e-4, "rad/s/sqrt(Hz)", "gyro white-noise density (angle random walk)", gt=0)
    accel_noise_m_s2_sqrt_hz: float = quantity(
        4.0e-3, "m/s^2/sqrt(Hz)", "accelerometer white-noise density (velocity random "
        "walk)", gt=0)
    gyro_bias_walk_rad_s_sqrt_s: float = quantity(
        1.5e-4, "rad/s/sqrt(s)", "gyro bias random walk", ge=0)
    accel_bias_walk_m_s2_sqrt_s: float = quantity(
        3.0e-3, "m/s^2/sqrt(s)", "accelerometer bias random walk", ge=0)
    baro_offset_walk_m_sqrt_s: float = quantity(
        0.07, "m/sqrt(s)", "random walk of the barometer's height offset (an MS5611-class "
        "sensor's in-flight thermal and airflow drift, ~0.1 hPa = 0.8 m over ~300 s: "
        "0.8 sqrt(2/300); docs/estimation.md §10)", ge=0)
    gyro_bias_sigma_rad_s: float = quantity(
        0.01, "rad/s", "prior standard deviation of each gyro bias", gt=0)
    accel_bias_sigma_m_s2: float = quantity(
        0.15, "m/s^2", "prior standard deviation of each accelerometer bias", gt=0)
    baro_offset_sigma_m: float = quantity(
        0.5, "m", "prior standard deviation of the barometer's height offset (beyond the "
        "GNSS height's own accuracy)", gt=0)
    tilt_sigma_rad: float = quantity(
        0.02, "rad", "prior standard deviation of roll and pitch after alignment", gt=0)
    yaw_sigma_rad: float = quantity(
        0.15, "rad", "prior standard deviation of yaw after alignment", gt=0)
    align_time_s: float = quantity(
        1.0, "s", "how long accelerometer and magnetometer are averaged for the static "
        "alignment", gt=0, le=60)
    air_align_time_s: float = quantity(
        0.2, "s", "the alignment's averaging when the first GNSS fix finds the vehicle in "
        "the air (a simulation started in hover): it hovers open loop meanwhile", gt=0,
        le=60)
    gyro_calibration_at_rest: bool = quantity(
        True, "", "the gyro biases set at a still alignment on the ground to the mean rate "
        "read meanwhile (ArduPilot's INS_GYR_CAL 1, a gyro calibration at start-up; the "
        "filter then holds them to within the mean's noise); false: they start at 0 with "
        "gyro_bias_sigma_rad_s")
    align_max_accel_std_m_s2: float = quantity(
        1.0, "m/s^2", "alignment restarts while the specific force varies more than this "
        "(standard deviation of its magnitude): the vehicle is not still enough", gt=0)
    gnss_delay_s: float = quantity(
        0.1, "s", "age of a GNSS fix when it arrives: it is compared with the state that "
        "long ago", ge=0, le=0.5)
    output_tau_s: float = quantity(
        0.25, "s", "time constant over which the position and velocity the vehicle flies on "
        "take up each fusion's correction (EKF2's output predictor, EKF2_TAU_POS/VEL): the "
        "controllers see no step at each GNSS fix (0: at once)", ge=0)
    gnss_delay_uncertainty_s: float = quantity(
        0.05, "s", "how well gnss_delay_s is known: the fix's position noise grows by the "
        "speed times this", ge=0, le=0.5)
    gnss_pos_tau_s: float = quantity(
        0.0, "s", "correlation time of the receiver's position error (0: white, each fix "
        "independent, as EKF2 and EKF3 take it); above 0 the error is a Gauss-Markov state "
        "per axis, the fix's claimed accuracy its standard deviation, so that a slowly "
        "wandering receiver does not shrink the covariance below the error", ge=0, le=600)
    gnss_pos_correlated_fraction: float = quantity(
        0.9, "1", "with gnss_pos_tau_s > 0: the share of the claimed position variance that "
        "is the wander (the rest is white)", gt=0, lt=1)
    gnss_vel_noise_m_s: float = quantity(
        0.1, "m/s", "GNSS velocity noise (per axis; HIL_GPS carries no speed accuracy)",
        gt=0)
    gnss_pos_noise_min_m: float = quantity(
        0.01, "m", "floor on the GNSS position noise taken from the fix's eph/epv", gt=0)
    gnss_max_eph_m: float = quantity(
        5.0, "m", "fixes claiming a horizontal accuracy worse than this are not used", gt=0)
    gnss_fuse_height: bool = quantity(
        True, "", "fuse the GNSS height as well as the barometer's (the baro offset then "
        "follows it)")
    gnss_pos_gate_sigma: float = quantity(
        5.0, "1", "GNSS position innovation gate [standard deviations]", gt=0)
    gnss_vel_gate_sigma: float = quantity(
        5.0, "1", "GNSS velocity innovation gate [standard deviations]", gt=0)
    baro_noise_m: float = quantity(
        0.15, "m", "barometric height noise", gt=0)
    baro_delay_s: float = quantity(
        0.0, "s", "age of a barometer sample when it arrives", ge=0, le=0.5)
    baro_gate_sigma: float = quantity(
        5.0, "1", "barometric height innovation gate [standard deviations]", gt=0)
    mag_yaw_noise_rad: float = quantity(
        0.05, "rad", "magnetic heading noise", gt=0)
    mag_gate_sigma: float = quantity(
        3.0, "1", "magnetic heading innovation gate [standard deviations]", gt=0)
    mag_fusion: str = quantity(
        "3d", "", "3d: the field's three axes, with the magnetometer's bias (the vehicle's "
        "hard iron left after calibration) estimated; heading: the heading alone (the bias "
        "is then not estimated: it passes into the yaw)", choices=MAG_FUSIONS)
    mag_noise_gauss: float = quantity(
        0.01, "gauss", "3-axis fusion: noise of each axis (the sensor's noise, the field "
        "model's error and soft iron; EKF2's MAG_NOISE)", gt=0)
    mag_bias_sigma_gauss: float = quantity(
        0.01, "gauss", "3-axis fusion: prior standard deviation of each magnetometer bias",
        gt=0)
    mag_bias_walk_gauss_sqrt_s: float = quantity(
        1.0e-5, "gauss/sqrt(s)", "3-axis fusion: random walk of the magnetometer biases",
        ge=0)
    mag_3d_accel_m_s2: float = quantity(
        0.2, "m/s^2", "3-axis fusion only while the horizontal acceleration (low-passed "
        "over 1 s) reaches this, or the yaw rate mag_3d_yaw_rate_rad_s (EKF2's "
        "MAG_ACCLIM, MAG_YAWLIM): else the heading alone", gt=0)
    mag_3d_yaw_rate_rad_s: float = quantity(
        0.25, "rad/s", "3-axis fusion while the yaw rate (low-passed over 1 s) reaches this",
        gt=0)
    mag_3d_hold_s: float = quantity(
        5.0, "s", "3-axis fusion goes on this long after the last manoeuvre", ge=0)
    mag_yaw_only: bool = quantity(
        False, "", "heading fusion: the heading's Jacobian on yaw alone (EKF2's heading "
        "fusion: the magnetometer never corrects roll and pitch); False: its exact Jacobian, which "
        "includes the tilt error's effect on the heading through the field's inclination")
    baro_min_interval_s: float = quantity(
        0.02, "s", "barometer samples closer than this to the last fused one are skipped "
        "(the part's own output rate: an MS5611 gives about 50 Hz at full resolution)", ge=0)
    mag_min_interval_s: float = quantity(
        0.02, "s", "magnetometer samples closer than this to the last fused one are "
        "skipped", ge=0)
    gnss_timeout_s: float = quantity(
        1.0, "s", "no GNSS fused for this long: position and velocity flags drop, the "
        "filter reports no GNSS", gt=0)
    innovation_fail_s: float = quantity(
        2.0, "s", "an innovation test failing for this long makes the filter unhealthy",
        gt=0)
    gnss_reset_s: float = quantity(
        5.0, "s", "GNSS position rejected for this long (fixes still arriving): position "
        "and velocity are reset to the GNSS", gt=0)
    const_pos_after_s: float = quantity(
        10.0, "s", "no GNSS position for this long: constant-position mode (the held "
        "position fused with a large noise, to keep the attitude)", gt=0)
    const_pos_noise_m: float = quantity(
        10.0, "m", "noise of the held position in constant-position mode", gt=0)
    pos_variance_limit_m2: float = quantity(
        1.0e4, "m^2", "a position variance above this counts as a covariance blow-up",
        gt=0)
    converged_tilt_sigma_rad: float = quantity(
        0.02, "rad", "healthy needs roll and pitch standard deviations below this", gt=0)
    converged_yaw_sigma_rad: float = quantity(
        0.1, "rad", "healthy needs a yaw standard deviation below this", gt=0)
    tether_aid: bool = quantity(
        True, "", "fuse the winch's tether fix (ODOMETRY from the ground station) as a "
        "position source beside the GNSS (ArduPilot's ExternalNav, EK3_SRC1_POSXY 6)")
    tether_noise_min_m: float = quantity(
        0.05, "m", "floor on each axis's standard deviation of a tether fix (added to its "
        "covariance)", gt=0)
    tether_gate_sigma: float = quantity(
        5.0, "1", "tether fix gate: its innovation's Mahalanobis distance [standard "
        "deviations]", gt=0)
    tether_max_delay_s: float = quantity(
        0.3, "s", "tether fixes older than this on arrival are not used (the delay buffer "
        "covers it)", gt=0, le=1.0)
    tether_timeout_s: float = quantity(
        1.0, "s", "no tether fix fused for this long: it no longer counts as a position "
        "source", gt=0)
    tether_reset_s: float = quantity(
        5.0, "s", "tether fixes rejected for this long without GNSS: the position is reset "
        "to the fix", gt=0)
    stationary_vel_noise_m_s: float = quantity(
        0.05, "m/s", "on the ground and disarmed (at rest on its gear): a zero velocity is "
        "fused with this noise on each axis (the stationary constraint EKF2 and EKF3 use on "
        "the ground without GNSS: the estimate does not drift)", gt=0)
    stationary_interval_s: float = quantity(
        0.1, "s", "the stationary constraint's interval", gt=0)
    arming_settle_s: float = quantity(
        2.0, "s", "arming is refused (PreArm: EKF settling) until the filter has been "
        "aligned this long: on the ground its first second takes in the gear's height and "
        "the tether's fix, which correct a consumer receiver's first fix by a metre (armed "
        "at once, such a vehicle took off from the wrong place and pulled a 2 m line "
        "taut); ArduPilot's EKF waits for 10 s of good GNSS", ge=0)
    ground_height_noise_m: float = quantity(
        0.05, "m", "on the ground and disarmed: the height the gear puts the vehicle at (the "
        "ground flat and level with the winder's, as the navigator's land detector takes "
        "it) is fused with the zero velocity, with this noise (0: not fused). A consumer "
        "receiver's height is metres off: without it a vehicle on the ground took itself "
        "to be 1.2 m up", ge=0)
    tether_align_vel_sigma_m_s: float = quantity(
        0.5, "m/s", "velocity standard deviation when the filter aligns on a tether fix "
        "(no GNSS velocity): the vehicle is taken to be near rest", gt=0)


# ----- health and status
class FilterHealth(IntEnum):
    """What the filter's estimate is good for."""

    INITIALISING = 0
    """Not aligned yet: averaging for the static alignment, or waiting for a GNSS fix."""
    ALIGNED = 1
    """Initialised, no failure, but not converged yet (attitude uncertainty above the
    thresholds, or no GNSS fused yet)."""
    HEALTHY = 2
    """Converged and fusing GNSS."""
    UNHEALTHY = 3
    """Something failed: see :class:`HealthReason`."""


class HealthReason(IntFlag):
    """Why the filter is unhealthy (several can hold)."""

    NONE = 0
    NO_GNSS = 1
    """No GNSS position or velocity fused for ``gnss_timeout_s``."""
    GNSS_REJECTED = 2
    """The GNSS innovation test has failed for ``innovation_fail_s``."""
    BARO_REJECTED = 4
    """The barometer's innovation test has failed for ``innovation_fail_s``."""
    MAG_REJECTED = 8
    """The magnetic heading's innovation test has failed for ``innovation_fail_s``."""
    COVARIANCE = 16
    """A variance is negative or above ``pos_variance_limit_m2``."""
    NAN = 32
    """The state or the covariance is not finite (the filter must be reset)."""
    TETHER_REJECTED = 64
    """Without GNSS, the tether fix's innovation test has failed for
    ``innovation_fail_s``."""


class EstimatorFlags(IntFlag):
    """MAVLink's ``ESTIMATOR_STATUS_FLAGS`` (the same bit values)."""

    ATTITUDE = 1
    VELOCITY_HORIZ = 2
    VELOCITY_VERT = 4
    POS_HORIZ_REL = 8
    POS_HORIZ_ABS = 16
    POS_VERT_ABS = 32
    POS_VERT_AGL = 64
    CONST_POS_MODE = 128
    PRED_POS_HORIZ_REL = 256
    PRED_POS_HORIZ_ABS = 512
    GPS_GLITCH = 1024
    ACCEL_ERROR = 2048


class AidSource(IntFlag):
    """The measurements the filter fuses (within their timeouts)."""

    NONE = 0
    GNSS = 1
    """GNSS position."""
    TETHER = 2
    """The winch's tether fix."""
    BARO = 4
    MAG = 8


@dataclass(frozen=True)
class FilterStatus:
    """The filter's health, flags and checks at one time.

    The ``*_variance`` fields are what ArduPilot puts in ``EKF_STATUS_REPORT``: the square
    root of the latest test ratio of each measurement, |innovation| / (gate x its standard
    deviation), so 1.0 is at the gate and above 1 the measurement was rejected.
    """

    health: FilterHealth
    reasons: HealthReason
    flags: EstimatorFlags
    velocity_variance: float
    pos_horiz_variance: float
    pos_vert_variance: float
    compass_variance: float
    terrain_alt_variance: float
    pos_innovation_m: Vec3
    """Latest GNSS position innovation (measurement - delayed state) [m]."""
    vel_innovation_m_s: Vec3
    """Latest GNSS velocity innovation [m/s]."""
    baro_innovation_m: float
    mag_innovation_rad: float
    pos_sigma_m: Vec3
    """Standard deviations of the position estimate [m] (east, north, up)."""
    vel_sigma_m_s: Vec3
    attitude_sigma_rad: Vec3
    """Standard deviations of the attitude error about the inertial axes [rad]."""
    time_since_gnss_s: float
    """Since the last GNSS position fused [s] (inf: never)."""
    sources: AidSource = AidSource.NONE
    """What is fused now."""
    tether_variance: float = 0.0
    """sqrt of the latest tether fix's test ratio (1.0 at its gate)."""
    tether_innovation_m: Vec3 = (0.0, 0.0, 0.0)
    """Latest tether fix innovation (fix - delayed state) [m]."""

    @property
    def healthy(self) -> bool:
        """Whether the estimate is fit to fly on."""
        return self.health == FilterHealth.HEALTHY


# ----- kernels
@njit
def _rot(qw: float, qx: float, qy: float, qz: float) -> tuple[float, ...]:
    """The rotation matrix of a unit quaternion, row-major (9 floats)."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz),
            2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz),
            2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx),
            1.0 - 2.0 * (qx * qx + qy * qy))


@njit
def _exp_rotvec(rx: float, ry: float, rz: float) -> tuple[float, float, float, float]:
    """The unit quaternion ``Exp(r)`` of a rotation vector ``r`` [rad]."""
    a = math.sqrt(rx * rx + ry * ry + rz * rz)
    if a < 1e-9:
        c, s = 1.0, 0.5
    else:
        c, s = math.cos(0.5 * a), math.sin(0.5 * a) / a
    return c, s * rx, s * ry, s * rz


@njit
def _qmul_unit(aw: float, ax: float, ay: float, az: float, bw: float, bx: float,
               by: float, bz: float) -> tuple[float, float, float, float, float]:
    """The product ``a * b`` and the inverse of its norm."""
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    return w, x, y, z, 1.0 / math.sqrt(w * w + x * x + y * y + z * z)


@njit
def _qmul_exp(qw: float, qx: float, qy: float, qz: float, rx: float, ry: float,
              rz: float) -> tuple[float, float, float, float]:
    """``q * Exp(r)`` for a rotation vector ``r`` [rad] (right: in the body frame),
    normalised."""
    ew, ex, ey, ez = _exp_rotvec(rx, ry, rz)
    w, x, y, z, n = _qmul_unit(qw, qx, qy, qz, ew, ex, ey, ez)
    return w * n, x * n, y * n, z * n


@njit
def _expq_mul(rx: float, ry: float, rz: float, qw: float, qx: float, qy: float,
              qz: float) -> tuple[float, float, float, float]:
    """``Exp(r) * q`` for a rotation vector ``r`` [rad] (left: in the inertial frame),
    normalised, its scalar part kept non-negative."""
    ew, ex, ey, ez = _exp_rotvec(rx, ry, rz)
    w, x, y, z, n = _qmul_unit(ew, ex, ey, ez, qw, qx, qy, qz)
    if w < 0.0:
        n = -n
    return w * n, x * n, y * n, z * n


@njit
def predict_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                   prm: np.ndarray, rates: np.ndarray, t_s: float, dt_s: float,
                   gx: float, gy: float, gz: float, ax: float, ay: float, az: float
                   ) -> None:
    """One IMU step of ``dt_s`` [s] ending at ``t_s`` [s]: the nominal state ``x``
    integrated with the rates ``g*`` [rad/s] and specific force ``a*`` [m/s^2] (body FLU),
    the covariance ``P`` propagated (``F P F' + Q``), the state stored in the ring buffer
    ``buf`` (``meta`` = next slot, entries); ``rates`` [0:3] = the bias-corrected rates,
    [3:6] = the inertial acceleration and [6] the yaw rate [rad/s], low-passed over
    ``_MANOEUVRE_TAU_S`` (whether the vehicle manoeuvres)."""
    g = prm[_P_GRAV]
    # bias-corrected measurements
    wx, wy, wz = gx - x[10], gy - x[11], gz - x[12]
    fx, fy, fz = ax - x[13], ay - x[14], az - x[15]
    rates[0], rates[1], rates[2] = wx, wy, wz
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    # the specific force rotated with the attitude at mid-step
    mw, mx, my, mz = _qmul_exp(qw, qx, qy, qz, 0.5 * wx * dt_s, 0.5 * wy * dt_s,
                               0.5 * wz * dt_s)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rot(mw, mx, my, mz)
    aix = r00 * fx + r01 * fy + r02 * fz
    aiy = r10 * fx + r11 * fy + r12 * fz
    aiz = r20 * fx + r21 * fy + r22 * fz - g
    lp = dt_s / (_MANOEUVRE_TAU_S + dt_s)
    rates[3] += lp * (aix - rates[3])
    rates[4] += lp * (aiy - rates[4])
    rates[5] += lp * (aiz - rates[5])
    rates[6] += lp * (r20 * wx + r21 * wy + r22 * wz - rates[6])
    for i, a in enumerate((aix, aiy, aiz)):
        x[i] += (x[3 + i] + 0.5 * a * dt_s) * dt_s
        x[3 + i] += a * dt_s
    nw, nx, ny, nz = _qmul_exp(qw, qx, qy, qz, wx * dt_s, wy * dt_s, wz * dt_s)
    x[6], x[7], x[8], x[9] = nw, nx, ny, nz
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
            P[i, j] += dt_s * P[3 + i, j]
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc += A[i][k] * P[6 + k, j] - R[i][k] * dt_s * P[12 + k, j]
            P[3 + i, j] += acc
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc -= R[i][k] * dt_s * P[9 + k, j]
            P[6 + i, j] += acc
    # (F P) F' (columns)
    for j in range(n):
        for i in range(3):
            P[j, i] += dt_s * P[j, 3 + i]
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc += A[i][k] * P[j, 6 + k] - R[i][k] * dt_s * P[j, 12 + k]
            P[j, 3 + i] += acc
        for i in range(3):
            acc = 0.0
            for k in range(3):
                acc -= R[i][k] * dt_s * P[j, 9 + k]
            P[j, 6 + i] += acc
    # Q: white noise of the accelerometer (on dv) and gyro (on dtheta), bias random walks
    qv = prm[_P_ACC_N] ** 2 * dt_s
    qt = prm[_P_GYRO_N] ** 2 * dt_s
    qbg = prm[_P_BG_W] ** 2 * dt_s
    qba = prm[_P_BA_W] ** 2 * dt_s
    for i in range(3):
        P[i, i] += qv * dt_s * dt_s / 3.0
        P[i, 3 + i] += 0.5 * qv * dt_s
        P[3 + i, i] += 0.5 * qv * dt_s
        P[3 + i, 3 + i] += qv
        P[6 + i, 6 + i] += qt
        P[9 + i, 9 + i] += qbg
        P[12 + i, 12 + i] += qba
    P[15, 15] += prm[_P_BH_W] ** 2 * dt_s
    qbm = prm[_P_BM_W] ** 2 * dt_s
    for i in range(3):
        P[16 + i, 16 + i] += qbm
    # the receiver's wander: b_p <- exp(-dt/tau) b_p, its stationary variance kept
    tau = prm[_P_BP_TAU]
    if tau > 0.0:
        phi = math.exp(-dt_s / tau)
        for i in range(3):
            x[20 + i] *= phi
            for j in range(n):
                P[19 + i, j] *= phi
            for j in range(n):
                P[j, 19 + i] *= phi
            var = prm[_P_BP_VAR_H] if i < 2 else prm[_P_BP_VAR_V]
            P[19 + i, 19 + i] += var * (1.0 - phi * phi)
    _symmetrise(P)
    # the ring buffer of (t, p, v)
    k = meta[0]
    buf[k, 0] = t_s
    for i in range(6):
        buf[k, 1 + i] = x[i]
    meta[0] = (k + 1) % buf.shape[0]
    if meta[1] < buf.shape[0]:
        meta[1] += 1


@njit
def predict_output_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                          prm: np.ndarray, rates: np.ndarray, lag: np.ndarray,
                          tau_s: float, t_s: float, dt_s: float, gx: float, gy: float,
                          gz: float, ax: float, ay: float, az: float) -> None:
    """:func:`predict_kernel`, then the output's lag behind the filter (``lag``: position
    [m], velocity [m/s]) decayed over ``dt_s`` at the time constant ``tau_s`` [s]."""
    predict_kernel(x, P, buf, meta, prm, rates, t_s, dt_s, gx, gy, gz, ax, ay, az)
    if tau_s > 0.0:
        decay = math.exp(-dt_s / tau_s)
        for i in range(6):
            lag[i] *= decay


@njit
def _symmetrise(P: np.ndarray) -> None:
    """``P = (P + P') / 2`` in place."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            m = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = m
            P[j, i] = m


@njit
def _delayed(buf: np.ndarray, meta: np.ndarray, x: np.ndarray, t_s: float,
             out: np.ndarray) -> None:
    """``out`` = (p, v) at time ``t_s`` [s]: interpolated in the ring buffer, the oldest
    entry if older, the current state if newer than the newest (or the buffer empty)."""
    n, count, size = meta[0], meta[1], buf.shape[0]
    newest = (n - 1) % size
    if count == 0 or t_s >= buf[newest, 0]:
        for i in range(6):
            out[i] = x[i]
        return
    later = newest
    for m in range(1, count):
        k = (newest - m) % size
        if buf[k, 0] <= t_s:
            t0, t1 = buf[k, 0], buf[later, 0]
            w = (t_s - t0) / (t1 - t0) if t1 > t0 else 1.0
            for i in range(6):
                out[i] = buf[k, 1 + i] + w * (buf[later, 1 + i] - buf[k, 1 + i])
            return
        later = k
    for i in range(6):       # older than the buffer: its oldest entry
        out[i] = buf[later, 1 + i]


@njit
def scalar_update(P: np.ndarray, dx: np.ndarray, var_min: float, y: float, r: float,
                  i0: int, h0: float, i1: int, h1: float, i2: int, h2: float,
                  i3: int = -1, h3: float = 0.0) -> bool:
    """One scalar measurement with up to four non-zero Jacobian entries ``h`` at error
    indices ``i`` (-1: unused), innovation ``y`` (against the state before this batch's
    corrections ``dx``, which it accumulates into) and noise variance ``r``. Updates ``P``
    (symmetric by construction; refused if a variance it changes would fall below
    ``var_min``). Returns whether it was applied."""
    n = P.shape[0]
    pht = np.zeros(n)
    yy = y
    for i, h in ((i0, h0), (i1, h1), (i2, h2), (i3, h3)):
        if i >= 0:
            yy -= h * dx[i]
            for k in range(n):
                pht[k] += P[k, i] * h
    s = r
    for i, h in ((i0, h0), (i1, h1), (i2, h2), (i3, h3)):
        if i >= 0:
            s += h * pht[i]
    if not (s > 0.0) or not math.isfinite(s):
        return False
    inv = 1.0 / s
    for k in range(n):
        if pht[k] != 0.0 and P[k, k] - pht[k] * pht[k] * inv < var_min:
            return False
    for k in range(n):
        dx[k] += pht[k] * inv * yy
    for a in range(n):
        ka = pht[a] * inv
        for b in range(n):
            P[a, b] -= ka * pht[b]
    return True


@njit
def row_update(P: np.ndarray, dx: np.ndarray, var_min: float, y: float, r: float,
               h: np.ndarray, c0: int, c1: int) -> bool:
    """:func:`scalar_update` with a dense Jacobian row ``h``; the error states ``c0`` to
    ``c1 - 1`` are *considered*, not estimated (Schmidt's update: their gain is zero, their
    uncertainty still enters the innovation's variance and their correlations are kept
    right)."""
    n = P.shape[0]
    pht = P @ h
    yy = y - float(h @ dx)
    s = float(h @ pht) + r
    if not (s > 0.0) or not math.isfinite(s):
        return False
    inv = 1.0 / s
    for k in range(n):
        if (pht[k] != 0.0 and not c0 <= k < c1
                and P[k, k] - pht[k] * pht[k] * inv < var_min):
            return False
    for k in range(n):
        if not c0 <= k < c1:
            dx[k] += pht[k] * inv * yy
    for a in range(n):
        ka = pht[a] * inv
        ca = c0 <= a < c1
        for b in range(n):
            if not (ca and c0 <= b < c1):
                P[a, b] -= ka * pht[b]
    return True


@njit
def inject(x: np.ndarray, dx: np.ndarray, buf: np.ndarray, meta: np.ndarray) -> None:
    """Add the error-state correction ``dx`` to the nominal state (the attitude as
    ``q <- Exp(dtheta) q``), and its position and velocity to the buffered past states;
    ``dx`` is zeroed. The covariance's reset Jacobian is taken as the identity."""
    for i in range(6):
        x[i] += dx[i]
    x[6], x[7], x[8], x[9] = _expq_mul(dx[6], dx[7], dx[8], x[6], x[7], x[8], x[9])
    for i in range(3):
        x[10 + i] += dx[9 + i]
        x[13 + i] += dx[12 + i]
    x[16] += dx[15]
    for i in range(3):
        x[17 + i] += dx[16 + i]
        x[20 + i] += dx[19 + i]
    for m in range(meta[1]):
        for i in range(6):
            buf[m, 1 + i] += dx[i]
    for i in range(dx.shape[0]):
        dx[i] = 0.0


@njit
def fuse_gnss_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                     dx: np.ndarray, diag: np.ndarray, delayed: np.ndarray, var_min: float,
                     t_meas_s: float, px: float, py: float, pz: float, vx: float,
                     vy: float, vz: float, r_h: float, r_v: float, r_vel: float,
                     gate_pos: float, gate_vel: float, fuse_height: bool,
                     wander: bool) -> int:
    """A GNSS fix of the time ``t_meas_s`` [s]: position ``p*`` [m] and velocity ``v*``
    [m/s] (ENU), noise variances ``r_h``, ``r_v`` [m^2] and ``r_vel`` [m^2/s^2]; with
    ``wander`` the position is ``p + b_p`` (the receiver's Gauss-Markov error state). The
    innovations are taken against the state at ``t_meas_s`` (``delayed``), gated (the
    test ratios into ``diag``), the accepted axes fused one by one, the correction injected
    into the current state. Returns the accepted groups as bits (1 horizontal position, 2
    vertical position, 4 velocity, 8 numerical refusal)."""
    _delayed(buf, meta, x, t_meas_s, delayed)
    z = (px, py, pz, vx, vy, vz)
    rr = (r_h, r_h, r_v, r_vel, r_vel, r_vel)
    gates = (gate_pos, gate_pos, gate_pos, gate_vel, gate_vel, gate_vel)
    tr = np.zeros(6)
    for i in range(6):
        y = z[i] - delayed[i]
        s = P[i, i] + rr[i]
        if wander and i < 3:
            y -= x[20 + i]
            s += 2.0 * P[i, 19 + i] + P[19 + i, 19 + i]
        diag[i] = y
        tr[i] = y * y / (s * gates[i] * gates[i])
    diag[_D_POS_TR] = max(tr[0], tr[1])
    diag[_D_POS_TR + 1] = tr[2]
    diag[_D_VEL_TR] = max(tr[3], max(tr[4], tr[5]))
    result = 0
    ok = np.zeros(6, dtype=np.bool_)
    if diag[_D_POS_TR] <= 1.0:
        ok[0] = ok[1] = True
        result |= _ACC_POS_H
    if tr[2] <= 1.0 and fuse_height:
        ok[2] = True
        result |= _ACC_POS_V
    if diag[_D_VEL_TR] <= 1.0:
        ok[3] = ok[4] = ok[5] = True
        result |= _ACC_VEL
    for i in range(6):
        ib = 19 + i if wander and i < 3 else -1
        if ok[i] and not scalar_update(P, dx, var_min, diag[i], rr[i], i, 1.0, ib, 1.0,
                                       -1, 0.0):
            result |= _NUMERIC
    inject(x, dx, buf, meta)
    return result


@njit
def fuse_baro_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                     dx: np.ndarray, diag: np.ndarray, delayed: np.ndarray, var_min: float,
                     t_meas_s: float, height_m: float, r: float, gate: float) -> int:
    """A barometric height ``height_m`` [m] (above the reference taken at alignment) of
    the time ``t_meas_s`` [s]: ``h = p_z + b_h``, noise variance ``r`` [m^2]. Returns 1
    if fused, 0 if rejected by the gate, 8 if refused numerically."""
    _delayed(buf, meta, x, t_meas_s, delayed)
    y = height_m - (delayed[2] + x[16])
    s = P[2, 2] + 2.0 * P[2, 15] + P[15, 15] + r
    diag[_D_BARO_INNOV] = y
    diag[_D_BARO_TR] = y * y / (s * gate * gate)
    if diag[_D_BARO_TR] > 1.0:
        return 0
    if not scalar_update(P, dx, var_min, y, r, 2, 1.0, 15, 1.0, -1, 0.0):
        return _NUMERIC
    inject(x, dx, buf, meta)
    return 1


@njit
def fuse_mag_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                    dx: np.ndarray, diag: np.ndarray, var_min: float, mx: float, my: float,
                    mz: float, heading_earth_rad: float, r: float, gate: float,
                    tilt: bool, couple_x: float, couple_y: float, with_bias: bool) -> int:
    """A magnetometer sample ``m*`` [gauss] (body FLU) as a heading: the field rotated
    into the inertial frame with the estimated attitude, the innovation the Earth field's
    heading ``heading_earth_rad`` [rad] minus its heading (the yaw error, the tilt
    taken from the estimate); noise variance ``r`` [rad^2]. Its Jacobian: that of the
    yaw, and with ``tilt`` also the heading's dependence on the tilt error through the
    field's inclination (``couple_*`` = E_z E_x / |E_h|^2, E_z E_y / |E_h|^2).
    Returns 1 if fused, 0 if rejected by the gate, 8 if refused (numerically, or no
    horizontal field). The bias estimate ``b_m`` is taken off the sample first; with
    ``with_bias`` the Jacobian has the heading's dependence on the bias error too, the
    bias considered, not estimated (the 3-axis mode's still phases, where a heading cannot
    tell the bias from the yaw: the yaw's variance stays honest, the bias waits for a
    manoeuvre)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rot(x[6], x[7], x[8], x[9])
    mx, my, mz = mx - x[17], my - x[18], mz - x[19]
    ex = r00 * mx + r01 * my + r02 * mz
    ey = r10 * mx + r11 * my + r12 * mz
    if ex * ex + ey * ey < 1e-12:
        return _NUMERIC
    y = heading_earth_rad - math.atan2(ey, ex)
    y = (y + math.pi) % (2.0 * math.pi) - math.pi
    # yaw = atan2(R10, R00); d yaw / d dtheta for R <- (I + [dtheta]x) R
    d = r00 * r00 + r10 * r10
    if d < 1e-9:
        return _NUMERIC
    h0, h1 = -r20 * r00 / d, -r20 * r10 / d
    if tilt:
        # the heading of the field rotated with the estimate depends on its tilt error
        # too, through the field's inclination
        h0, h1 = -couple_x, -couple_y
    n = P.shape[0]
    h = np.zeros(n)
    h[6], h[7], h[8] = h0, h1, 1.0
    if with_bias:
        # the heading of R (m - b_m - db_m): d/d db_m = (e_y R_0j - e_x R_1j) / |e_h|^2
        eh2 = ex * ex + ey * ey
        for j, (a0, a1) in enumerate(((r00, r10), (r01, r11), (r02, r12))):
            h[16 + j] = (ey * a0 - ex * a1) / eh2
    ph = P @ h
    s = float(h @ ph) + r
    diag[_D_MAG_INNOV] = y
    diag[_D_MAG_TR] = y * y / (s * gate * gate)
    if diag[_D_MAG_TR] > 1.0:
        return 0
    c0, c1 = (16, 19) if with_bias else (0, 0)
    if not row_update(P, dx, var_min, y, r, h, c0, c1):
        return _NUMERIC
    inject(x, dx, buf, meta)
    return 1


@njit
def fuse_mag3d_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                      dx: np.ndarray, diag: np.ndarray, var_min: float, mx: float,
                      my: float, mz: float, ex: float, ey: float, ez: float,
                      heading_earth_rad: float, r: float, gate: float) -> int:
    """A magnetometer sample ``m*`` [gauss] (body FLU) fused on its three axes: the model
    ``m = R' E + b_m`` with the Earth field ``E = e*`` [gauss] (inertial), Jacobians
    ``R' [E]x`` on the attitude error and the identity on the bias, noise variance ``r``
    [gauss^2] per axis. Gated as one: any axis's test ratio above 1 rejects the sample.
    The diagnostics carry the heading innovation of the bias-corrected sample and the
    largest test ratio. Returns 1 if fused, 0 if rejected, 8 if refused numerically."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rot(x[6], x[7], x[8], x[9])
    cols = ((r00, r10, r20), (r01, r11, r21), (r02, r12, r22))   # rows of R'
    m = (mx, my, mz)
    y = np.zeros(3)
    h = np.zeros((3, 3))
    worst = 0.0
    for k in range(3):
        a0, a1, a2 = cols[k]
        y[k] = m[k] - (a0 * ex + a1 * ey + a2 * ez + x[17 + k])
        h0, h1, h2 = a1 * ez - a2 * ey, a2 * ex - a0 * ez, a0 * ey - a1 * ex
        h[k, 0], h[k, 1], h[k, 2] = h0, h1, h2
        b = 16 + k
        s = (h0 * h0 * P[6, 6] + h1 * h1 * P[7, 7] + h2 * h2 * P[8, 8]
             + 2.0 * (h0 * h1 * P[6, 7] + h0 * h2 * P[6, 8] + h1 * h2 * P[7, 8])
             + 2.0 * (h0 * P[6, b] + h1 * P[7, b] + h2 * P[8, b]) + P[b, b] + r)
        worst = max(worst, y[k] * y[k] / (s * gate * gate))
    # the heading innovation, for the status
    cx, cy, cz = mx - x[17], my - x[18], mz - x[19]
    hx = r00 * cx + r01 * cy + r02 * cz
    hy = r10 * cx + r11 * cy + r12 * cz
    yh = heading_earth_rad - math.atan2(hy, hx)
    diag[_D_MAG_INNOV] = (yh + math.pi) % (2.0 * math.pi) - math.pi
    diag[_D_MAG_TR] = worst
    if worst > 1.0:
        return 0
    res = 1
    for k in range(3):
        if not scalar_update(P, dx, var_min, y[k], r, 6, h[k, 0], 7, h[k, 1], 8, h[k, 2],
                             16 + k, 1.0):
            res = _NUMERIC
    inject(x, dx, buf, meta)
    return res


@njit
def fuse_position_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                         dx: np.ndarray, var_min: float, px: float, py: float,
                         r: float) -> bool:
    """A horizontal position ``p*`` [m] of now with noise variance ``r`` [m^2], ungated
    (constant-position mode's held position)."""
    ok = scalar_update(P, dx, var_min, px - x[0], r, 0, 1.0, -1, 0.0, -1, 0.0)
    ok = scalar_update(P, dx, var_min, py - x[1], r, 1, 1.0, -1, 0.0, -1, 0.0) and ok
    inject(x, dx, buf, meta)
    return ok


@njit
def fuse_zero_velocity_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray,
                              meta: np.ndarray, dx: np.ndarray, var_min: float,
                              r: float, height_m: float, r_height: float) -> bool:
    """A zero velocity of now on each axis with noise variance ``r`` [m^2/s^2], and with
    ``r_height`` > 0 the height ``height_m`` [m] with that variance [m^2], ungated (the
    stationary constraint of a vehicle at rest on its gear)."""
    ok = True
    for i in range(3):
        ok = scalar_update(P, dx, var_min, -x[3 + i], r, 3 + i, 1.0, -1, 0.0, -1,
                           0.0) and ok
    if r_height > 0.0:
        ok = scalar_update(P, dx, var_min, height_m - x[2], r_height, 2, 1.0, -1, 0.0, -1,
                           0.0) and ok
    inject(x, dx, buf, meta)
    return ok


@njit
def _cholesky3(s00: float, s01: float, s02: float, s11: float, s12: float, s22: float
               ) -> tuple[bool, float, float, float, float, float, float]:
    """The lower Cholesky factor of the symmetric 3 x 3 matrix of upper triangle ``s``:
    (positive definite, l00, l10, l20, l11, l21, l22); False (and zeros) as soon as a
    leading minor is not positive."""
    if not s00 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    l00 = math.sqrt(s00)
    l10, l20 = s01 / l00, s02 / l00
    d11 = s11 - l10 * l10
    if not d11 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    l11 = math.sqrt(d11)
    l21 = (s12 - l20 * l10) / l11
    d22 = s22 - l20 * l20 - l21 * l21
    if not d22 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return True, l00, l10, l20, l11, l21, math.sqrt(d22)


@njit
def fuse_tether_kernel(x: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                       dx: np.ndarray, diag: np.ndarray, delayed: np.ndarray,
                       var_min: float, t_meas_s: float, px: float, py: float, pz: float,
                       c00: float, c01: float, c02: float, c11: float, c12: float,
                       c22: float, gate: float) -> int:
    """A tether fix of the time ``t_meas_s`` [s]: position ``p*`` [m] with the covariance
    ``c`` [m^2] (its upper triangle), against the state at that time (``delayed``). Gated
    as one on the innovation's Mahalanobis distance (``diag``: the innovation and the test
    ratio d^2 / gate^2); fused as three whitened scalar measurements (``L^-1 z`` with ``C =
    L L'``: unit, independent noises), the correction injected into the current state.
    Returns 1 if fused, 0 if rejected by the gate, 8 if refused (numerically, or the
    covariance not positive definite)."""
    _delayed(buf, meta, x, t_meas_s, delayed)
    y0, y1, y2 = px - delayed[0], py - delayed[1], pz - delayed[2]
    diag[_D_TETHER_INNOV], diag[_D_TETHER_INNOV + 1], diag[_D_TETHER_INNOV + 2] = y0, y1, y2
    # S = P_pp + C, its Cholesky factor, and d^2 = y' S^-1 y
    s00, s01, s02 = P[0, 0] + c00, P[0, 1] + c01, P[0, 2] + c02
    s11, s12, s22 = P[1, 1] + c11, P[1, 2] + c12, P[2, 2] + c22
    ok, a00, a10, a20, a11, a21, a22 = _cholesky3(s00, s01, s02, s11, s12, s22)
    if not ok:
        return _NUMERIC
    w0 = y0 / a00
    w1 = (y1 - a10 * w0) / a11
    w2 = (y2 - a20 * w0 - a21 * w1) / a22
    diag[_D_TETHER_TR] = (w0 * w0 + w1 * w1 + w2 * w2) / (gate * gate)
    if diag[_D_TETHER_TR] > 1.0:
        return 0
    # the measurement's own factor C = L L'
    ok, l00, l10, l20, l11, l21, l22 = _cholesky3(c00, c01, c02, c11, c12, c22)
    if not ok:
        return _NUMERIC
    # rows of L^-1 (lower triangular): z' = L^-1 z has the noise I
    m00 = 1.0 / l00
    m10 = -l10 / (l00 * l11)
    m11 = 1.0 / l11
    m20 = (l10 * l21 - l11 * l20) / (l00 * l11 * l22)
    m21 = -l21 / (l11 * l22)
    m22 = 1.0 / l22
    res = 1
    if not scalar_update(P, dx, var_min, m00 * y0, 1.0, 0, m00, -1, 0.0, -1, 0.0):
        res = _NUMERIC
    if not scalar_update(P, dx, var_min, m10 * y0 + m11 * y1, 1.0, 0, m10, 1, m11, -1, 0.0):
        res = _NUMERIC
    if not scalar_update(P, dx, var_min, m20 * y0 + m21 * y1 + m22 * y2, 1.0, 0, m20, 1,
                         m21, 2, m22):
        res = _NUMERIC
    inject(x, dx, buf, meta)
    return res


# ----- the filter
def _vec3(v: Sequence[float]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


#: The least time between the first and the last fix an alignment in the air takes
#: the acceleration from [s].
AIR_ALIGN_SPAN_S = 0.15


class NavFilter:
    """The onboard navigation filter (module docstring, docs/estimation.md).

    ``gravity_m_s2`` is the filter's gravity [m/s^2]; ``earth_field_enu_gauss`` the Earth's
    magnetic field it assumes [gauss] in the inertial frame (east, north, up: the
    declination and inclination are in it). Times are the companion's [s], monotonic.
    """

    def __init__(self, params: EstimatorParams, gravity_m_s2: float,
                 earth_field_enu_gauss: tuple[float, float, float]) -> None:
        self.params = params
        self.gravity_m_s2 = float(gravity_m_s2)
        self.earth_field_enu_gauss = _vec3(earth_field_enu_gauss)
        ex, ey, _ = self.earth_field_enu_gauss
        if math.hypot(ex, ey) <= 0.0:
            raise ValueError("earth_field_enu_gauss: no horizontal component, no heading")
        self._heading_earth_rad = math.atan2(ey, ex)
        ez = self.earth_field_enu_gauss[2]
        self._couple = (ez * ex / (ex * ex + ey * ey), ez * ey / (ex * ex + ey * ey))
        p = params
        self._x = np.zeros(NX)
        self._x[_X_Q] = 1.0
        self._P = np.zeros((N_ERR, N_ERR))
        #: the position variances [m^2] on P's diagonal (a view)
        self._pos_var = self._P.reshape(-1)[:2 * N_ERR + 3:N_ERR + 1]
        self._dx = np.zeros(N_ERR)
        self._diag = np.zeros(_N_DIAG)
        self._delayed_pv = np.zeros(6)
        #: bias-corrected rates [rad/s], low-passed inertial acceleration [m/s^2] and yaw
        #: rate [rad/s] (predict_kernel)
        self._rates = np.zeros(7)
        longest = max(p.gnss_delay_s, p.baro_delay_s,
                      p.tether_max_delay_s if p.tether_aid else 0.0)
        n_buf = int(math.ceil(longest * p.imu_rate_hz)) + 8
        self._buf = np.zeros((n_buf, _BUF_COLS))
        self._meta = np.zeros(2, dtype=np.int64)
        self._prm = np.zeros(_N_PRM)
        self._prm[_P_GRAV] = self.gravity_m_s2
        self._prm[_P_GYRO_N] = p.gyro_noise_rad_s_sqrt_hz
        self._prm[_P_ACC_N] = p.accel_noise_m_s2_sqrt_hz
        self._prm[_P_BG_W] = p.gyro_bias_walk_rad_s_sqrt_s
        self._prm[_P_BA_W] = p.accel_bias_walk_m_s2_sqrt_s
        self._prm[_P_BH_W] = p.baro_offset_walk_m_sqrt_s
        self._prm[_P_BM_W] = p.mag_bias_walk_gauss_sqrt_s
        self._prm[_P_BP_TAU] = p.gnss_pos_tau_s
        self._wander = p.gnss_pos_tau_s > 0.0
        self._accel_offsets = _vec3(p.accel_offsets_m_s2)
        self._mag3d = p.mag_fusion == "3d"
        self._prm[_P_DT_MAX] = 5.0 / p.imu_rate_hz
        self._var_min = 1e-14
        self._prm[_P_VAR_MIN] = self._var_min
        self._dt_max_s = 5.0 / p.imu_rate_hz
        self._output_tau_s = p.output_tau_s
        #: what the output (state()) still lags the filter by: the corrections of the
        #: fusions, position [m] and velocity [m/s], decaying at output_tau_s
        self._out_lag = np.zeros(6)
        self._compile()
        # alignment
        #: how long the alignment averages [s] (align_time_s; shorter for a start in the
        #: air, see :meth:`companion.onboard.Companion.estimate`)
        self.align_time_s = p.align_time_s
        self._aligned = False
        #: when the filter aligned [s] (None: not yet)
        self.aligned_at_s: float | None = None
        self._acc_sum = np.zeros(3)
        self._gyro_sum = np.zeros(3)
        self._gyro_sq_sum = np.zeros(3)
        self._acc_norm_sq = 0.0
        self._acc_norm = 0.0
        self._acc_n = 0
        self._mag_lp = np.zeros(3)
        self._mag_n = 0
        self._t_mag_align = 0.0
        self._baro_sum = 0.0
        self._baro_n = 0
        self._align_t0: float | None = None
        #: the fixes' (measurement time [s], velocity [m/s]) since the alignment began, and
        #: whether it aligns in the air (:meth:`start_in_air`)
        self._align_vels: list[tuple[float, Vec3]] = []
        self._in_air = False
        self._fix: tuple[float, Vec3, Vec3, float, float] | None = None
        self._baro_ref_m: float | None = None
        # times
        self._t_last: float | None = None
        self._t_mag: float = -math.inf
        self._t_manoeuvre: float = -math.inf
        self._t_baro_fused: float = -math.inf
        self._t_gnss_pos: float = -math.inf   # last fused (or since alignment)
        self._t_gnss_vel: float = -math.inf
        self._t_gnss_hgt: float = -math.inf
        self._t_baro: float = -math.inf
        self._t_stationary: float = -math.inf
        self._t_fix: float = -math.inf        # last usable fix received
        self._fail_since = {"gnss": math.inf, "baro": math.inf, "mag": math.inf}
        self._glitch = False
        self._numeric_refusals = 0
        self._const_pos: tuple[float, float] | None = None
        self._t_const_fuse = -math.inf
        #: Times the position and velocity were reset to the GNSS.
        self.gnss_resets = 0
        # the tether fix
        self._t_tether: float = -math.inf       # last fused (arrival time) [s]
        self._tether_fix: tuple[float, Vec3, np.ndarray] | None = None   # for alignment
        #: Times the position was reset to a tether fix.
        self.tether_resets = 0
        #: Tether fixes refused as too old, not finite or not positive definite.
        self.tether_refused = 0
        self._fail_since["tether"] = math.inf


    def _compile(self) -> None:
        """The kernels' machine code for these arrays (loaded or compiled now)."""
        x, P, buf, meta, dx, diag, dl = (self._x, self._P, self._buf, self._meta,
                                         self._dx, self._diag, self._delayed_pv)
        self._predict_k = entry_point(predict_output_kernel, x, P, buf, meta, self._prm,
                                      self._rates, self._out_lag, 0.0, 0.0, 0.0, 0.0, 0.0,
                                      0.0, 0.0, 0.0, 0.0)
        self._gnss_k = entry_point(fuse_gnss_kernel, x, P, buf, meta, dx, diag, dl, 0.0,
                                   0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                   0.0, True, True)
        self._baro_k = entry_point(fuse_baro_kernel, x, P, buf, meta, dx, diag, dl, 0.0,
                                   0.0, 0.0, 0.0, 0.0)
        self._mag_k = entry_point(fuse_mag_kernel, x, P, buf, meta, dx, diag, 0.0, 0.0,
                                  0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, True)
        self._mag3d_k = entry_point(fuse_mag3d_kernel, x, P, buf, meta, dx, diag, 0.0, 0.0,
                                    0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._pos_k = entry_point(fuse_position_kernel, x, P, buf, meta, dx, 0.0, 0.0, 0.0,
                                  0.0)
        self._zero_vel_k = entry_point(fuse_zero_velocity_kernel, x, P, buf, meta, dx, 0.0,
                                       0.0, 0.0, 0.0)
        self._tether_k = (entry_point(fuse_tether_kernel, x, P, buf, meta, dx, diag, dl, 0.0,
                                      0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                          if self.params.tether_aid else None)

    # ----- properties
    @property
    def aligned(self) -> bool:
        """Whether the filter is initialised (static alignment done, a GNSS fix taken)."""
        return self._aligned

    @property
    def covariance(self) -> np.ndarray:
        """The error-state covariance (22 x 22, a copy): dp [m], dv [m/s], dtheta [rad]
        (inertial axes), db_g [rad/s], db_a [m/s^2], db_h [m], db_m [gauss], db_p [m]."""
        return self._P.copy()

    @property
    def gyro_bias_rad_s(self) -> Vec3:
        """The gyro bias estimate [rad/s], body FLU."""
        return _vec3(self._x[_X_BG:_X_BG + 3])

    @property
    def accel_bias_m_s2(self) -> Vec3:
        """The accelerometer bias estimate [m/s^2], body FLU."""
        return _vec3(self._x[_X_BA:_X_BA + 3])

    @property
    def mag_bias_gauss(self) -> Vec3:
        """The magnetometer bias estimate [gauss], body FLU (0 with heading fusion)."""
        return _vec3(self._x[_X_BM:_X_BM + 3])

    @property
    def gnss_wander_m(self) -> Vec3:
        """The estimate of the GNSS receiver's position error [m], ENU (0 unless
        ``gnss_pos_tau_s`` > 0)."""
        return _vec3(self._x[_X_BP:_X_BP + 3])

    def position_sigma_m(self) -> Vec3:
        """Standard deviations of the position estimate [m] (east, north, up)."""
        a, b, c = self._pos_var.tolist()
        return (math.sqrt(max(a, 0.0)), math.sqrt(max(b, 0.0)), math.sqrt(max(c, 0.0)))

    @property
    def baro_offset_m(self) -> float:
        """The barometer's height offset estimate [m] (above the alignment's reference)."""
        return float(self._x[_X_BH])

    def state(self) -> VehicleState:
        """(position [m], velocity [m/s], attitude quaternion body FLU -> inertial, body
        rates [rad/s] = the last gyro sample minus the bias), as the flight controller
        takes it."""
        px, py, pz, vx, vy, vz, qw, qx, qy, qz = self._x[:10].tolist()
        r0, r1, r2, r3, r4, r5 = self._out_lag.tolist()
        # (built as the tuple it is, without its Python-level constructor: every period)
        return tuple.__new__(VehicleState, ((px - r0, py - r1, pz - r2),
                                            (vx - r3, vy - r4, vz - r5), (qw, qx, qy, qz),
                                            tuple(self._rates[0:3].tolist())))

    # ----- inputs
    def predict(self, t_s: float, gyro_flu_rad_s: Sequence[float],
                accel_flu_m_s2: Sequence[float]) -> None:
        """One IMU sample at ``t_s`` [s]: rates [rad/s] and specific force [m/s^2], body
        FLU. Before alignment the sample is averaged for it."""
        gx, gy, gz = gyro_flu_rad_s
        ax, ay, az = accel_flu_m_s2
        ox, oy, oz = self._accel_offsets
        ax, ay, az = ax - ox, ay - oy, az - oz
        if not self._aligned:
            self._rates[0:3] = (gx, gy, gz)
            self._align_sample(t_s, gx, gy, gz, ax, ay, az)
            self._t_last = t_s
            return
        t_last = self._t_last if self._t_last is not None else t_s
        dt = min(max(t_s - t_last, 0.0), self._dt_max_s)
        self._t_last = t_s
        self._predict_k(self._x, self._P, self._buf, self._meta, self._prm, self._rates,
                        self._out_lag, self._output_tau_s, t_s, dt, gx, gy, gz, ax, ay, az)
        if self._const_pos is not None and t_s - self._t_const_fuse >= 0.2:
            self._t_const_fuse = t_s
            self._pos_k(self._x, self._P, self._buf, self._meta, self._dx, self._var_min,
                        self._const_pos[0], self._const_pos[1],
                        self.params.const_pos_noise_m ** 2)
        elif (self._const_pos is None
              and t_s - max(self._t_gnss_pos, self._t_tether) > self.params.const_pos_after_s):
            self._const_pos = (float(self._x[0]), float(self._x[1]))

    def fuse_gnss(self, t_s: float, pos_enu_m: Sequence[float],
                  vel_enu_m_s: Sequence[float], eph_m: float, epv_m: float) -> bool:
        """A GNSS fix arriving at ``t_s`` [s] (taken ``gnss_delay_s`` earlier): position
        [m] and velocity [m/s] in the inertial ENU frame, the receiver's claimed
        horizontal and vertical accuracies [m] (its noise). Returns whether its position
        was fused (velocity may be fused alone; see :meth:`status`)."""
        p = self.params
        pos, vel = _vec3(pos_enu_m), _vec3(vel_enu_m_s)
        if not (math.isfinite(eph_m) and math.isfinite(epv_m) and eph_m <= p.gnss_max_eph_m
                and all(map(math.isfinite, pos + vel))):
            return False
        self._t_fix = t_s
        if not self._aligned:
            self._fix = (t_s, pos, vel, float(eph_m), float(epv_m))
            if self._align_t0 is not None:
                self._align_vels.append((t_s - p.gnss_delay_s, vel))
            self._try_align(t_s)
            return False
        # the fix's age is known only to within gnss_delay_uncertainty_s: at speed v that is
        # a position error of up to v u, added to the receiver's claimed accuracy
        vx, vy, vz = vel
        u = p.gnss_delay_uncertainty_s
        var_h, var_v = self._gnss_white_var(eph_m, epv_m)
        r_h = var_h + (vx * vx + vy * vy) * u * u
        r_v = var_v + vz * vz * u * u
        before = self._x[0:6].copy()
        res = self._gnss_k(self._x, self._P, self._buf, self._meta, self._dx, self._diag,
                           self._delayed_pv, self._var_min, t_s - p.gnss_delay_s, *pos,
                           *vel, r_h, r_v, p.gnss_vel_noise_m_s ** 2, p.gnss_pos_gate_sigma,
                           p.gnss_vel_gate_sigma, p.gnss_fuse_height, self._wander)
        self._lag_correction(before)
        if res & _NUMERIC:
            self._numeric_refusals += 1
        if res & _ACC_VEL:
            self._t_gnss_vel = t_s
        if res & _ACC_POS_V:
            self._t_gnss_hgt = t_s
        accepted = bool(res & _ACC_POS_H)
        self._glitch = not accepted
        if accepted:
            self._t_gnss_pos = t_s
            self._const_pos = None
            self._fail_since["gnss"] = math.inf
        else:
            self._fail_since["gnss"] = min(self._fail_since["gnss"], t_s)
            if t_s - self._fail_since["gnss"] >= p.gnss_reset_s:
                self._reset_to_gnss(pos, vel, r_h, r_v)
                self._t_gnss_pos = self._t_gnss_vel = t_s
                self._fail_since["gnss"] = math.inf
                self._const_pos = None
                self._glitch = False
                accepted = True
        return accepted

    def fuse_stationary(self, t_s: float, height_m: float | None = None) -> bool:
        """The vehicle is at rest on its gear at ``t_s`` [s] (the caller knows: landed and
        disarmed): a zero velocity fused, and the height ``height_m`` [m] it rests at
        (None: not known) with ``ground_height_noise_m``, every ``stationary_interval_s``.
        Returns whether it was fused."""
        p = self.params
        if not self._aligned or t_s - self._t_stationary < p.stationary_interval_s:
            return False
        self._t_stationary = t_s
        before = self._x[0:6].copy()
        use_height = height_m is not None and math.isfinite(height_m)
        ok = self._zero_vel_k(self._x, self._P, self._buf, self._meta, self._dx,
                              self._var_min, p.stationary_vel_noise_m_s ** 2,
                              float(height_m) if use_height else 0.0,
                              p.ground_height_noise_m ** 2 if use_height else 0.0)
        self._lag_correction(before)
        if not ok:
            self._numeric_refusals += 1
        return bool(ok)

    def fuse_tether(self, t_s: float, t_meas_s: float, pos_m: Sequence[float],
                    cov_m2: Sequence[Sequence[float]]) -> bool:
        """A tether fix arriving at ``t_s`` [s], taken at ``t_meas_s`` [s] (its timestamp,
        the companion's clock): position [m] and covariance [m^2] (inertial, z up), with
        ``tether_noise_min_m`` added on each axis. Before alignment it is kept for it (the
        position source when there is no GNSS). Returns whether it was fused."""
        p = self.params
        if not p.tether_aid:
            return False
        px, py, pz = pos = _vec3(pos_m)
        (a, b, c), (_, d, e), (_, _, f) = cov_m2
        floor = p.tether_noise_min_m ** 2
        a, d, f = float(a) + floor, float(d) + floor, float(f) + floor
        b = 0.5 * (float(b) + float(cov_m2[1][0]))
        c = 0.5 * (float(c) + float(cov_m2[2][0]))
        e = 0.5 * (float(e) + float(cov_m2[2][1]))
        age = t_s - t_meas_s
        # finite (NaN fails every comparison), fresh, positive definite (leading minors)
        if not (age <= p.tether_max_delay_s and abs(px) + abs(py) + abs(pz) < math.inf
                and abs(b) + abs(c) + abs(e) < math.inf and a > 0.0 and d < math.inf
                and f < math.inf and a * d - b * b > 0.0
                and a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c) > 0.0):
            self.tether_refused += 1
            return False
        t_meas = min(t_meas_s, t_s)       # a stamp from the future is taken as now
        if not self._aligned:
            self._tether_fix = (t_meas, pos, np.array(((a, b, c), (b, d, e), (c, e, f))))
            self._try_align(t_s)
            return False
        before = self._x[0:6].copy()
        res = self._tether_k(self._x, self._P, self._buf, self._meta, self._dx, self._diag,
                             self._delayed_pv, self._var_min, t_meas, px, py, pz, a, b, c, d,
                             e, f, p.tether_gate_sigma)
        self._lag_correction(before)
        if res & _NUMERIC:
            self._numeric_refusals += 1
        if res == 1:
            self._t_tether = t_s
            self._fail_since["tether"] = math.inf
            self._const_pos = None
            return True
        if res == 0:
            self._fail_since["tether"] = min(self._fail_since["tether"], t_s)
            if (t_s - self._fail_since["tether"] >= p.tether_reset_s
                    and t_s - self._t_gnss_pos > p.gnss_timeout_s):
                self._reset_to_tether(pos, np.array(((a, b, c), (b, d, e), (c, e, f))))
                self._t_tether = t_s
                self._fail_since["tether"] = math.inf
                self._const_pos = None
                return True
        return False

    def _reset_to_tether(self, pos: Vec3, c: np.ndarray) -> None:
        """Position set to the fix ``pos`` [m], its covariance to the fix's ``c`` [m^2]
        (3 x 3, with the floor; uncorrelated with the rest); the velocity kept."""
        delta = np.array(pos) - self._x[0:3]
        self._x[0:3] = pos
        n = int(self._meta[1])
        self._buf[:n, 1:4] += delta
        P = self._P
        P[0:3, :] = 0.0
        P[:, 0:3] = 0.0
        P[0:3, 0:3] = c
        self.tether_resets += 1
        self._out_lag[0:3] = 0.0

    def _gnss_white_var(self, eph_m: float, epv_m: float) -> tuple[float, float]:
        """The white part of a fix's position variance [m^2] (horizontal, vertical) from
        its claimed accuracies [m]; with the receiver's wander modelled, its share of the
        claim goes to the wander state (its stationary variance, set here)."""
        p = self.params
        floor = p.gnss_pos_noise_min_m ** 2
        var_h, var_v = max(eph_m, p.gnss_pos_noise_min_m) ** 2, max(
            epv_m, p.gnss_pos_noise_min_m) ** 2
        if not self._wander:
            return var_h, var_v
        c = p.gnss_pos_correlated_fraction
        self._prm[_P_BP_VAR_H] = c * var_h
        self._prm[_P_BP_VAR_V] = c * var_v
        return max((1.0 - c) * var_h, floor), max((1.0 - c) * var_v, floor)

    def _lag_correction(self, before: np.ndarray) -> None:
        """The output takes up the fusion's correction of position and velocity (from
        ``before``) over ``output_tau_s``."""
        if self.params.output_tau_s > 0.0:
            self._out_lag += self._x[0:6] - before

    def fuse_baro(self, t_s: float, pressure_alt_m: float) -> bool:
        """A barometer's pressure altitude [m AMSL] arriving at ``t_s`` [s]; its height is
        taken above the reference set at alignment (the pressure altitude then minus the
        GNSS height). Returns whether it was fused."""
        if self._aligned and t_s - self._t_baro_fused < self.params.baro_min_interval_s:
            return False
        if not math.isfinite(pressure_alt_m):
            return False
        if not self._aligned:
            self._baro_sum += pressure_alt_m
            self._baro_n += 1
            return False
        if self._baro_ref_m is None:        # no baro at alignment: referenced now
            self._baro_ref_m = pressure_alt_m - float(self._x[2])
        p = self.params
        if t_s - self._t_baro_fused < p.baro_min_interval_s:
            return False
        self._t_baro_fused = t_s
        before = self._x[0:6].copy()
        res = self._baro_k(self._x, self._P, self._buf, self._meta, self._dx, self._diag,
                           self._delayed_pv, self._var_min, t_s - p.baro_delay_s,
                           pressure_alt_m - self._baro_ref_m, p.baro_noise_m ** 2,
                           p.baro_gate_sigma)
        self._lag_correction(before)
        return self._outcome("baro", t_s, res)

    def fuse_mag(self, t_s: float, mag_flu_gauss: Sequence[float]) -> bool:
        """A magnetometer sample [gauss], body FLU, at ``t_s`` [s], fused as a heading
        (yaw only). Returns whether it was fused (samples within ``mag_min_interval_s``
        of the last fused one are skipped: False)."""
        if self._aligned and t_s - self._t_mag < self.params.mag_min_interval_s:
            return False
        mx, my, mz = _vec3(mag_flu_gauss)
        if not (math.isfinite(mx) and math.isfinite(my) and math.isfinite(mz)):
            return False
        if not self._aligned:
            # low-passed (time constant _MAG_ALIGN_TAU_S): the heading at the end of the
            # window, should the vehicle turn during it
            if self._mag_n == 0:
                self._mag_lp[:] = (mx, my, mz)
            else:
                dt = max(t_s - self._t_mag_align, 0.0)
                a = 1.0 - math.exp(-dt / _MAG_ALIGN_TAU_S)
                self._mag_lp += a * (np.array((mx, my, mz)) - self._mag_lp)
            self._t_mag_align = t_s
            self._mag_n += 1
            return False
        p = self.params
        if t_s - self._t_mag < p.mag_min_interval_s:
            return False
        if self._mag3d and self._manoeuvring(t_s):
            res = self._mag3d_k(self._x, self._P, self._buf, self._meta, self._dx,
                                self._diag, self._var_min, mx, my, mz,
                                *self.earth_field_enu_gauss, self._heading_earth_rad,
                                p.mag_noise_gauss ** 2, p.mag_gate_sigma)
        else:
            res = self._mag_k(self._x, self._P, self._buf, self._meta, self._dx,
                              self._diag, self._var_min, mx, my, mz,
                              self._heading_earth_rad, p.mag_yaw_noise_rad ** 2,
                              p.mag_gate_sigma, not p.mag_yaw_only, *self._couple,
                              self._mag3d)
        if res == 1:
            self._t_mag = t_s
        return self._outcome("mag", t_s, res)

    def _manoeuvring(self, t_s: float) -> bool:
        """Whether the magnetometer's bias is observable now (EKF2's rule for its 3-axis
        fusion): the low-passed horizontal acceleration or yaw rate above its threshold,
        or was within ``mag_3d_hold_s``. Still, the bias and the heading cannot be told
        apart, and the heading alone is fused (with the bias learnt so far taken off)."""
        p, r = self.params, self._rates
        if (math.hypot(r[3], r[4]) >= p.mag_3d_accel_m_s2
                or abs(r[6]) >= p.mag_3d_yaw_rate_rad_s):
            self._t_manoeuvre = t_s
        return t_s - self._t_manoeuvre <= p.mag_3d_hold_s

    def _outcome(self, name: str, t_s: float, res: int) -> bool:
        if res & _NUMERIC:
            self._numeric_refusals += 1
        if res == 1:
            self._fail_since[name] = math.inf
            if name == "baro":
                self._t_baro = t_s
            return True
        if res == 0:
            self._fail_since[name] = min(self._fail_since[name], t_s)
        return False

    # ----- alignment
    def _align_sample(self, t_s: float, gx: float, gy: float, gz: float, ax: float,
                      ay: float, az: float) -> None:
        if self._align_t0 is None:
            self._align_t0 = t_s
        self._gyro_sum += (gx, gy, gz)
        self._gyro_sq_sum += (gx * gx, gy * gy, gz * gz)
        self._acc_sum += (ax, ay, az)
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        self._acc_norm += norm
        self._acc_norm_sq += norm * norm
        self._acc_n += 1
        self._try_align(t_s)

    def start_in_air(self) -> None:
        """The first fix found the vehicle in the air (a simulation started in hover): it
        hovers open loop while the filter aligns, over ``air_align_time_s``, on the specific
        force less the acceleration the fixes' velocities show (:meth:`_try_align`)."""
        self.align_time_s = self.params.air_align_time_s
        self._in_air = True

    def _fix_acceleration(self) -> Vec3 | None:
        """The acceleration [m/s^2] the fixes since the alignment began show: the least-
        squares slope of their velocities; None until two fixes ``AIR_ALIGN_SPAN_S`` apart
        are in."""
        pts = self._align_vels
        if len(pts) < 2 or pts[-1][0] - pts[0][0] < AIR_ALIGN_SPAN_S:
            return None
        ts = np.array([t for t, _ in pts])
        vs = np.array([v for _, v in pts])
        dt = ts - ts.mean()
        sxx = float(dt @ dt)
        slope = (dt @ (vs - vs.mean(axis=0))) / sxx
        return (float(slope[0]), float(slope[1]), float(slope[2]))

    def _restart_alignment(self, t_s: float) -> None:
        self._align_t0 = t_s
        self._align_vels.clear()
        self._acc_sum[:] = 0.0
        self._gyro_sum[:] = 0.0
        self._gyro_sq_sum[:] = 0.0
        self._acc_norm = self._acc_norm_sq = 0.0
        self._acc_n = 0
        self._mag_n = 0
        self._baro_sum = 0.0
        self._baro_n = 0

    def _try_align(self, t_s: float) -> None:
        """Initialise once ``align_time_s`` of samples, a magnetometer sample and a fix
        are in: tilt from the mean specific force, yaw from the low-passed field, position and
        velocity from the fix (brought forward by its age)."""
        p = self.params
        if self._align_t0 is None or t_s - self._align_t0 < self.align_time_s:
            return
        n = self._acc_n
        mean_norm = self._acc_norm / n
        std = math.sqrt(max(self._acc_norm_sq / n - mean_norm * mean_norm, 0.0))
        if std > p.align_max_accel_std_m_s2:
            self._restart_alignment(t_s)
            return
        gnss = self._fix is not None and t_s - self._fix[0] <= 1.0
        tether = self._tether_fix is not None and t_s - self._tether_fix[0] <= 1.0
        if self._mag_n == 0 or not (gnss or tether):
            return
        fx, fy, fz = self._acc_sum / n
        accel = None
        if self._in_air and gnss:
            accel = self._fix_acceleration()
            if accel is None:
                return      # not yet two fixes far enough apart
        x = self._x
        if accel is not None and any(accel):
            # accelerating open loop (a tether pulling the hover off its trim): the mean
            # specific force is the acceleration less gravity, not gravity alone; tilt and
            # heading together from it and the field (TRIAD)
            q = _triad((fx, fy, fz), tuple(self._mag_lp),
                       (accel[0], accel[1], accel[2] + self.gravity_m_s2),
                       tuple(self.earth_field_enu_gauss))
        else:
            roll = math.atan2(fy, fz)
            pitch = math.atan2(-fx, math.hypot(fy, fz))
            q_tilt = euler_to_quat(roll, pitch, 0.0)
            m = self._mag_lp
            x_tilt = np.array(_rot_py(q_tilt)).reshape(3, 3) @ m
            yaw = self._heading_earth_rad - math.atan2(x_tilt[1], x_tilt[0])
            q = euler_to_quat(roll, pitch, yaw)
        P = self._P
        P[:] = 0.0
        x[:] = 0.0
        if gnss:
            t_fix, pos, vel, eph, epv = self._fix
            age = t_s - t_fix + p.gnss_delay_s
            x[0:3] = [pos[i] + vel[i] * age for i in range(3)]
            x[3:6] = vel
            self._gnss_position_prior(eph, epv)
            var_v = max(epv, p.gnss_pos_noise_min_m) ** 2
            var_vel = p.gnss_vel_noise_m_s ** 2
        else:
            # no GNSS: the tether fix is the position (the vehicle taken to be near rest)
            _, pos, c = self._tether_fix
            x[0:3] = pos
            P[0:3, 0:3] = c
            var_v = float(c[2, 2])
            var_vel = p.tether_align_vel_sigma_m_s ** 2
        x[_X_Q:_X_Q + 4] = q
        var_bg = p.gyro_bias_sigma_rad_s ** 2
        if p.gyro_calibration_at_rest and not self._in_air:
            # still on the ground: the mean rate is the bias, known to the mean's noise
            # (the rate's density over the averaging time) and the walk meanwhile; rates
            # that spread beyond three times the noise of a sample are a vehicle moving,
            # and leave the biases to the filter
            t_avg = max(t_s - self._align_t0, 1.0 / p.imu_rate_hz)
            bias = self._gyro_sum / n
            spread = self._gyro_sq_sum / n - bias * bias
            sample_var = p.gyro_noise_rad_s_sqrt_hz ** 2 * p.imu_rate_hz
            if float(np.max(spread)) <= 9.0 * sample_var:
                x[_X_BG:_X_BG + 3] = bias
                var_bg = min(var_bg, p.gyro_noise_rad_s_sqrt_hz ** 2 / t_avg
                             + p.gyro_bias_walk_rad_s_sqrt_s ** 2 * t_avg)
        for i in range(3):
            P[IDX_V + i, IDX_V + i] = var_vel
            P[IDX_BG + i, IDX_BG + i] = var_bg
            P[IDX_BA + i, IDX_BA + i] = p.accel_bias_sigma_m_s2 ** 2
            P[IDX_BM + i, IDX_BM + i] = p.mag_bias_sigma_gauss ** 2
        P[IDX_TH, IDX_TH] = P[IDX_TH + 1, IDX_TH + 1] = p.tilt_sigma_rad ** 2
        P[IDX_TH + 2, IDX_TH + 2] = p.yaw_sigma_rad ** 2
        # the baro offset is referenced to the GNSS height: their errors are opposed
        P[IDX_BH, IDX_BH] = var_v + p.baro_offset_sigma_m ** 2
        P[IDX_P + 2, IDX_BH] = P[IDX_BH, IDX_P + 2] = -var_v
        if not gnss:    # the fix's height error is correlated with its horizontal one
            P[0:3, IDX_BH] = P[IDX_BH, 0:3] = -P[0:3, 2]
        # ... and the fix's height held the receiver's wander, which the offset took too
        P[IDX_BP + 2, IDX_BH] = P[IDX_BH, IDX_BP + 2] = P[IDX_BP + 2, IDX_BP + 2]
        # the baro's reference: its mean altitude then minus the GNSS height then
        if self._baro_n:
            self._baro_ref_m = self._baro_sum / self._baro_n - float(x[2])
        self._meta[:] = 0
        self._aligned = True
        self.aligned_at_s = t_s
        self._t_last = t_s
        if gnss:
            self._t_gnss_pos = self._t_gnss_vel = self._t_gnss_hgt = t_s
        else:
            self._t_tether = t_s
        self._t_baro = t_s

    def _gnss_position_prior(self, eph_m: float, epv_m: float) -> None:
        """The position's covariance (and the receiver wander's) when the position is set
        from a fix with claimed accuracies [m]: the position's error is the fix's, minus
        the wander's where it is modelled (the wander estimate then 0)."""
        p, P = self.params, self._P
        white = self._gnss_white_var(eph_m, epv_m)
        claim = (max(eph_m, p.gnss_pos_noise_min_m) ** 2,
                 max(epv_m, p.gnss_pos_noise_min_m) ** 2)
        self._x[_X_BP:_X_BP + 3] = 0.0
        P[IDX_BP:IDX_BP + 3, :] = 0.0
        P[:, IDX_BP:IDX_BP + 3] = 0.0
        for i in range(3):
            k = 0 if i < 2 else 1
            if self._wander:
                wander = claim[k] - white[k] if claim[k] > white[k] else 0.0
                P[IDX_P + i, IDX_P + i] = white[k] + wander
                P[IDX_BP + i, IDX_BP + i] = wander
                P[IDX_P + i, IDX_BP + i] = P[IDX_BP + i, IDX_P + i] = -wander
            else:
                P[IDX_P + i, IDX_P + i] = claim[k]

    def _reset_to_gnss(self, pos: Vec3, vel: Vec3, r_h: float, r_v: float) -> None:
        """Position and velocity set to the fix (brought forward by its age), their
        covariance to the fix's noise (``r_h``, ``r_v`` [m^2], the white part where the
        receiver's wander is modelled: that is reset too), uncorrelated with the rest."""
        age = self.params.gnss_delay_s
        new = np.array([pos[i] + vel[i] * age for i in range(3)] + list(vel))
        delta = new - self._x[0:6]
        self._x[0:6] = new
        n = int(self._meta[1])
        self._buf[:n, 1:7] += delta
        P = self._P
        P[0:6, :] = 0.0
        P[:, 0:6] = 0.0
        for i, v in enumerate((r_h, r_h, r_v)):
            P[i, i] = v
            P[3 + i, 3 + i] = self.params.gnss_vel_noise_m_s ** 2
        if self._wander:
            h, v = self._prm[_P_BP_VAR_H], self._prm[_P_BP_VAR_V]
            self._x[_X_BP:_X_BP + 3] = 0.0
            P[IDX_BP:IDX_BP + 3, :] = 0.0
            P[:, IDX_BP:IDX_BP + 3] = 0.0
            for i, w in enumerate((h, h, v)):
                P[i, i] += w
                P[IDX_BP + i, IDX_BP + i] = w
                P[i, IDX_BP + i] = P[IDX_BP + i, i] = -w
        self.gnss_resets += 1
        self._out_lag[:] = 0.0   # a reset is flown at once

    # ----- status
    def status(self, t_s: float | None = None) -> FilterStatus:
        """Health, flags and checks at ``t_s`` [s] (default: the last IMU sample's time)."""
        p = self.params
        t = self._t_last if t_s is None else t_s
        if t is None:
            t = 0.0
        d, P, x = self._diag, self._P, self._x
        var = np.diag(P)
        finite = bool(np.all(np.isfinite(x)) and np.all(np.isfinite(P)))
        reasons = HealthReason.NONE
        flags = EstimatorFlags(0)
        sources = AidSource.NONE
        health = FilterHealth.INITIALISING
        since_pos = t - self._t_gnss_pos
        if self._aligned:
            if not finite:
                reasons |= HealthReason.NAN
            elif (np.any(var < 0.0)
                  or float(np.max(var[0:3])) > p.pos_variance_limit_m2):
                reasons |= HealthReason.COVARIANCE
            gnss_pos = since_pos <= p.gnss_timeout_s
            gnss_vel = t - self._t_gnss_vel <= p.gnss_timeout_s
            tether = t - self._t_tether <= p.tether_timeout_s
            if not (gnss_pos or gnss_vel or tether):
                reasons |= HealthReason.NO_GNSS
            for name, reason in (("gnss", HealthReason.GNSS_REJECTED),
                                 ("baro", HealthReason.BARO_REJECTED),
                                 ("mag", HealthReason.MAG_REJECTED)):
                if t - self._fail_since[name] >= p.innovation_fail_s:
                    reasons |= reason
            if (not gnss_pos and t - self._fail_since["tether"] >= p.innovation_fail_s):
                reasons |= HealthReason.TETHER_REJECTED
            if gnss_pos:
                sources |= AidSource.GNSS
            if tether:
                sources |= AidSource.TETHER
            if t - self._t_baro <= p.gnss_timeout_s:
                sources |= AidSource.BARO
            if t - self._t_mag <= p.gnss_timeout_s:
                sources |= AidSource.MAG
            vert = (t - self._t_baro <= p.gnss_timeout_s
                    or t - self._t_gnss_hgt <= p.gnss_timeout_s)
            if finite:
                flags |= EstimatorFlags.ATTITUDE
                if gnss_vel or tether:   # a position source makes velocity observable
                    flags |= EstimatorFlags.VELOCITY_HORIZ | EstimatorFlags.VELOCITY_VERT
                elif vert:
                    flags |= EstimatorFlags.VELOCITY_VERT
                if gnss_pos or tether:
                    # the fix is relative to the winder, whose global position is home
                    flags |= EstimatorFlags.POS_HORIZ_REL | EstimatorFlags.POS_HORIZ_ABS
                if vert:
                    flags |= EstimatorFlags.POS_VERT_ABS
            if self._const_pos is not None:
                flags |= EstimatorFlags.CONST_POS_MODE
            if t - self._t_fix <= p.gnss_timeout_s:
                flags |= EstimatorFlags.PRED_POS_HORIZ_REL | EstimatorFlags.PRED_POS_HORIZ_ABS
            if self._glitch:
                flags |= EstimatorFlags.GPS_GLITCH
            if reasons:
                health = FilterHealth.UNHEALTHY
            elif ((gnss_pos or tether)
                  and max(var[6], var[7]) < p.converged_tilt_sigma_rad ** 2
                  and var[8] < p.converged_yaw_sigma_rad ** 2):
                health = FilterHealth.HEALTHY
            else:
                health = FilterHealth.ALIGNED
        sd = np.sqrt(np.maximum(var, 0.0))
        return FilterStatus(
            health, reasons, flags,
            velocity_variance=math.sqrt(max(d[_D_VEL_TR], 0.0)),
            pos_horiz_variance=math.sqrt(max(
                d[_D_POS_TR] if AidSource.GNSS in sources or AidSource.TETHER not in sources
                else d[_D_TETHER_TR], 0.0)),
            pos_vert_variance=math.sqrt(max(d[_D_BARO_TR], 0.0)),
            compass_variance=math.sqrt(max(d[_D_MAG_TR], 0.0)),
            terrain_alt_variance=0.0,
            pos_innovation_m=_vec3(d[_D_POS_INNOV:_D_POS_INNOV + 3]),
            vel_innovation_m_s=_vec3(d[_D_VEL_INNOV:_D_VEL_INNOV + 3]),
            baro_innovation_m=float(d[_D_BARO_INNOV]),
            mag_innovation_rad=float(d[_D_MAG_INNOV]),
            pos_sigma_m=_vec3(sd[0:3]), vel_sigma_m_s=_vec3(sd[3:6]),
            attitude_sigma_rad=_vec3(sd[6:9]),
            time_since_gnss_s=since_pos if self._aligned else math.inf,
            sources=sources,
            tether_variance=math.sqrt(max(d[_D_TETHER_TR], 0.0)),
            tether_innovation_m=_vec3(d[_D_TETHER_INNOV:_D_TETHER_INNOV + 3]))


def _triad(body1: Vec3, body2: Vec3, nav1: Vec3, nav2: Vec3) -> Quat:
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


def _rot_py(q: Quat) -> tuple[float, ...]:
    """:func:`_rot` of a quaternion tuple, interpreted (the alignment's one use)."""
    return _rot.py_func(*q) if hasattr(_rot, "py_func") else _rot(*q)


__all__ = ["EstimatorParams", "NavFilter", "FilterStatus", "FilterHealth", "HealthReason",
           "EstimatorFlags", "AidSource", "N_ERR"]

