"""The tether's shape under its weight and the wind: where the line's far end is, from what
the winder measures at the exit, and how that end moves with each measurement and with each
parameter the model is unsure of (docs/estimation.md §11).

The measurements: the paid-out (unstretched) length ``L`` [m], the tension at the exit
``T0`` [N], the direction the line leaves the exit, azimuth ``psi`` and elevation ``eps``
[rad] (the guide arm's encoders, read with biases ``b_psi``, ``b_eps`` [rad]: the true
angles are the readings minus them). The parameters: the line's weight per metre ``w``
[N/m], its drag per metre per (m/s)^2 of wind across it ``c`` = ½ rho_air C_dn d
[N s^2/m^3], its axial stiffness ``EA`` [N] and the horizontal wind ``U`` [m/s] as blowing
at the height ``z_ref`` [m], sheared as ``U(z) = U (max(z, z_min)/z_ref)^alpha`` (alpha 0: a
uniform wind).

The line is static, in the frame z-up at the exit. Its load per metre is its weight and the
drag of the wind across it (the cross-flow principle: a cylinder feels only the wind's part
normal to it, ``U_n = U - (U.t) t``, ``t`` the tangent; the drag along it, a hundredth of
that, is neglected):

    f(s) = (0, 0, -w) + c |U_n| U_n
    dT/ds = -f,   dp/ds = (1/|T| + 1/EA) T,   T(0) = T0 e0,  p(0) = 0

with ``e0 = (cos eps cos psi, cos eps sin psi, sin eps)``. Integrated from the exit over
``steps`` classical Runge-Kutta steps of arc length. Without a drag load the load is uniform
and the end has a closed form (:func:`line_end`: the elastic catenary for the weight alone).

The sensitivities: :func:`end_differences` gives the end and its central differences with
respect to every input (:class:`Column`), with a step per input. Steps that are the inputs'
standard deviations give the columns ``J_k sigma_k`` a covariance is built of (the ground
station's fix); small steps give the Jacobian a filter linearises with. Quadratic drag has
no slope at calm air, so a wind known only to within its spread is propagated by points
instead: a Gaussian error by a rule exact to the fifth degree (:func:`wind_covariance`), a
wind of a known speed from an unknown direction by its four directions
(:func:`wind_speed_covariance`).

Pure arithmetic for the ground station's fix and the onboard filter alike: nothing here
reads the plant or any process.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from tuavdefs.jit import njit
from tuavdefs.params import TetherParams

Vec3 = tuple[float, float, float]


class Column(IntEnum):
    """The inputs of the line's end, in the order of :func:`end_differences`'s columns."""

    LENGTH = 0            #: paid-out length L [m]
    TENSION = 1           #: tension at the exit T0 [N]
    AZIMUTH = 2           #: exit azimuth as read psi [rad]
    ELEVATION = 3         #: exit elevation as read eps [rad]
    WIND_X = 4            #: wind at the reference height, x [m/s]
    WIND_Y = 5            #: wind at the reference height, y [m/s]
    WEIGHT = 6            #: weight per metre w [N/m]
    DRAG = 7              #: drag per metre per (m/s)^2 across the line c [N s^2/m^3]
    AZIMUTH_BIAS = 8      #: the azimuth reading's bias b_psi [rad]
    ELEVATION_BIAS = 9    #: the elevation reading's bias b_eps [rad]


N_COLUMNS = len(Column)


@dataclass(frozen=True)
class LineModel:
    """The line as a model believes it: weight per metre ``weight_n_m`` [N/m], drag per
    metre per (m/s)^2 across it ``drag_n_s2_m3`` [N s^2/m^3], axial stiffness ``ea_n`` [N]
    (0 or infinite: inextensible), the wind profile's reference height
    ``reference_height_m`` [m], shear exponent ``shear_exponent`` and floor
    ``min_height_m`` [m], and the integration's ``steps``."""

    weight_n_m: float
    drag_n_s2_m3: float
    ea_n: float
    reference_height_m: float = 10.0
    shear_exponent: float = 0.0
    min_height_m: float = 1.0
    steps: int = 32

    @classmethod
    def from_tether(cls, tether: TetherParams, gravity_m_s2: float, air_density_kg_m3: float,
                    **kw: float) -> LineModel:
        """The model of a line with the parameters ``tether`` (weight ``rho g``, drag
        ``½ rho_air C_dn d``, ``EA``) in air of ``air_density_kg_m3`` [kg/m^3]; ``kw``
        sets the wind profile and the steps."""
        return cls(tether.linear_density_kg_m * gravity_m_s2,
                   drag_per_metre(tether.normal_drag_coeff, tether.diameter_m,
                                  air_density_kg_m3),
                   tether.axial_stiffness_n, **kw)  # type: ignore[arg-type]

    def with_weight(self, weight_n_m: float) -> LineModel:
        """The same line with the weight per metre ``weight_n_m`` [N/m]."""
        return replace(self, weight_n_m=float(weight_n_m))


