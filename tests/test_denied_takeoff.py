"""The GNSS-denied take-off: the pad as a position source at rest and through the climb
(the line lying slack on the ground gives no tether fix), and the lumped line's mission
flown from the ground without GNSS (docs/estimation.md §10, *On the ground without
GNSS*)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.ekf import AidSource, EstimatorParams, FilterHealth, HealthReason, NavFilter, health
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario
from tuavdefs.frames import ned_to_enu

PARKED = (2.0, 0.0, 0.2)
RATE_HZ = 250


def _parked_filter(params: EstimatorParams):
    """A filter fed a still vehicle's IMU (white noise), baro and magnetometer, tether
    fixes of the parked position for the first 3 s only, and the stationary constraint
    while ``rest(t)``; returns the filter and a function running it to a time."""
    rng = np.random.default_rng(5)
    f = NavFilter(params, 9.81, ned_to_enu((0.2, 0.0, 0.45)))
    cov = ((0.04, 0.0, 0.0), (0.0, 0.04, 0.0), (0.0, 0.0, 0.04))
    clock = {"k": 0}

    def run_to(t_end: float, rest: bool, fix: bool = False) -> float:
        t = clock["k"] / RATE_HZ
        while t < t_end:
            k = clock["k"]
            t = k / RATE_HZ
            n = rng.normal(0.0, 0.06, 3)
            f.predict(t, tuple(rng.normal(0.0, 5e-3, 3)), (n[0], n[1], 9.81 + n[2]))
            f.fuse_baro(t, 100.0 + PARKED[2])
            f.fuse_mag(t, (0.2, 0.0, -0.45))
            if (fix or t < 3.0) and k % 25 == 0:
                f.fuse_tether(t, t - 0.02, PARKED, cov)
            if rest:
                f.fuse_stationary(t)
            clock["k"] = k + 1
        return t

    return f, run_to


def test_the_pad_is_a_position_source_at_rest_and_through_the_take_off(monkeypatch):
    """Aligned on tether fixes, then none (a slack line on the ground): at rest the filter
    stays healthy on the pad, its position within 2 cm; leaving the pad (no stationary
    constraint) it holds for PAD_HOLD_S (5 s here) and then, no fix having come, raises NO_GNSS;
    tether fixes fused after leaving do not end the hold early."""
    monkeypatch.setattr(health, "PAD_HOLD_S", 5.0)
    monkeypatch.setattr(health, "TETHER_HOLD_S", 3.0)
    params = EstimatorParams()
    f, run_to = _parked_filter(params)
    t = run_to(12.0, rest=True)
    st = f.status(t)
    assert f.aligned and st.reasons == HealthReason.NONE
    assert st.health == FilterHealth.HEALTHY
    assert AidSource.PAD in st.sources and AidSource.TETHER not in st.sources
    p = f.state().pos_m
    assert math.hypot(p[0] - PARKED[0], p[1] - PARKED[1]) <= 0.02
    t = run_to(15.0, rest=False)                  # armed: the constraint is no longer fused
    st = f.status(t)
    assert st.health == FilterHealth.HEALTHY and AidSource.PAD in st.sources
    t = run_to(17.5, rest=False)                  # 5.5 s off the pad, no fix
    st = f.status(t)
    assert AidSource.PAD not in st.sources
    assert st.reasons & HealthReason.NO_GNSS and st.health == FilterHealth.UNHEALTHY
    # a second filter: fixes that come and go after leaving the pad (a line lifting off
    # the ground) do not end the hold; past PAD_HOLD_S they alone are the source (the
    # last one held TETHER_HOLD_S, 3 s here: to 16 s)
    g, run_g = _parked_filter(params)
    run_g(12.0, rest=True)
    run_g(13.0, rest=False, fix=True)
    t = run_g(15.0, rest=False)                   # the fixes stopped 2 s ago
    st = g.status(t)
    assert AidSource.PAD in st.sources and AidSource.TETHER not in st.sources
    assert st.health == FilterHealth.HEALTHY
    t = run_g(17.5, rest=False)
    assert g.status(t).reasons & HealthReason.NO_GNSS
    # without the hold only rest counts
    monkeypatch.setattr(health, "PAD_HOLD_S", 0.0)
    h, run_h = _parked_filter(params)
    run_h(12.0, rest=True)
    t = run_h(12.5, rest=False)
    assert h.status(t).reasons & HealthReason.NO_GNSS


def test_the_last_tether_fix_holds_through_a_gap_and_a_rejected_fix_does_not(monkeypatch):
    """Off the pad (no stationary constraint), fused tether fixes, then a gap: the filter
    stays healthy for TETHER_HOLD_S after the last fix fused (the line slack for a moment),
    then raises NO_GNSS; fixes far off (rejected by the gate) do not renew the hold, and a
    fix fused again ends NO_GNSS."""
    monkeypatch.setattr(health, "PAD_HOLD_S", 0.0)
    params = EstimatorParams()
    f, run_to = _parked_filter(params)
    run_to(12.0, rest=True)
    t = run_to(14.0, rest=False, fix=True)        # in the air on the fixes
    st = f.status(t)
    assert st.health == FilterHealth.HEALTHY and AidSource.TETHER in st.sources
    t = run_to(14.0 + 0.8 * health.TETHER_HOLD_S, rest=False)
    st = f.status(t)
    assert AidSource.TETHER not in st.sources
    assert st.health == FilterHealth.HEALTHY and not st.reasons & HealthReason.NO_GNSS
    far = (PARKED[0] + 30.0, PARKED[1], PARKED[2])
    cov = ((0.04, 0.0, 0.0), (0.0, 0.04, 0.0), (0.0, 0.0, 0.04))
    for k in range(10):                             # rejected: 30 m off at a sigma of 0.2 m
        tk = t + 0.1 * k
        assert not f.fuse_tether(tk, tk - 0.02, far, cov)
    t = run_to(14.0 + 1.2 * health.TETHER_HOLD_S, rest=False)
    assert f.status(t).reasons & HealthReason.NO_GNSS
    t = run_to(t + 0.5, rest=False, fix=True)
    st = f.status(t)
    assert st.health == FilterHealth.HEALTHY and AidSource.TETHER in st.sources


#: chi-square(3)'s 99th percentile: a consistent fix's normalised squared error
#: exceeds it one time in a hundred.
CHI2_3_99 = 11.34


@pytest.mark.parametrize("home", [(2.0, 0.0, 0.0), (4.0, -3.0, 0.0), (-3.0, 4.0, 0.0)])
def test_a_gnss_denied_take_off_on_the_lumped_line(home):
    """mission-gnss-denied (the lumped line its truth, the tension law) from three homes
    around the winder, 20 s: the line lies on the ground (friction takes its pull: the arm
    reads nothing) but while the pre-tension pulls it straight; the filter aligns on that
    fix, arms on the pad and climbs on it and on the fixes as the line lifts, with no EKF
    failsafe. At 20 s the vehicle is up and the truth within 1 m of the estimate (a
    consumer receiver's tracking target). Every tether fix from the take-off on against
    the truth (the attachment is the centre of mass), under its covariance as the filter
    takes it (``tether_noise_min_m`` added): at least 90 % within chi-square(3)'s 99 %
    bound, none beyond the filter's gate (a fix whose covariance does not hold its error is
    rejected: rejected for innovation_fail_s, the filter is unhealthy)."""
    sc = load_scenario("mission-gnss-denied")
    assert sc.plant.tether.model == "lumped"
    sc = sc.replace(duration_s=20.0, initial=sc.initial.replace(position_m=home))
    runner = OfflineRunner(sc)
    fixes = []
    to_vehicle = runner._tether_fix_to_vehicle

    def keep(fix):
        fixes.append(fix)
        to_vehicle(fix)

    runner._tether_fix_to_vehicle = keep
    res = runner.run()
    nav = runner.companion.nav
    assert res.metrics["arming_refused"] is None
    assert nav.armed and nav.flying
    assert not [v for k, v, _ in runner.nav_events if k.value == "failsafe"]
    st = runner.companion.filter.status()
    assert AidSource.TETHER in st.sources
    est, pos, t = res.series["est_pos"], res.series["pos"], res.series["t"]
    assert pos[-1][2] >= 8.0
    assert math.dist(est[-1], pos[-1]) <= 1.0
    t_arm = t[np.isfinite(res.series["ref_pos"]).all(axis=1)][0]    # the take-off's start
    params = EstimatorParams()
    floor = np.eye(3) * params.tether_noise_min_m ** 2     # as the filter takes the fix
    nees = []
    for fix in fixes:
        ts = fix.sample_time_ms * 1e-3
        if ts < t_arm:
            continue
        e = np.subtract(fix.pos_m, pos[min(int(np.searchsorted(t, ts)), len(t) - 1)])
        nees.append(float(e @ np.linalg.solve(np.array(fix.cov_m2) + floor, e)))
    gate = params.tether_gate_sigma
    assert len(nees) >= 50
    assert np.mean(np.array(nees) <= CHI2_3_99) >= 0.9
    assert max(nees) <= gate * gate
