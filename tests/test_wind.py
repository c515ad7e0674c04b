"""Tests of sitl.wind: steady wind, discrete gusts and Dryden turbulence.

The statistical tests use fixed seeds, so they are deterministic. Their tolerances are
``N_SE`` standard errors of each estimator, computed for the analytic Dryden process from
its autocorrelation (the effective number of independent samples), and each test also
checks that its tolerance is tight enough to catch a few-percent error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl.wind import (
    FT_M,
    KNOT_M_S,
    MAX_ALTITUDE_M,
    MIN_ALTITUDE_M,
    MIN_PASSING_SPEED_M_S,
    WindModel,
    dryden_length_scales_m,
    dryden_sigmas_m_s,
)
from tuavdefs.params import GustParams, WindParams


def uniform_wind(**fields) -> WindParams:
    """Wind parameters with a mean wind the same at every height (the Dryden and gust
    tests: the profile has tests of its own)."""
    return WindParams(profile="uniform", **fields)

N_SE = 4.0  # tolerance in standard errors of the estimator


def run(model: WindModel, n: int, altitude_m: float,
        velocity_m_s: tuple[float, float, float]) -> np.ndarray:
    """``n`` samples (n x 3) at a fixed altitude and vehicle velocity, t = k dt."""
    dt = model.dt_s
    return np.array([model.sample(k * dt, altitude_m, velocity_m_s) for k in range(n)])


# --- analytic Dryden autocorrelations and estimator standard errors ---------------------

def rho_first_order(tau_s: np.ndarray, t_s: float) -> np.ndarray:
    """Normalised autocorrelation of the u-component: exp(-|tau| / T), T = L / V."""
    return np.exp(-np.abs(tau_s) / t_s)


def rho_second_order(tau_s: np.ndarray, t_s: float) -> np.ndarray:
    """Normalised autocorrelation of v and w: (1 - |tau| / (2T)) exp(-|tau| / T)."""
    x = np.abs(tau_s) / t_s
    return (1.0 - 0.5 * x) * np.exp(-x)


def rho_lags(rho, t_s: float, dt_s: float, extra: int = 0) -> tuple[np.ndarray, int]:
    """rho at integer lags -M..M (M covers 30 correlation times plus ``extra``), and M."""
    m = int(math.ceil(30.0 * t_s / dt_s)) + extra
    return rho(np.arange(-m, m + 1) * dt_s, t_s), m


def rel_se_std(rho, t_s: float, dt_s: float, n: int) -> float:
    """Relative standard error of a sample standard deviation of a Gaussian process:
    half the relative error of the variance, Var(s^2)/sigma^4 = (2/n) sum_i rho_i^2."""
    r, _ = rho_lags(rho, t_s, dt_s)
    return 0.5 * math.sqrt(2.0 * float(np.sum(r * r)) / n)


def se_mean(rho, t_s: float, dt_s: float, n: int) -> float:
    """Standard error of the sample mean in units of sigma: sqrt(sum_i rho_i / n)."""
    r, _ = rho_lags(rho, t_s, dt_s)
    return math.sqrt(float(np.sum(r)) / n)


def se_acf(rho, t_s: float, dt_s: float, n: int, k: int) -> float:
    """Bartlett's standard error of the sample autocorrelation at lag k."""
    r, m = rho_lags(rho, t_s, dt_s, extra=k)
    i = np.arange(-m + k, m - k + 1) + m  # indices where i - k and i + k are in range
    rk = r[m + k]
    terms = (r[i] ** 2 + r[i + k] * r[i - k] + 2.0 * rk * rk * r[i] ** 2
             - 4.0 * rk * r[i] * r[i + k])
    return math.sqrt(float(np.sum(terms)) / n)


def sample_acf(x: np.ndarray, k: int) -> float:
    d = x - x.mean()
    return float(np.dot(d[:-k], d[k:]) / np.dot(d, d))


# --- calm, steady, gusts ---------------------------------------------------------------

def test_calm_is_zero_everywhere():
    m = WindModel(uniform_wind(), 0.01)
    for k in range(100):
        assert m.sample(0.37 * k, 10.0 * k - 5.0, (3.0 * k, -k, 0.5)) == (0.0, 0.0, 0.0)
    assert m.turbulence_m_s == (0.0, 0.0, 0.0)