def drag_per_metre(normal_drag_coeff: float, diameter_m: float,
                   air_density_kg_m3: float) -> float:
    """The line's drag per metre per (m/s)^2 of wind across it, ½ rho_air C_dn d
    [N s^2/m^3]."""
    return 0.5 * air_density_kg_m3 * normal_drag_coeff * diameter_m


@njit
def uniform_end(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
                fx: float, fy: float, fz: float, ea_n: float) -> tuple[float, float, float]:
    """The far end [m] of an elastic line of unstretched length ``length_m`` leaving the
    origin in the direction (``azimuth_rad``, ``elevation_rad``) with tension ``t0_n`` [N],
    under the uniform load (``fx``, ``fy``, ``fz``) [N/m]. Its tension is ``T(s) = T0 e0 -
    f s``; with ``u = -f/|f|``, ``V = T0 e0.u``, ``H e_h = T0 e0 - V u``:

        p(L) = e_h (H/|f|) (asinh((V + |f| L)/H) - asinh(V/H))
             + u (sqrt(H^2 + (V + |f| L)^2) - sqrt(H^2 + V^2)) / |f|
             + (H L e_h + (V L + |f| L^2/2) u) / EA
    """
    ce = math.cos(elevation_rad)
    e0x = ce * math.cos(azimuth_rad)
    e0y = ce * math.sin(azimuth_rad)
    e0z = math.sin(elevation_rad)
    fm = math.sqrt(fx * fx + fy * fy + fz * fz)
    L = length_m
    tx, ty, tz = t0_n * e0x, t0_n * e0y, t0_n * e0z
    stretch = 1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n) else 0.0
    if fm <= 0.0:
        k = L * (1.0 + t0_n * stretch)
        return (e0x * k, e0y * k, e0z * k)
    ux, uy, uz = -fx / fm, -fy / fm, -fz / fm
    V = tx * ux + ty * uy + tz * uz
    hx, hy, hz = tx - V * ux, ty - V * uy, tz - V * uz
    H = math.sqrt(hx * hx + hy * hy + hz * hz)
    top = V + fm * L
    along_u = (math.hypot(H, top) - math.hypot(H, V)) / fm + (V * L + 0.5 * fm * L * L) * stretch
    if H > 1e-9:
        ehx, ehy, ehz = hx / H, hy / H, hz / H
        across = (H / fm) * (math.asinh(top / H) - math.asinh(V / H)) + H * L * stretch
    else:
        ehx = ehy = ehz = 0.0
        across = 0.0
    return (ehx * across + ux * along_u, ehy * across + uy * along_u,
            ehz * across + uz * along_u)


def line_end(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
             load_n_m: Vec3, ea_n: float) -> Vec3:
    """:func:`uniform_end` with the load as a vector ``load_n_m`` [N/m]."""
    return uniform_end(float(length_m), float(t0_n), float(azimuth_rad),
                       float(elevation_rad), float(load_n_m[0]), float(load_n_m[1]),
                       float(load_n_m[2]), float(ea_n))


@njit
def _across(z: float, tx: float, ty: float, tz: float, ux: float, uy: float, zr: float,
            shear: float, zmin: float) -> tuple[float, float, float, float, float, float]:
    """The wind across the line at height ``z`` [m] with tension (``tx``, ``ty``, ``tz``)
    [N]: ``(|T|, k, a, nx, ny, nz)`` with ``|T|`` floored at 1e-12 N, the shear factor
    ``k = (max(z, zmin)/zr)^shear``, ``a = W.T/|T|^2`` and the wind's component across the
    line ``n = W - a T`` [m/s] for the wind ``W = k (ux, uy, 0)``."""
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    tn = max(tn, 1e-12)
    k = (max(z, zmin) / zr) ** shear if shear != 0.0 else 1.0
    wx, wy = ux * k, uy * k
    along = (wx * tx + wy * ty) / (tn * tn)
    return tn, k, along, wx - along * tx, wy - along * ty, -along * tz


@njit
def _slope(z: float, tx: float, ty: float, tz: float, w: float, c: float, ux: float,
           uy: float, zr: float, shear: float, zmin: float, stretch: float
           ) -> tuple[float, float, float, float, float, float]:
    """(dp/ds, dT/ds) of the line at height ``z`` [m] with tension (``tx``, ``ty``,
    ``tz``) [N] (module docstring)."""
    tn, k, along, nx, ny, nz = _across(z, tx, ty, tz, ux, uy, zr, shear, zmin)
    q = c * math.sqrt(nx * nx + ny * ny + nz * nz)
    g = 1.0 / tn + stretch
    return (g * tx, g * ty, g * tz, -q * nx, -q * ny, w - q * nz)


