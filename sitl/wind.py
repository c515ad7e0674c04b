"""The wind at the vehicle: steady wind, Dryden turbulence and discrete (1 - cos) gusts.

Frames and units: inertial, z up, x east, y north; SI throughout (the MIL-F-8785C
formulas are written in feet and are converted at the boundary).

Turbulence follows the MIL-F-8785C low-altitude Dryden model (h < 1000 ft). Its axes are
those of the standard's low-altitude definition: ``u`` horizontal along the mean wind,
``v`` horizontal and perpendicular to it (u, v, w right-handed, so v points to the left of
the mean wind), ``w`` vertical (up). With no horizontal mean wind, ``u`` is taken along +x.

The forming filters are sampled exactly: each filter is a linear system driven by
continuous white noise, and its state is advanced over one step with the transition
matrix and the exact covariance of the noise accumulated over that step. The samples are
therefore those of the continuous process at the step instants, and their variance and
correlation do not depend on the step length. With the time constant ``T = L / V`` and
``x = dt / T``, the states are scaled to be dimensionless with a stationary variance
independent of ``T``:

* u (first order, ``H_u = sigma_u sqrt(2 L_u/(pi V)) / (1 + L_u s/V)``)::

      z' = e^-x z + sqrt(1 - e^-2x) n,              u = sigma_u z

* v and w (second order, ``H = sigma sqrt(L/(pi V)) (1 + sqrt(3) L s/V) / (1 + L s/V)^2``)::

      z1' = e^-x z1                 + n1,           stationary cov(z) = [[1/2, 1/4],
      z2' = e^-x (z2 + x z1)        + n2,                                [1/4, 1/4]]
      v   = sigma_v (sqrt(3) z1 + (1 - sqrt(3)) z2)

  with ``(n1, n2) ~ N(0, Q)``, ``Q11 = x J0(2x)``, ``Q12 = x^2 J1(2x)``,
  ``Q22 = x^3 J2(2x)`` and ``J_k(y) = integral_0^1 s^k e^(-y s) ds``.

``n`` are independent standard normal draws from a ``numpy.random.Generator`` seeded with
``WindParams.seed`` (the initial state is drawn from the stationary distribution, so there
is no start-up transient).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tuavdefs.params import WindParams

__all__ = [
    "FT_M", "KNOT_M_S", "W20_DEFAULT_M_S", "MIN_ALTITUDE_M", "MAX_ALTITUDE_M",
    "MIN_PASSING_SPEED_M_S", "COEFF_RTOL", "dryden_length_scales_m", "dryden_sigmas_m_s",
    "WindModel",
]

FT_M = 0.3048
"""One foot [m]."""
KNOT_M_S = 1852.0 / 3600.0
"""One knot [m/s]."""
W20_DEFAULT_M_S = {"light": 15.0 * KNOT_M_S, "moderate": 30.0 * KNOT_M_S,
                   "severe": 45.0 * KNOT_M_S}
"""MIL-F-8785C wind speed at 20 ft for each turbulence intensity [m/s]."""
MIN_ALTITUDE_M = 10.0 * FT_M
"""Altitudes below this (10 ft) use the scales at this altitude [m]."""
MAX_ALTITUDE_M = 1000.0 * FT_M
"""Upper limit of the low-altitude model (1000 ft); altitudes above use its scales [m]."""
MIN_PASSING_SPEED_M_S = 1.0
"""Floor on the speed at which the frozen turbulence field passes the vehicle [m/s]."""
COEFF_RTOL = 0.005
"""Relative change of altitude or passing speed that triggers a recomputation of the
filter coefficients (so scales and time constants lag their exact value by at most this)."""

_NOISE_BLOCK_STEPS = 4096
_SQRT3 = math.sqrt(3.0)
# Output weights of the second-order states and the Cholesky factor of their stationary
# covariance [[1/2, 1/4], [1/4, 1/4]].
_W1, _W2 = _SQRT3, 1.0 - _SQRT3
_P11, _P21, _P22 = math.sqrt(0.5), math.sqrt(2.0) / 4.0, 1.0 / (2.0 * math.sqrt(2.0))


def _clamped_altitude_ft(altitude_m: float) -> float:
    return min(max(float(altitude_m), MIN_ALTITUDE_M), MAX_ALTITUDE_M) / FT_M


def dryden_length_scales_m(altitude_m: float) -> tuple[float, float, float]:
    """MIL-F-8785C low-altitude turbulence length scales ``(L_u, L_v, L_w)`` [m].

    ``altitude_m`` [m] is clamped to [MIN_ALTITUDE_M, MAX_ALTITUDE_M] (10 ft to 1000 ft).
    In feet: ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``.
    """
    h = _clamped_altitude_ft(altitude_m)
    l_uv = h / (0.177 + 0.000823 * h) ** 1.2 * FT_M
    return (l_uv, l_uv, h * FT_M)


def dryden_sigmas_m_s(altitude_m: float, w20_m_s: float) -> tuple[float, float, float]:
    """MIL-F-8785C low-altitude turbulence intensities ``(sigma_u, sigma_v, sigma_w)`` [m/s].

    ``altitude_m`` [m] is clamped as in :func:`dryden_length_scales_m`; ``w20_m_s`` [m/s] is
    the mean wind speed at 20 ft. ``sigma_w = 0.1 W20``,
    ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4`` (h in ft).
    """
    h = _clamped_altitude_ft(altitude_m)
    s_w = 0.1 * float(w20_m_s)
    s_uv = s_w / (0.177 + 0.000823 * h) ** 0.4
    return (s_uv, s_uv, s_w)


def _j_integral(k: int, y: float) -> float:
    """``integral_0^1 s^k exp(-y s) ds`` for k in 0, 1, 2 and y >= 0, without cancellation."""
    if y < 1.0:
        total, term, m = 0.0, 1.0, 0
        while True:
            add = term / (k + m + 1)
            total += add
            if abs(add) < 1e-17 * abs(total):
                return total
            m += 1
            term *= -y / m
    e = math.exp(-y)
    if k == 0:
        return -math.expm1(-y) / y
    if k == 1:
        return (1.0 - e * (1.0 + y)) / (y * y)
    return (2.0 - e * (2.0 + y * (2.0 + y))) / (y * y * y)


def _first_order_coeffs(x: float) -> tuple[float, float]:
    """``(a, b)`` of ``z' = a z + b n`` for a step of ``x = dt / T``."""
    return math.exp(-x), math.sqrt(-math.expm1(-2.0 * x))


