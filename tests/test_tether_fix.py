"""The ground station's tether fix (groundstation/tether_fix.py) against independent truths:
the plant's own catenary solver (sitl.tether, MoorPy-compatible) for the UAV's position, a
numerical integration of the loaded line for the closed form, the plant's exit-angle sensor
for the noise, and the fix's covariance against its actual errors (NEES), on the catenary
and, given the wind, on the plant's lumped line settled in it (tests/lumped_util.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from lumped_util import settled_exit
from scipy.integrate import solve_ivp

from groundstation.tether_fix import TetherFixer, TetherFixParams
from sitl.catenary import CatenaryRegime
from sitl.exit_angle import ExitAngleSensor, ExitAngleSensorParams
from sitl.tether import Tether
from tuavdefs.line_shape import line_end
from tuavdefs.params import TetherParams

G = 9.81
TP = TetherParams()
W = TP.linear_density_kg_m * G
EA = TP.youngs_modulus_pa * TP.section_area_m2


def _fixer(**kw) -> TetherFixer:
    return TetherFixer(TetherFixParams(**kw), W, EA, TP.diameter_m)


def _exit(forces) -> tuple[float, float]:
    fx, fy, fz = forces.on_exit_n
    return math.atan2(fy, fx), math.atan2(fz, math.hypot(fx, fy))


#: (UAV position [m], slack over the straight line [m]) across lengths, heights, sags
GEOMETRIES = [((8.0, 4.0, 15.0), 0.3), ((8.0, 4.0, 15.0), 1.0), ((2.0, 0.0, 1.0), 0.05),
              ((-12.0, 9.0, 20.0), 0.5), ((2.0, 0.5, 20.0), 0.05), ((25.0, -5.0, 10.0), 0.4),
              ((1.0, -1.0, 3.0), 0.1), ((30.0, 10.0, 30.0), 2.0)]


@pytest.mark.parametrize(("pos", "slack"), GEOMETRIES)
def test_exact_angles_give_the_plant_catenary_position(pos, slack):
    """Noise-free measurements: the fix is the plant's truth (its elastic catenary solved
    by Newton's method from the two ends) to the millimetre."""
    tf = Tether(TP, G).forces(*pos, math.dist(pos, (0, 0, 0)) + slack)
    assert tf.info.regime == CatenaryRegime.SUSPENDED
    az, el = _exit(tf)
    p, cov, ground = _fixer().position(math.dist(pos, (0, 0, 0)) + slack, tf.drum_tension_n,
                                       az, el)
    assert not ground
    assert p == pytest.approx(pos, abs=1e-3)
    assert np.all(np.linalg.eigvalsh(np.array(cov)) > 0.0)


