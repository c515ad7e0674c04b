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

from sitl._jit import njit
from sitl.pymath import hypot3
from tuavdefs.jit import I64, array, record
from tuavdefs.params import WindParams, WindProfile

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


@njit
def _clamped_altitude_ft(altitude_m: float) -> float:
    """``altitude_m`` [m] clamped to [MIN_ALTITUDE_M, MAX_ALTITUDE_M], in feet."""
    h = MIN_ALTITUDE_M if altitude_m < MIN_ALTITUDE_M else altitude_m   # max(., MIN)
    h = MAX_ALTITUDE_M if h > MAX_ALTITUDE_M else h                    # min(., MAX)
    return h / FT_M


@njit
def _scales_kernel(altitude_m: float) -> tuple[float, float]:
    """(L_u = L_v, L_w) [m] of :func:`dryden_length_scales_m`."""
    h = _clamped_altitude_ft(altitude_m)
    return h / (0.177 + 0.000823 * h) ** 1.2 * FT_M, h * FT_M


@njit
def _sigmas_kernel(altitude_m: float, w20_m_s: float) -> tuple[float, float]:
    """(sigma_u = sigma_v, sigma_w) [m/s] of :func:`dryden_sigmas_m_s`."""
    h = _clamped_altitude_ft(altitude_m)
    s_w = 0.1 * w20_m_s
    return s_w / (0.177 + 0.000823 * h) ** 0.4, s_w


def dryden_length_scales_m(altitude_m: float) -> tuple[float, float, float]:
    """MIL-F-8785C low-altitude turbulence length scales ``(L_u, L_v, L_w)`` [m].

    ``altitude_m`` [m] is clamped to [MIN_ALTITUDE_M, MAX_ALTITUDE_M] (10 ft to 1000 ft).
    In feet: ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``.
    """
    l_uv, l_w = _scales_kernel(float(altitude_m))
    return (l_uv, l_uv, l_w)


def dryden_sigmas_m_s(altitude_m: float, w20_m_s: float) -> tuple[float, float, float]:
    """MIL-F-8785C low-altitude turbulence intensities ``(sigma_u, sigma_v, sigma_w)`` [m/s].

    ``altitude_m`` [m] is clamped as in :func:`dryden_length_scales_m`; ``w20_m_s`` [m/s] is
    the mean wind speed at 20 ft. ``sigma_w = 0.1 W20``,
    ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4`` (h in ft).
    """
    s_uv, s_w = _sigmas_kernel(float(altitude_m), float(w20_m_s))
    return (s_uv, s_uv, s_w)


@njit
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


@njit
def _first_order_coeffs(x: float) -> tuple[float, float]:
    """``(a, b)`` of ``z' = a z + b n`` for a step of ``x = dt / T``."""
    return math.exp(-x), math.sqrt(-math.expm1(-2.0 * x))


@njit
def _second_order_coeffs(x: float) -> tuple[float, float, float, float, float]:
    """``(a, ax, c11, c21, c22)`` of ``z1' = a z1 + c11 n1``,
    ``z2' = a z2 + ax z1 + c21 n1 + c22 n2`` for a step of ``x = dt / T``."""
    a = math.exp(-x)
    q11 = x * _j_integral(0, 2.0 * x)
    q12 = x * x * _j_integral(1, 2.0 * x)
    q22 = x * x * x * _j_integral(2, 2.0 * x)
    c11 = math.sqrt(q11)
    c21 = q12 / c11
    d = q22 - c21 * c21
    c22 = math.sqrt(0.0 if d < 0.0 else d)     # max(d, 0.0)
    return a, a * x, c11, c21, c22


# The model's packed parameters (WindModel._wp) and state (WindModel._ws), as the compiled
# step reads them; the gusts are rows (start, duration, end, amplitude x/2, y/2, z/2).
WP_STEADY, WP_TURBULENT, WP_W20, WP_DIR, WP_DT = 0, 3, 4, 5, 7
WP_PROFILE, WP_Z_REF, WP_Z0, WP_ALPHA, WP_LOG_REF = 8, 9, 10, 11, 12
N_WIND_PARAMS = 13
#: WP_PROFILE's values (tuavdefs.params.WindProfile).
PROFILE_UNIFORM, PROFILE_LOG, PROFILE_POWER = 0, 1, 2
_PROFILE_CODES = {WindProfile.UNIFORM: PROFILE_UNIFORM, WindProfile.LOG: PROFILE_LOG,
                  WindProfile.POWER: PROFILE_POWER}


