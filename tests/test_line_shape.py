"""The line-shape model (tuavdefs/line_shape.py) against independent truths: MoorPy's line
under its weight and a uniform current load (its own catenary solver), the plant's lumped
line (sitl/lumped.py) settled in a steady wind, and the analytic limits (no wind: the plant's
elastic catenary; a weightless line: straight)."""

from __future__ import annotations

import math

import moorpy as mp
import numpy as np
import pytest
from lumped_util import exit_reading, settled_exit

from sitl.catenary import CatenaryRegime
from sitl.tether import Tether
from tuavdefs import line_shape as ls
from tuavdefs.params import EnvironmentParams, TetherParams

G = 9.81
TP = TetherParams()
RHO_AIR = EnvironmentParams().air_density_kg_m3
MODEL = ls.LineModel.from_tether(TP, G, RHO_AIR)


_exit = exit_reading


def _moorpy(top: tuple[float, float, float], length_m: float, wind: tuple[float, float]):
    """MoorPy's line in air from the exit (its end A) to ``top`` (B) in the uniform
    current ``wind`` [m/s]: the drag normal to the line (C_dn on the diameter), none along
    it, the load iterated to convergence (MoorPy lags it by one solve)."""
    s = mp.System(depth=1000.0, rho=RHO_AIR, g=G, current=np.array([*wind, 0.0]))
    lt = dict(name="tether", d_vol=TP.diameter_m, m=TP.linear_density_kg_m,
              w=TP.linear_density_kg_m * G - math.pi / 4 * TP.diameter_m ** 2 * RHO_AIR * G,
              EA=TP.axial_stiffness_n, Cd=TP.normal_drag_coeff, CdAx=0.0,
              d_nom=TP.diameter_m, material="tether")
    s.lineTypes["tether"] = lt
    s.addPoint(1, np.zeros(3))
    s.addPoint(1, np.array(top, dtype=float))
    s.addLine(length_m, lt, nSegs=80, pointA=1, pointB=2)
    s.initialize()
    line = s.lineList[0]
    for _ in range(40):
        line.staticSolve(profiles=1)
    return line


#: (top [m], slack over the straight line [m], wind [m/s])
MOORPY_CASES = [((8.0, 4.0, 15.0), 0.5, (3.0, 0.0)), ((0.0, -14.0, 25.0), 1.5, (0.0, -8.0)),
                ((20.0, 0.0, 10.0), 1.0, (12.0, 0.0)), ((-5.0, -5.0, 35.0), 0.4, (6.0, -4.0)),
                ((12.0, 3.0, 4.0), 0.3, (-2.0, 5.0))]


@pytest.mark.parametrize(("top", "slack", "wind"), MOORPY_CASES)
def test_the_closed_form_under_a_uniform_load_is_moorpys_line_in_a_current(top, slack, wind):
    """MoorPy solves a line in a current as a catenary under one uniform load per metre,
    its weight plus the drag averaged over the line: the closed form under that load,
    started with MoorPy's tension at the exit, ends at MoorPy's top within 0.1 mm."""
    length = math.dist(top, (0.0, 0.0, 0.0)) + slack
    line = _moorpy(top, length, wind)
    t0, psi, eps = _exit(line.fA)
    load = line.fCurrent / line.L + np.array([0.0, 0.0, -line.w])
    end = ls.line_end(length, t0, psi, eps, tuple(load), TP.axial_stiffness_n)
    assert math.dist(end, top) < 1e-4


def test_across_the_line_the_cross_flow_model_is_moorpys_line_in_a_current():
    """A wind across the line's vertical plane meets every piece of it nearly normally: the
    drag is nearly uniform, MoorPy's averaged load holds, and the model (the drag computed
    where it acts) ends within 2 cm of MoorPy's top on lines of 10-40 m in 3-12 m/s."""
    errors = []
    for top, slack in (((8.0, 4.0, 15.0), 0.5), ((20.0, 0.0, 10.0), 1.0),
                       ((-5.0, -5.0, 35.0), 0.4), ((9.0, 0.0, 3.0), 0.3)):
        az = math.atan2(top[1], top[0])
        for speed in (3.0, 6.0, 12.0):
            wind = (-speed * math.sin(az), speed * math.cos(az))
            length = math.dist(top, (0.0, 0.0, 0.0)) + slack
            line = _moorpy(top, length, wind)
            t0, psi, eps = _exit(line.fA)
            x = ls.inputs(length, t0, psi, eps, MODEL.with_weight(line.w), wind)
            errors.append(math.dist(ls.end(MODEL, x), top))
    print("moorpy across: model error [m]", np.round(errors, 3))
    assert max(errors) < 0.08