@njit
def _rk4_sum(y: tuple[float, float, float, float, float, float],
             a: tuple[float, float, float, float, float, float],
             b: tuple[float, float, float, float, float, float],
             d: tuple[float, float, float, float, float, float],
             e: tuple[float, float, float, float, float, float], k: float
             ) -> tuple[float, float, float, float, float, float]:
    """The line's state (p [m], T [N]) ``y`` after a classical Runge-Kutta step of its
    four stages' slopes ``a``, ``b``, ``d``, ``e``, ``k`` a sixth of the step [m]."""
    return (y[0] + k * (a[0] + 2.0 * b[0] + 2.0 * d[0] + e[0]),
            y[1] + k * (a[1] + 2.0 * b[1] + 2.0 * d[1] + e[1]),
            y[2] + k * (a[2] + 2.0 * b[2] + 2.0 * d[2] + e[2]),
            y[3] + k * (a[3] + 2.0 * b[3] + 2.0 * d[3] + e[3]),
            y[4] + k * (a[4] + 2.0 * b[4] + 2.0 * d[4] + e[4]),
            y[5] + k * (a[5] + 2.0 * b[5] + 2.0 * d[5] + e[5]))


@njit
def line_top(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
             w_n_m: float, drag_n_s2_m3: float, wind_x_m_s: float, wind_y_m_s: float,
             ea_n: float, reference_height_m: float, shear_exponent: float,
             min_height_m: float, steps: int
             ) -> tuple[float, float, float, float, float, float]:
    """(the far end [m], the tension vector there [N], pointing on along the line: the line
    pulls the vehicle with its opposite) of the line of :func:`wind_end` (same arguments):
    ``steps`` RK4 steps, or the closed form without drag (its tension ``T(L) = T0 e0 - f
    L``). The line's pull on the vehicle, ``-T(L)``, is what its accelerometer feels of
    the tether."""
    L = max(length_m, 0.0)
    t0 = max(t0_n, 1e-9)
    ce = math.cos(elevation_rad)
    tx = t0 * ce * math.cos(azimuth_rad)
    ty = t0 * ce * math.sin(azimuth_rad)
    tz = t0 * math.sin(elevation_rad)
    if drag_n_s2_m3 <= 0.0 or (wind_x_m_s == 0.0 and wind_y_m_s == 0.0):
        e = uniform_end(L, t0, azimuth_rad, elevation_rad, 0.0, 0.0, -w_n_m, ea_n)
        return (e[0], e[1], e[2], tx, ty, tz + w_n_m * L)
    stretch = 1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n) else 0.0
    c, ux, uy = drag_n_s2_m3, wind_x_m_s, wind_y_m_s
    zr, sh, zm = reference_height_m, shear_exponent, min_height_m
    px = py = pz = 0.0
    h = L / steps
    for _ in range(steps):
        a = _slope(pz, tx, ty, tz, w_n_m, c, ux, uy, zr, sh, zm, stretch)
        b = _slope(pz + 0.5 * h * a[2], tx + 0.5 * h * a[3], ty + 0.5 * h * a[4],
                   tz + 0.5 * h * a[5], w_n_m, c, ux, uy, zr, sh, zm, stretch)
        d = _slope(pz + 0.5 * h * b[2], tx + 0.5 * h * b[3], ty + 0.5 * h * b[4],
                   tz + 0.5 * h * b[5], w_n_m, c, ux, uy, zr, sh, zm, stretch)
        e = _slope(pz + h * d[2], tx + h * d[3], ty + h * d[4], tz + h * d[5], w_n_m, c,
                   ux, uy, zr, sh, zm, stretch)
        k = h / 6.0
        px, py, pz, tx, ty, tz = _rk4_sum((px, py, pz, tx, ty, tz), a, b, d, e, k)
    return (px, py, pz, tx, ty, tz)


@njit
def wind_end(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
             w_n_m: float, drag_n_s2_m3: float, wind_x_m_s: float, wind_y_m_s: float,
             ea_n: float, reference_height_m: float, shear_exponent: float,
             min_height_m: float, steps: int) -> tuple[float, float, float]:
    """The far end [m] of the line (module docstring) of unstretched length ``length_m``
    [m] leaving the exit in the true direction (``azimuth_rad``, ``elevation_rad``) with
    tension ``t0_n`` [N], under its weight ``w_n_m`` [N/m] and the drag ``drag_n_s2_m3``
    |U_n| U_n of the wind (``wind_x_m_s``, ``wind_y_m_s``) at ``reference_height_m`` [m],
    sheared with ``shear_exponent`` above ``min_height_m`` [m]: ``steps`` RK4 steps, or the
    closed form :func:`uniform_end` without drag (:func:`line_top`)."""
    r = line_top(length_m, t0_n, azimuth_rad, elevation_rad, w_n_m, drag_n_s2_m3,
                 wind_x_m_s, wind_y_m_s, ea_n, reference_height_m, shear_exponent,
                 min_height_m, steps)
    return (r[0], r[1], r[2])


