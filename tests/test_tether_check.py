"""The tether fix checked against the GNSS (companion/ekf/tether_check.py): a fix with a
slow error its covariance does not hold must not pull the estimate off a consumer
receiver's; a fix that holds keeps its covariance (docs/estimation.md §10, *The fix
against the GNSS*)."""

from __future__ import annotations

import numpy as np
import pytest
from ekf_harness import gauss_markov, params_for, simulate, static

from companion.ekf.params import TetherCheckParams, TetherFixParams
from companion.ekf.tether_check import TetherFixCheck, mean_variance
from sitl.sensors import GNSS_MODELS, GnssPreset, SensorNoise

#: chi-square(6)'s 95 % two-sided bounds (the NEES of position and velocity)
CHI2_6_LOW, CHI2_6_HIGH = 1.237, 14.449
HOVER = (12.0, -4.0, 20.0)


def _hover(bias_m: tuple[float, float, float] | None, check: bool, seed: int = 5,
           sigma_m: float = 0.3):
    """A minute's hover on the consumer receiver with a 10 Hz tether fix off the truth by
    ``bias_m`` [m] (plus 0.1 m white noise) claiming a σ of ``sigma_m`` per axis (None: no
    tether fix)."""
    model = GNSS_MODELS[GnssPreset("gnss")]
    noise = SensorNoise.preset("gnss", seed)
    params = params_for(noise, gnss_delay_s=model.latency_s, gnss_pos_tau_s=8.0,
                        tether_fix=TetherFixParams(
                            gnss_check=TetherCheckParams(enabled=check)))
    rng = np.random.default_rng(seed)
    v = sigma_m * sigma_m
    cov = ((v, 0.0, 0.0), (0.0, v, 0.0), (0.0, 0.0, v))

    def fix(t, pos):
        return tuple(np.add(pos, bias_m) + rng.normal(0.0, 0.1, 3)), cov

    return simulate(static(pos=HOVER), noise, 60.0, params=params, gnss_hz=model.rate_hz,
                    gnss_delay_s=model.latency_s,
                    tether_fix=None if bias_m is None else fix)


def _after(run, t0_s: float = 20.0) -> tuple[float, float]:
    """The horizontal position error's RMS [m] after ``t0_s`` and the share of the
    position's NEES within chi-square(3)'s 95 % bounds."""
    t = np.array(run.t)
    k = t >= t0_s
    e = np.array(run.pos_err)[k]
    rms = float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1))))
    nees = np.array(run.nees)[k]
    return rms, float(np.mean((nees >= CHI2_6_LOW) & (nees <= CHI2_6_HIGH)))


def test_a_biased_fix_does_not_pull_the_estimate_off_the_receiver():
    """A fix 2 m east and 1 m below the truth claiming 0.3 m (a line heavier than
    believed) beside a consumer receiver: unchecked, the estimate follows it and its NEES
    leaves the chi-square bounds; checked against the receiver, the estimate is within 0.25 m
    RMS of the receiver's alone, and consistent."""
    alone, alone_in = _after(_hover(None, check=True))
    unchecked, unchecked_in = _after(_hover((2.0, 0.0, -1.0), check=False))
    checked, checked_in = _after(_hover((2.0, 0.0, -1.0), check=True))
    print(f"horizontal RMS (NEES inside chi-square(6) 95 %): GNSS alone {alone:.2f} m "
          f"({alone_in:.0%}), 2 m biased fix unchecked {unchecked:.2f} m ({unchecked_in:.0%}),"
          f" checked {checked:.2f} m ({checked_in:.0%})")
    assert unchecked > alone + 0.5, (unchecked, alone)
    assert unchecked_in < 0.5, unchecked_in
    assert checked <= alone + 0.25, (checked, alone)
    assert checked_in >= 0.85, checked_in