#: (top [m], slack [m], wind speed [m/s], its direction from the line's azimuth [rad])
LUMPED_CASES = [((8.0, 4.0, 15.0), 0.8, 0.0, 0.0), ((8.0, 4.0, 15.0), 0.8, 3.0, 0.0),
                ((8.0, 4.0, 15.0), 0.3, 6.0, 0.5 * math.pi), ((8.0, 4.0, 15.0), 0.8, 12.0, 0.0),
                ((0.0, -14.0, 25.0), 1.5, 8.0, 0.0), ((0.0, -14.0, 25.0), 0.5, 12.0, 2.3),
                ((15.0, 0.0, 12.0), 0.5, 12.0, 0.0), ((15.0, 5.0, 12.0), 1.0, 6.0, 0.5 * math.pi),
                ((-5.0, -5.0, 35.0), 0.5, 9.0, 1.0), ((4.0, 3.0, 6.0), 0.2, 10.0, 0.0)]


def test_against_the_plants_lumped_line_settled_in_a_steady_wind():
    """The plant's lumped line (its own drag: normal and tangential, on 60 nodes; its own
    elasticity) held still in 0-12 m/s along, across and oblique to lines of 8-36 m,
    suspended clear of the ground: with the lumped line's exit tension and angles the
    model's end is within 0.08 m of the truth (at most 0.5 % of the line's length; 1 cm in
    calm air), where the windless line is metres off, and the line's pull on the vehicle
    (the tension at its end) within 3 % and 0.02 N of the lumped line's."""
    errors, windless, pulls = [], [], []
    for top, slack, speed, turn in LUMPED_CASES:
        az = math.atan2(top[1], top[0]) + turn
        wind = (speed * math.cos(az), speed * math.sin(az))
        length = math.dist(top, (0.0, 0.0, 0.0)) + slack
        t0, psi, eps, lowest, pull = settled_exit(top, length, wind)
        assert lowest > 0.0 and eps > 0.03, "the case must be a line clear of the ground"
        x = ls.inputs(length, t0, psi, eps, MODEL, wind)
        end, tension = ls.top(MODEL, x)
        err = math.dist(end, top)
        errors.append(err)
        assert err < 0.08 and err < 0.005 * length
        pull_err = math.dist(tension, tuple(-f for f in pull))
        pulls.append(pull_err)
        assert pull_err < 0.03 * math.hypot(*pull) + 0.02
        windless.append(math.dist(ls.end(MODEL, ls.inputs(length, t0, psi, eps, MODEL)),
                                  top))
    print("lumped: model error [m]", np.round(errors, 3), "windless", np.round(windless, 2),
          "pull error [N]", np.round(pulls, 3))
    assert max(windless) > 2.0


@pytest.mark.parametrize(("pos", "slack"), [((8.0, 4.0, 15.0), 0.3), ((2.0, 0.5, 20.0), 0.05),
                                            ((25.0, -5.0, 10.0), 0.4), ((30.0, 10.0, 30.0), 2.0)])
def test_no_wind_gives_the_plants_elastic_catenary(pos, slack):
    """Calm air: the model is the plant's elastic catenary (Newton's solution from the two
    ends) to the millimetre, the integrated form (a breath of wind) the same within 1 mm."""
    length = math.dist(pos, (0.0, 0.0, 0.0)) + slack
    tf = Tether(TP, G).forces(*pos, length)
    assert tf.info.regime == CatenaryRegime.SUSPENDED
    t0, psi, eps = _exit(np.array(tf.on_exit_n))
    assert ls.end(MODEL, ls.inputs(length, t0, psi, eps, MODEL)) == pytest.approx(pos, abs=1e-3)
    breath = ls.inputs(length, t0, psi, eps, MODEL, (1e-6, 0.0))
    assert ls.end(MODEL, breath) == pytest.approx(pos, abs=1e-3)