@njit
def _end_at(x: np.ndarray, ea_n: float, zr: float, shear: float, zmin: float, steps: int
            ) -> tuple[float, float, float]:
    """:func:`wind_end` of the input vector ``x`` (:class:`Column` order), the angles
    corrected by their biases, the length, weight and drag kept non-negative."""
    return wind_end(max(x[0], 0.0), x[1], x[2] - x[8], x[3] - x[9], max(x[6], 0.0),
                    max(x[7], 0.0), x[4], x[5], ea_n, zr, shear, zmin, steps)


@njit
def end_differences(x: np.ndarray, step: np.ndarray, ea_n: float, reference_height_m: float,
                    shear_exponent: float, min_height_m: float, steps: int,
                    out: np.ndarray) -> tuple[float, float, float]:
    """The end [m] at the inputs ``x`` (:data:`N_COLUMNS` floats in :class:`Column`
    order) and, in ``out`` (3 x :data:`N_COLUMNS`), its central differences
    ``(p(x + h_k e_k) - p(x - h_k e_k)) / (2 h_k)`` for the steps ``h_k`` = ``step[k]``
    (a column of zeros where ``h_k`` is 0). Small steps: the Jacobian; the inputs'
    standard deviations: the columns whose outer products ``J_k J_k' h_k^2`` sum to the
    propagated covariance, robust to the curvature over that spread."""
    xe = x.copy()
    for k in range(x.shape[0]):
        hk = step[k]
        if hk == 0.0:
            out[0, k] = out[1, k] = out[2, k] = 0.0
            continue
        xe[k] = x[k] + hk
        hi = _end_at(xe, ea_n, reference_height_m, shear_exponent, min_height_m, steps)
        xe[k] = x[k] - hk
        lo = _end_at(xe, ea_n, reference_height_m, shear_exponent, min_height_m, steps)
        xe[k] = x[k]
        s = 0.5 / hk
        out[0, k] = (hi[0] - lo[0]) * s
        out[1, k] = (hi[1] - lo[1]) * s
        out[2, k] = (hi[2] - lo[2]) * s
    return _end_at(x, ea_n, reference_height_m, shear_exponent, min_height_m, steps)


#: The sensitivities integrated in :func:`line_sensitivities`' one pass: with respect to
#: the tension at the exit, the elevation, the wind's two components and the weight (the
#: others follow from the line's symmetries, :func:`end_slopes`).
_N_SENS = 5


