"""The navigation filter's facade, :class:`NavFilter`: what the companion feeds and reads.

It owns the filter's arrays (:mod:`companion.ekf.memory`), the aid sources' records
(:mod:`companion.ekf.aid_source`) and one control per source; before the alignment it
hands the samples to :mod:`companion.ekf.alignment`, after it to the sources' controls
(PX4 EKF2's ``control.cpp`` dispatch). The arithmetic is compiled (numba kernels on the
arrays, through :func:`tuavdefs.jit.entry_point`); everything the filter assumes about its
sensors is in :class:`~companion.ekf.params.EstimatorParams`: its own numbers, never the
plant's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.alignment import Alignment
from companion.ekf.baro import BaroControl
from companion.ekf.const_pos import ConstPosControl
from companion.ekf.drag import DragControl, DragModel
from companion.ekf.gnss import GnssControl, usable_fix
from companion.ekf.health import FilterStatus, filter_status
from companion.ekf.layout import (
    IDX_LINE,
    LINE_BEPS,
    LINE_BPSI,
    LINE_KC,
    LINE_KW,
    N_LINE,
    PRM_ACC_N,
    PRM_BA_W,
    PRM_BG_W,
    PRM_BH_W,
    PRM_BM_W,
    PRM_BP_TAU,
    PRM_DT_MAX,
    PRM_GRAV,
    PRM_GYRO_N,
    PRM_OUT_TAU,
    PRM_VAR_MIN,
    W_HEADING_INNOV,
    W_RATES,
    X_BA,
    X_BG,
    X_BH,
    X_BM,
    X_BP,
    X_W,
)
from companion.ekf.mag import MagControl, finite_sample
from companion.ekf.memory import FilterMemory
from companion.ekf.output import OutputPredictor, predict_output_kernel
from companion.ekf.params import EstimatorParams
from companion.ekf.tether import TetherControl, cov_matrix
from companion.ekf.tether_check import TetherFixCheck
from companion.ekf.tether_line import TetherLineControl
from companion.ekf.zero_velocity import ZeroVelocityControl
from companion.flight_controller import VehicleState
from tuavdefs.frames import Vec3
from tuavdefs.jit import entry_point
from tuavdefs.line_shape import LineModel

#: The least variance an update may leave on the covariance's diagonal.
_VAR_MIN = 1e-14


def _vec3(v: Sequence[float]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


class NavFilter:
    """The onboard navigation filter (docs/estimation.md): an error-state EKF predicted
    with each IMU sample, fusing GNSS, barometer, magnetometer, the tether fix and the
    stationary constraint, each by its control under the aid sources' policy.

    ``gravity_m_s2`` is the filter's gravity [m/s^2]; ``earth_field_enu_gauss`` the Earth's
    magnetic field it assumes [gauss] in the inertial frame (east, north, up: the
    declination and inclination are in it). Times are the companion's [s], monotonic.
    ``drag`` is the vehicle's drag model (the controllers' vehicle's), which drag fusion
    (``params.drag.enabled``, the default) uses (None: the companion's default vehicle's,
    :meth:`~companion.ekf.drag.DragModel.default_vehicle`); ``line`` the tether as the
    companion believes it and ``attachment_m`` where it is attached [m] (body FLU), which
    the raw reading's fusion (``params.drag.tether_line.enabled``) needs.
    """

    #: The state the vehicle flies on (:meth:`companion.ekf.output.OutputPredictor.state`):
    #: position [m], velocity [m/s], attitude, bias-corrected body rates [rad/s].
    state: Callable[[], VehicleState]

    def __init__(self, params: EstimatorParams, gravity_m_s2: float,
                 earth_field_enu_gauss: tuple[float, float, float],
                 drag: DragModel | None = None, line: LineModel | None = None,
                 attachment_m: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        self.params = p = params
        self.gravity_m_s2 = float(gravity_m_s2)
        self.earth_field_enu_gauss = field = _vec3(earth_field_enu_gauss)
        if math.hypot(field[0], field[1]) <= 0.0:
            raise ValueError("earth_field_enu_gauss: no horizontal component, no heading")
        self._mem = mem = FilterMemory(p)
        prm = mem.prm
        prm[PRM_GRAV] = self.gravity_m_s2
        prm[PRM_GYRO_N] = p.gyro_noise_rad_s_sqrt_hz
        prm[PRM_ACC_N] = p.accel_noise_m_s2_sqrt_hz
        prm[PRM_BG_W] = p.gyro_bias_walk_rad_s_sqrt_s
        prm[PRM_BA_W] = p.accel_bias_walk_m_s2_sqrt_s
        prm[PRM_BH_W] = p.baro_offset_walk_m_sqrt_s
        prm[PRM_BM_W] = p.mag_bias_walk_gauss_sqrt_s
        prm[PRM_BP_TAU] = p.gnss_pos_tau_s
        prm[PRM_DT_MAX] = self._dt_max_s = 5.0 / p.imu_rate_hz
        prm[PRM_VAR_MIN] = _VAR_MIN
        prm[PRM_OUT_TAU] = p.output_tau_s
        self._accel_offsets = _vec3(p.accel_offsets_m_s2)
        #: every aid source's status record (innovation, test ratio, times, resets)
        self.aid_sources = src = AidSources(p, mem.aid)
        out = OutputPredictor(mem.w)
        self._out = out
        self.state = out.state
        self._const_pos = cp = ConstPosControl(p, mem, src)
        self._gnss = GnssControl(p, mem, src, out, cp.leave)
        self._baro = BaroControl(p, mem, src.baro)
        self._mag = MagControl(p, mem, src.mag, field)
        self._tether = (TetherControl(p, mem, src, out, cp.leave) if p.tether_aid
                        else None)
        #: the tether fix checked against the GNSS (None: not checked)
        self.tether_check = (TetherFixCheck(p.tether_fix.gnss_check, p.gnss_pos_tau_s,
                                            p.gnss_pos_correlated_fraction)
                             if p.tether_aid and p.tether_fix.gnss_check.enabled else None)
        self._zero_vel = ZeroVelocityControl(p, mem, src.zero_vel)
        if p.drag.enabled and drag is None:
            drag = DragModel.default_vehicle()
        self._drag = (DragControl(p, mem, src.drag, drag) if p.drag.enabled else None)
        lp = p.drag.tether_line
        if lp.enabled and (line is None or not p.drag.enabled):
            raise ValueError("drag.tether_line.enabled: the filter needs the drag fusion "
                             "(its wind states) and the line's model")
        self._line = (TetherLineControl(p, mem, src, out, cp.leave, line, _vec3(attachment_m))
                      if lp.enabled and line is not None else None)
        self._align = Alignment(p, mem, src, self.gravity_m_s2, field)
        self._aligned = False
        #: when the filter aligned [s] (None: not yet)
        self.aligned_at_s: float | None = None
        #: the last IMU sample's time [s] (None: none yet)
        self._t_last: float | None = None
        self._predict_k = entry_point(predict_output_kernel, mem.w, mem.P, mem.buf,
                                      mem.meta, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._rates = mem.w[W_RATES:W_RATES + 3]

    # ----- properties
    @property
    def aligned(self) -> bool:
        """Whether the filter is initialised (static alignment done, a fix taken)."""
        return self._aligned

    @property
    def align_time_s(self) -> float:
        """How long the alignment averages [s] (shorter after :meth:`start_in_air`)."""
        return self._align.align_time_s

    @property
    def covariance(self) -> np.ndarray:
        """The error-state covariance (28 x 28, a copy): dp [m], dv [m/s], dtheta [rad]
        (inertial axes), db_g [rad/s], db_a [m/s^2], db_h [m], db_m [gauss], db_p [m],
        dU [m/s] (east, north), the line's dk_c, dk_w, db_psi, db_eps [rad]."""
        return self._mem.P.copy()

    @property
    def gyro_bias_rad_s(self) -> Vec3:
        """The gyro bias estimate [rad/s], body FLU."""
        return _vec3(self._mem.x[X_BG:X_BG + 3])

    @property
    def accel_bias_m_s2(self) -> Vec3:
        """The accelerometer bias estimate [m/s^2], body FLU."""
        return _vec3(self._mem.x[X_BA:X_BA + 3])

    @property
    def mag_bias_gauss(self) -> Vec3:
        """The magnetometer bias estimate [gauss], body FLU (0 with heading fusion)."""
        return _vec3(self._mem.x[X_BM:X_BM + 3])

    @property
    def gnss_wander_m(self) -> Vec3:
        """The estimate of the GNSS receiver's position error [m], ENU (0 unless
        ``gnss_pos_tau_s`` > 0)."""
        return _vec3(self._mem.x[X_BP:X_BP + 3])

    @property
    def baro_offset_m(self) -> float:
        """The barometer's height offset estimate [m] (above the alignment's reference)."""
        return float(self._mem.x[X_BH])

    @property
    def wind_m_s(self) -> Vec3:
        """The wind states [m/s]: the velocity the air moves with (east, north; vertical
        0). Zero until drag fusion starts; kept while inhibited on the ground."""
        x = self._mem.x
        return (float(x[X_W]), float(x[X_W + 1]), 0.0)

    @property
    def wind_estimated(self) -> bool:
        """Whether the wind states are estimated now (drag fusion on, in the air)."""
        return self._drag is not None and self._drag.active

    @property
    def drag_fusion(self) -> bool:
        """Whether the filter fuses the drag's specific force (and has wind states)."""
        return self._drag is not None

    @property
    def tether_line_fusion(self) -> bool:
        """Whether the filter fuses the raw tether reading tightly (with the line's
        states)."""
        return self._line is not None

    @property
    def line_states(self) -> tuple[float, float, float, float]:
        """The line's states: its weight and drag per metre as factors on the belief
        (k_w, k_c) and the guide arm's azimuth and elevation biases [rad]; (1, 1, 0, 0)
        without the raw reading's fusion."""
        return (1.0, 1.0, 0.0, 0.0) if self._line is None else self._line.states

    @property
    def line_weight_belief_n_m(self) -> float | None:
        """The line's weight per metre [N/m] that ``k_w`` multiplies (the winder's
        estimate once a reading carried one); None without the raw reading's fusion."""
        return None if self._line is None else self._line.weight_belief_n_m

    @property
    def line_sigmas(self) -> tuple[float, float, float, float]:
        """The standard deviations of :attr:`line_states` (0 without the raw reading's
        fusion)."""
        if self._line is None:
            return (0.0, 0.0, 0.0, 0.0)
        d = np.diag(self._mem.P)[IDX_LINE:IDX_LINE + N_LINE]
        s = [math.sqrt(max(float(v), 0.0)) for v in d]
        return (s[LINE_KW], s[LINE_KC], s[LINE_BPSI], s[LINE_BEPS])

    @property
    def gnss_resets(self) -> int:
        """Times the position and velocity were reset to the GNSS."""
        return self.aid_sources.gnss_pos.resets

    @property
    def tether_resets(self) -> int:
        """Times the position was reset to a tether fix."""
        return self.aid_sources.tether.resets

    @property
    def tether_refused(self) -> int:
        """Tether fixes refused as too old, not finite or not positive definite."""
        return 0 if self._tether is None else self._tether.refused

    def position_sigma_m(self) -> Vec3:
        """Standard deviations of the position estimate [m] (east, north, up)."""
        a, b, c = self._mem.pos_var.tolist()
        return (math.sqrt(max(a, 0.0)), math.sqrt(max(b, 0.0)), math.sqrt(max(c, 0.0)))

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
            self._rates[:] = (gx, gy, gz)
            self._align.add_imu(t_s, gx, gy, gz, ax, ay, az)
            self._try_align(t_s)
            self._t_last = t_s
            return
        t_last = self._t_last if self._t_last is not None else t_s
        dt = min(max(t_s - t_last, 0.0), self._dt_max_s)
        self._t_last = t_s
        m = self._mem
        self._predict_k(m.w, m.P, m.buf, m.meta, t_s, dt, gx, gy, gz, ax, ay, az)
        self._const_pos.step(t_s)

    def fuse_gnss(self, t_s: float, pos_enu_m: Sequence[float],
                  vel_enu_m_s: Sequence[float], eph_m: float, epv_m: float) -> bool:
        """A GNSS fix arriving at ``t_s`` [s] (taken ``gnss_delay_s`` earlier): position
        [m] and velocity [m/s] in the inertial ENU frame, the receiver's claimed
        horizontal and vertical accuracies [m] (its noise). Returns whether its position
        was fused (velocity may be fused alone; see :meth:`status`)."""
        # the fix checked once, for the tether check and the alignment alike
        fix = (usable_fix(self.params, pos_enu_m, vel_enu_m_s, eph_m, epv_m)
               if self.tether_check is not None or not self._aligned else None)
        if self.tether_check is not None and fix is not None:
            self.tether_check.add_gnss(t_s - self.params.gnss_delay_s, fix[0], fix[1],
                                       eph_m, epv_m)
        if self._aligned:
            return self._gnss.fuse(t_s, pos_enu_m, vel_enu_m_s, eph_m, epv_m)
        if fix is not None:
            self.aid_sources.gnss_pos.time_last_attempt = t_s
            self._align.add_gnss_fix(t_s, fix[0], fix[1], eph_m, epv_m)
            self._try_align(t_s)
        return False

    def fuse_baro(self, t_s: float, pressure_alt_m: float) -> bool:
        """A barometer's pressure altitude [m AMSL] arriving at ``t_s`` [s]; its height is
        taken above the reference set at alignment (the pressure altitude then minus the
        GNSS height). Returns whether it was fused."""
        if self._aligned:
            return self._baro.fuse(t_s, pressure_alt_m)
        if math.isfinite(pressure_alt_m):
            self._align.add_baro(pressure_alt_m)
        return False

    def fuse_mag(self, t_s: float, mag_flu_gauss: Sequence[float]) -> bool:
        """A magnetometer sample [gauss], body FLU, at ``t_s`` [s]. Returns whether it was
        fused (samples within ``mag_min_interval_s`` of the last fused one are skipped)."""
        if self._aligned:
            return self._mag.fuse(t_s, mag_flu_gauss)
        m = finite_sample(mag_flu_gauss)
        if m is not None:
            self._align.add_mag(t_s, *m)
        return False

    def fuse_tether(self, t_s: float, t_meas_s: float, pos_m: Sequence[float],
                    cov_m2: Sequence[Sequence[float]]) -> bool:
        """A tether fix arriving at ``t_s`` [s], taken at ``t_meas_s`` [s] (its timestamp,
        the companion's clock): position [m] and covariance [m^2] (inertial, z up), with
        ``tether_noise_min_m`` added on each axis. Before alignment it is kept for it (the
        position source when there is no GNSS). Returns whether it was fused."""
        tc = self._tether
        if tc is None:
            return False
        fix = tc.check(t_s, t_meas_s, pos_m, cov_m2)
        if fix is None:
            return False
        if self.tether_check is not None:
            fix = (fix[0], *self.tether_check.correct(*fix))
        if self._aligned:
            return tc.fuse(t_s, fix)
        self._align.add_tether_fix(fix[0], fix[1], cov_matrix(fix[2]))
        self._try_align(t_s)
        return False

    def fuse_tether_reading(self, t_s: float, t_meas_s: float, length_m: float,
                            tension_n: float, azimuth_rad: float, elevation_rad: float,
                            in_air: bool, weight_n_m: float = math.nan) -> bool | None:
        """The winch's raw tether reading arriving at ``t_s`` [s], taken at ``t_meas_s``
        [s]: paid-out length [m], tension [N], exit azimuth and elevation as read [rad],
        the winder's estimate of the line's weight per metre [N/m] (NaN: none; the line
        model's belief when it has one, docs/estimation.md §11); the vehicle in the air or
        not. Returns None when it is not fused tightly (no such fusion, not aligned, a
        line on the ground or slack, no GNSS and the line's states not learnt yet: the
        ground station's fix of the same sample is the tether's position then), else
        whether it was fused."""
        lc = self._line
        if lc is None:
            return None
        lc.take_weight(t_s, weight_n_m, self._aligned)
        if not self._aligned:
            return None
        return lc.fuse(t_s, t_meas_s, length_m, tension_n, azimuth_rad, elevation_rad,
                       in_air)

    def drag_due(self, t_s: float) -> bool:
        """Whether :meth:`fuse_drag` would fuse (or start) at ``t_s`` [s] in the air: the
        caller computes the tether's pull only then."""
        d = self._drag
        return d is not None and self._aligned and not self.aid_sources.drag.too_soon(t_s)

    def fuse_drag(self, t_s: float, in_air: bool, tether_pull_n: Sequence[float]) -> bool:
        """The drag's specific force at ``t_s`` [s] (the IMU's since the last fusion, every
        ``drag.interval_s``), with the tether's modelled pull on the vehicle [N]
        (inertial); ``in_air`` False inhibits the wind states. Returns whether it was
        fused (never without ``drag.enabled`` or before alignment)."""
        d = self._drag
        return d is not None and self._aligned and d.fuse(t_s, in_air, tether_pull_n)

    def fuse_stationary(self, t_s: float, height_m: float | None = None) -> bool:
        """The vehicle is at rest on its gear at ``t_s`` [s] (the caller knows: landed and
        disarmed): a zero velocity fused, and the height ``height_m`` [m] it rests at
        (None: not known) with ``ground_height_noise_m``, every ``stationary_interval_s``.
        Returns whether it was fused."""
        return self._aligned and self._zero_vel.fuse(t_s, height_m)

    def start_in_air(self) -> None:
        """The first fix found the vehicle in the air (a simulation started in hover): it
        hovers open loop while the filter aligns, over ``air_align_time_s``, on the specific
        force less the acceleration the fixes' velocities show."""
        self._align.start_in_air()

    def _try_align(self, t_s: float) -> None:
        if self._align.try_align(t_s):
            self._aligned = True
            self.aligned_at_s = t_s
            self._t_last = t_s
            self._baro.ref_m = self._align.baro_ref_m
            if self._line is not None:
                self._line.start()

    # ----- status
    def status(self, t_s: float | None = None) -> FilterStatus:
        """Health, flags and checks at ``t_s`` [s] (default: the last IMU sample's time)."""
        t = self._t_last if t_s is None else t_s
        m = self._mem
        return filter_status(self.params, 0.0 if t is None else t, self._aligned, m.x, m.P,
                             float(m.w[W_HEADING_INNOV]), self.aid_sources,
                             self._const_pos.held is not None)