def test_steady_only_is_exactly_the_steady_vector():
    steady = (3.25, -1.5, 0.125)
    m = WindModel(uniform_wind(steady_m_s=steady, seed=7), 0.004)
    assert m.steady_m_s == steady
    for k in range(200):
        assert m.sample(0.004 * k, 0.3 * k, (k, 2.0, -1.0)) == steady


def test_gust_exact_values_and_zero_outside():
    t0, dur, amp = 2.0, 1.6, (3.0, -2.0, 1.0)
    steady = (1.0, 0.5, 0.0)
    m = WindModel(uniform_wind(steady_m_s=steady, gusts=(
        GustParams(start_s=t0, duration_s=dur, amplitude_m_s=amp),)), 0.01)

    def gust(t):
        w = m.sample(t, 5.0, (0.0, 0.0, 0.0))
        return tuple(w[i] - steady[i] for i in range(3))

    assert gust(t0) == (0.0, 0.0, 0.0)
    assert gust(t0 + dur / 2) == pytest.approx(amp, abs=1e-12)
    assert gust(t0 + dur) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    # a quarter of the way: A/2 (1 - cos(pi/2)) = A/2
    assert gust(t0 + dur / 4) == pytest.approx(tuple(a / 2 for a in amp), abs=1e-12)
    for t in (0.0, t0 - 1e-9, t0 - 0.5, t0 + dur + 1e-9, t0 + dur + 3.0, 100.0):
        assert gust(t) == (0.0, 0.0, 0.0)


def test_overlapping_gusts_add():
    g1 = GustParams(start_s=1.0, duration_s=2.0, amplitude_m_s=(2.0, 0.0, 0.0))
    g2 = GustParams(start_s=1.5, duration_s=1.0, amplitude_m_s=(1.0, 0.0, -4.0))
    m = WindModel(uniform_wind(gusts=(g1, g2)), 0.01)
    # t = 2: g1 at its peak (2, 0, 0), g2 at its peak (1, 0, -4).
    assert m.sample(2.0, 1.0, (0.0, 0.0, 0.0)) == pytest.approx((3.0, 0.0, -4.0), abs=1e-12)
    # t = 2.75: g2 is over; g1 at 7/8 of its duration.
    f = 0.5 * (1.0 - math.cos(2.0 * math.pi * 1.75 / 2.0))
    assert m.sample(2.75, 1.0, (0.0, 0.0, 0.0)) == pytest.approx((2.0 * f, 0.0, 0.0))


@settings(max_examples=200, deadline=None)
@given(t=st.floats(0.0, 30.0), start=st.floats(0.0, 20.0), dur=st.floats(0.05, 10.0),
       amp=st.tuples(*[st.floats(-20.0, 20.0)] * 3),
       steady=st.tuples(*[st.floats(-15.0, 15.0)] * 3))