@njit
def _slope_sensitivity(z: float, tx: float, ty: float, tz: float,
                       line: tuple[float, float, float, float, float, float, float, float],
                       stage: int, step: float, Sin: np.ndarray, S: np.ndarray,
                       Sk: np.ndarray, acc: np.ndarray, D: np.ndarray
                       ) -> tuple[float, float, float, float, float, float]:
    """:func:`_slope` at one Runge-Kutta stage (``line``: the weight ``w``, the drag ``c``,
    the wind ``ux``, ``uy``, its reference height ``zr``, shear exponent and least height
    ``zmin``, and the line's ``1/EA``, as :func:`line_sensitivities` packs them) and that
    stage's share of the sensitivities' step: the variational equation's right-hand side
    ``dS/ds = (d slope / d state) S + d slope / d inputs`` at the stage's sensitivities
    ``Sin`` (6 x 5: the rows p, T; the columns the tension at the exit, the elevation, the
    wind's two components, the weight), taken into the step's sum ``acc`` and the next
    stage's ``Sk = S + step dS`` (``stage`` 0 to 2: ``acc`` set, or added twice), or at the
    last stage (3) ``S += step (acc + dS)``; ``D`` (3 x 5) is scratch for the inputs' own
    terms. Column by column, so ``Sin`` may be ``Sk``. With ``t = T/|T|``, ``P = I - t
    t'``, the wind across ``n = P W``, ``a = t.W``, the drag ``D = -c |n| n`` (``n.t = 0``):

        d(dp/ds)/dT = g I - t t'/|T|                (g = 1/|T| + 1/EA)
        dn/dT = -(a P + t n')/|T|,   dn/dW = P,     dD/dn = -c (|n| I + n n'/|n|)
        dW/dU = k(z) I_2,  dW/dz = U dk/dz,         d(dT/ds)/dw = e_z
    """
    w, c, ux, uy, zr, shear, zmin, stretch = line
    tn, k, along, nx, ny, nz = _across(z, tx, ty, tz, ux, uy, zr, shear, zmin)
    nm = math.sqrt(nx * nx + ny * ny + nz * nz)
    q = c * nm
    g = 1.0 / tn + stretch
    inv = 1.0 / tn
    t0, t1, t2 = tx * inv, ty * inv, tz * inv
    a = along * tn                                           # t.W
    # d(dT/ds)/dT s = (dD/dn)(dn/dT) s = al s + t (be n.s - al t.s) + ga n n.s (n.t = 0)
    al = q * a * inv
    be = q * inv
    ga = c * a * inv / nm if nm > 0.0 else 0.0
    # d(dT/ds)/dz = (dD/dn) P dW/dz = (dk/dz / k) (dD/dn) n = -2 c |n| n shear / z
    zf = -2.0 * q * shear / z if shear != 0.0 and z > zmin else 0.0
    # the inputs' own terms: the wind's components (dD/dn) P k e_x, e_y, the weight e_z
    qk = -q * k
    hx = -c * k * nx / nm if nm > 0.0 else 0.0
    hy = -c * k * ny / nm if nm > 0.0 else 0.0
    D[0, 2] = qk * (1.0 - t0 * t0) + hx * nx
    D[1, 2] = -qk * t1 * t0 + hx * ny
    D[2, 2] = -qk * t2 * t0 + hx * nz
    D[0, 3] = -qk * t0 * t1 + hy * nx
    D[1, 3] = qk * (1.0 - t1 * t1) + hy * ny
    D[2, 3] = -qk * t2 * t1 + hy * nz
    D[2, 4] = 1.0
    keep = 0.0 if stage == 0 else 1.0
    twice = 1.0 if stage == 0 else 2.0
    last = stage == 3
    for j in range(_N_SENS):
        s3, s4, s5, sz = Sin[3, j], Sin[4, j], Sin[5, j], Sin[2, j]
        ts = t0 * s3 + t1 * s4 + t2 * s5
        ns = nx * s3 + ny * s4 + nz * s5
        u = ts * inv
        v = be * ns - al * ts
        r = ga * ns + zf * sz
        d0 = g * s3 - t0 * u
        d1 = g * s4 - t1 * u
        d2 = g * s5 - t2 * u
        d3 = al * s3 + t0 * v + nx * r + D[0, j]
        d4 = al * s4 + t1 * v + ny * r + D[1, j]
        d5 = al * s5 + t2 * v + nz * r + D[2, j]
        if last:
            S[0, j] += step * (acc[0, j] + d0)
            S[1, j] += step * (acc[1, j] + d1)
            S[2, j] += step * (acc[2, j] + d2)
            S[3, j] += step * (acc[3, j] + d3)
            S[4, j] += step * (acc[4, j] + d4)
            S[5, j] += step * (acc[5, j] + d5)
        else:
            acc[0, j] = keep * acc[0, j] + twice * d0
            acc[1, j] = keep * acc[1, j] + twice * d1
            acc[2, j] = keep * acc[2, j] + twice * d2
            acc[3, j] = keep * acc[3, j] + twice * d3
            acc[4, j] = keep * acc[4, j] + twice * d4
            acc[5, j] = keep * acc[5, j] + twice * d5
            Sk[0, j] = S[0, j] + step * d0
            Sk[1, j] = S[1, j] + step * d1
            Sk[2, j] = S[2, j] + step * d2
            Sk[3, j] = S[3, j] + step * d3
            Sk[4, j] = S[4, j] + step * d4
            Sk[5, j] = S[5, j] + step * d5
    return (g * tx, g * ty, g * tz, -q * nx, -q * ny, w - q * nz)


@njit
def line_sensitivities(length_m: float, t0_n: float, azimuth_rad: float,
                       elevation_rad: float, w_n_m: float, drag_n_s2_m3: float,
                       wind_x_m_s: float, wind_y_m_s: float, ea_n: float,
                       reference_height_m: float, shear_exponent: float, min_height_m: float,
                       steps: int, S: np.ndarray
                       ) -> tuple[float, float, float, float, float, float]:
    """:func:`line_top` integrated with drag (``steps`` RK4 steps, the same arithmetic) and,
    alongside it in the same pass, its variational equation (:func:`_slope_sensitivity`):
    into ``S`` (6 x 5) the derivatives of the end (rows 0-2) and of the tension there (rows
    3-5) with respect to the tension at the exit, the elevation, the wind's two components
    and the weight (:func:`end_slopes` has the azimuth's and the drag's from them). RK4
    applied to the state and its variational equation together is the exact derivative of
    RK4's map of the state: the Jacobian of the very end the filter uses, at the cost of
    about two and a half integrations instead of one per column."""
    L = max(length_m, 0.0)
    t0 = max(t0_n, 1e-9)
    ce, se = math.cos(elevation_rad), math.sin(elevation_rad)
    ca, sa = math.cos(azimuth_rad), math.sin(azimuth_rad)
    tx, ty, tz = t0 * ce * ca, t0 * ce * sa, t0 * se
    for i in range(6):
        for j in range(_N_SENS):
            S[i, j] = 0.0
    S[3, 0], S[4, 0], S[5, 0] = ce * ca, ce * sa, se            # d T(0) / d T0
    S[3, 1], S[4, 1], S[5, 1] = -t0 * se * ca, -t0 * se * sa, t0 * ce   # ... / d eps
    stretch = 1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n) else 0.0
    line = (w_n_m, drag_n_s2_m3, wind_x_m_s, wind_y_m_s, reference_height_m,
            shear_exponent, min_height_m, stretch)
    Sk = np.empty((6, _N_SENS))
    acc = np.zeros((6, _N_SENS))
    D = np.zeros((3, _N_SENS))       # the inputs' own terms of a stage
    px = py = pz = 0.0
    h = L / steps
    hh = 0.5 * h
    k = h / 6.0
    for _ in range(steps):
        a = _slope_sensitivity(pz, tx, ty, tz, line, 0, hh, S, S, Sk, acc, D)
        b = _slope_sensitivity(pz + 0.5 * h * a[2], tx + 0.5 * h * a[3],
                               ty + 0.5 * h * a[4], tz + 0.5 * h * a[5], line, 1, hh, Sk, S,
                               Sk, acc, D)
        d = _slope_sensitivity(pz + 0.5 * h * b[2], tx + 0.5 * h * b[3],
                               ty + 0.5 * h * b[4], tz + 0.5 * h * b[5], line, 2, h, Sk, S,
                               Sk, acc, D)
        e = _slope_sensitivity(pz + h * d[2], tx + h * d[3], ty + h * d[4], tz + h * d[5],
                               line, 3, k, Sk, S, Sk, acc, D)
        px, py, pz, tx, ty, tz = _rk4_sum((px, py, pz, tx, ty, tz), a, b, d, e, k)
    return (px, py, pz, tx, ty, tz)


