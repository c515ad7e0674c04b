"""Control laws against independent truth: the plant's catenary, numerical arc lengths, and
their Lyapunov functions on exact models of the subsystems they were derived for."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from companion.attitude import AttitudeController, euler_rate_matrices
from companion.gains import FlightControlParams
from companion.position import PositionController, attitude_from_thrust_vector
from companion.tether_model import TetherModel
from groundstation.lbar import LBarEstimator, LBarParams, catenary_length_m
from groundstation.winder_control import WinderController, WinderControlParams
from sitl.catenary import CatenaryRegime, catenary_end_forces
from sitl.winder import WinderModel
from tuavdefs.frames import euler_to_quat, quat_to_matrix
from tuavdefs.params import TetherParams, WinderParams

W = 0.034 * 9.81
RNG = np.random.default_rng(20261122)


# ---------------------------------------------------------------- onboard tether model
def _cases(n):
    out = []
    while len(out) < n:
        h, v = RNG.uniform(0.5, 40.0), RNG.uniform(0.5, 40.0)
        chord = math.hypot(h, v)
        length = RNG.uniform(chord * 1.001, (h + v) * 1.2)
        out.append((h, v, length))
    return out


def test_onboard_model_equals_an_inextensible_catenary():
    """With EA huge, the plant's elastic solver is the inextensible catenary."""
    model = TetherModel(W)
    regimes = set()
    for h, v, length in _cases(400):
        fah, fav, fbh, fbv, info = catenary_end_forces(h, v, length, 1e12, W)
        regimes.add(info.regime)
        phi = RNG.uniform(-math.pi, math.pi)
        est = model.estimate((h * math.cos(phi), h * math.sin(phi), v), length)
        want = (fbh * math.cos(phi), fbh * math.sin(phi), fbv)
        assert np.allclose(est.force_n, want, rtol=1e-6, atol=1e-7), (h, v, length, info)
    assert {CatenaryRegime.SUSPENDED, CatenaryRegime.TOUCHDOWN, CatenaryRegime.SLACK} <= regimes


def test_onboard_model_with_measured_tension_tracks_the_elastic_truth():
    model = TetherModel(W)
    ea = TetherParams().axial_stiffness_n
    for h, v, length in _cases(200):
        fah, fav, fbh, fbv, _ = catenary_end_forces(h, v, length, ea, W)
        drum = math.hypot(fah, fav)
        est = model.estimate((h, 0.0, v), length, drum_tension_n=drum)
        top = math.hypot(fbh, fbv)
        # the inextensible identity T_top = T_drum + w v is off by the stretch only
        assert np.linalg.norm(est.force_n) == pytest.approx(top, rel=2e-3, abs=1e-6)


# ---------------------------------------------------------------- L-bar
@pytest.mark.parametrize("seed", range(5))
def test_catenary_length_equals_the_arc_length(seed):
    rng = np.random.default_rng(seed)
    a, h, v = rng.uniform(2, 30), rng.uniform(0.5, 40), rng.uniform(0.5, 40)
    # vertex x0 from v = a (cosh((h - x0)/a) - cosh(x0/a)), solved independently
    from scipy.optimize import brentq

    x0 = brentq(lambda x: a * (math.cosh((h - x) / a) - math.cosh(x / a)) - v, -1e3, h)
    arc, _ = quad(lambda x: math.cosh((x - x0) / a), 0.0, h, epsabs=1e-12, epsrel=1e-12)
    assert catenary_length_m(a, h, v) == pytest.approx(arc, rel=1e-9)


def test_paper_waypoint_length_is_longer_than_the_straight_line():
    # the paper's formula gives 15.2 m here, shorter than the 19.0 m chord
    length = catenary_length_m(15.0, math.hypot(6.0, 10.0), 15.0)
    assert length > math.sqrt(6 ** 2 + 10 ** 2 + 15 ** 2)


def test_lbar_keeps_the_tether_off_the_ground_and_slack():
    est = LBarEstimator(LBarParams(), W)
    ea = TetherParams().axial_stiffness_n
    for _ in range(300):
        h, v = RNG.uniform(0.5, 35.0), RNG.uniform(3.0, 40.0)
        if v / h <= math.tan(LBarParams().min_exit_angle_rad) * 1.05:
            continue
        length, a = est.length((h, 0.0, v))
        fah, fav, fbh, fbv, info = catenary_end_forces(h, v, length, ea, W)
        assert info.regime == CatenaryRegime.SUSPENDED, (h, v, length)
        assert fav >= 0.0                                   # leaves the winder upward
        assert length - math.hypot(h, v) >= LBarParams().min_slack_m - 1e-12
        assert fah <= max(LBarParams().target_horizontal_tension_n, fah) + 1e-9


def test_lbar_rate_matches_finite_differences():
    est = LBarEstimator(LBarParams(), W)
    p, vel = np.array([6.0, -3.0, 15.0]), np.array([1.2, 0.7, -0.4])
    got = est.estimate(tuple(p), tuple(vel)).rate_m_s
    dt = 1e-5
    fd = (est.length(tuple(p + vel * dt))[0] - est.length(tuple(p - vel * dt))[0]) / (2 * dt)
    assert got == pytest.approx(fd, rel=1e-6)