@njit
def profile_factor(wp: np.ndarray, height_m: float) -> float:
    """The mean wind at ``height_m`` [m] above the ground over its value at the reference
    height: 1 (uniform), ln(z/z0)/ln(z_ref/z0) (log; 0 at and below z0) or
    (z/z_ref)^alpha (power; 0 at and below the ground)."""
    kind = wp[WP_PROFILE]
    if kind == PROFILE_UNIFORM:
        return 1.0
    if kind == PROFILE_LOG:
        z0 = wp[WP_Z0]
        if height_m <= z0:
            return 0.0
        return math.log(height_m / z0) / wp[WP_LOG_REF]
    if height_m <= 0.0:
        return 0.0
    return (height_m / wp[WP_Z_REF]) ** wp[WP_ALPHA]
(WS_ZU, WS_ZV1, WS_ZV2, WS_ZW1, WS_ZW2, WS_H_REF, WS_V_REF, WS_SIG_U, WS_SIG_W, WS_CU, WS_CV,
 WS_CW, WS_TURB_XYZ, WS_TURB_UVW) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 16, 21, 24)
N_WIND_STATES = 27


@njit
def _set_coeffs(wp: np.ndarray, ws: np.ndarray, h_m: float, speed_m_s: float) -> None:
    """The filters' coefficients for altitude ``h_m`` [m] and passing speed [m/s]."""
    ws[WS_H_REF] = h_m
    ws[WS_V_REF] = speed_m_s
    l_u, l_w = _scales_kernel(h_m)
    ws[WS_SIG_U], ws[WS_SIG_W] = _sigmas_kernel(h_m, wp[WP_W20])
    dt = wp[WP_DT]
    x_uv = dt * speed_m_s / l_u
    ws[WS_CU], ws[WS_CU + 1] = _first_order_coeffs(x_uv)
    a, ax, c11, c21, c22 = _second_order_coeffs(x_uv)
    ws[WS_CV], ws[WS_CV + 1], ws[WS_CV + 2], ws[WS_CV + 3], ws[WS_CV + 4] = (
        a, ax, c11, c21, c22)
    a, ax, c11, c21, c22 = _second_order_coeffs(dt * speed_m_s / l_w)
    ws[WS_CW], ws[WS_CW + 1], ws[WS_CW + 2], ws[WS_CW + 3], ws[WS_CW + 4] = (
        a, ax, c11, c21, c22)