#: The relative step of :func:`end_slopes`' forward differences in calm air (about the
#: square root of the float's resolution, times each input's scale).
SLOPE_STEP = 2e-8


@njit
def end_slopes(x: np.ndarray, ea_n: float, reference_height_m: float, shear_exponent: float,
               min_height_m: float, steps: int, out: np.ndarray
               ) -> tuple[float, float, float, float, float, float]:
    """(the end [m], the tension there [N]: :func:`line_top`) at the inputs ``x``
    (:class:`Column` order), and in ``out`` (3 x :data:`N_COLUMNS`) the Jacobian of the
    end with respect to every input, for a filter to linearise with: the length's column
    is the line's tangent at the end, ``dp/ds = (1/|T| + 1/EA) T(L)``; the biases' are the
    angles' negated; the others, in a wind, the sensitivities integrated with the line in
    one pass (:func:`line_sensitivities`), in calm air forward differences of the closed
    form of :data:`SLOPE_STEP` times the input's scale (the tension, the weight; 1 rad for
    the angles), the wind's and the drag's columns 0 (the quadratic drag has no slope at
    calm air)."""
    L, t0 = max(x[0], 0.0), x[1]
    az, el = x[2] - x[8], x[3] - x[9]
    w, c = max(x[6], 0.0), max(x[7], 0.0)
    ux, uy = x[4], x[5]
    calm = c <= 0.0 or (ux == 0.0 and uy == 0.0)
    if calm:
        base = line_top(L, t0, az, el, w, c, ux, uy, ea_n, reference_height_m,
                        shear_exponent, min_height_m, steps)
        for k in range(1, 8):
            if k == 4 or k == 5 or k == 7:
                out[0, k] = out[1, k] = out[2, k] = 0.0
                continue
            if k == 1:
                h = SLOPE_STEP * max(abs(t0), 1.0)
            elif k == 6:
                h = SLOPE_STEP * max(w, 1e-3)
            else:
                h = SLOPE_STEP
            e = line_top(L, t0 + h if k == 1 else t0, az + h if k == 2 else az,
                         el + h if k == 3 else el, w + h if k == 6 else w, c, ux, uy, ea_n,
                         reference_height_m, shear_exponent, min_height_m, steps)
            out[0, k] = (e[0] - base[0]) / h
            out[1, k] = (e[1] - base[1]) / h
            out[2, k] = (e[2] - base[2]) / h
    else:
        S = np.empty((6, _N_SENS))
        base = line_sensitivities(L, t0, az, el, w, c, ux, uy, ea_n, reference_height_m,
                                  shear_exponent, min_height_m, steps, S)
        for i in range(3):
            out[i, 1] = S[i, 0]
            out[i, 3] = S[i, 1]
            out[i, 4] = S[i, 2]
            out[i, 5] = S[i, 3]
            out[i, 6] = S[i, 4]
            # turning the exit and the wind together about the vertical turns the line:
            # p(psi + d, U) = Rz(d) p(psi, Rz(-d) U)
            out[i, 2] = uy * S[i, 2] - ux * S[i, 3]
            # the drag c |U_n| U_n: the wind times l is the drag times l^2
            out[i, 7] = (ux * S[i, 2] + uy * S[i, 3]) / (2.0 * c)
        out[0, 2] -= base[1]
        out[1, 2] += base[0]
    tx, ty, tz = base[3], base[4], base[5]
    tn = math.sqrt(tx * tx + ty * ty + tz * tz)
    g = (1.0 / tn if tn > 0.0 else 0.0) + (1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n)
                                           else 0.0)
    out[0, 0], out[1, 0], out[2, 0] = g * tx, g * ty, g * tz
    for i in range(3):
        out[i, 8] = -out[i, 2]
        out[i, 9] = -out[i, 3]
    return base