# ---------------------------------------------------------------- position loop
def test_position_lyapunov_decreases_on_its_design_model():
    """m p'' = f + F_t - m g e3 + m d with d constant, f = f_d exactly: the composite
    V = |e1|^2/2 + |e2|^2/2 + d_tilde' Gamma^-1 d_tilde / 2 must never increase."""
    gains = FlightControlParams()
    m, g, dt = 2.84, 9.81, 1e-3
    pc = PositionController(gains, m, g, max_total_thrust_n=80.0)
    d = np.array([0.3, -0.2, 0.15])
    ft = np.array([-1.0, 0.5, -6.0])
    p, v = np.array([1.0, -0.5, 10.5]), np.array([0.2, 0.0, -0.3])
    ref = (0.0, 0.0, 10.0)
    gam = np.array(gains.disturbance_gain_1_s2)
    k1, k2 = np.array(gains.pos_k1_1_s), np.array(gains.pos_k2_1_s)
    values, rates = [], []
    for _ in range(20000):
        out = pc.update(dt, tuple(p), tuple(v), ref, (0, 0, 0), (0, 0, 0), 0.0,
                        tether_force_n=tuple(ft))
        assert not out.saturated
        dt_ = d - np.array(out.disturbance_m_s2)
        values.append(out.lyapunov + 0.5 * float(dt_ @ (dt_ / gam)))
        e1, e2 = np.array(out.e1_m), np.array(out.e2_m_s)
        rates.append(-float(e1 @ (k1 * e1)) - float(e2 @ (k2 * e2)))
        acc = (np.array(out.thrust_vector_n) + ft) / m - [0, 0, g] + d
        v = v + acc * dt
        p = p + v * dt
    values, rates = np.array(values), np.array(rates)
    assert np.all(np.diff(values) <= 1e-6 * values[:-1] + 1e-12)
    # the derivation's identity dV/dt = -e1'K1e1 - e2'K2e2, to the Euler step's accuracy
    num = np.diff(values) / dt
    mid = 0.5 * (rates[1:] + rates[:-1])
    sig = np.abs(mid) > 1e-6
    assert np.all(np.abs(num[sig] - mid[sig]) <= 0.02 * np.abs(mid[sig]))
    assert np.linalg.norm(p - ref) < 1e-3
    assert np.allclose(pc.d_hat, d, atol=1e-2)


def test_position_loop_limits_tilt_and_thrust():
    gains = FlightControlParams()
    pc = PositionController(gains, 2.84, 9.81, max_total_thrust_n=80.0)
    out = pc.update(0.004, (0, 0, 10), (0, 0, 0), (100.0, 0, 10), (0, 0, 0), (0, 0, 0), 0.0)
    f = np.array(out.thrust_vector_n)
    assert out.saturated
    assert math.atan2(math.hypot(f[0], f[1]), f[2]) <= gains.max_tilt_rad + 1e-12
    assert np.linalg.norm(f) <= gains.max_thrust_fraction * 80.0 + 1e-9
    # held far away for 10 s, the estimate stays within its projection bound, and the
    # compensation signals carry the part of the error the limits caused
    for _ in range(2500):
        out = pc.update(0.004, (0, 0, 10), (0, 0, 0), (100.0, 0, 10), (0, 0, 0), (0, 0, 0),
                        0.0)
    assert np.linalg.norm(pc.d_hat) <= gains.disturbance_limit_m_s2 + 1e-12
    assert abs(out.e1_m[0]) < 0.05 * 100.0


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_attitude_from_thrust_vector_points_body_z_along_it(yaw):
    f = (2.0, -3.0, 25.0)
    roll, pitch, yaw_out = attitude_from_thrust_vector(f, yaw)
    r = np.array(quat_to_matrix(euler_to_quat(roll, pitch, yaw_out)))
    assert np.allclose(r[:, 2], np.array(f) / np.linalg.norm(f), atol=1e-12)
    assert yaw_out == yaw