def test_closed_form_against_an_integrated_line_under_any_load():
    """line_end against solve_ivp of dp/ds = T/|T| (1 + |T|/EA), T(s) = T0 e0 - f s, with
    a load tilted by wind and a soft line."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        L = rng.uniform(1.0, 40.0)
        T0 = rng.uniform(0.2, 20.0)
        az, el = rng.uniform(-math.pi, math.pi), rng.uniform(0.0, 1.4)
        f = np.array((rng.normal(0.0, 0.1), rng.normal(0.0, 0.1), -W))
        ea = rng.choice([EA, 200.0])
        e0 = np.array((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                       math.sin(el)))

        def rhs(s, p, e0=e0, T0=T0, f=f, ea=ea):
            T = T0 * e0 - f * s
            n = np.linalg.norm(T)
            return T / n * (1.0 + n / ea)

        sol = solve_ivp(rhs, (0.0, L), np.zeros(3), rtol=1e-10, atol=1e-12)
        assert line_end(L, T0, az, el, tuple(f), ea) == pytest.approx(sol.y[:, -1],
                                                                     abs=1e-6)


def _noisy_fix(rng, fixer, sensor, pos, slack):
    L = math.dist(pos, (0, 0, 0)) + slack
    tf = Tether(TP, G).forces(*pos, L)
    az, el, valid = sensor.read(tf.on_exit_n)
    assert valid
    p = fixer.p
    tension = (tf.drum_tension_n * (1.0 + rng.normal(0.0, p.tension_noise_fraction))
               + rng.normal(0.0, p.tension_noise_n))
    length = L + rng.normal(0.0, p.length_noise_m)
    return fixer.position(length, tension, az, el)


def test_covariance_is_consistent_with_the_actual_error():
    """NEES of noisy fixes (the plant's exit-angle sensor with its bias and quantisation,
    noisy tension and length) over the geometries: no worse than chi-square(3) says (mean
    at most 3: the covariance may be cautious, it allows for wind the plant's catenary does
    not put on the line), and never grossly optimistic."""
    rng = np.random.default_rng(11)
    fixer = _fixer()
    nees = []
    for seed in range(12):
        sensor = ExitAngleSensor(ExitAngleSensorParams(seed=seed))
        for pos, slack in GEOMETRIES:
            p, cov, _ = _noisy_fix(rng, fixer, sensor, pos, slack)
            e = np.subtract(p, pos)
            nees.append(float(e @ np.linalg.solve(np.array(cov), e)))
    nees = np.array(nees)
    assert nees.mean() <= 3.0
    assert np.quantile(nees, 0.99) <= 11.34      # chi-square(3) at 0.99


def test_covariance_without_wind_allowance_is_not_far_too_cautious():
    """With no wind allowed for, the NEES is of chi-square(3)'s order: the covariance is the
    noise, not a blanket."""
    rng = np.random.default_rng(5)
    fixer = _fixer(design_wind_m_s=0.0, weight_uncertainty_fraction=0.0)
    nees = []
    for seed in range(12):
        sensor = ExitAngleSensor(ExitAngleSensorParams(seed=seed))
        for pos, slack in GEOMETRIES:
            p, cov, _ = _noisy_fix(rng, fixer, sensor, pos, slack)
            e = np.subtract(p, pos)
            nees.append(float(e @ np.linalg.solve(np.array(cov), e)))
    assert 0.3 <= float(np.mean(nees)) <= 3.0


def _sigma(fixer, pos, slack):
    L = math.dist(pos, (0, 0, 0)) + slack
    tf = Tether(TP, G).forces(*pos, L)
    az, el = _exit(tf)
    _, cov, ground = fixer.position(L, tf.drum_tension_n, az, el)
    return math.sqrt(np.trace(np.array(cov))), ground


def test_covariance_grows_where_the_fix_is_weak():
    f = _fixer()
    taut, _ = _sigma(f, (8.0, 4.0, 15.0), 0.1)
    slack, _ = _sigma(f, (8.0, 4.0, 15.0), 1.5)
    assert slack > 1.5 * taut                        # a slack line: its shape is soft
    short, _ = _sigma(f, (2.0, 1.0, 4.0), 0.1)
    long_, _ = _sigma(f, (24.0, 12.0, 30.0), 0.4)
    assert long_ > 3.0 * short                       # a long line
    calm, _ = _sigma(_fixer(design_wind_m_s=0.0), (8.0, 4.0, 15.0), 0.3)
    windy, _ = _sigma(_fixer(design_wind_m_s=10.0), (8.0, 4.0, 15.0), 0.3)
    assert windy > 3.0 * calm                        # strong wind
    ground, on = _sigma(f, (12.0, 0.0, 0.5), 2.0)    # the line lying on the ground
    assert on
    assert ground > 5.0 * short


def test_line_on_the_ground_with_the_reported_height():
    """Touchdown (part of the line on the ground): with the UAV's reported position the
    fix is the plant's truth horizontally (the line's reach bounds it), and says nothing of
    the height."""
    f = _fixer()
    for pos, slack in (((3.0, 0.0, 0.2), 0.1), ((6.0, -8.0, 1.0), 0.3),
                       ((0.0, 5.0, 4.0), 1.0)):
        L = math.dist(pos, (0, 0, 0)) + slack
        tf = Tether(TP, G).forces(*pos, L)
        assert tf.info.regime == CatenaryRegime.TOUCHDOWN
        az, el = _exit(tf)
        # reported where it is: the line's bound holds it there
        p, cov, ground = f.position(L, tf.drum_tension_n, az, el, reported_m=pos)
        assert ground
        assert p[:2] == pytest.approx(pos[:2], abs=0.02)
        assert math.sqrt(cov[2][2]) >= f.p.ground_vertical_sigma_m
        # reported beyond the line's reach: brought back to it (the straight line on the
        # ground, the plant's truth); reported nearer: a line pulling the straight tension
        # (the winch's ground pre-tension) lies straight, still the truth; a slacker one
        # may lie in curves, the azimuth only
        far = (pos[0] * 1.5 + 0.5, pos[1] * 1.5 + 0.5, pos[2])
        p, _, _ = f.position(L, tf.drum_tension_n, az, el, reported_m=far)
        assert p[:2] == pytest.approx(pos[:2], abs=0.02)
        near = (pos[0] * 0.5, pos[1] * 0.5, pos[2])
        for tension in (tf.drum_tension_n, f.p.ground_straight_tension_n,
                        0.5 * f.p.ground_straight_tension_n):
            p, _, _ = f.position(L, tension, az, el, reported_m=near)
            if tension >= f.p.ground_straight_tension_n:
                if tension == tf.drum_tension_n:
                    assert p[:2] == pytest.approx(pos[:2], abs=0.02)
            else:
                assert math.hypot(*p[:2]) == pytest.approx(math.hypot(*near[:2]), abs=1e-9)
            assert math.atan2(p[1], p[0]) == pytest.approx(az, abs=1e-9)
        # without the height: the spread over the unknown length on the ground
        p0, cov0, _ = f.position(L, tf.drum_tension_n, az, el)
        e = np.subtract(p0, pos)
        assert float(e @ np.linalg.solve(np.array(cov0), e)) <= 11.34


def test_a_line_read_flat_is_never_fixed_beyond_its_reach():
    """The guide arm reading the line flat while the vehicle reports itself high on a
    short, pulling line (on the lumped line: the exit segment read flat for a moment under
    a tension spike, 7.3 N at 9.8 m on 10.3 m of line): the fix is no farther out than the
    line's straight reach, no nearer than its slack hanging straight down, and its error
    from the truth (2.94 m out) within its covariance; so for any pull."""
    f = _fixer()
    truth = (1.80, 2.33, 9.82)
    L, az = 10.29, math.atan2(truth[1], truth[0])
    reported = (1.35, -0.84, 9.81)
    for tension in (0.2, 1.0, 7.27, 40.0):
        p, cov, ground = f.position(L, tension, az, 0.001, reported_m=reported)
        assert ground
        d = math.hypot(p[0], p[1])
        assert L - reported[2] - 1e-9 <= d <= math.sqrt(L * L - reported[2] ** 2) + 1e-9
        e = np.subtract(p, truth)
        assert float(e @ np.linalg.solve(np.array(cov), e)) <= 11.34
    # a height the line cannot reach: the line straight up
    p, _, _ = f.position(L, 7.27, az, 0.001, reported_m=(0.0, 0.0, L + 0.5))
    assert math.hypot(p[0], p[1]) == pytest.approx(0.0, abs=1e-9)


def test_a_heavier_line_than_believed_is_fixed_on_the_winders_weight_estimate():
    """The plant's line 1.6x the belief's weight: the fix on the belief lands far from
    the UAV; handed the true weight as the winder's estimate, it uses all of it beyond
    the band (here 0: the truth to the millimetre; by default 10 % short of it, much
    nearer), and an estimate within the band changes nothing."""
    heavy = TetherParams(linear_density_kg_m=1.6 * TP.linear_density_kg_m)
    pos, slack = (8.0, 4.0, 15.0), 0.5
    length = math.dist(pos, (0, 0, 0)) + slack
    tf = Tether(heavy, G).forces(*pos, length)
    az, el = _exit(tf)
    w_true = heavy.linear_density_kg_m * G
    believed = _fixer().position(length, tf.drum_tension_n, az, el)[0]
    exact = _fixer(weight_band_fraction=0.0).position(length, tf.drum_tension_n, az, el,
                                                      None, w_true)[0]
    banded = _fixer().position(length, tf.drum_tension_n, az, el, None, w_true)[0]
    assert math.dist(believed, pos) > 0.5
    assert exact == pytest.approx(pos, abs=1e-3)
    assert math.dist(banded, pos) < 0.5 * math.dist(believed, pos)
    assert _fixer().position(length, tf.drum_tension_n, az, el, None, 1.05 * W)[0] == believed


@pytest.mark.parametrize("factor", [0.5, 0.55, 0.8, 1.6, 2.0])
def test_covariance_is_consistent_on_a_line_off_the_belief(factor):
    """The plant's line ``factor`` times the belief's weight, the winder's estimate its
    true weight: the fix takes the belief moved to within the band of the estimate, so
    the weight it uses is off the truth by the band; its covariance carries that (the
    weight's standard deviation at least the distance to the estimate), and the NEES of
    noisy fixes over the geometries is as for a line as designed: no worse than
    chi-square(3) says. (A covariance with the weight's 3 % alone is over-confident on
    the lighter lines: mean NEES 4.1, 7.8 and 9.2 at 0.8, 0.55 and 0.5 times the
    belief.)"""
    line = TetherParams(linear_density_kg_m=factor * TP.linear_density_kg_m)
    w_true = line.linear_density_kg_m * G
    rng = np.random.default_rng(7)
    fixer = _fixer()
    nees = []
    for seed in range(6):
        sensor = ExitAngleSensor(ExitAngleSensorParams(seed=seed))
        for pos, slack in GEOMETRIES:
            L = math.dist(pos, (0, 0, 0)) + slack
            tf = Tether(line, G).forces(*pos, L)
            if tf.info.regime != CatenaryRegime.SUSPENDED:
                continue
            az, el, valid = sensor.read(tf.on_exit_n)
            assert valid
            p = fixer.p
            tension = (tf.drum_tension_n * (1.0 + rng.normal(0.0, p.tension_noise_fraction))
                       + rng.normal(0.0, p.tension_noise_n))
            length = L + rng.normal(0.0, p.length_noise_m)
            fix, cov, _ = fixer.position(length, tension, az, el, None, w_true)
            e = np.subtract(fix, pos)
            nees.append(float(e @ np.linalg.solve(np.array(cov), e)))
    nees = np.array(nees)
    assert len(nees) >= 30
    assert nees.mean() <= 3.0
    assert np.quantile(nees, 0.99) <= 11.34


def test_the_weights_standard_deviation_covers_its_distance_to_the_estimate():
    """The weight the fix uses and its standard deviation: the belief and 3 % of it
    without an estimate or with one at the belief; the belief moved to within the band of
    an estimate off it, the standard deviation at least the band."""
    f = _fixer()
    frac, band = f.p.weight_uncertainty_fraction, f.p.weight_band_fraction
    assert f.weight(None) == (W, pytest.approx(frac * W))
    assert f.weight(W) == (W, pytest.approx(frac * W))
    w, s = f.weight(1.05 * W)               # within the band: the belief, 5 % uncertain
    assert w == W
    assert s == pytest.approx(math.hypot(frac * W, 0.05 * W))
    w, s = f.weight(0.5 * W)                # a light line: the band short of it
    assert w == pytest.approx((0.5 + band) * W)
    assert s >= band * W
    w, s = f.weight(2.0 * W)
    assert w == pytest.approx((2.0 - band) * W)
    assert s >= band * W


#: (UAV position [m], slack [m]) of the lumped line's consistency check
LUMPED_GEOMETRIES = [((8.0, 4.0, 15.0), 0.8), ((0.0, -14.0, 25.0), 1.0),
                     ((-5.0, -5.0, 35.0), 0.5), ((4.0, 3.0, 6.0), 0.2),
                     ((15.0, 5.0, 14.0), 0.6), ((-10.0, 3.0, 20.0), 1.2)]


def test_the_fix_in_wind_is_consistent_on_the_lumped_line():
    """The fix given the wind as estimated (the truth plus an error of 1 m/s per axis, its
    stated covariance) on the plant's lumped line settled in a steady wind of 0-12 m/s
    from any direction, the line's weight and drag drawn from the fix's priors about its
    beliefs (3 % and 25 %), the arm's biases (3 mrad) and every reading's noise drawn from
    theirs: the NEES of the fix against the truth is chi-square(3)'s (mean within 2-4.5,
    at least 88 % of the fixes within its 95 % bound), where the windless fix's is
    hundreds."""
    rng = np.random.default_rng(7)
    p = TetherFixParams(wind_shear_exponent=0.0)        # the truth's wind is uniform
    fixer = TetherFixer(p, W, EA, TP.diameter_m)
    nees, windless = [], []
    for k in range(18):
        top, slack = LUMPED_GEOMETRIES[k % len(LUMPED_GEOMETRIES)]
        length = math.dist(top, (0.0, 0.0, 0.0)) + slack
        speed, heading = rng.uniform(0.0, 12.0), rng.uniform(-math.pi, math.pi)
        wind = (speed * math.cos(heading), speed * math.sin(heading))
        density = 1.0 + p.weight_uncertainty_fraction * rng.standard_normal()
        drag = max(1.0 + p.drag_uncertainty_fraction * rng.standard_normal(), 0.2)
        t0, psi, eps, lowest, _ = settled_exit(top, length, wind, density, drag)
        if lowest <= 0.0 or eps < p.ground_elevation_rad:
            continue                                    # the line touches the ground
        bias = rng.normal(0.0, p.angle_bias_rad, 2)
        for _ in range(4):
            sigma_t = math.hypot(p.tension_noise_n, p.tension_noise_fraction * t0)
            reading = (length + rng.normal(0.0, p.length_noise_m),
                       t0 + rng.normal(0.0, sigma_t),
                       psi + bias[0] + rng.normal(0.0, p.angle_noise_rad),
                       eps + bias[1] + rng.normal(0.0, p.angle_noise_rad))
            estimate = (wind[0] + rng.standard_normal(), wind[1] + rng.standard_normal())
            pos, cov, ground = fixer.position(*reading, wind_m_s=estimate)
            assert not ground
            e = np.subtract(pos, top)
            nees.append(float(e @ np.linalg.solve(np.array(cov), e)))
            pos0, cov0, _ = fixer.position(*reading)
            e0 = np.subtract(pos0, top)
            windless.append(float(e0 @ np.linalg.solve(np.array(cov0), e0)))
    nees = np.array(nees)
    print("lumped NEES: n", nees.size, "mean", nees.mean(), "within 7.81",
          np.mean(nees <= 7.81), "windless mean", np.mean(windless))
    assert nees.size >= 48
    assert 2.0 <= nees.mean() <= 4.5
    assert np.mean(nees <= 7.81) >= 0.88
