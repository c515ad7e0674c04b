"""The tether fix checked against the GNSS: the slow error its covariance misses, measured
and taken off (docs/estimation.md §10, *The fix against the GNSS*).

The ground station's fix has a slow error its covariance may not hold: a line heavier or
lighter than believed, the wind's drag on it, a line that is not the model's shape. Fused
at 10 Hz as white, such an error outweighs the receiver, and the position's variance,
which a well-known velocity keeps from growing, locks the estimate onto the fix. While
the receiver gives fixes, the difference ``e = z_fix - z_gnss`` (the GNSS fix of the
nearest measurement time, brought to the tether fix's time by its velocity) is the fix's
error less the receiver's, whatever the filter's own estimate. Its running mean ``ē``
(``bias_tau_s``) is the fix's slow error as the receiver sees it, its spread under the
claims ``V = C + diag(eph², eph², epv²) + (v Δt)(v Δt)'``. With ``s = ē' V⁻¹ ē`` and the
weight ``λ`` rising smoothly from 0 at ``s = d²`` to 1 at ``s = 4 d²`` (``dead_band_sigma``
d), held once it has risen (falling by at most 1 over ``release_s``: a receiver wandering
towards the fix for a while must not let a known error back in, for fused again it locks
the estimate onto the fix),

    z' = z - λ ē,        C' = C + λ n V

the fix is taken less its measured slow error, and what is left of it (the mean's own
error, the receiver's wander, which is already fused) is counted as many times as the fix
samples it within its correlation time (``n = correlation_s`` / the fix's interval): an
error the same over ``n`` fixes must not count as ``n`` independent ones. A fix that
agrees with the receiver (λ = 0) is left as it is. Without a receiver (none compared
within ``gnss_hold_s``) the last ``λ ē`` is still taken off and ``λ V`` added once: the
fix is then the only position there is.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from companion.ekf.params import TetherCheckParams
from tuavdefs.frames import Vec3

#: Upper triangle (c00, c01, c02, c11, c12, c22) of a 3 x 3 covariance [m^2].
Cov6 = tuple[float, float, float, float, float, float]
#: A GNSS fix as kept: measurement time [s], position [m], velocity [m/s] (ENU), the
#: claimed horizontal and vertical variances [m^2].
_Gnss = tuple[float, np.ndarray, np.ndarray, float, float]


def mean_variance(var_m2: float, tau_s: float, fraction: float, window_s: float,
                  interval_s: float) -> float:
    """The variance [m^2] of the mean over ``window_s`` [s] of a receiver's error whose
    variance ``var_m2`` [m^2] is the share ``fraction`` a first-order Gauss-Markov process
    of time constant ``tau_s`` [s] (none if ``tau_s`` is 0) and the rest white, sampled
    every ``interval_s`` [s]: ``σ_c² g(W/τ) + σ_w² Δt/W``, ``g(x) = 2(x − 1 + e^−x)/x²``
    (1 at W = 0, 2τ/W for W ≫ τ)."""
    w = max(window_s, interval_s, 1e-9)
    white = var_m2 * min(interval_s / w, 1.0)
    if not tau_s > 0.0:
        return white
    x = w / tau_s
    g = 1.0 - x / 3.0 if x < 1e-4 else 2.0 * (x - 1.0 + math.exp(-x)) / (x * x)
    return fraction * var_m2 * g + (1.0 - fraction) * white


def smooth_weight(s: float, d2: float) -> float:
    """0 up to ``s = d2``, 1 from ``s = 4 d2``, a smoothstep in between."""
    u = min(max((s - d2) / (3.0 * d2), 0.0), 1.0)
    return u * u * (3.0 - 2.0 * u)


class TetherFixCheck:
    """Compares each tether fix with the GNSS fixes and returns it less the slow error they
    reveal, with its covariance (module docstring)."""

    __slots__ = ("_p", "_gnss", "_mean", "_count", "_t_last_fix", "_t_last_compared",
                 "_interval_s", "_weight", "_spread", "last_ratio", "_tau_s", "_fraction",
                 "_t_first_compared")

    def __init__(self, params: TetherCheckParams, wander_tau_s: float = 0.0,
                 wander_fraction: float = 0.0) -> None:
        self._p = params
        #: the receiver's error model (``gnss_pos_tau_s`` [s], ``gnss_pos_correlated_fraction``)
        #: the mean difference is judged against
        self._tau_s = wander_tau_s
        self._fraction = wander_fraction
        self._t_first_compared = math.nan
        self._gnss: deque[_Gnss] = deque(maxlen=8)
        self._mean = np.zeros(3)
        self._count = 0
        self._t_last_fix = -math.inf
        self._t_last_compared = -math.inf
        self._interval_s = 0.1
        #: λ of the last comparison
        self._weight = 0.0
        #: V of the last comparison [m^2] (3 x 3)
        self._spread = np.zeros((3, 3))
        #: the latest s / d^2 (the mean difference's test ratio; 0 before any)
        self.last_ratio = 0.0

    @property
    def offset_m(self) -> Vec3:
        """What is taken off the fixes now [m] (ENU): λ ē."""
        o = self._weight * self._mean
        return (float(o[0]), float(o[1]), float(o[2]))

    def add_gnss(self, t_meas_s: float, pos_m: Vec3, vel_m_s: Vec3, eph_m: float,
                 epv_m: float) -> None:
        """A usable GNSS fix taken at ``t_meas_s`` [s]: position [m], velocity [m/s]
        (inertial ENU), its claimed horizontal and vertical accuracies [m]."""
        self._gnss.append((t_meas_s, np.array(pos_m, dtype=float),
                           np.array(vel_m_s, dtype=float), eph_m * eph_m, epv_m * epv_m))

    def _gnss_interval_s(self) -> float:
        """The receiver's fix interval [s], from the fixes kept (0.2 s before two)."""
        g = self._gnss
        if len(g) < 2:
            return 0.2
        return max((g[-1][0] - g[0][0]) / (len(g) - 1), 1e-3)

    def _nearest(self, t_s: float) -> _Gnss | None:
        best = min(self._gnss, key=lambda g: abs(g[0] - t_s), default=None)
        if best is None or abs(best[0] - t_s) > self._p.gnss_max_offset_s:
            return None
        return best

    def correct(self, t_meas_s: float, pos_m: Vec3, cov: Cov6) -> tuple[Vec3, Cov6]:
        """The fix taken at ``t_meas_s`` [s] at ``pos_m`` [m] with covariance ``cov``
        [m^2]: that fix less the slow error the GNSS reveals, and its covariance."""
        p = self._p
        dt = t_meas_s - self._t_last_fix
        if 0.0 < dt < 1.0:   # the fix's interval, smoothed
            self._interval_s += 0.05 * (dt - self._interval_s)
        self._t_last_fix = t_meas_s
        g = self._nearest(t_meas_s)
        if g is not None:
            self._compare(t_meas_s, pos_m, cov, g)
        lam = self._weight
        if lam <= 0.0:
            return pos_m, cov
        if t_meas_s - self._t_last_compared <= p.gnss_hold_s:
            n = max(p.correlation_s / max(self._interval_s, 1e-3), 1.0)
        else:
            n = 1.0
        a = lam * n * self._spread
        o = self.offset_m
        c00, c01, c02, c11, c12, c22 = cov
        return ((pos_m[0] - o[0], pos_m[1] - o[1], pos_m[2] - o[2]),
                (c00 + a[0, 0], c01 + a[0, 1], c02 + a[0, 2], c11 + a[1, 1], c12 + a[1, 2],
                 c22 + a[2, 2]))

    def _compare(self, t_meas_s: float, pos_m: Vec3, cov: Cov6, g: _Gnss) -> None:
        p = self._p
        tg, gp, gv, var_h, var_v = g
        dt = t_meas_s - tg
        e = np.array(pos_m, dtype=float) - (gp + gv * dt)
        # the running mean: equal weights over the first samples, then bias_tau_s
        self._count += 1
        gap = t_meas_s - self._t_last_compared
        step = min(gap, 1.0)
        alpha = max(1.0 / self._count, step / p.bias_tau_s)
        self._mean += alpha * (e - self._mean)
        self._t_last_compared = t_meas_s
        if not math.isfinite(self._t_first_compared):
            self._t_first_compared = t_meas_s
        c00, c01, c02, c11, c12, c22 = cov
        lag = gv * dt
        fix_cov = np.array(((c00, c01, c02), (c01, c11, c12), (c02, c12, c22)))
        lag_cov = np.outer(lag, lag)
        v = fix_cov + np.diag((var_h, var_h, var_v)) + lag_cov
        # the mean is judged against its own spread: the receiver's share from its wander
        # model over the mean's window (an exponential mean of time constant T averages
        # as a window of 2 T), the fix's and the lag's as white; the fix's claimed
        # covariance is not a spread the mean may have, for an error within it that stays
        # is what the filter, fusing the fixes as white, would lock onto
        window = min(t_meas_s - self._t_first_compared, 2.0 * p.bias_tau_s)
        n_fix = mean_variance(1.0, 0.0, 0.0, window, self._interval_s)   # white: the share
        gi = self._gnss_interval_s()
        v_mean = (fix_cov + lag_cov) * n_fix + np.diag(
            (mean_variance(var_h, self._tau_s, self._fraction, window, gi),) * 2
            + (mean_variance(var_v, self._tau_s, self._fraction, window, gi),))
        m = self._mean
        s = float(m @ np.linalg.solve(v_mean, m))
        d2 = p.dead_band_sigma ** 2
        self.last_ratio = s / d2
        held = self._weight - step / p.release_s
        self._weight = max(smooth_weight(s, d2), held)
        self._spread = v
