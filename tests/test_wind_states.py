"""The filter's wind states and the drag's specific-force fusion (companion/ekf/drag.py;
docs/estimation.md §11): the measurement's Jacobian against finite differences of its
model, the states' inhibition, and the wind learnt from an analytic hover and circle in a
steady wind sampled through the plant's sensor models."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.ekf import DragFusionParams, EstimatorParams, NavFilter
from companion.ekf.drag import DragModel, drag_prediction
from companion.ekf.layout import (
    IDX_BA,
    IDX_TH,
    IDX_V,
    IDX_W,
    N_ERR,
    N_PRM,
    NX,
    PRM_DRAG_ALL,
    PRM_DRAG_MX,
    PRM_DRAG_MY,
    PRM_DRAG_QX,
    PRM_DRAG_QY,
    PRM_MASS_INV,
    W_DRAG_SUM,
    X_Q,
    X_V,
    X_W,
)
from sitl.sensors import SensorSuite, specific_force_flu
from tests.ekf_harness import IMU_HZ, G, _attitude, _quat, circle, params_for, rtk_noise
from tuavdefs.frames import euler_to_quat, quat_multiply, quat_to_euler, quat_to_matrix
from tuavdefs.params import VehicleParams

RHO = 1.225
VEH = VehicleParams()
MODEL = DragModel.from_vehicle(VEH, RHO)
ON = DragFusionParams(enabled=True)
OFF = DragFusionParams(enabled=False)


def _prm() -> np.ndarray:
    prm = np.zeros(N_PRM)
    prm[PRM_DRAG_QX] = 0.5 * RHO / MODEL.bcoef_x_kg_m2
    prm[PRM_DRAG_QY] = 0.5 * RHO / MODEL.bcoef_y_kg_m2
    prm[PRM_DRAG_MX] = MODEL.mcoef_x_1_s
    prm[PRM_DRAG_MY] = MODEL.mcoef_y_1_s
    prm[PRM_MASS_INV] = 1.0 / MODEL.mass_kg
    return prm


def _exp_q(th: np.ndarray) -> tuple[float, float, float, float]:
    a = float(np.linalg.norm(th))
    if a == 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(a / 2) / a
    return (math.cos(a / 2), th[0] * s, th[1] * s, th[2] * s)


def test_model_is_the_vehicles():
    """EKF3's coefficients from the vehicle model: B = m / C_dA, M = D / m."""
    assert MODEL.bcoef_x_kg_m2 == pytest.approx(VEH.mass_kg / VEH.drag_area_m2[0])
    assert MODEL.mcoef_y_1_s == pytest.approx(VEH.drag_coeff_n_s_m[1] / VEH.mass_kg)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_jacobian_matches_finite_differences(seed):
    """The analytic rows (velocity, attitude error, wind) against central differences of
    the predicted specific force, the attitude perturbed as ``Exp(dtheta) R``."""
    rng = np.random.default_rng(seed)
    x = np.zeros(NX)
    x[X_Q:X_Q + 4] = euler_to_quat(*rng.uniform(-0.4, 0.4, 2), rng.uniform(-3, 3))
    x[X_V:X_V + 3] = rng.uniform(-4, 4, 3)
    x[X_W:X_W + 2] = rng.uniform(-8, 8, 2)
    pull = tuple(rng.uniform(-3, 3, 3))
    prm = _prm()
    h = np.zeros((2, N_ERR))
    drag_prediction(x, prm, *pull, h)
    eps = 1e-6
    scratch = np.zeros((2, N_ERR))

    def pred(xx):
        return np.array(drag_prediction(xx, prm, *pull, scratch))

    for col in list(range(IDX_V, IDX_V + 3)) + list(range(IDX_TH, IDX_TH + 3)) + [IDX_W,
                                                                             IDX_W + 1]:
        d = np.zeros(3)
        xp, xm = x.copy(), x.copy()
        if IDX_V <= col < IDX_V + 3:
            xp[X_V + col - IDX_V] += eps
            xm[X_V + col - IDX_V] -= eps
        elif IDX_W <= col < IDX_W + 2:
            xp[X_W + col - IDX_W] += eps
            xm[X_W + col - IDX_W] -= eps
        else:
            d[col - IDX_TH] = eps
            q = tuple(x[X_Q:X_Q + 4])
            xp[X_Q:X_Q + 4] = quat_multiply(_exp_q(d), q)
            xm[X_Q:X_Q + 4] = quat_multiply(_exp_q(-d), q)
        num = (pred(xp) - pred(xm)) / (2 * eps)
        np.testing.assert_allclose(h[:, col], num, atol=1e-7, rtol=1e-5)
    assert h[0, IDX_BA] == 1.0 and h[1, IDX_BA + 1] == 1.0


