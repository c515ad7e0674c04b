"""The tether fix's sway allowance (groundstation.tether_fix.FixScatter, docs/estimation.md
§10, *The line's sway*): the fix's recent scatter about the vehicle's reported position
widens its covariance. Against an independent truth: the plant's catenary (sitl.tether)
for the still line's exit reading, swung across by a known sway."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.tether_fix import FixScatter, TetherFixer, TetherFixParams
from sitl.tether import Tether
from tuavdefs.params import TetherParams

G = 9.81
TP = TetherParams()
TOP = (8.0, 4.0, 15.0)            # hover-gnss-loss's hover
LENGTH_M = math.dist(TOP, (0.0, 0.0, 0.0)) + 0.3
RATE_HZ = 10.0


def _still_exit() -> tuple[float, float, float]:
    """(tension [N], azimuth, elevation [rad]) at the exit of the still catenary to TOP."""
    forces = Tether(TP, G).forces(*TOP, LENGTH_M)
    fx, fy, fz = forces.on_exit_n
    return (math.sqrt(fx * fx + fy * fy + fz * fz), math.atan2(fy, fx),
            math.atan2(fz, math.hypot(fx, fy)))


def _swaying_fixes(amplitude_rad: float, params: TetherFixParams, seconds: float = 30.0):
    """(fix errors [m], covariances as sent, covariances before the allowance) of fixes
    at RATE_HZ of the still line whose exit azimuth swings by ``amplitude_rad`` over a
    1.4 s period (the lumped line's sway in calm air), the vehicle still at TOP and
    reporting it."""
    fixer = TetherFixer(params, TP.linear_density_kg_m * G, TP.axial_stiffness_n,
                        TP.diameter_m)
    scatter = FixScatter(params)
    t0, az, el = _still_exit()
    errors, sent, bare = [], [], []
    for k in range(int(seconds * RATE_HZ)):
        t = k / RATE_HZ
        swing = amplitude_rad * math.sin(2.0 * math.pi * t / 1.4)
        pos, cov, ground = fixer.position(LENGTH_M, t0, az + swing, el, TOP)
        assert not ground
        widened = scatter.widen(t, pos, cov, TOP, ground)
        if t >= params.scatter_window_s:
            errors.append(np.subtract(pos, TOP))
            sent.append(np.array(widened))
            bare.append(np.array(cov))
    return np.array(errors), np.array(sent), np.array(bare)


def _nees(errors: np.ndarray, covs: np.ndarray) -> float:
    return float(np.mean([e @ np.linalg.solve(c, e) for e, c in zip(errors, covs, strict=True)]))


def test_the_sway_widens_the_fix_to_cover_it():
    """The exit's azimuth swinging by 0.145 rad (the fix 1.3 m across the line at the
    swing's peak, 0.92 m RMS: the lumped line's sway measured in hover-gnss-loss's calm
    hover): the static fix's own covariance does not cover it (NEES above chi-square(3)'s
    mean of 3), the widened one does (at most 3); the widening is across the line, where
    the sway is, and there it claims the sway's variance ``scatter_gain`` times (as the
    fixes' errors are correlated over the swing), to within the still fix's own share."""
    params = TetherFixParams()
    errors, sent, bare = _swaying_fixes(0.145, params)
    rms_across = float(np.sqrt(np.mean(np.sum(errors[:, :2] ** 2, axis=1))))
    assert 0.8 < rms_across < 1.1
    assert _nees(errors, bare) > 3.0
    assert _nees(errors, sent) <= 3.0
    _, az, _ = _still_exit()
    across = np.array([-math.sin(az), math.cos(az), 0.0])
    radial = np.array([math.cos(az), math.sin(az), 0.0])
    added = sent[-1] - bare[-1]
    assert across @ added @ across > 10.0 * (radial @ added @ radial)
    sway_var = float(np.mean((errors @ across) ** 2))
    claimed = np.mean([across @ c @ across for c in sent])
    bare_claimed = np.mean([across @ c @ across for c in bare])
    assert claimed - bare_claimed == pytest.approx(params.scatter_gain * sway_var, rel=0.1)


def test_a_still_line_and_a_steady_offset_are_not_widened():
    """No sway: the widening is nil (the readings repeat); a fix steadily off the report
    (its bias, or a moving vehicle's report late by a constant time) is not scatter: the
    window's mean is taken off."""
    params = TetherFixParams()
    _, sent, bare = _swaying_fixes(0.0, params)
    assert np.abs(sent - bare).max() < 1e-9
    scatter = FixScatter(params)
    for k in range(60):
        scatter.add(k / RATE_HZ, (8.7, 3.9, 15.2), TOP)
    cov = scatter.covariance()
    assert cov is not None and np.abs(cov).max() < 1e-12


def test_the_window_forgets_and_the_ground_regime_is_left_alone():
    """The scatter counts the last ``scatter_window_s`` only: a sway that has died out
    stops widening the fix one window later; a fix of a line on the ground (made from the
    reported position itself) is neither widened nor counted; none before
    ``scatter_min_fixes`` fixes or with the gain at 0."""
    params = TetherFixParams()
    scatter = FixScatter(params)
    rng = np.random.default_rng(3)
    n = int(params.scatter_window_s * RATE_HZ)
    for k in range(n):
        scatter.add(k / RATE_HZ, tuple(np.add(TOP, rng.normal(0.0, 0.5, 3))), TOP)
    swaying = scatter.covariance()
    assert swaying is not None and np.trace(swaying) > params.scatter_gain * 0.5
    for k in range(n, 2 * n + 1):
        scatter.add(k / RATE_HZ, TOP, TOP)
    still = scatter.covariance()
    assert still is not None and np.abs(still).max() < 1e-12
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    fresh = FixScatter(params)
    for k in range(3 * params.scatter_min_fixes):
        assert fresh.widen(k / RATE_HZ, (0.0, k, 0.0), eye, TOP, True) == eye
    assert fresh.covariance() is None
    for k in range(params.scatter_min_fixes - 1):
        fresh.add(k / RATE_HZ, (0.0, k, 0.0), TOP)
    assert fresh.covariance() is None
    off = FixScatter(TetherFixParams(scatter_gain=0.0))
    for k in range(3 * params.scatter_min_fixes):
        assert off.widen(k / RATE_HZ, (0.0, k, 0.0), eye, TOP, False) == eye