@njit
def _add_wind_point(x: np.ndarray, xe: np.ndarray, base: tuple[float, float, float],
                    dx: float, dy: float, weight: float, ea_n: float, zr: float,
                    shear: float, zmin: float, steps: int, out: np.ndarray) -> None:
    """Adds ``weight`` d d' to ``out`` (3 x 3), d the end in the wind of ``x`` moved by
    (``dx``, ``dy``) [m/s] less ``base``."""
    xe[4] = x[4] + dx
    xe[5] = x[5] + dy
    e = _end_at(xe, ea_n, zr, shear, zmin, steps)
    d0, d1, d2 = e[0] - base[0], e[1] - base[1], e[2] - base[2]
    out[0, 0] += weight * d0 * d0
    out[0, 1] += weight * d0 * d1
    out[0, 2] += weight * d0 * d2
    out[1, 1] += weight * d1 * d1
    out[1, 2] += weight * d1 * d2
    out[2, 2] += weight * d2 * d2
    out[1, 0] = out[0, 1]
    out[2, 0] = out[0, 2]
    out[2, 1] = out[1, 2]


@njit
def wind_covariance(x: np.ndarray, cov_xx: float, cov_xy: float, cov_yy: float,
                    ea_n: float, reference_height_m: float, shear_exponent: float,
                    min_height_m: float, steps: int, out: np.ndarray) -> None:
    """The second moment [m^2] (into ``out``, 3 x 3) of the end about the end at the wind
    of ``x`` that a Gaussian error of that wind, of covariance (``cov_xx``, ``cov_xy``,
    ``cov_yy``) [m^2/s^2], makes: eight points on the ellipse of twice its standard
    deviations, at every 45 degrees from its principal axes (an isotropic error: from the
    line's azimuth), each with weight 1/16 (the rest, 1/2, at the mean, adding nothing).
    The rule integrates every polynomial of the wind error up to the fifth degree exactly
    against the Gaussian: the drag's square at calm air (whose slope, hence a Jacobian's
    share, is zero there) and its fourth moment included."""
    base = _end_at(x, ea_n, reference_height_m, shear_exponent, min_height_m, steps)
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    mean = 0.5 * (cov_xx + cov_yy)
    dev = math.sqrt(0.25 * (cov_xx - cov_yy) ** 2 + cov_xy * cov_xy)
    if dev <= 1e-12 * max(mean, 1e-300):
        theta = x[2] - x[8]
    else:
        theta = 0.5 * math.atan2(2.0 * cov_xy, cov_xx - cov_yy)
    c, s = math.cos(theta), math.sin(theta)
    r1 = 2.0 * math.sqrt(max(mean + dev, 0.0))
    r2 = 2.0 * math.sqrt(max(mean - dev, 0.0))
    if r1 <= 0.0:
        return
    xe = x.copy()
    h = math.sqrt(0.5)
    for ca, sa in ((1.0, 0.0), (h, h), (0.0, 1.0), (-h, h), (-1.0, 0.0), (-h, -h),
                   (0.0, -1.0), (h, -h)):
        a, b = r1 * ca, r2 * sa
        _add_wind_point(x, xe, base, a * c - b * s, a * s + b * c, 1.0 / 16.0, ea_n,
                        reference_height_m, shear_exponent, min_height_m, steps, out)


@njit
def wind_speed_covariance(x: np.ndarray, speed_m_s: float, ea_n: float,
                          reference_height_m: float, shear_exponent: float,
                          min_height_m: float, steps: int, out: np.ndarray) -> None:
    """The second moment [m^2] (into ``out``, 3 x 3) of the end about the end at the wind
    of ``x`` when a further wind of ``speed_m_s`` [m/s] blows from a direction not known:
    the mean over the four directions along and across the line's azimuth, both ways (the
    drag being quadratic, each way bends the line differently)."""
    base = _end_at(x, ea_n, reference_height_m, shear_exponent, min_height_m, steps)
    for i in range(3):
        for j in range(3):
            out[i, j] = 0.0
    if speed_m_s <= 0.0:
        return
    az = x[2] - x[8]
    c, s = speed_m_s * math.cos(az), speed_m_s * math.sin(az)
    xe = x.copy()
    for dx, dy in ((c, s), (-c, -s), (-s, c), (s, -c)):
        _add_wind_point(x, xe, base, dx, dy, 0.25, ea_n, reference_height_m,
                        shear_exponent, min_height_m, steps, out)