# ---------------------------------------------------------------- attitude loop
@pytest.mark.parametrize("tau_d", [(0.0, 0.0, 0.0), (0.3, -0.2, 0.05)])
def test_attitude_lyapunov_decreases_on_the_rigid_body(tau_d):
    """Euler's equations integrated by RK4, the state starting far from a smoothly moving
    command, with a constant disturbance torque ``tau_d`` (a tether attached off the centre
    of mass): the proof's V (the logged one plus the adaptation term
    1/2 (tau_d - tau_hat)' Gamma^-1 (tau_d - tau_hat)) follows the derivation's
    dV/dt = -e_eta'K3e_eta - e_w'K4e_w (the filtered command's derivatives are exact) and
    never increases, and the estimate converges to ``tau_d``."""
    gains = FlightControlParams()
    j = np.array([0.5192, 0.4929, 0.0947])
    c = 0.01
    dt = 1e-3
    ac = AttitudeController(gains, tuple(j), c, dt)
    gam = np.array(gains.att_disturbance_gain_n_m_rad)
    disturbance = np.array(tau_d)

    def desired(t):
        return (0.2 * math.sin(0.8 * t), -0.15 * math.cos(0.6 * t), 0.5 * math.sin(0.3 * t))

    ac.reset(desired(0.0))
    eta = np.array([0.3, -0.25, 1.0])
    om = np.array([0.5, -0.4, 0.3])

    def f(state, tau):
        e, w = state[:3], state[3:]
        _, t = euler_rate_matrices(e[0], e[1])
        return np.concatenate([t @ w, (tau + disturbance - c * w - np.cross(w, j * w)) / j])

    state = np.concatenate([eta, om])
    g3, g4 = np.array(gains.att_k3_1_s), np.array(gains.att_k4_n_m_s)
    values, logged, rates = [], [], []
    for k in range(6000):
        out = ac.update(tuple(state[:3]), tuple(state[3:]), desired(k * dt))
        tilde = disturbance - np.array(out.disturbance_n_m)
        logged.append(out.lyapunov)
        values.append(out.lyapunov + 0.5 * float(tilde @ (tilde / gam)))
        ee, ew = np.array(out.e_eta_rad), np.array(out.e_omega_rad_s)
        rates.append(-float(ee @ (g3 * ee)) - float(ew @ (g4 * ew)))
        tau = np.array(out.torque_n_m)
        s1 = f(state, tau)
        s2 = f(state + 0.5 * dt * s1, tau)
        s3 = f(state + 0.5 * dt * s2, tau)
        s4 = f(state + dt * s3, tau)
        state = state + dt / 6 * (s1 + 2 * s2 + 2 * s3 + s4)
    values, logged, rates = np.array(values), np.array(logged), np.array(rates)
    num = np.diff(values) / dt
    mid = 0.5 * (rates[1:] + rates[:-1])
    # within 5 % of the derivation's rate, above the floor that sampling a moving command
    # at 1 kHz leaves (V ~ dt^2 ~ 1e-5, its rate ~1e-2 here: measured 0.011 at most with
    # and without the adaptation; it shrinks 16x at a quarter of the step, and is zero
    # for a constant command)
    sig = logged[:-1] > 1e-2
    assert sig.sum() > 500
    assert np.all(np.abs(num[sig] - mid[sig]) <= 0.05 * np.abs(mid[sig]) + 0.02)
    # the proof's V falls wherever its rate is clear of that floor
    falling = np.abs(mid) > 0.05
    assert falling.sum() > 500
    assert np.all(np.diff(values)[falling] < 0.0)
    assert values[-1] < 1e-3 * values[0]
    # the estimate finds the disturbance (to the torque the sampled moving command itself
    # leaves: measured 0.014 N m)
    assert np.allclose(ac.tau_hat, disturbance, atol=0.03)


# ---------------------------------------------------------------- winder loop
def test_winder_law_tracks_and_its_lyapunov_decreases():
    wp, tp = WinderParams(), TetherParams()
    drum = WinderModel(wp, tp)
    ctl = WinderController(WinderControlParams(), wp, tp)
    dt_c, dt = 0.01, 0.001
    theta, omega = drum.theta_rad(20.0), 0.0
    tension = 3.0
    values, rates, ref = [], [], 22.0
    gains = WinderControlParams()
    for _ in range(600):
        length = drum.length_m(theta)
        cmd = ctl.update(dt_c, length, omega, tension, ref, 0.0)
        values.append(cmd.lyapunov)
        rates.append(-gains.length_stiffness_n_m * gains.k_length_1_s * cmd.e_length_m ** 2
                     - gains.k_rate_n_m_s * cmd.e_rate_rad_s ** 2)
        tau = drum.motor_torque_n_m(cmd.torque_n_m, omega, True)
        for _ in range(10):  # the drum, integrated finely with the torque held
            acc = drum.acceleration(theta, omega, tau, tension, braked=False)
            omega += acc * dt
            theta += omega * dt
    assert abs(drum.length_m(theta) - ref) < 1e-4
    values, rates = np.array(values), np.array(rates)
    # dV/dt = -c k_L e_L^2 - k_w e_w^2 while the torque is not saturated (from 0.3 s on),
    # to the accuracy of a 10 ms zero-order hold: compare the integral over each step
    unsat = np.arange(len(values) - 1) >= 30
    num = np.diff(values)
    pred = 0.5 * (rates[1:] + rates[:-1]) * dt_c
    sig = unsat & (np.abs(pred) > 1e-9)
    assert np.all(np.abs(num[sig] - pred[sig]) <= 0.25 * np.abs(pred[sig]))
    big = values > 1e-10
    assert np.all(np.diff(values)[big[:-1]] <= 0.02 * values[:-1][big[:-1]])
    assert values[-1] < 1e-6 * values[0]