@njit
def wind_kernel(wp: np.ndarray, gusts: np.ndarray, ws: np.ndarray, noise: np.ndarray,
                noise_next: np.ndarray, t_s: float, altitude_m: float, vx: float,
                vy: float, vz: float, out: np.ndarray) -> bool:
    """:meth:`WindModel.sample` on the packed parameters and state: writes the air velocity
    (x, y, z) [m/s] at the vehicle's height into ``out[0:3]`` (and, when ``out`` has six
    elements, its part that is the same at every height, turbulence and gusts, into
    ``out[3:6]``) and advances the turbulence by one step, drawing five standard normals
    from ``noise`` at ``noise_next[0]``. Returns False, having changed nothing, when the
    turbulence needs draws and ``noise`` has fewer than five left."""
    f = profile_factor(wp, altitude_m)
    sx, sy, sz = f * wp[WP_STEADY], f * wp[WP_STEADY + 1], f * wp[WP_STEADY + 2]
    wx, wy, wz = sx, sy, sz
    if wp[WP_TURBULENT] != 0.0:
        k = noise_next[0]
        if k + 5 > noise.size:
            return False
        speed = hypot3(wx - vx, wy - vy, wz - vz)
        if speed < MIN_PASSING_SPEED_M_S:
            speed = MIN_PASSING_SPEED_M_S
        h = altitude_m
        h = MIN_ALTITUDE_M if h < MIN_ALTITUDE_M else (MAX_ALTITUDE_M if h > MAX_ALTITUDE_M
                                                       else h)
        v_ref, h_ref = ws[WS_V_REF], ws[WS_H_REF]
        if (abs(speed - v_ref) > COEFF_RTOL * v_ref
                or abs(h - h_ref) > COEFF_RTOL * h_ref):
            _set_coeffs(wp, ws, h, speed)
        # the current (u, v, w), then the filters advanced by one step
        zu, zv1, zv2 = ws[WS_ZU], ws[WS_ZV1], ws[WS_ZV2]
        zw1, zw2 = ws[WS_ZW1], ws[WS_ZW2]
        s_uv, s_w = ws[WS_SIG_U], ws[WS_SIG_W]
        tu = s_uv * zu
        tv = s_uv * (_W1 * zv1 + _W2 * zv2)
        tw = s_w * (_W1 * zw1 + _W2 * zw2)
        n0, n1, n2, n3, n4 = noise[k], noise[k + 1], noise[k + 2], noise[k + 3], noise[k + 4]
        noise_next[0] = k + 5
        ws[WS_ZU] = ws[WS_CU] * zu + ws[WS_CU + 1] * n0
        a, ax, c11, c21, c22 = (ws[WS_CV], ws[WS_CV + 1], ws[WS_CV + 2], ws[WS_CV + 3],
                                ws[WS_CV + 4])
        ws[WS_ZV1] = a * zv1 + c11 * n1
        ws[WS_ZV2] = a * zv2 + ax * zv1 + c21 * n1 + c22 * n2
        a, ax, c11, c21, c22 = (ws[WS_CW], ws[WS_CW + 1], ws[WS_CW + 2], ws[WS_CW + 3],
                                ws[WS_CW + 4])
        ws[WS_ZW1] = a * zw1 + c11 * n3
        ws[WS_ZW2] = a * zw2 + ax * zw1 + c21 * n3 + c22 * n4
        cx, cy = wp[WP_DIR], wp[WP_DIR + 1]
        tx = tu * cx - tv * cy
        ty = tu * cy + tv * cx
        ws[WS_TURB_UVW], ws[WS_TURB_UVW + 1], ws[WS_TURB_UVW + 2] = tu, tv, tw
        ws[WS_TURB_XYZ], ws[WS_TURB_XYZ + 1], ws[WS_TURB_XYZ + 2] = tx, ty, tw
        wx += tx
        wy += ty
        wz += tw
    for i in range(gusts.shape[0]):
        t0, dur, t1 = gusts[i, 0], gusts[i, 1], gusts[i, 2]
        if t0 <= t_s <= t1:
            g = 1.0 - math.cos(2.0 * math.pi * (t_s - t0) / dur)
            wx += gusts[i, 3] * g
            wy += gusts[i, 4] * g
            wz += gusts[i, 5] * g
    out[0] = wx
    out[1] = wy
    out[2] = wz
    if out.size >= 6:
        out[3] = wx - sx
        out[4] = wy - sy
        out[5] = wz - sz
    return True