def inputs(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
           model: LineModel, wind_m_s: tuple[float, float] = (0.0, 0.0),
           biases_rad: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The input vector (:class:`Column` order) of the measurements, the wind [m/s] at
    the model's reference height and the arm's biases [rad] on ``model``'s line."""
    x = np.empty(N_COLUMNS)
    x[Column.LENGTH], x[Column.TENSION] = length_m, t0_n
    x[Column.AZIMUTH], x[Column.ELEVATION] = azimuth_rad, elevation_rad
    x[Column.WIND_X], x[Column.WIND_Y] = wind_m_s
    x[Column.WEIGHT], x[Column.DRAG] = model.weight_n_m, model.drag_n_s2_m3
    x[Column.AZIMUTH_BIAS], x[Column.ELEVATION_BIAS] = biases_rad
    return x


def end(model: LineModel, x: np.ndarray) -> Vec3:
    """The far end [m] of ``model``'s line at the inputs ``x`` (:func:`inputs`)."""
    return _end_at(np.ascontiguousarray(x, dtype=np.float64), float(model.ea_n),
                   float(model.reference_height_m), float(model.shear_exponent),
                   float(model.min_height_m), int(model.steps))


def top(model: LineModel, x: np.ndarray) -> tuple[Vec3, Vec3]:
    """(the far end [m], the tension there [N]) of ``model``'s line at the inputs ``x``
    (:func:`inputs`; :func:`line_top`)."""
    r = line_top(max(float(x[0]), 0.0), float(x[1]), float(x[2] - x[8]),
                 float(x[3] - x[9]), max(float(x[6]), 0.0), max(float(x[7]), 0.0),
                 float(x[4]), float(x[5]), float(model.ea_n),
                 float(model.reference_height_m), float(model.shear_exponent),
                 float(model.min_height_m), int(model.steps))
    return (r[0], r[1], r[2]), (r[3], r[4], r[5])


def jacobian(model: LineModel, x: np.ndarray, relative_step: float = 1e-6
             ) -> tuple[Vec3, np.ndarray]:
    """(the end [m], its Jacobian 3 x :data:`N_COLUMNS` with respect to the inputs ``x``
    (:func:`inputs`)) by central differences of steps ``relative_step`` times a scale per
    input (the length, the tension, the wind's speed, the weight, the drag, 1 rad for the
    angles)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    wind = math.hypot(x[Column.WIND_X], x[Column.WIND_Y])
    scale = np.array([max(x[0], 1.0), max(abs(x[1]), 1.0), 1.0, 1.0, max(wind, 1.0),
                      max(wind, 1.0), max(x[6], 1e-3), max(x[7], 1e-4), 1.0, 1.0])
    out = np.zeros((3, N_COLUMNS))
    e = differences(model, x, relative_step * scale, out)
    return e, out


def slopes(model: LineModel, x: np.ndarray) -> tuple[Vec3, Vec3, np.ndarray]:
    """(the end [m], the tension there [N], the Jacobian 3 x :data:`N_COLUMNS`) of
    ``model``'s line at the inputs ``x`` (:func:`inputs`; :func:`end_slopes`)."""
    out = np.zeros((3, N_COLUMNS))
    r = end_slopes(np.ascontiguousarray(x, dtype=np.float64), float(model.ea_n),
                   float(model.reference_height_m), float(model.shear_exponent),
                   float(model.min_height_m), int(model.steps), out)
    return (r[0], r[1], r[2]), (r[3], r[4], r[5]), out


def differences(model: LineModel, x: np.ndarray, step: np.ndarray, out: np.ndarray) -> Vec3:
    """:func:`end_differences` on ``model``'s line."""
    return end_differences(np.ascontiguousarray(x, dtype=np.float64),
                           np.ascontiguousarray(step, dtype=np.float64), float(model.ea_n),
                           float(model.reference_height_m), float(model.shear_exponent),
                           float(model.min_height_m), int(model.steps), out)


def wind_spread(model: LineModel, x: np.ndarray, cov_m2_s2: np.ndarray) -> np.ndarray:
    """The end's covariance [m^2] from a Gaussian error of the wind in ``x``, of 2 x 2
    covariance ``cov_m2_s2`` [m^2/s^2] (:func:`wind_covariance`)."""
    out = np.zeros((3, 3))
    wind_covariance(np.ascontiguousarray(x, dtype=np.float64), float(cov_m2_s2[0][0]),
                    float(cov_m2_s2[0][1]), float(cov_m2_s2[1][1]), float(model.ea_n),
                    float(model.reference_height_m), float(model.shear_exponent),
                    float(model.min_height_m), int(model.steps), out)
    return out


def wind_speed_spread(model: LineModel, x: np.ndarray, speed_m_s: float) -> np.ndarray:
    """The end's covariance [m^2] from a further wind of ``speed_m_s`` [m/s] from a
    direction not known (:func:`wind_speed_covariance`)."""
    out = np.zeros((3, 3))
    wind_speed_covariance(np.ascontiguousarray(x, dtype=np.float64), float(speed_m_s),
                          float(model.ea_n), float(model.reference_height_m),
                          float(model.shear_exponent), float(model.min_height_m),
                          int(model.steps), out)
    return out
