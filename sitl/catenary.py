"""Quasi-static elastic catenary of a tether whose bottom end lies on flat, frictionless ground.

End A (bottom) is the winder's tether exit, on the ground (z = 0); end B (top) is the UAV attach
point at horizontal distance ``span_m`` = x and height ``height_m`` = h above A. The tether has
unstretched length L [m], axial stiffness EA [N] and weight per unit length w [N/m]. The model is
the classic elastic catenary (Irvine; Jonkman's FAST form) with a frictionless ground, the model
of MoorPy's ``catenary(..., CB=0)``, and the forces are returned in MoorPy's order and signs:
``(fAH, fAV, fBH, fBV)``, the horizontal (positive from A towards B) and vertical (positive up)
forces that the line exerts on A and on B.

With H, V the horizontal and vertical tension at B (force on B = (-H, -V)) and
lh = 2h / (1 + sqrt(1 + 2 h w/EA)) the unstretched length that hangs vertically to height h
(the root of lh + w lh^2/(2 EA) = h), the regimes are, tested in this order:

* FLAT (h = 0): H = EA (x - L)/L if x > L else 0; V = 0.
* SLACK (L >= x + lh): H = 0, V = w lh; L - lh lies on the ground at zero tension.
* VERTICAL (x < 1e-4 h, MoorPy's threshold; taut since L < lh): H = 0, bottom tension
  T0 = EA (h - L)/L - w L/2 (from L + T0 L/EA + w L^2/(2 EA) = h), V = T0 + w L.
* otherwise Newton's method with the analytic Jacobian on the two equations below, with
  t = V/H, t_A = (V - wL)/H, q = sqrt(1 + t^2), q_A = sqrt(1 + t_A^2):

  SUSPENDED (V >= wL; bottom forces H and V - wL)::

    x = H/w (asinh t - asinh t_A) + H L/EA
    h = H/w (q - q_A)             + (V L - w L^2/2)/EA

  TOUCHDOWN (V < wL; the bottom L_B = L - V/w lies on the ground at tension H)::

    x = H/w asinh t + L_B + H L/EA
    h = H/w (q - 1)   + V^2/(2 w EA)

The two sets agree, with their first derivatives, at V = wL, so an iteration may cross between
them; the regime is that of the converged V. The Newton step is damped by a backtracking line
search on the line's complementary energy (convex, its gradient is the position error), and
decreases of H and of V - V_low (a lower bound of V) are applied multiplicatively, which keeps
the iterates feasible near slack. The solver is scalar ``math`` arithmetic (no numpy, closures
or dicts in the solve) so that ``_solve`` could be compiled by numba unchanged.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from sitl._jit import njit

__all__ = [
    "CatenaryConvergenceError", "CatenaryInfo", "CatenaryInputError", "CatenaryRegime",
    "VERTICAL_SPAN_RATIO", "catenary_end_forces", "catenary_profile", "hanging_length_m",
]

# span/height below which the line is treated as exactly vertical (H = 0): MoorPy's threshold.
VERTICAL_SPAN_RATIO = 1.0e-4

_MAX_ITER = 100
_INF = math.inf
_MAX_HALVINGS = 40


class CatenaryInputError(ValueError):
    """An argument of the catenary solver is out of its domain (the message names it)."""


class CatenaryConvergenceError(RuntimeError):
    """The Newton iteration did not converge (should not happen for valid inputs)."""


class CatenaryRegime(IntEnum):
    """How the line lies."""

    SUSPENDED = 1  # no ground contact except at A (includes taut, stretched lines)
    TOUCHDOWN = 2  # a bottom part lies on the ground at tension H > 0
    SLACK = 3  # H = 0: hangs vertically from B, the rest lies on the ground
    VERTICAL = 4  # span ~ 0 (span < VERTICAL_SPAN_RATIO * height) and taut: H = 0
    FLAT = 5  # height = 0: lies along the ground, taut or slack


#: The regime of each of _solve's regime numbers.
REGIMES = (None, CatenaryRegime.SUSPENDED, CatenaryRegime.TOUCHDOWN, CatenaryRegime.SLACK,
           CatenaryRegime.VERTICAL, CatenaryRegime.FLAT)


class CatenaryInfo(NamedTuple):
    """Details of one solution.

    ``hf_n``/``vf_n`` are the horizontal/vertical tension at the top end B [N] (pass them back as
    ``hf0``/``vf0`` to warm-start the next call); ``ha_n``/``va_n`` the same at the bottom end A
    (``va_n`` positive when the line pulls A up). ``length_on_ground_m`` is the unstretched
    length lying on the ground [m], ``lowest_point_height_m`` the lowest height of the line
    above A's level [m]: as A itself is on the ground and the line never dips below it, this is
    always 0 here (negative would mean a line below the ground). ``iterations`` is the number of
    Newton steps (0 for the closed-form regimes; warm plus cold if a warm start failed) and
    ``warm_started`` tells whether the solution was reached from the caller's hf0/vf0.
    """

    hf_n: float
    vf_n: float
    ha_n: float
    va_n: float
    length_on_ground_m: float
    regime: CatenaryRegime
    iterations: int
    lowest_point_height_m: float
    warm_started: bool


def _check(value: float, name: str, lower: float, strict: bool) -> None:
    if not math.isfinite(value):
        raise CatenaryInputError(f"{name}: must be finite, got {value!r}")
    if (value <= lower) if strict else (value < lower):
        relation = ">" if strict else ">="
        raise CatenaryInputError(f"{name}: must be {relation} {lower}, got {value!r}")


def hanging_length_m(height_m: float, ea_n: float, w_n_per_m: float) -> float:
    """Unstretched length [m] that, hanging vertically under its own weight from its top end,
    stretches to exactly ``height_m``: the root of l + w l^2/(2 EA) = height."""
    return 2.0 * height_m / (math.sqrt(1.0 + 2.0 * height_m * w_n_per_m / ea_n) + 1.0)


@njit
def _eval(H: float, V: float, span: float, height: float, L: float, WL: float, iw: float,
          iea: float):
    """Residuals and merit function for top tensions (H, V); WL = w L, iw = 1/w, iea = 1/EA.

    Returns (ex, ez, j11, j12, j22, pi, pi_mag): the position errors (ex, ez) [m] of end B, the
    Jacobian d(ex, ez)/d(H, V) = [[j11, j12], [j12, j22]] (the line's compliance, symmetric and
    positive definite), and pi = G(H, V) - H span - V height [J], where G is the line's
    complementary energy (dG/dH = horizontal reach, dG/dV = vertical reach), so that
    (ex, ez) = grad(pi) and pi is convex: it serves as the line-search merit function.
    pi_mag is the size of the terms summed into pi, for judging its rounding error."""
    t = V / H
    q = math.sqrt(1.0 + t * t)
    Hw = H * iw
    LE = L * iea
    if V >= WL:  # suspended
        Va = V - WL
        ta = Va / H
        qa = math.sqrt(1.0 + ta * ta)
        dt = WL / H
        # Differences of asinh, sqrt and t*q written without cancellation for taut lines.
        if ta > 0.0:
            D = math.asinh(dt * (t + ta) / (t * qa + ta * q))
            tq = dt * (t + ta) * ((1.0 + t * t + ta * ta) / (t * q + ta * qa))
        else:
            D = math.asinh(t * qa - ta * q)
            tq = t * q - ta * qa
        s = (t + ta) / (q + qa)
        ex = Hw * D + H * LE - span
        ez = L * s + (V - 0.5 * WL) * LE - height
        c = t / q - ta / qa
        j11 = (D - c) * iw + LE
        j12 = -dt * s / (q * qa) * iw
        j22 = c * iw + LE
        g = 0.5 * H * Hw * (tq + D) + 0.5 * LE * (H * H + (V * V + V * Va + Va * Va) / 3.0)
    else:  # touchdown
        qm1 = t * t / (q + 1.0)
        ash = math.asinh(t)
        lb = L - V * iw
        ex = Hw * ash + lb + H * LE - span
        ez = Hw * qm1 + 0.5 * V * V * iw * iea - height
        tq = t / q
        j11 = (ash - tq) * iw + LE
        j12 = -qm1 / q * iw
        j22 = (tq + V * iea) * iw
        g = (0.5 * H * Hw * (t * q + ash) + 0.5 * (H * H * V + V * V * V / 3.0) * iw * iea
             + H * lb * (1.0 + 0.5 * H * iea))
    hs = H * span
    vh = V * height
    return ex, ez, j11, j12, j22, g - hs - vh, abs(g) + hs + vh


@njit
def _newton(span: float, height: float, L: float, EA: float, w: float,
            H: float, V: float, v_low: float, tol: float):
    """Damped Newton iteration on (H, V) from the guess H > 0, V > v_low, minimising the convex
    merit function pi of :func:`_eval` (whose gradient is the position error). ``v_low`` is a
    strict lower bound of the solution's V.

    Returns (H, V, iterations, converged)."""
    if not v_low < V:
        V = 1.5 * v_low + 1e-300
    floor = 1e-15 * (L + span + height)  # a position error that is exact to rounding
    WL = w * L
    iw = 1.0 / w
    iea = 1.0 / EA
    ex, ez, j11, j12, j22, pi, mag = _eval(H, V, span, height, L, WL, iw, iea)
    for it in range(_MAX_ITER):
        det = j11 * j22 - j12 * j12
        if not (det > 0.0 and det < math.inf):
            return H, V, it, False
        dH = -(j22 * ex - j12 * ez) / det
        dV = -(j11 * ez - j12 * ex) / det
        lim = 1e-13 * (H + V)  # rounding level
        if abs(dH) <= max(tol * H, lim) and abs(dV) <= max(tol * V, lim):
            # Converged; the last, negligible correction is applied without evaluating again.
            if H + dH > 0.0 and V + dV > v_low:
                return H + dH, V + dV, it + 1, True
            return H, V, it, True
        slope = ex * dH + ez * dV  # directional derivative of pi, negative
        # Decreases of H and of V - v_low are applied multiplicatively, H*exp(dH/H): Newton's
        # step in ln H, which keeps them positive and suits the H ln(1/H) behaviour near slack.
        step = 1.0
        gap = max(V - v_low, 1e-14 * V)  # the bound blurred by rounding
        accepted = False
        for _ in range(_MAX_HALVINGS):
            Hn = H + step * dH if dH >= 0.0 else H * math.exp(max(step * dH / H, -700.0))
            Vn = (V + step * dV if dV >= 0.0
                  else V - gap + gap * math.exp(max(step * dV / gap, -700.0)))
            Hn = max(Hn, 1e-100 * Vn)  # keeps V/H finite
            exn, ezn, k11, k12, k22, pin, magn = _eval(Hn, Vn, span, height, L, WL, iw, iea)
            # Armijo decrease of pi, allowing for its rounding error near the minimum
            if pin <= pi + 1e-4 * step * slope + 1e-13 * (mag + magn):
                accepted = True
                break
            step *= 0.5
        if not accepted:
            # no decrease possible: at the rounding floor (converged) or stuck (failed)
            return H, V, it, math.sqrt(ex * ex + ez * ez) <= 1e4 * floor
        H, V = Hn, Vn
        ex, ez, j11, j12, j22, pi, mag = exn, ezn, k11, k12, k22, pin, magn
        if abs(ex) <= floor and abs(ez) <= floor:
            return H, V, it + 1, True
    return H, V, _MAX_ITER, False


@njit
def _cold_guess(span: float, height: float, L: float, EA: float, w: float):
    """Initial (H, V): Peyrot & Goulois' lambda guess, raised to the straight-spring tension
    when the line must stretch to reach B."""
    d = math.sqrt(span * span + height * height)
    # length the line would have if stretched by about its self-weight tension
    Le = L + 0.5 * w * L * L / EA
    if Le <= d:
        lam = 0.2
    else:
        lam = math.sqrt(3.0 * ((Le * Le - height * height) / (span * span) - 1.0))
        lam = max(lam, 0.2)
    H = 0.5 * w * span / lam
    V = 0.5 * w * (height / math.tanh(lam) + L)
    if d > L:
        T = EA * (d - L) / L
        H = max(H, T * span / d)
        V = max(V, T * height / d + 0.5 * w * L)
    return max(H, 1e-12 * w * L), max(V, 1e-12 * w * L)


@njit
def _solve(span: float, height: float, L: float, EA: float, w: float,
           hf0: float, vf0: float, tol: float):
    """The scalar core. Returns (H, V, HA, VA, length_on_ground, regime, iterations, lowest,
    warm_started, converged) with regime as an int (the CatenaryRegime value)."""
    if height == 0.0:  # FLAT: stretched only if the span exceeds L
        H = EA * (span - L) / L if span > L else 0.0
        return H, 0.0, H, 0.0, L, 5, 0, 0.0, False, True
    lh = 2.0 * height / (math.sqrt(1.0 + 2.0 * height * w / EA) + 1.0)  # hanging_length_m
    if span + lh <= L:  # SLACK: L-shaped, hanging part vertical at zero bottom tension
        return 0.0, w * lh, 0.0, 0.0, L - lh, 3, 0, 0.0, False, True
    if span < VERTICAL_SPAN_RATIO * height:
        if lh <= L:  # a sliver of tiny spans with the line just longer than the hanging length
            return 0.0, w * lh, 0.0, 0.0, L - lh, 3, 0, 0.0, False, True
        # VERTICAL taut: bottom tension T0 from stretched length L + T0 L/EA + w L^2/(2EA)
        T0 = EA * (height - L) / L - 0.5 * w * L
        return 0.0, T0 + w * L, 0.0, T0, 0.0, 4, 0, 0.0, False, True
    # Strict lower bound of V: the line must reach up to B, so with a part on the ground
    # V/w + V^2/(2 w EA) > height, i.e. V > w lh; a line shorter than lh is suspended and
    # needs at least the tension of the vertical taut line.
    v_low = w * lh if lh <= L else EA * (height - L) / L + 0.5 * w * L
    it = 0
    warm = False
    if hf0 > 0.0 and vf0 > 0.0:
        H, V, it, warm = _newton(span, height, L, EA, w, hf0, vf0, v_low, tol)
    if not warm:  # cold start, also after a failed warm start
        H0, V0 = _cold_guess(span, height, L, EA, w)
        H, V, it2, ok = _newton(span, height, L, EA, w, H0, V0, v_low, tol)
        it += it2
    else:
        ok = True
    WL = w * L
    if V >= WL:
        VA = V - WL
        return H, V, H, VA, 0.0, 1, it, 0.0, warm, ok
    return H, V, H, 0.0, L - V / w, 2, it, 0.0, warm, ok


def catenary_end_forces(span_m: float, height_m: float, length_m: float, ea_n: float,
                        w_n_per_m: float, hf0: float = 0.0, vf0: float = 0.0,
                        tol: float = 1e-8):
    """Forces a tether exerts on its ends, bottom end A on flat frictionless ground.

    Parameters: ``span_m`` horizontal distance from A to B [m] (>= 0), ``height_m`` height of B
    above A [m] (>= 0), ``length_m`` unstretched length L [m] (> 0), ``ea_n`` axial stiffness
    EA [N] (> 0), ``w_n_per_m`` weight per unit length [N/m] (> 0), ``hf0``/``vf0`` optional warm
    start (the top tensions of a previous solution, ``info.hf_n``/``info.vf_n``; ignored unless
    both are positive), ``tol`` the relative Newton step at which the iteration stops (that
    last step is still applied; convergence is quadratic, so the result is accurate to about
    tol^2 relative).

    Returns ``(fAH, fAV, fBH, fBV, info)`` [N] in MoorPy's order and signs: the horizontal
    (positive from A towards B) and vertical (positive up) forces that the line exerts on A and
    on B, and a :class:`CatenaryInfo`. A warm-started solve that fails is retried cold.

    Raises :class:`CatenaryInputError` for a non-finite or out-of-domain argument and
    :class:`CatenaryConvergenceError` if the Newton iteration fails.
    """
    # one chained comparison per argument (false for NaN) keeps the common path fast
    if not (0.0 <= span_m < _INF and 0.0 <= height_m < _INF and 0.0 < length_m < _INF
            and 0.0 < ea_n < _INF and 0.0 < w_n_per_m < _INF and -_INF < hf0 < _INF
            and -_INF < vf0 < _INF and 0.0 < tol < _INF):
        _check(span_m, "span_m", 0.0, False)
        _check(height_m, "height_m", 0.0, False)
        _check(length_m, "length_m", 0.0, True)
        _check(ea_n, "ea_n", 0.0, True)
        _check(w_n_per_m, "w_n_per_m", 0.0, True)
        _check(hf0, "hf0", -_INF, False)
        _check(vf0, "vf0", -_INF, False)
        _check(tol, "tol", 0.0, True)
    H, V, HA, VA, lbot, reg, it, low, warm, ok = _solve(
        span_m, height_m, length_m, ea_n, w_n_per_m, hf0, vf0, tol)
    if not ok:
        raise CatenaryConvergenceError(
            f"catenary did not converge: span_m={span_m!r}, height_m={height_m!r}, "
            f"length_m={length_m!r}, ea_n={ea_n!r}, w_n_per_m={w_n_per_m!r}, "
            f"hf0={hf0!r}, vf0={vf0!r}")
    info = CatenaryInfo(H, V, HA, VA, lbot, REGIMES[reg], it, low, warm)
    return HA, VA, -H, -V, info


def catenary_profile(span_m: float, height_m: float, length_m: float, ea_n: float,
                     w_n_per_m: float, n_points: int = 50, hf0: float = 0.0, vf0: float = 0.0):
    """Points along the stretched tether from A to B, for drawing.

    Same arguments as :func:`catenary_end_forces`; ``n_points`` (>= 2) samples are taken at
    equal steps of unstretched arc length from A, except that the sample nearest the touchdown
    point (where the line leaves the ground) is moved onto it. Returns two numpy arrays
    ``(x, z)`` [m]: horizontal distance from A towards B and height above A. The part lying on
    the ground is included (z = 0); a slack part on the ground, which in reality bunches up, is
    drawn compressed evenly between A and the foot of the hanging part.
    """
    if n_points < 2:
        raise CatenaryInputError(f"n_points: must be >= 2, got {n_points!r}")
    _, _, _, _, info = catenary_end_forces(span_m, height_m, length_m, ea_n, w_n_per_m,
                                           hf0, vf0)
    L, EA, w = length_m, ea_n, w_n_per_m
    H = info.hf_n
    lb = info.length_on_ground_m
    s = np.linspace(0.0, L, n_points)
    if 0.0 < lb < L and n_points > 2:
        k = int(np.clip(np.argmin(np.abs(s[1:-1] - lb)) + 1, 1, n_points - 2))
        s[k] = lb
    regime = info.regime
    if regime == CatenaryRegime.FLAT:
        return s * (span_m / L), np.zeros_like(s)
    if regime == CatenaryRegime.VERTICAL:
        T0 = info.va_n
        return s * (span_m / L), s * (1.0 + T0 / EA) + 0.5 * w * s * s / EA
    if regime == CatenaryRegime.SLACK:
        sig = np.maximum(s - lb, 0.0)
        x = np.where(s <= lb, s * (span_m / lb) if lb > 0.0 else 0.0, span_m)
        return x, sig + 0.5 * w * sig * sig / EA
    if regime == CatenaryRegime.SUSPENDED:
        va = info.va_n
        a = (va + w * s) / H  # V/H along the line
        b = va / H
        qa, qb = np.sqrt(1.0 + a * a), math.sqrt(1.0 + b * b)
        # asinh(a) - asinh(b), without cancellation when b > 0
        d = np.arcsinh((w * s / H) * (a + b) / (a * qb + b * qa)) if b > 0.0 else np.arcsinh(a)
        x = H / w * d + H * s / EA
        z = s * (a + b) / (qa + qb) + (va * s + 0.5 * w * s * s) / EA
        return x, z
    # TOUCHDOWN
    sig = np.maximum(s - lb, 0.0)
    a = w * sig / H
    x = np.minimum(s, lb) * (1.0 + H / EA) + H / w * np.arcsinh(a) + H * sig / EA
    z = sig * a / (np.sqrt(1.0 + a * a) + 1.0) + 0.5 * w * sig * sig / EA
    return x, z