def test_prediction_is_the_drag_and_pull():
    """Level, at rest in a wind along body x: the drag pushes downwind by
    (rho/(2B) U + M) U, the pull adds F/m."""
    x = np.zeros(NX)
    x[X_Q] = 1.0
    x[X_W] = 6.0
    ax, ay = drag_prediction(x, _prm(), 0.0, 2.0, -5.0, np.zeros((2, N_ERR)))
    assert ax == pytest.approx((0.5 * RHO / MODEL.bcoef_x_kg_m2 * 6.0 + MODEL.mcoef_x_1_s)
                               * 6.0)
    assert ay == pytest.approx(2.0 / MODEL.mass_kg)


def _drag_accel(R: np.ndarray, vel, wind) -> np.ndarray:
    """The vehicle model's drag acceleration [m/s^2] (inertial), all three body axes."""
    vr = R.T @ (np.asarray(vel) - np.asarray(wind))
    q = 0.5 * RHO * float(np.linalg.norm(vr))
    d = np.array([-(VEH.drag_coeff_n_s_m[i] + q * VEH.drag_area_m2[i]) * vr[i]
                  for i in range(3)]) / VEH.mass_kg
    return R @ d


def _balanced(pos, vel, acc, wind, yaw):
    """The attitude whose thrust (body z) with the drag gives ``acc``."""
    R = _attitude(acc, yaw)
    for _ in range(6):
        R = _attitude(np.asarray(acc) - _drag_accel(R, vel, wind), yaw)
    return R


def _fly(truth, wind, duration_s, params, yaw_rate=0.0):
    """Fly ``truth(t) -> (pos, vel, acc, yaw)`` through the sensors, fusing the drag with
    no tether; returns (t, the filter's wind) after alignment."""
    noise = rtk_noise(3)
    suite = SensorSuite(noise=noise)
    f = NavFilter(params, G, suite.earth_field_enu_gauss, MODEL)
    dt = 1.0 / IMU_HZ
    out = []
    last_R = None
    for k in range(int(duration_s * IMU_HZ) + 1):
        t = k * dt
        pos, vel, acc, yaw = truth(t)
        R = _balanced(pos, vel, acc, wind, yaw)
        q = _quat(R)
        rates = (0.0, 0.0, 0.0)
        if last_R is not None:
            W = last_R.T @ (R - last_R) / dt
            rates = (0.5 * (W[2, 1] - W[1, 2]), 0.5 * (W[0, 2] - W[2, 0]),
                     0.5 * (W[1, 0] - W[0, 1]))
        last_R = R
        imu = suite.imu(specific_force_flu(acc, q, G), rates, q, dt)
        f.predict(t, imu.gyro_flu_rad_s, imu.accel_flu_m_s2)
        f.fuse_baro(t, suite.baro(suite.home[2] + pos[2], dt).pressure_alt_m)
        f.fuse_mag(t, imu.mag_flu_gauss)
        if k % 25 == 0:
            fix = suite.gps(pos, vel, 0.1)
            f.fuse_gnss(t, fix.position_enu_m, fix.velocity_enu_m_s, fix.eph_m, fix.epv_m)
        if f.aligned and f.drag_due(t):
            f.fuse_drag(t, t > 2.0, (0.0, 0.0, 0.0))
        if f.aligned:
            out.append((t, *f.wind_m_s[:2]))
    return f, np.array(out)