def _second_order_coeffs(x: float) -> tuple[float, float, float, float, float]:
    """``(a, ax, c11, c21, c22)`` of ``z1' = a z1 + c11 n1``,
    ``z2' = a z2 + ax z1 + c21 n1 + c22 n2`` for a step of ``x = dt / T``."""
    a = math.exp(-x)
    q11 = x * _j_integral(0, 2.0 * x)
    q12 = x * x * _j_integral(1, 2.0 * x)
    q22 = x * x * x * _j_integral(2, 2.0 * x)
    c11 = math.sqrt(q11)
    c21 = q12 / c11
    c22 = math.sqrt(max(q22 - c21 * c21, 0.0))
    return a, a * x, c11, c21, c22


class WindModel:
    """Air velocity at the vehicle [m/s], inertial frame (x east, y north, z up).

    ``dt_s`` [s] is the physics step: every :meth:`sample` advances the turbulence filters
    by exactly one step. The same parameters (and seed) always give the same sequence.
    """

    def __init__(self, params: WindParams, dt_s: float) -> None:
        dt_s = float(dt_s)
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s: must be a positive finite step, got {dt_s!r}")
        self._params = params
        self._dt = dt_s
        self._steady = tuple(float(c) for c in params.steady_m_s)
        self._turbulent = params.turbulence != "none"
        if not self._turbulent:
            self._w20 = 0.0
        elif params.wind_speed_at_6m_m_s > 0.0:
            self._w20 = float(params.wind_speed_at_6m_m_s)
        else:
            self._w20 = W20_DEFAULT_M_S[params.turbulence]
        sx, sy = self._steady[0], self._steady[1]
        horiz = math.hypot(sx, sy)
        self._dir = (sx / horiz, sy / horiz) if horiz > 0.0 else (1.0, 0.0)
        self._gusts = tuple(
            (float(g.start_s), float(g.duration_s), float(g.start_s + g.duration_s),
             *(0.5 * float(c) for c in g.amplitude_m_s))
            for g in params.gusts)
        self.reset()

    # -- public API ---------------------------------------------------------------------

    @property
    def params(self) -> WindParams:
        """The parameters the model was built from."""
        return self._params

    @property
    def dt_s(self) -> float:
        """Step by which each :meth:`sample` advances the turbulence [s]."""
        return self._dt

    @property
    def steady_m_s(self) -> tuple[float, float, float]:
        """Steady wind velocity (x east, y north, z up) [m/s]."""
        return self._steady

    @property
    def constant(self) -> bool:
        """True when the wind is the steady wind at every instant (no turbulence, no gusts):
        :meth:`sample` then returns :attr:`steady_m_s` and changes nothing."""
        return not (self._turbulent or self._gusts)

    @property
    def w20_m_s(self) -> float:
        """Wind speed at 20 ft scaling the turbulence; 0 with no turbulence [m/s]."""
        return self._w20

    @property
    def turbulence_m_s(self) -> tuple[float, float, float]:
        """Turbulence part (x, y, z) of the last :meth:`sample` result; zeros before [m/s]."""
        return self._turb_xyz

    @property
    def turbulence_uvw_m_s(self) -> tuple[float, float, float]:
        """The same turbulence in the Dryden axes (u along the mean wind, v left, w up) [m/s]."""
        return self._turb_uvw

    def reset(self) -> None:
        """Restart: same state (and thus the same future sequence) as a fresh object."""
        self._rng = np.random.default_rng(self._params.seed)
        self._noise: list[float] = []
        self._k = 0
        self._turb_xyz = (0.0, 0.0, 0.0)
        self._turb_uvw = (0.0, 0.0, 0.0)
        # Zero references force a coefficient computation on the first sample.
        self._h_ref = 0.0
        self._v_ref = 0.0
        if self._turbulent:
            n0, n1, n2, n3, n4 = self._draw5()
            self._zu = n0
            self._zv1, self._zv2 = _P11 * n1, _P21 * n1 + _P22 * n2
            self._zw1, self._zw2 = _P11 * n3, _P21 * n3 + _P22 * n4

    def sample(self, t_s: float, altitude_m: float,
               vehicle_velocity_m_s: Sequence[float]) -> tuple[float, float, float]:
        """Air velocity at the vehicle at time ``t_s`` [s] (x, y, z) [m/s].

        ``altitude_m`` [m] is the height above ground that sets the turbulence scales and
        ``vehicle_velocity_m_s`` [m/s] the inertial velocity of the vehicle; the turbulence
        field passes it at ``V = max(|steady - vehicle velocity|, MIN_PASSING_SPEED_M_S)``.
        Returns steady + turbulence + gusts, then advances the turbulence by one ``dt_s``.
        """
        if not (self._turbulent or self._gusts):  # constant: the same answer, faster
            return self._steady
        wx, wy, wz = self._steady
        if self._turbulent:
            vx, vy, vz = vehicle_velocity_m_s
            speed = math.hypot(wx - vx, wy - vy, wz - vz)
            if speed < MIN_PASSING_SPEED_M_S:
                speed = MIN_PASSING_SPEED_M_S
            h = float(altitude_m)
            h = MIN_ALTITUDE_M if h < MIN_ALTITUDE_M else min(h, MAX_ALTITUDE_M)
            if (abs(speed - self._v_ref) > COEFF_RTOL * self._v_ref
                    or abs(h - self._h_ref) > COEFF_RTOL * self._h_ref):
                self._set_coeffs(h, speed)
            tu, tv, tw = self._step()
            cx, cy = self._dir
            tx = tu * cx - tv * cy
            ty = tu * cy + tv * cx
            self._turb_uvw = (tu, tv, tw)
            self._turb_xyz = (tx, ty, tw)
            wx += tx
            wy += ty
            wz += tw
        for t0, dur, t1, ax, ay, az in self._gusts:
            if t0 <= t_s <= t1:
                f = 1.0 - math.cos(2.0 * math.pi * (t_s - t0) / dur)
                wx += ax * f
                wy += ay * f
                wz += az * f
        return (wx, wy, wz)

    # -- internals ----------------------------------------------------------------------

    def _draw5(self) -> tuple[float, float, float, float, float]:
        k = self._k
        if k + 5 > len(self._noise):
            # Drawing in blocks keeps the per-sample cost to a few list look-ups.
            self._noise = self._rng.standard_normal(5 * _NOISE_BLOCK_STEPS).tolist()
            k = 0
        self._k = k + 5
        n = self._noise
        return n[k], n[k + 1], n[k + 2], n[k + 3], n[k + 4]

    def _set_coeffs(self, h_m: float, speed_m_s: float) -> None:
        self._h_ref, self._v_ref = h_m, speed_m_s
        l_u, _, l_w = dryden_length_scales_m(h_m)
        self._sig_u, _, self._sig_w = dryden_sigmas_m_s(h_m, self._w20)
        x_uv = self._dt * speed_m_s / l_u
        self._cu = _first_order_coeffs(x_uv)
        self._cv = _second_order_coeffs(x_uv)
        self._cw = _second_order_coeffs(self._dt * speed_m_s / l_w)

    def _step(self) -> tuple[float, float, float]:
        """Current (u, v, w) [m/s], then advance the filter states by one step."""
        zu, zv1, zv2, zw1, zw2 = self._zu, self._zv1, self._zv2, self._zw1, self._zw2
        s_uv, s_w = self._sig_u, self._sig_w
        out = (s_uv * zu, s_uv * (_W1 * zv1 + _W2 * zv2), s_w * (_W1 * zw1 + _W2 * zw2))
        n0, n1, n2, n3, n4 = self._draw5()
        a, b = self._cu
        self._zu = a * zu + b * n0
        a, ax, c11, c21, c22 = self._cv
        self._zv1 = a * zv1 + c11 * n1
        self._zv2 = a * zv2 + ax * zv1 + c21 * n1 + c22 * n2
        a, ax, c11, c21, c22 = self._cw
        self._zw1 = a * zw1 + c11 * n3
        self._zw2 = a * zw2 + ax * zw1 + c21 * n3 + c22 * n4
        return out
