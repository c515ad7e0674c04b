"""The alignment: the filter's state and covariance initialised once ``align_time_s`` of
IMU samples, a magnetometer sample and a position fix (GNSS or tether) are in; tilt from
the mean specific force, yaw from the low-passed field (or both by TRIAD when a start in
the air accelerates), position and velocity from the fix (docs/estimation.md)."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.gnss import position_prior
from companion.ekf.layout import IDX_BA, IDX_BG, IDX_BH, IDX_BM, IDX_BP, IDX_TH, IDX_V, X_BG, X_Q
from companion.ekf.memory import FilterMemory
from companion.ekf.params import EstimatorParams
from companion.ekf.rotation import triad
from tuavdefs.frames import Vec3, euler_to_quat, quat_to_matrix

#: Time constant of the magnetometer's low-pass for the alignment [s].
MAG_ALIGN_TAU_S = 0.1
#: The least time between the first and the last fix an alignment in the air takes
#: the acceleration from [s].
AIR_ALIGN_SPAN_S = 0.15
#: A fix older than this [s] is not aligned on.
_FIX_MAX_AGE_S = 1.0


class Alignment:
    """The samples averaged for the alignment, and the alignment itself (:meth:`try_align`)
    into the filter's arrays ``mem`` and its sources' records."""

    __slots__ = ("_p", "_mem", "_src", "_gravity", "_field", "_heading", "align_time_s",
                 "_acc_sum", "_gyro_sum", "_gyro_sq_sum", "_acc_norm", "_acc_norm_sq",
                 "_acc_n", "_mag_lp", "_mag_n", "_t_mag", "_baro_sum", "_baro_n", "_t0",
                 "_vels", "_in_air", "_fix", "_tether_fix", "baro_ref_m")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, sources: AidSources,
                 gravity_m_s2: float, earth_field_enu_gauss: Vec3) -> None:
        self._p = params
        self._mem = mem
        self._src = sources
        self._gravity = gravity_m_s2
        self._field = earth_field_enu_gauss
        self._heading = math.atan2(earth_field_enu_gauss[1], earth_field_enu_gauss[0])
        #: how long the alignment averages [s] (align_time_s; shorter for a start in the
        #: air, :meth:`start_in_air`)
        self.align_time_s = params.align_time_s
        self._acc_sum = np.zeros(3)
        self._gyro_sum = np.zeros(3)
        self._gyro_sq_sum = np.zeros(3)
        self._acc_norm = 0.0
        self._acc_norm_sq = 0.0
        self._acc_n = 0
        self._mag_lp = np.zeros(3)
        self._mag_n = 0
        self._t_mag = 0.0
        self._baro_sum = 0.0
        self._baro_n = 0
        self._t0: float | None = None
        #: the fixes' (measurement time [s], velocity [m/s]) since the alignment began
        self._vels: list[tuple[float, Vec3]] = []
        self._in_air = False
        #: the latest GNSS fix: arrival time [s], position [m], velocity [m/s], eph, epv [m]
        self._fix: tuple[float, Vec3, Vec3, float, float] | None = None
        #: the latest tether fix: measurement time [s], position [m], covariance [m^2]
        self._tether_fix: tuple[float, Vec3, np.ndarray] | None = None
        #: the pressure altitude [m AMSL] at the filter's zero height (None: no baro)
        self.baro_ref_m: float | None = None

    # ----- the samples
    def add_imu(self, t_s: float, gx: float, gy: float, gz: float, ax: float, ay: float,
                az: float) -> None:
        """An IMU sample at ``t_s`` [s]: rates [rad/s], specific force [m/s^2]."""
        if self._t0 is None:
            self._t0 = t_s
        self._gyro_sum += (gx, gy, gz)
        self._gyro_sq_sum += (gx * gx, gy * gy, gz * gz)
        self._acc_sum += (ax, ay, az)
        norm = math.sqrt(ax * ax + ay * ay + az * az)
        self._acc_norm += norm
        self._acc_norm_sq += norm * norm
        self._acc_n += 1

    def add_mag(self, t_s: float, mx: float, my: float, mz: float) -> None:
        """A finite magnetometer sample [gauss] at ``t_s`` [s], low-passed (time constant
        :data:`MAG_ALIGN_TAU_S`): the heading at the end of the window, should the vehicle
        turn during it."""
        if self._mag_n == 0:
            self._mag_lp[:] = (mx, my, mz)
        else:
            dt = max(t_s - self._t_mag, 0.0)
            a = 1.0 - math.exp(-dt / MAG_ALIGN_TAU_S)
            self._mag_lp += a * (np.array((mx, my, mz)) - self._mag_lp)
        self._t_mag = t_s
        self._mag_n += 1

    def add_baro(self, pressure_alt_m: float) -> None:
        """A finite pressure altitude [m AMSL]."""
        self._baro_sum += pressure_alt_m
        self._baro_n += 1

    def add_gnss_fix(self, t_s: float, pos: Vec3, vel: Vec3, eph_m: float,
                     epv_m: float) -> None:
        """A usable GNSS fix arriving at ``t_s`` [s]."""
        self._fix = (t_s, pos, vel, float(eph_m), float(epv_m))
        if self._t0 is not None:
            self._vels.append((t_s - self._p.gnss_delay_s, vel))

    def add_tether_fix(self, t_meas_s: float, pos: Vec3, cov_m2: np.ndarray) -> None:
        """A usable tether fix of the time ``t_meas_s`` [s]."""
        self._tether_fix = (t_meas_s, pos, cov_m2)

    def start_in_air(self) -> None:
        """The first fix found the vehicle in the air: it aligns over ``air_align_time_s``
        on the specific force less the acceleration the fixes' velocities show."""
        self.align_time_s = self._p.air_align_time_s
        self._in_air = True

    def _fix_acceleration(self) -> Vec3 | None:
        """The acceleration [m/s^2] the fixes since the alignment began show: the least-
        squares slope of their velocities; None until two fixes ``AIR_ALIGN_SPAN_S`` apart
        are in."""
        pts = self._vels
        if len(pts) < 2 or pts[-1][0] - pts[0][0] < AIR_ALIGN_SPAN_S:
            return None
        ts = np.array([t for t, _ in pts])
        vs = np.array([v for _, v in pts])
        dt = ts - ts.mean()
        sxx = float(dt @ dt)
        slope = (dt @ (vs - vs.mean(axis=0))) / sxx
        return (float(slope[0]), float(slope[1]), float(slope[2]))

    def _restart(self, t_s: float) -> None:
        self._t0 = t_s
        self._vels.clear()
        self._acc_sum[:] = 0.0
        self._gyro_sum[:] = 0.0
        self._gyro_sq_sum[:] = 0.0
        self._acc_norm = self._acc_norm_sq = 0.0
        self._acc_n = 0
        self._mag_n = 0
        self._baro_sum = 0.0
        self._baro_n = 0

    # ----- the alignment
    def try_align(self, t_s: float) -> bool:
        """Initialise the state and covariance at ``t_s`` [s] if ``align_time_s`` of
        samples, a magnetometer sample and a fix are in: tilt from the mean specific
        force, yaw from the low-passed field, position and velocity from the fix (brought
        forward by its age). Returns whether it did."""
        p = self._p
        if self._t0 is None or t_s - self._t0 < self.align_time_s:
            return False
        n = self._acc_n
        mean_norm = self._acc_norm / n
        std = math.sqrt(max(self._acc_norm_sq / n - mean_norm * mean_norm, 0.0))
        if std > p.align_max_accel_std_m_s2:
            self._restart(t_s)
            return False
        gnss = self._fix is not None and t_s - self._fix[0] <= _FIX_MAX_AGE_S
        tether = (self._tether_fix is not None
                  and t_s - self._tether_fix[0] <= _FIX_MAX_AGE_S)
        if self._mag_n == 0 or not (gnss or tether):
            return False
        fx, fy, fz = self._acc_sum / n
        accel = None
        if self._in_air and gnss:
            accel = self._fix_acceleration()
            if accel is None:
                return False      # not yet two fixes far enough apart
        if accel is not None and any(accel):
            # accelerating open loop (a tether pulling the hover off its trim): the mean
            # specific force is the acceleration less gravity, not gravity alone; tilt and
            # heading together from it and the field (TRIAD)
            q = triad((fx, fy, fz), tuple(self._mag_lp),
                      (accel[0], accel[1], accel[2] + self._gravity), tuple(self._field))
        else:
            roll = math.atan2(fy, fz)
            pitch = math.atan2(-fx, math.hypot(fy, fz))
            q_tilt = euler_to_quat(roll, pitch, 0.0)
            x_tilt = np.array(quat_to_matrix(q_tilt)) @ self._mag_lp
            yaw = self._heading - math.atan2(x_tilt[1], x_tilt[0])
            q = euler_to_quat(roll, pitch, yaw)
        self._initialise(t_s, q, gnss, n)
        return True

    def _initialise(self, t_s: float, q: tuple[float, float, float, float], gnss: bool,
                    n: int) -> None:
        """The state and covariance at ``t_s`` [s] with the attitude ``q``, aligned on the
        GNSS fix (``gnss``) or the tether's, after ``n`` IMU samples."""
        p, mem = self._p, self._mem
        x, P = mem.x, mem.P
        P[:] = 0.0
        x[:] = 0.0
        if gnss:
            assert self._fix is not None
            t_fix, pos, vel, eph, epv = self._fix
            age = t_s - t_fix + p.gnss_delay_s
            x[0:3] = [pos[i] + vel[i] * age for i in range(3)]
            x[3:6] = vel
            position_prior(p, mem, eph, epv)
            var_v = max(epv, p.gnss_pos_noise_min_m) ** 2
            var_vel = p.gnss_vel_noise_m_s ** 2
        else:
            # no GNSS: the tether fix is the position (the vehicle taken to be near rest)
            assert self._tether_fix is not None
            _, pos, c = self._tether_fix
            x[0:3] = pos
            P[0:3, 0:3] = c
            var_v = float(c[2, 2])
            var_vel = p.tether_fix.align_vel_sigma_m_s ** 2
        x[X_Q:X_Q + 4] = q
        var_bg = p.gyro_bias_sigma_rad_s ** 2
        if p.gyro_calibration_at_rest and not self._in_air:
            # still on the ground: the mean rate is the bias, known to the mean's noise
            # (the rate's density over the averaging time) and the walk meanwhile; rates
            # that spread beyond three times the noise of a sample are a vehicle moving,
            # and leave the biases to the filter
            assert self._t0 is not None
            t_avg = max(t_s - self._t0, 1.0 / p.imu_rate_hz)
            bias = self._gyro_sum / n
            spread = self._gyro_sq_sum / n - bias * bias
            sample_var = p.gyro_noise_rad_s_sqrt_hz ** 2 * p.imu_rate_hz
            if float(np.max(spread)) <= 9.0 * sample_var:
                x[X_BG:X_BG + 3] = bias
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
        P[2, IDX_BH] = P[IDX_BH, 2] = -var_v
        if not gnss:    # the fix's height error is correlated with its horizontal one
            P[0:3, IDX_BH] = P[IDX_BH, 0:3] = -P[0:3, 2]
        # ... and the fix's height held the receiver's wander, which the offset took too
        P[IDX_BP + 2, IDX_BH] = P[IDX_BH, IDX_BP + 2] = P[IDX_BP + 2, IDX_BP + 2]
        # the baro's reference: its mean altitude then minus the GNSS height then
        if self._baro_n:
            self.baro_ref_m = self._baro_sum / self._baro_n - float(x[2])
        mem.meta[:] = 0
        src = self._src
        if gnss:
            for st in (src.gnss_pos, src.gnss_vel, src.gnss_hgt):
                st.time_last_fused = t_s
        else:
            src.tether.time_last_fused = t_s
        src.baro.time_last_fused = t_s