def test_wind_inhibited_on_the_ground_and_before_drag_fusion():
    """Inhibited (EKF3's inhibitWindStates): zero covariance and no walk until drag fusion
    starts in the air; its prior then; zero again on the ground."""
    params = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON)
    wind = (0.0, 0.0, 0.0)
    f, _ = _fly(lambda t: ((0.0, 0.0, 20.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3), wind,
                1.9, params)
    P = f.covariance
    assert f.aligned and not f.wind_estimated
    assert not np.any(P[IDX_W:IDX_W + 2, :]) and not np.any(P[:, IDX_W:IDX_W + 2])
    f.fuse_drag(3.0, True, (0.0, 0.0, 0.0))
    assert f.wind_estimated
    assert f.covariance[IDX_W, IDX_W] == pytest.approx(params.drag.wind_sigma_m_s ** 2)
    f.fuse_drag(3.1, False, (0.0, 0.0, 0.0))
    assert not f.wind_estimated and not np.any(f.covariance[IDX_W:IDX_W + 2, :])
    plain = NavFilter(EstimatorParams(drag=OFF), G, (0.2, 0.0, -0.4))
    assert not plain.drag_fusion and plain.wind_m_s == (0.0, 0.0, 0.0)


def test_drag_fusion_is_the_default():
    """EstimatorParams() fuses the drag (EKF3's way: WIND is the filter's); a filter built
    without a drag model takes the companion's default vehicle's (the controllers' model,
    the position loop's quadratic drag area and linear drag) in the default air."""
    assert EstimatorParams().drag.enabled
    f = NavFilter(EstimatorParams(), G, (0.2, 0.0, -0.4))
    assert f.drag_fusion
    prm = f._mem.prm
    area, lin, mass = VEH.drag_area_m2, VEH.drag_coeff_n_s_m, VEH.mass_kg
    for i, (q, m) in enumerate(((PRM_DRAG_QX, PRM_DRAG_MX), (PRM_DRAG_QY, PRM_DRAG_MY))):
        assert prm[q] == pytest.approx(0.5 * RHO * area[i] / mass, rel=1e-12)
        assert prm[m] == pytest.approx(lin[i] / mass, rel=1e-12)
    assert prm[PRM_MASS_INV] == pytest.approx(1.0 / mass, rel=1e-12)


def test_drag_fusion_moves_the_wind_alone():
    """A drag fusion whose model is far off (the tether pulling 6 N sideways that the
    model is told is 0): only the wind states and their covariance rows move; every other
    state, its covariance block and the output stay as they were, to the bit (Schmidt's
    update: the drag's model error never reaches the attitude or the position). The
    innovation's variance holds the model's and the pull's error as fractions of what
    they predict."""
    params = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON)
    f, _ = _fly(lambda t: ((0.0, 0.0, 20.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3),
                (4.0, 0.0, 0.0), 6.0, params)
    assert f.wind_estimated
    mem = f._mem
    for _ in range(10):     # the IMU's sums for the next fusion
        mem.w[W_DRAG_SUM:W_DRAG_SUM + 3] += (0.3, -0.4, 1.0)
    x0, P0, out0 = mem.x.copy(), mem.P.copy(), f.state()
    t = 6.0 + params.drag.interval_s
    pull = (0.0, 6.0, 0.0)
    assert f.fuse_drag(t, True, pull)
    rest = np.r_[0:IDX_W, IDX_W + 2:N_ERR]
    xrest = np.r_[0:X_W, X_W + 2:NX]
    assert np.array_equal(mem.x[xrest], x0[xrest])
    assert np.array_equal(mem.P[np.ix_(rest, rest)], P0[np.ix_(rest, rest)])
    assert f.state() == out0
    assert not np.array_equal(mem.x[X_W:X_W + 2], x0[X_W:X_W + 2])
    assert np.all(np.diag(mem.P)[IDX_W:IDX_W + 2] < np.diag(P0)[IDX_W:IDX_W + 2])
    np.testing.assert_allclose(mem.P, mem.P.T, atol=0.0)
    # the innovation's variance: H P H' + noise^2 + (f_d drag)^2 + (f_p pull)^2 per axis
    h = np.zeros((2, N_ERR))
    px, py = drag_prediction(x0, mem.prm, *pull, h)
    R = quat_to_matrix(tuple(x0[X_Q:X_Q + 4]))
    ub = np.asarray(R).T @ np.asarray(pull) / MODEL.mass_kg
    dp = params.drag
    row = f.aid_sources.drag
    for i, pred in enumerate((px, py)):
        noise = (dp.noise_m_s2 ** 2 + (dp.model_error_fraction * (pred - ub[i])) ** 2
                 + (dp.pull_error_fraction * ub[i]) ** 2)
        assert row.innovation_variance[i] == pytest.approx(h[i] @ P0 @ h[i] + noise,
                                                           rel=1e-9)
    # correct_navigation: the same measurement moves the velocity and the attitude too
    mem.x[:], mem.P[:] = x0, P0
    mem.prm[PRM_DRAG_ALL] = 1.0
    for _ in range(10):
        mem.w[W_DRAG_SUM:W_DRAG_SUM + 3] += (0.3, -0.4, 1.0)
    assert f.fuse_drag(t + 0.5, True, pull)
    assert not np.array_equal(mem.x[X_V:X_V + 3], x0[X_V:X_V + 3])
    assert not np.array_equal(mem.x[X_Q:X_Q + 4], x0[X_Q:X_Q + 4])
    assert EstimatorParams(drag=ON.replace(correct_navigation=True)).drag.correct_navigation


@pytest.mark.parametrize("wind,yaw", [((6.0, 0.0, 0.0), 0.3), ((-3.0, 7.0, 0.0), 2.0)])
def test_hover_learns_the_wind(wind, yaw):
    """A hover in a steady wind, tilted into it: the wind states converge to it (the
    drag's specific force at rest says the wind on both axes)."""
    params = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON)
    _, w = _fly(lambda t: ((5.0, 3.0, 20.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), yaw), wind,
                25.0, params)
    late = w[w[:, 0] > 18.0, 1:3]
    err = late - np.asarray(wind[:2])
    assert np.sqrt((err ** 2).sum(axis=1).mean()) < 0.3