def test_a_weightless_line_in_calm_air_is_straight_and_its_jacobian_analytic():
    """No weight, no wind: the end is ``L (1 + T0/EA) e0``; the Jacobian's columns are
    ``e0 (1 + T0/EA)`` for the length, ``L e0 / EA`` for the tension, ``L (1 + T0/EA)
    de0/dangle`` for the angles and their negatives for the biases, zero for the wind (the
    quadratic drag has no slope at calm air)."""
    model = ls.LineModel(weight_n_m=0.0, drag_n_s2_m3=MODEL.drag_n_s2_m3, ea_n=2000.0)
    L, T, psi, eps = 20.0, 40.0, 0.7, 0.4
    x = ls.inputs(L, T, psi, eps, model)
    e0 = np.array([math.cos(eps) * math.cos(psi), math.cos(eps) * math.sin(psi), math.sin(eps)])
    k = 1.0 + T / model.ea_n
    end, J = ls.jacobian(model, x)
    assert end == pytest.approx(tuple(L * k * e0), abs=1e-9)
    de_dpsi = np.array([-math.cos(eps) * math.sin(psi), math.cos(eps) * math.cos(psi), 0.0])
    de_deps = np.array([-math.sin(eps) * math.cos(psi), -math.sin(eps) * math.sin(psi),
                        math.cos(eps)])
    C = ls.Column
    np.testing.assert_allclose(J[:, C.LENGTH], k * e0, atol=1e-6)
    np.testing.assert_allclose(J[:, C.TENSION], L * e0 / model.ea_n, atol=1e-6)
    np.testing.assert_allclose(J[:, C.AZIMUTH], L * k * de_dpsi, atol=1e-5)
    np.testing.assert_allclose(J[:, C.ELEVATION], L * k * de_deps, atol=1e-5)
    np.testing.assert_allclose(J[:, C.AZIMUTH_BIAS], -J[:, C.AZIMUTH], atol=1e-9)
    np.testing.assert_allclose(J[:, C.ELEVATION_BIAS], -J[:, C.ELEVATION], atol=1e-9)
    np.testing.assert_allclose(J[:, [C.WIND_X, C.WIND_Y]], 0.0, atol=1e-9)


def test_the_jacobian_predicts_the_lumped_line_in_a_changed_wind():
    """The wind and weight columns, taken at one wind, predict the end in another: the
    lumped line settled in 6 m/s and in 7 m/s along the line hang from the same top, so with
    the exit's readings in 7 m/s the model in the wrong wind (6 m/s) errs by the wind's
    column times 1 m/s to first order (within 20 % of that error, which is decimetres)."""
    top, length = (8.0, 4.0, 15.0), math.dist((8.0, 4.0, 15.0), (0.0, 0.0, 0.0)) + 0.8
    az = math.atan2(top[1], top[0])
    u6 = (6.0 * math.cos(az), 6.0 * math.sin(az))
    u7 = (7.0 * math.cos(az), 7.0 * math.sin(az))
    t0, psi, eps, _, _ = settled_exit(top, length, u7)
    x6 = ls.inputs(length, t0, psi, eps, MODEL, u6)
    end6, J = ls.jacobian(MODEL, x6)
    err = np.array(end6) - np.array(top)
    du = np.array(u7) - np.array(u6)
    predicted = -(J[:, ls.Column.WIND_X] * du[0] + J[:, ls.Column.WIND_Y] * du[1])
    assert np.linalg.norm(err) > 0.1
    assert np.linalg.norm(err - predicted) < 0.2 * np.linalg.norm(err)


@pytest.mark.parametrize(("wind", "sigma"), [((0.0, 0.0), 2.0), ((1.0, -2.0), 2.0),
                                           ((5.0, 0.0), 1.0), ((0.0, 6.0), 1.5)])
def test_the_wind_spread_is_the_gaussian_second_moment(wind, sigma):
    """The end's covariance from a Gaussian wind error (eight points) against a Monte Carlo
    of 4000 winds drawn from that Gaussian, the second moment of their ends about the end in
    the mean wind: within 12 % per axis, at calm air (where the drag's slope is zero and a
    Jacobian would say nothing) as in a steady wind."""
    x = ls.inputs(18.0, 2.5, 0.46, 0.6, MODEL, wind)
    cov = ls.wind_spread(MODEL, x, np.eye(2) * sigma ** 2)
    base = np.array(ls.end(MODEL, x))
    rng = np.random.default_rng(1)
    d = np.empty((4000, 3))
    for i in range(d.shape[0]):
        xe = x.copy()
        xe[ls.Column.WIND_X:ls.Column.WIND_Y + 1] += rng.normal(0.0, sigma, 2)
        d[i] = np.array(ls.end(MODEL, xe)) - base
    mc = d.T @ d / d.shape[0]
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.sqrt(np.diag(mc)), rtol=0.12)