class WindModel:
    """Air velocity at the vehicle [m/s], inertial frame (x east, y north, z up).

    ``dt_s`` [s] is the physics step: every :meth:`sample` advances the turbulence filters
    by exactly one step. The same parameters (and seed) always give the same sequence.
    """

    #: The type of :attr:`kernel_args` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(), array(2), array(), array(), array(1, I64))

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
        self._gusts_array = np.array(self._gusts, dtype=float).reshape(len(self._gusts), 6)
        wp = np.zeros(N_WIND_PARAMS)
        wp[WP_STEADY:WP_STEADY + 3] = self._steady
        wp[WP_TURBULENT] = 1.0 if self._turbulent else 0.0
        wp[WP_W20] = self._w20
        wp[WP_DIR:WP_DIR + 2] = self._dir
        wp[WP_DT] = self._dt
        kind = params.profile_kind
        wp[WP_PROFILE] = _PROFILE_CODES[kind]
        wp[WP_Z_REF] = params.reference_height_m
        wp[WP_Z0] = params.roughness_length_m
        wp[WP_ALPHA] = params.power_exponent
        wp[WP_LOG_REF] = math.log(params.reference_height_m / params.roughness_length_m)
        self._wp = wp
        self._sheared = kind != WindProfile.UNIFORM and any(c != 0.0 for c in self._steady)
        self._out = np.zeros(3)
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
        """True when the wind is the steady wind at every instant and height (no turbulence,
        no gusts, no mean wind varying with height): :meth:`sample` then returns
        :attr:`steady_m_s` and changes nothing."""
        return not (self._turbulent or self._gusts or self._sheared)

    @property
    def packed(self) -> np.ndarray:
        """The packed parameters the compiled kernels read (:func:`profile_factor`)."""
        return self._wp

    @property
    def w20_m_s(self) -> float:
        """Wind speed at 20 ft scaling the turbulence; 0 with no turbulence [m/s]."""
        return self._w20

    @property
    def turbulence_m_s(self) -> tuple[float, float, float]:
        """Turbulence part (x, y, z) of the last :meth:`sample` result; zeros before [m/s]."""
        return tuple(self._ws[WS_TURB_XYZ:WS_TURB_XYZ + 3].tolist())  # type: ignore[return-value]

    @property
    def turbulence_uvw_m_s(self) -> tuple[float, float, float]:
        """The same turbulence in the Dryden axes (u along the mean wind, v left, w up) [m/s]."""
        return tuple(self._ws[WS_TURB_UVW:WS_TURB_UVW + 3].tolist())  # type: ignore[return-value]

    def reset(self) -> None:
        """Restart: same state (and thus the same future sequence) as a fresh object."""
        self._rng = np.random.default_rng(self._params.seed)
        self._noise = np.zeros(0)
        self._noise_next = np.zeros(1, dtype=np.int64)
        # zero references (h_ref, v_ref) force a coefficient computation on the first sample
        self._ws = np.zeros(N_WIND_STATES)
        self._bind()
        if self._turbulent:
            self.refill()
            n0, n1, n2, n3, n4 = self._noise[0:5].tolist()
            self._noise_next[0] = 5
            ws = self._ws
            ws[WS_ZU] = n0
            ws[WS_ZV1], ws[WS_ZV2] = _P11 * n1, _P21 * n1 + _P22 * n2
            ws[WS_ZW1], ws[WS_ZW2] = _P11 * n3, _P21 * n3 + _P22 * n4

    def sample(self, t_s: float, altitude_m: float,
               vehicle_velocity_m_s: Sequence[float]) -> tuple[float, float, float]:
        """Air velocity at the vehicle at time ``t_s`` [s] (x, y, z) [m/s].

        ``altitude_m`` [m] is the height above ground that sets the mean wind (the profile),
        the turbulence scales, and
        ``vehicle_velocity_m_s`` [m/s] the inertial velocity of the vehicle; the turbulence
        field passes it at ``V = max(|steady - vehicle velocity|, MIN_PASSING_SPEED_M_S)``.
        Returns steady + turbulence + gusts, then advances the turbulence by one ``dt_s``.
        """
        if self.constant:  # the same answer, faster
            return self._steady
        vx, vy, vz = vehicle_velocity_m_s
        out = self._out
        while not wind_kernel(*self.kernel_args, float(t_s), float(altitude_m), float(vx),
                              float(vy), float(vz), out):
            self.refill()
        return tuple(out.tolist())  # type: ignore[return-value]

    def _bind(self) -> None:
        #: What :func:`wind_kernel` takes before the time: the packed parameters, the
        #: gusts, the state, the noise block and the index of its next draw (the arrays are
        #: updated in place; the tuple is renewed when one is replaced).
        self.kernel_args: tuple[np.ndarray, ...] = (self._wp, self._gusts_array, self._ws,
                                                    self._noise, self._noise_next)

    def refill(self) -> None:
        """A fresh block of standard normal draws (when the kernel has used up the last)."""
        # drawing in blocks keeps the per-sample cost to a few look-ups
        self._noise = self._rng.standard_normal(5 * _NOISE_BLOCK_STEPS)
        self._noise_next[0] = 0
        self._bind()