def test_a_wind_far_off_is_reset_to():
    """A hover in 14 m/s: at the start (the wind states at 0) the model's slope is the
    linear drag's alone, the innovation beyond the gate, so without a reset the wind is
    never learnt; rejected for ``drag.reset_s`` the states are set to the wind the drag
    model inverted says (once), and fusion then holds them to it."""
    wind = (14.0, 0.0, 0.0)

    def hover(t):
        return (5.0, 3.0, 20.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.3

    never = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON.replace(reset_s=1e9))
    f, w = _fly(hover, wind, 8.0, never)
    assert f.aid_sources.drag.resets == 0 and np.all(w[:, 1:3] == 0.0)
    params = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON)
    f, w = _fly(hover, wind, 12.0, params)
    assert f.aid_sources.drag.resets == 1
    late = w[w[:, 0] > 6.0, 1:3]
    err = late - np.asarray(wind[:2])
    assert np.sqrt((err ** 2).sum(axis=1).mean()) < 0.3


def test_circle_learns_the_wind():
    """A circle of 8 m at 3 m/s in 7 m/s of wind: the air-relative speed swings 4-10 m/s
    round the circle, the wind stays the same."""
    wind = (5.0, -5.0, 0.0)
    circ = circle(radius_m=8.0, speed_m_s=3.0, height_m=20.0, hover_s=3.0, ramp_s=5.0)

    def truth(t):
        tr = circ(t)
        return tr.pos, tr.vel, tr.acc, quat_to_euler(tr.quat)[2]

    params = params_for(rtk_noise(3), gnss_delay_s=0.0, drag=ON)
    _, w = _fly(truth, wind, 30.0, params)
    late = w[w[:, 0] > 20.0, 1:3]
    err = late - np.asarray(wind[:2])
    assert np.sqrt((err ** 2).sum(axis=1).mean()) < 0.4


def test_wind_reported_is_the_filters():
    """WIND's source (Companion.wind_estimate) is the filter's wind states with drag
    fusion (the default), whatever the position loop's disturbance says; without it the
    disturbance's (0 on the ground)."""
    from companion.gains import FlightControlParams
    from companion.navigation import NavigationParams
    from companion.onboard import Companion
    from tuavdefs.params import SystemParams

    c = Companion(SystemParams(), FlightControlParams(), NavigationParams())
    c.filter._mem.x[X_W:X_W + 2] = (3.0, -4.0)
    assert c.wind_estimate() == (3.0, -4.0, 0.0)
    plain = Companion(SystemParams(), FlightControlParams(), NavigationParams(),
                      EstimatorParams(drag=OFF))
    assert not plain.filter.drag_fusion
    assert plain.wind_estimate() == (0.0, 0.0, 0.0)      # on the ground


def test_wind_on_the_lumped_line_in_the_wind():
    """Offline, the lumped truth (the line's own drag pulls the vehicle), hovering at
    (8, 4, 15) m in 6 m/s with light turbulence: the filter's wind against the plant's
    wind at the vehicle averaged over the last 10 s, within 1 m/s RMS once settled
    (issue 33). The tether's pull comes from the winch's raw reading in the filter's
    wind: with the windless model it was 1.7 m/s off."""
    from tuav_sitl.offline import OfflineRunner
    from tuav_sitl.scenario import load_scenario

    sc = load_scenario("hover-gnss-loss").with_tether_model("lumped")
    sc = sc.replace(wind=sc.wind.replace(steady_m_s=(6.0, 0.0, 0.0), turbulence="light"),
                    duration_s=40.0, faults=(),
                    estimator=sc.estimator.replace(drag=ON))
    runner = OfflineRunner(sc)
    rows = []
    record = runner._record

    def rec(t, out, fresh):
        record(t, out, fresh)
        f = runner.companion.filter
        if f.aligned:
            rows.append((t, *f.wind_m_s[:2], *runner.plant.wind_m_s[:2]))

    runner._record = rec
    runner.run()
    a = np.array(rows)
    n = int(round(10.0 / (a[1, 0] - a[0, 0])))
    mean = np.stack([np.convolve(a[:, 3 + i], np.ones(n) / n)[:len(a)] for i in range(2)],
                    axis=1)
    late = a[:, 0] > 15.0
    err = a[late, 1:3] - mean[late]
    assert np.sqrt((err ** 2).sum(axis=1).mean()) < 1.0