def test_a_slow_error_within_the_fix_claim_does_not_lock_the_estimate():
    """A fix 1.2 m east and 0.6 m below the truth claiming 1 m per axis (a lumped line's
    allowance for its weight and drag, as in robustness-gnss): one fix's error is within
    its claim, but it stays, and fused at 10 Hz as white it would hold the estimate on the
    fix. Judged against the spread of the mean difference (the receiver's wander averaged
    over the check's window), the estimate stays within 0.25 m RMS of the receiver's
    alone, and consistent."""
    alone, _ = _after(_hover(None, check=True))
    checked, checked_in = _after(_hover((1.2, 0.0, -0.6), check=True, sigma_m=1.0))
    print(f"horizontal RMS: GNSS alone {alone:.2f} m, a 1.2 m slow error claiming 1 m "
          f"checked {checked:.2f} m (NEES inside chi-square(6) 95 %: {checked_in:.0%})")
    assert checked <= alone + 0.25, (checked, alone)
    assert checked_in >= 0.85, checked_in


@pytest.mark.parametrize(("tau_s", "window_s"), [(8.0, 0.0), (8.0, 4.0), (8.0, 40.0),
                                                 (0.0, 40.0)])
def test_the_mean_of_a_wandering_receiver_spreads_as_its_model_says(tau_s, window_s):
    """The variance of a receiver error's mean over a window (a Gauss-Markov share 0.9 of
    0.64 m^2 with tau_s, the rest white, at 5 Hz) against the sample variance of such
    means over many simulated windows."""
    rng = np.random.default_rng(7)
    var, frac, dt = 0.64, 0.9, 0.2
    n = int(round(window_s / dt)) + 1
    runs = 4000
    if tau_s > 0.0:
        phi = np.exp(-dt / tau_s)
        b = np.empty((runs, n))
        b[:, 0] = rng.normal(0.0, np.sqrt(frac * var), runs)
        for k in range(1, n):
            b[:, k] = phi * b[:, k - 1] + rng.normal(0.0, np.sqrt(frac * var * (1 - phi ** 2)),
                                                     runs)
        white = 1.0 - frac
    else:
        b = np.zeros((runs, n))
        white = 1.0
    e = b + rng.normal(0.0, np.sqrt(white * var), (runs, n))
    sample = float(np.var(e.mean(axis=1)))
    model = mean_variance(var, tau_s, frac, window_s, dt)
    print(f"tau {tau_s} s, window {window_s} s: sample {sample:.4f} m^2, model {model:.4f}")
    assert abs(model - sample) <= 0.1 * sample + 0.002, (model, sample)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_fix_that_holds_is_moved_less_than_the_receiver_errs(seed):
    """Fixes whose error is their claimed covariance's, beside a consumer receiver (its
    0.8 m wander over 8 s): the check cannot tell the receiver's wander from the fix's
    error for certain, but what it takes off the fixes is never more than the receiver's
    own error (RMS over a minute), and a fix's covariance only grows."""
    check = TetherFixCheck(TetherCheckParams())
    rng = np.random.default_rng(seed)
    wander = gauss_markov(0.8, 8.0, seed)
    c = (0.25, 0.05, 0.0, 0.16, 0.0, 0.09)
    chol = np.linalg.cholesky(np.array(((0.25, 0.05, 0.0), (0.05, 0.16, 0.0),
                                        (0.0, 0.0, 0.09))))
    taken, gnss_err = [], []
    for i in range(600):
        t = 0.1 * i
        truth = np.array((10.0 + 0.2 * t, 3.0, 20.0))
        if i % 2 == 0:
            err = np.array(wander(t)) + rng.normal(0.0, 0.1, 3)
            gnss_err.append(err)
            check.add_gnss(t, tuple(truth + err), (0.2, 0.0, 0.0), 0.8, 0.8)
        z = truth + chol @ rng.normal(0.0, 1.0, 3)
        pos, cov = check.correct(t, tuple(z), c)
        taken.append(np.subtract(z, pos))
        assert all(cov[k] >= c[k] for k in (0, 3, 5))
    rms_taken = float(np.sqrt(np.mean(np.sum(np.square(taken), axis=1))))
    rms_gnss = float(np.sqrt(np.mean(np.sum(np.square(gnss_err), axis=1))))
    print(f"seed {seed}: taken off the fixes {rms_taken:.2f} m RMS, the receiver's error "
          f"{rms_gnss:.2f} m RMS")
    assert rms_taken <= rms_gnss