def test_no_turbulence_is_steady_plus_gust_formula(t, start, dur, amp, steady):
    m = WindModel(uniform_wind(steady_m_s=steady, gusts=(
        GustParams(start_s=start, duration_s=dur, amplitude_m_s=amp),)), 0.01)
    inside = start <= t <= start + dur
    f = 0.5 * (1.0 - math.cos(2.0 * math.pi * (t - start) / dur)) if inside else 0.0
    want = tuple(s + a * f for s, a in zip(steady, amp, strict=True))
    assert m.sample(t, 12.0, (1.0, 2.0, 3.0)) == pytest.approx(want, rel=1e-12, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(alt=st.floats(-1e4, 1e5), vel=st.tuples(*[st.floats(-100.0, 100.0)] * 3),
       level=st.sampled_from(["light", "moderate", "severe"]), dt=st.floats(1e-4, 0.5))
def test_turbulent_output_is_finite_for_any_altitude_and_velocity(alt, vel, level, dt):
    m = WindModel(uniform_wind(steady_m_s=(0.0, 0.0, 0.0), turbulence=level), dt)
    for k in range(5):
        w = m.sample(k * dt, alt, vel)
        assert all(math.isfinite(c) for c in w)
        assert abs(w[0]) < 50.0 and abs(w[1]) < 50.0 and abs(w[2]) < 50.0


def test_bad_step_rejected():
    for dt in (0.0, -0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="dt_s"):
            WindModel(uniform_wind(), dt)


# --- determinism -----------------------------------------------------------------------

def turbulent(seed: int, **kw) -> WindParams:
    return uniform_wind(steady_m_s=(4.0, 3.0, 0.0), turbulence="moderate", seed=seed, **kw)


def test_same_seed_same_sequence_different_seed_different():
    a = run(WindModel(turbulent(11), 0.005), 3000, 8.0, (1.0, 0.0, 0.0))
    b = run(WindModel(turbulent(11), 0.005), 3000, 8.0, (1.0, 0.0, 0.0))
    c = run(WindModel(turbulent(12), 0.005), 3000, 8.0, (1.0, 0.0, 0.0))
    assert np.array_equal(a, b)
    assert not np.any(a == c)  # every sample differs (the first included)


def test_reset_reproduces_a_fresh_object():
    m = WindModel(turbulent(5), 0.002)
    # long enough to cross a noise-block boundary; altitude and speed vary
    first = [m.sample(k * 0.002, 1.0 + 0.01 * k, (0.001 * k, 0.0, 0.0)) for k in range(9000)]
    m.reset()
    assert m.turbulence_m_s == (0.0, 0.0, 0.0)
    again = [m.sample(k * 0.002, 1.0 + 0.01 * k, (0.001 * k, 0.0, 0.0)) for k in range(9000)]
    assert first == again


def test_turbulence_views_match_the_output():
    m = WindModel(turbulent(3), 0.01)
    w = m.sample(0.0, 20.0, (0.0, 0.0, 0.0))
    t = m.turbulence_m_s
    assert w == pytest.approx(tuple(s + d for s, d in zip(m.steady_m_s, t, strict=True)))
    assert t != (0.0, 0.0, 0.0)
    with pytest.raises(AttributeError):
        m.turbulence_m_s = (0.0, 0.0, 0.0)


def test_turbulence_scales_linearly_with_w20():
    base = run(WindModel(turbulent(9, wind_speed_at_6m_m_s=5.0), 0.01), 500, 30.0,
               (0.0, 0.0, 0.0))
    double = run(WindModel(turbulent(9, wind_speed_at_6m_m_s=10.0), 0.01), 500, 30.0,
                 (0.0, 0.0, 0.0))
    steady = np.array([4.0, 3.0, 0.0])
    np.testing.assert_allclose(double - steady, 2.0 * (base - steady), rtol=1e-12, atol=1e-12)


def test_default_w20_per_intensity():
    for level, knots in (("light", 15.0), ("moderate", 30.0), ("severe", 45.0)):
        m = WindModel(uniform_wind(turbulence=level), 0.01)
        assert m.w20_m_s == pytest.approx(knots * 0.514444, rel=1e-5)
    assert WindModel(turbulent(0, wind_speed_at_6m_m_s=4.0), 0.01).w20_m_s == 4.0


def test_altitude_is_clamped_to_the_model_range():
    def seq(alt):
        return run(WindModel(turbulent(2), 0.01), 300, alt, (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(seq(-3.0), seq(MIN_ALTITUDE_M))
    np.testing.assert_array_equal(seq(0.0), seq(MIN_ALTITUDE_M))
    np.testing.assert_array_equal(seq(2000.0), seq(MAX_ALTITUDE_M))


def test_scales_follow_altitude_changes():
    """States are normalised, so changing altitude at step k rescales u at that step by
    the ratio of sigma_u; w (sigma_w = 0.1 W20) is unchanged at that step."""
    dt, k, h1, h2 = 0.01, 200, 5.0, 60.0
    a, b = WindModel(turbulent(4), dt), WindModel(turbulent(4), dt)
    for i in range(k):
        a.sample(i * dt, h1, (0.0, 0.0, 0.0))
        b.sample(i * dt, h1, (0.0, 0.0, 0.0))
    a.sample(k * dt, h1, (0.0, 0.0, 0.0))
    b.sample(k * dt, h2, (0.0, 0.0, 0.0))
    ua, va, wa = a.turbulence_uvw_m_s
    ub, vb, wb = b.turbulence_uvw_m_s
    ratio = dryden_sigmas_m_s(h2, 1.0)[0] / dryden_sigmas_m_s(h1, 1.0)[0]
    assert ratio < 0.9  # the test needs a real change
    assert ub == pytest.approx(ratio * ua, rel=1e-12)
    assert vb == pytest.approx(ratio * va, rel=1e-12)
    assert wb == pytest.approx(wa, rel=1e-12)
    # From then on the time constants differ too, so the sequences part.
    assert a.sample((k + 1) * dt, h1, (0.0, 0.0, 0.0)) != b.sample((k + 1) * dt, h2,
                                                                     (0.0, 0.0, 0.0))


# --- scales ----------------------------------------------------------------------------

@pytest.mark.parametrize(("h_ft", "l_uv_ft", "s_uv_over_s_w"), [
    # h / (0.177 + 0.000823 h)^1.2 and 1 / (0.177 + 0.000823 h)^0.4, by hand:
    # 100 ft: 0.177 + 0.0823 = 0.2593; 0.2593^1.2 = 0.19795; 0.2593^0.4 = 0.58280
    (100.0, 505.17, 1.71585),
    # 500 ft: 0.177 + 0.4115 = 0.5885; 0.5885^1.2 = 0.52929; 0.5885^0.4 = 0.80891
    (500.0, 944.66, 1.23624),
    # 10 ft (the floor): 0.177 + 0.00823 = 0.18523; ^1.2 = 0.13221; ^0.4 = 0.50943
    (10.0, 75.639, 1.96298),
])
def test_length_scales_and_sigmas_against_hand_values(h_ft, l_uv_ft, s_uv_over_s_w):
    l_u, l_v, l_w = dryden_length_scales_m(h_ft * FT_M)
    assert l_u == pytest.approx(l_uv_ft * FT_M, rel=2e-4)
    assert l_v == l_u
    assert l_w == pytest.approx(h_ft * FT_M, rel=1e-12)
    w20 = 30.0 * KNOT_M_S  # moderate: 15.433 m/s, sigma_w = 1.5433 m/s
    s_u, s_v, s_w = dryden_sigmas_m_s(h_ft * FT_M, w20)
    assert s_w == pytest.approx(1.54333, rel=1e-5)
    assert s_u == pytest.approx(1.54333 * s_uv_over_s_w, rel=1e-4)
    assert s_v == s_u


def test_scales_clamped_below_10_ft_and_above_1000_ft():
    assert dryden_length_scales_m(0.0) == dryden_length_scales_m(10.0 * FT_M)
    assert dryden_sigmas_m_s(-5.0, 7.0) == dryden_sigmas_m_s(10.0 * FT_M, 7.0)
    top = dryden_length_scales_m(1000.0 * FT_M)
    assert top == pytest.approx((1000.0 * FT_M,) * 3)  # isotropic at 1000 ft
    assert dryden_length_scales_m(5000.0) == top
    assert dryden_sigmas_m_s(5000.0, 7.0) == pytest.approx((0.7, 0.7, 0.7))


# --- statistics against the analytic Dryden model ----------------------------------------

ALT_M = 4.0
STEADY = (10.0, 0.0, 0.0)  # u along x, v along y, w along z
VEHICLE = (-20.0, 0.0, 0.0)  # the field passes at V = 30 m/s
V_M_S = 30.0
W20 = 30.0 * KNOT_M_S


@pytest.fixture(scope="module")
def long_run() -> tuple[np.ndarray, float]:
    """4000 s at dt = 10 ms: the turbulence part (n x 3) and dt."""
    dt = 0.01
    p = uniform_wind(steady_m_s=STEADY, turbulence="moderate", seed=2024)
    x = run(WindModel(p, dt), 400_000, ALT_M, VEHICLE)
    return x - np.array(STEADY), dt


def component_models(alt_m: float, v_m_s: float):
    l_u, l_v, l_w = dryden_length_scales_m(alt_m)
    s_u, s_v, s_w = dryden_sigmas_m_s(alt_m, W20)
    return [(rho_first_order, l_u / v_m_s, s_u), (rho_second_order, l_v / v_m_s, s_v),
            (rho_second_order, l_w / v_m_s, s_w)]


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["u", "v", "w"])
def test_std_and_mean_match_dryden(long_run, axis):
    x, dt = long_run
    rho, t_c, sigma = component_models(ALT_M, V_M_S)[axis]
    n = len(x)
    tol = N_SE * rel_se_std(rho, t_c, dt, n)
    assert tol < 0.05  # "within a few percent"
    assert np.std(x[:, axis]) == pytest.approx(sigma, rel=tol)
    tol_mean = N_SE * se_mean(rho, t_c, dt, n)
    assert tol_mean < 0.15
    assert abs(np.mean(x[:, axis])) < tol_mean * sigma


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["u", "v", "w"])
@pytest.mark.parametrize("lag_in_t", [0.25, 1.0, 2.0])
def test_autocorrelation_matches_dryden(long_run, axis, lag_in_t):
    x, dt = long_run
    rho, t_c, _ = component_models(ALT_M, V_M_S)[axis]
    k = max(1, round(lag_in_t * t_c / dt))
    want = float(rho(np.array(k * dt), t_c))
    tol = N_SE * se_acf(rho, t_c, dt, len(x), k)
    # Must separate the first-order from the second-order form at this lag.
    other = rho_second_order if rho is rho_first_order else rho_first_order
    assert abs(float(other(np.array(k * dt), t_c)) - want) > 1.5 * tol
    assert sample_acf(x[:, axis], k) == pytest.approx(want, abs=tol)


def test_variance_does_not_depend_on_dt():
    """Exact discretisation: the same sigma at dt = 1 ms and 10 ms, even when dt is a
    sizeable fraction of the correlation time (altitude at the 10 ft floor, V = 40 m/s,
    so T_w = 76 ms and a 10 ms step is 13 % of it)."""
    alt, v = 0.0, 40.0
    duration = 1000.0
    stds = {}
    for dt in (0.001, 0.01):
        p = uniform_wind(steady_m_s=(0.0, 0.0, 0.0), turbulence="severe", seed=99)
        n = round(duration / dt)
        x = run(WindModel(p, dt), n, alt, (0.0, -v, 0.0))
        models = component_models(alt, v)
        stds[dt] = np.std(x, axis=0)
        for axis, (rho, t_c, _) in enumerate(models):
            sigma = dryden_sigmas_m_s(alt, 45.0 * KNOT_M_S)[axis]
            tol = N_SE * rel_se_std(rho, t_c, dt, n)
            if axis == 2:
                assert tol < 0.025  # tight enough to see an O(dt/T) variance error
            assert stds[dt][axis] == pytest.approx(sigma, rel=tol), (dt, axis)
    # and against each other for w, the shortest time scale
    rho, t_c, _ = component_models(alt, v)[2]
    tol = N_SE * math.hypot(rel_se_std(rho, t_c, 0.001, 1_000_000),
                            rel_se_std(rho, t_c, 0.01, 100_000))
    assert stds[0.001][2] == pytest.approx(stds[0.01][2], rel=tol)


def test_exact_at_steps_comparable_to_the_correlation_times():
    """At dt = 0.25 s the step is 0.43 T_u and 3.3 T_w (floor altitude, V = 40 m/s): an
    approximate discretisation would be far off; the exact one keeps sigma and the
    one-step correlation."""
    alt, v, dt, n = 0.0, 40.0, 0.25, 100_000
    p = uniform_wind(turbulence="severe", seed=17)
    x = run(WindModel(p, dt), n, alt, (v, 0.0, 0.0))
    sigmas = dryden_sigmas_m_s(alt, 45.0 * KNOT_M_S)
    for axis, (rho, t_c, _) in enumerate(component_models(alt, v)):
        tol = N_SE * rel_se_std(rho, t_c, dt, n)
        assert tol < 0.03
        assert np.std(x[:, axis]) == pytest.approx(sigmas[axis], rel=tol), axis
        want = float(rho(np.array(dt), t_c))
        tol = N_SE * se_acf(rho, t_c, dt, n, 1)
        assert sample_acf(x[:, axis], 1) == pytest.approx(want, abs=tol), axis


def test_initial_state_is_stationary():
    """The first sample is drawn from the stationary distribution (no start-up
    transient): across seeds its standard deviation is sigma."""
    n = 1500
    first = np.array([
        WindModel(uniform_wind(turbulence="light", seed=s), 0.01).sample(0.0, 30.0, (5, 0, 0))
        for s in range(n)])
    sigmas = dryden_sigmas_m_s(30.0, 15.0 * KNOT_M_S)
    tol = N_SE * math.sqrt(0.5 / n)  # independent samples: rel. SE of s is 1/sqrt(2n)
    np.testing.assert_allclose(np.std(first, axis=0), sigmas, rtol=tol)


# --- direction -------------------------------------------------------------------------

def test_u_lies_along_a_mean_wind_along_y():
    dt, n, v = 0.01, 120_000, 20.0
    m = WindModel(uniform_wind(steady_m_s=(0.0, 6.0, 0.0), turbulence="light", seed=8), dt)
    rows = []
    for k in range(n):
        m.sample(dt * k, 3.0, (0.0, 6.0 - v, 0.0))  # the field passes at 20 m/s
        rows.append((*m.turbulence_m_s, *m.turbulence_uvw_m_s))
    r = np.array(rows)
    # u along +y, v (left of the wind, right-handed with w up) along -x, w along z
    np.testing.assert_array_equal(r[:, 1], r[:, 3])
    np.testing.assert_array_equal(r[:, 0], -r[:, 4])
    np.testing.assert_array_equal(r[:, 2], r[:, 5])
    # From the output alone: y has the first-order (u) correlation, x the second-order (v)
    # one; at lag T they are e^-1 and e^-1 / 2.
    t_c = dryden_length_scales_m(3.0)[0] / v
    k = round(t_c / dt)
    want_y = float(rho_first_order(np.array(k * dt), t_c))
    want_x = float(rho_second_order(np.array(k * dt), t_c))
    tol_y = N_SE * se_acf(rho_first_order, t_c, dt, n, k)
    tol_x = N_SE * se_acf(rho_second_order, t_c, dt, n, k)
    assert want_y - want_x > 1.5 * max(tol_x, tol_y)
    assert sample_acf(r[:, 1], k) == pytest.approx(want_y, abs=tol_y)
    assert sample_acf(r[:, 0], k) == pytest.approx(want_x, abs=tol_x)


def test_u_along_an_oblique_mean_wind():
    m = WindModel(uniform_wind(steady_m_s=(3.0, 4.0, 1.0), turbulence="light", seed=1), 0.01)
    for k in range(50):
        m.sample(0.01 * k, 10.0, (0.0, 0.0, 0.0))
        tx, ty, tz = m.turbulence_m_s
        u, v, w = m.turbulence_uvw_m_s
        assert tx == pytest.approx(0.6 * u - 0.8 * v, abs=1e-12)
        assert ty == pytest.approx(0.8 * u + 0.6 * v, abs=1e-12)
        assert tz == w


def test_no_mean_wind_still_gives_turbulence_with_speed_floored_at_1_m_s():
    def seq(vel):
        return run(WindModel(uniform_wind(turbulence="severe", seed=3), 0.01), 2000, 0.0, vel)
    hover = seq((0.0, 0.0, 0.0))
    assert np.all(np.isfinite(hover))
    assert np.all(np.std(hover, axis=0) > 0.0)
    np.testing.assert_array_equal(hover, seq((0.0, 0.0, 0.5)))
    np.testing.assert_array_equal(hover, seq((0.0, MIN_PASSING_SPEED_M_S, 0.0)))
    assert not np.array_equal(hover, seq((0.0, 1.5 * MIN_PASSING_SPEED_M_S, 0.0)))


# --- mean wind profile with height -----------------------------------------------------

@pytest.mark.parametrize("profile", ["log", "power"])
def test_mean_wind_follows_its_profile(profile):
    steady = (6.0, -2.0, 0.0)
    p = WindParams(steady_m_s=steady, profile=profile, reference_height_m=10.0,
                   roughness_length_m=0.05, power_exponent=0.2)
    m = WindModel(p, 0.001)
    assert not m.constant
    for z in (0.01, 0.5, 3.0, 10.0, 20.0, 75.0):
        if profile == "log":
            f = max(math.log(z / 0.05), 0.0) / math.log(10.0 / 0.05)
        else:
            f = (z / 10.0) ** 0.2
        w = m.sample(0.0, z, (0.0, 0.0, 0.0))
        assert w == pytest.approx(tuple(f * c for c in steady), rel=1e-12, abs=1e-12)
    # at the reference height the wind is the steady wind
    assert m.sample(0.0, 10.0, (0.0, 0.0, 0.0)) == pytest.approx(steady, rel=1e-14)


def test_uniform_part_is_the_wind_less_its_mean():
    p = WindParams(steady_m_s=(5.0, 0.0, 0.0), turbulence="moderate", seed=3,
                   gusts=(GustParams(start_s=0.0, duration_s=1.0, amplitude_m_s=(1.0, 2.0, 0.5)),))
    m = WindModel(p, 0.01)
    out = np.zeros(6)
    from sitl.wind import profile_factor, wind_kernel
    for k in range(50):
        while not wind_kernel(*m.kernel_args, 0.01 * k, 17.0, 0.0, 0.0, 0.0, out):
            m.refill()
        f = profile_factor(m.packed, 17.0)
        np.testing.assert_allclose(out[3:], out[:3] - f * np.array([5.0, 0.0, 0.0]),
                                   atol=1e-12)
