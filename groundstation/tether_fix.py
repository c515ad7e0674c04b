"""The tether fix: where the UAV is, from what the winch measures, through the ground
station's own tether model (docs/estimation.md §10).

Inputs: the paid-out (unstretched) length ``L`` [m] (the drum's encoder), the tension at the
exit ``T0`` [N] (the load cell) and the direction the tether leaves the fairlead, azimuth
``psi`` and elevation ``eps`` [rad] (the guide arm's encoders). The model is an elastic line
under a uniform load per metre ``f`` (its weight, here ``(0, 0, -w)``): its tension vector
at arc length ``s`` from the exit is ``T(s) = T0 e0 - f s`` (``e0`` the exit direction), so
with ``u = -f/|f|`` the load's "up", ``V = T0 e0 . u``, ``H e_h = T0 e0 - V u``,
``a = H/|f|``:

    p(L) = e_h a (asinh((V + |f| L)/H) - asinh(V/H))
         + u (sqrt(H^2 + (V + |f| L)^2) - sqrt(H^2 + V^2)) / |f|
         + (H e_h L + u (V L + |f| L^2 / 2)) / EA

When the exit angle cannot be told from flat (``eps`` below ``ground_elevation_rad``) the
line lies on the ground for a length ``L_g`` (frictionless: the tension along it is
``T0``) and hangs from there with its lowest point at the touchdown, ``a = T0/w``. With the
UAV's height ``z`` as the vehicle reports it, the hanging part is ``s = sqrt(z^2 + 2 a z)``
long and ``a acosh(1 + z/a)`` wide, so the UAV is at most ``L - s + a acosh(1 + z/a)`` out
along the azimuth (the line straight on the ground; lying in curves it ends nearer). A line
pulling ``ground_straight_tension_n`` or more (the winch's ground pre-tension) lies
straight: the fix is that end; a slacker one's fix is the reported distance kept below it,
on the azimuth. It says nothing of the
height (its vertical variance is ``ground_vertical_sigma_m^2``) and the reported height's
uncertainty enters its horizontal.
Without a reported height, the fix is the end of the line all on the ground (a vehicle on
the ground), and the spread of the other touchdowns (``L_g`` uniform in [0, L]) about it
is its covariance.

The covariance is the measurement noises propagated through the model (central differences
in ``L``, ``T0``, ``psi``, ``eps`` and the weight per metre, whose standard deviation covers
its distance to the winder's estimate: :meth:`TetherFixer.weight`), the wind's share (a horizontal
drag load of ``design_wind_m_s`` on the line from any direction, which the windless model
ignores), the ground regime's spread and a floor. It grows where the fix is weak: a long or
slack line (``T0`` small: the shape depends strongly on it), the line near the vertical (the
azimuth's lever vanishes, the elevation's does not), the line on the ground, strong wind.

Pure arithmetic, no I/O; ``Winch`` calls :meth:`TetherFixer.fix` at ``rate_hz``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from tuavdefs.component_link import TETHER_FIX_RATE_HZ
from tuavdefs.jit import njit
from tuavdefs.paramspec import Params, quantity

Vec3 = tuple[float, float, float]
Cov3 = tuple[tuple[float, float, float], tuple[float, float, float],
             tuple[float, float, float]]

#: Ground-contact lengths the ground regime averages over (fractions of L).
_GROUND_NODES = (0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)


@dataclass(frozen=True)
class TetherFixParams(Params):
    """The ground station's belief about its tether sensors and how to report the fix."""

    enabled: bool = quantity(True, "", "compute the fix and send it to the vehicle")
    rate_hz: float = quantity(TETHER_FIX_RATE_HZ, "Hz", "fix rate (of the winch's encoder frames, "
                              "simulated time)", gt=0, le=50)
    angle_noise_rad: float = quantity(
        1.5e-3, "rad", "white noise of each exit angle (the arm's play, the encoder)", ge=0)
    angle_bias_rad: float = quantity(
        3.0e-3, "rad", "uncertainty of each exit angle's zero (mounting; not estimated)",
        ge=0)
    tension_noise_n: float = quantity(0.05, "N", "load-cell noise and offset", ge=0)
    tension_noise_fraction: float = quantity(0.02, "1", "load-cell scale error", ge=0)
    length_noise_m: float = quantity(0.02, "m", "paid-out length error (drum layers, "
                                     "slip)", ge=0)
    weight_uncertainty_fraction: float = quantity(
        0.03, "1", "uncertainty of the weight per metre the winder estimates (of the "
        "belief's, without an estimate); the weight the fix uses is further off it by "
        "up to weight_band_fraction, which its covariance adds (docs/estimation.md §10)",
        ge=0)
    weight_band_fraction: float = quantity(
        0.1, "1", "the winder's estimate of the weight per metre is used only for its part "
        "beyond this fraction off the belief (within it the belief, which is exact when "
        "the line is as designed, holds)", ge=0)
    weight_height_sigma_m: float = quantity(
        0.3, "m", "the error of the vehicle's reported height that the winder's weight "
        "estimate inherits (its bias: the estimate's low-pass takes out the noise); the "
        "band widens to the weight error this makes (weight_spread)", ge=0)
    design_wind_m_s: float = quantity(
        3.0, "m/s", "the wind on the line the covariance allows for (its drag bends the "
        "line, which the windless model ignores), as blowing at wind_reference_height_m",
        ge=0)
    wind_reference_height_m: float = quantity(
        10.0, "m", "the height at which design_wind_m_s blows (the meteorological 10 m)",
        gt=0)
    wind_shear_exponent: float = quantity(
        1.0 / 7.0, "1", "the design wind's power-law profile, U(z) = U_ref (z/z_ref)^alpha "
        "(1/7: open terrain; 0: uniform)", ge=0, le=1)
    wind_min_height_m: float = quantity(
        1.0, "m", "heights below this take the profile's wind at this height", gt=0)
    wind_steps: int = quantity(
        32, "1", "steps of the line's integration under the wind's drag (midpoint rule)",
        ge=4, le=1000)
    air_density_kg_m3: float = quantity(1.225, "kg/m^3", "air density", gt=0)
    drag_coeff: float = quantity(1.2, "1", "the line's drag coefficient normal to it, on its "
                                 "diameter", ge=0)
    ground_elevation_rad: float = quantity(
        0.03, "rad", "an exit elevation below this is taken as the line lying on the ground "
        "at the exit (or leaving it flat: the ground model covers both)", ge=0)
    ground_straight_tension_n: float = quantity(
        0.15, "N", "line on the ground: a pull at the exit of at least this (the winch's "
        "ground pre-tension) is taken as the line lying straight along the ground, the fix "
        "its end; a slacker line may lie in curves: the fix is then the reported distance "
        "held below that end", ge=0)
    suspended_min_tension_n: float = quantity(
        0.05, "N", "a line leaving the exit above the ground needs at least this tension "
        "for a fix (the load cell's noise: a pull it cannot tell from nothing says nothing "
        "of the shape, which the model would take for a line hanging straight down from a "
        "vehicle above the winder)", ge=0)
    reported_height_sigma_m: float = quantity(
        1.0, "m", "line on the ground: the uncertainty of the UAV's height as the vehicle "
        "reports it", gt=0)
    ground_vertical_sigma_m: float = quantity(
        10.0, "m", "line on the ground: the fix's vertical standard deviation (it takes the "
        "height from the vehicle: no information on it)", gt=0)
    min_sigma_m: float = quantity(0.02, "m", "floor of each axis's standard deviation",
                                  gt=0)
    max_age_s: float = quantity(
        0.1, "s", "no fix when the exit angle or the tension is older than this against "
        "the encoder (winch clock)", gt=0)


class TetherFix(NamedTuple):
    """A fix: the UAV's tether attachment position [m] (z-up frame, origin at the exit), its
    covariance [m^2], the winch's sample time [ms] (full, unwrapped), whether the line was
    taken as lying on the ground at the exit."""

    pos_m: Vec3
    cov_m2: Cov3
    sample_time_ms: int
    on_ground: bool


def line_end(length_m: float, t0_n: float, azimuth_rad: float, elevation_rad: float,
             load_n_m: Vec3, ea_n: float) -> Vec3:
    """The far end [m] of an elastic line of unstretched length ``length_m`` leaving the
    origin in the direction (``azimuth_rad``, ``elevation_rad``) with tension ``t0_n`` [N]
    there, under the uniform load ``load_n_m`` [N/m] (module docstring)."""
    ce = math.cos(elevation_rad)
    e0 = (ce * math.cos(azimuth_rad), ce * math.sin(azimuth_rad), math.sin(elevation_rad))
    fx, fy, fz = load_n_m
    fm = math.sqrt(fx * fx + fy * fy + fz * fz)
    L = length_m
    tx, ty, tz = t0_n * e0[0], t0_n * e0[1], t0_n * e0[2]
    stretch = 1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n) else 0.0
    if fm <= 0.0:
        k = L * (1.0 + t0_n * stretch)
        return (e0[0] * k, e0[1] * k, e0[2] * k)
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


@njit
def _line_load(z: float, ax: float, ay: float, az: float, tn: float, ux: float, uy: float,
               drag: float, zr: float, shear: float, zmin: float, w: float
               ) -> tuple[float, float, float]:
    """The load per metre [N/m] on the line at height ``z`` [m] with tangent (``ax``,
    ``ay``, ``az``)/``tn``: its weight ``w`` [N/m] and the drag ``drag |U_n| U_n`` of the
    wind (``ux``, ``uy``) [m/s] at ``zr`` [m], sheared as ``(max(z, zmin)/zr)^shear``,
    ``U_n`` its part normal to the line (:func:`line_end_in_wind`)."""
    k = (max(z, zmin) / zr) ** shear
    wx, wy = ux * k, uy * k
    along = (wx * ax + wy * ay) / (tn * tn)
    nx, ny, nz = wx - along * ax, wy - along * ay, -along * az
    c = drag * math.sqrt(nx * nx + ny * ny + nz * nz)
    return (c * nx, c * ny, c * nz - w)


@njit
def _line_end_in_wind(length_m: float, t0_n: float, azimuth_rad: float,
                      elevation_rad: float, w_n_m: float, ea_n: float, ux: float,
                      uy: float, drag_n_s2_m3: float, reference_height_m: float,
                      shear_exponent: float, min_height_m: float, steps: int
                      ) -> tuple[float, float, float]:
    """:func:`line_end_in_wind` in scalars, compiled (each fix integrates the line five
    times for its covariance)."""
    ce = math.cos(elevation_rad)
    t0 = max(t0_n, 1e-9)
    tx = t0 * ce * math.cos(azimuth_rad)
    ty = t0 * ce * math.sin(azimuth_rad)
    tz = t0 * math.sin(elevation_rad)
    stretch = 1.0 / ea_n if ea_n > 0.0 and math.isfinite(ea_n) else 0.0
    drag = drag_n_s2_m3 if (ux != 0.0 or uy != 0.0) and drag_n_s2_m3 > 0.0 else 0.0
    px = py = pz = 0.0
    ds = max(length_m, 0.0) / steps
    for _ in range(steps):
        tn = math.sqrt(tx * tx + ty * ty + tz * tz)
        fx, fy, fz = _line_load(pz, tx, ty, tz, tn, ux, uy, drag, reference_height_m,
                                shear_exponent, min_height_m, w_n_m)
        h = 0.5 * ds * (1.0 / tn + stretch)
        mx, my, mz = tx - 0.5 * ds * fx, ty - 0.5 * ds * fy, tz - 0.5 * ds * fz
        mn = math.sqrt(mx * mx + my * my + mz * mz)
        if mn <= 1e-12:
            break
        gx, gy, gz = _line_load(pz + h * tz, mx, my, mz, mn, ux, uy, drag,
                                reference_height_m, shear_exponent, min_height_m, w_n_m)
        k = ds * (1.0 / mn + stretch)
        px, py, pz = px + k * mx, py + k * my, pz + k * mz
        tx, ty, tz = tx - ds * gx, ty - ds * gy, tz - ds * gz
    return (px, py, pz)


def line_end_in_wind(length_m: float, t0_n: float, azimuth_rad: float,
                     elevation_rad: float, w_n_m: float, ea_n: float,
                     wind_m_s: tuple[float, float], drag_n_s2_m3: float,
                     reference_height_m: float, shear_exponent: float,
                     min_height_m: float, steps: int) -> Vec3:
    """The far end [m] of the elastic line of :func:`line_end` under its weight ``w_n_m``
    [N/m] and the drag of a horizontal wind ``wind_m_s`` [m/s] (as blowing at
    ``reference_height_m`` [m]; at height ``z`` it is ``(max(z, min_height_m) /
    reference_height_m)^shear_exponent`` times that), integrated from the exit over
    ``steps`` midpoint steps. The drag per metre is ``drag_n_s2_m3 |U_n| U_n``
    (``drag_n_s2_m3`` = rho C_d d / 2 [N s^2/m^3]) with ``U_n`` the wind's part normal to
    the line (the cross-flow principle: a cylinder feels only the wind across it)."""
    return _line_end_in_wind(float(length_m), float(t0_n), float(azimuth_rad),
                             float(elevation_rad), float(w_n_m), float(ea_n),
                             float(wind_m_s[0]), float(wind_m_s[1]), float(drag_n_s2_m3),
                             float(reference_height_m), float(shear_exponent),
                             float(min_height_m), int(steps))


def _outer(a: Vec3, b: Vec3, k: float, acc: list[list[float]]) -> None:
    for i in range(3):
        for j in range(3):
            acc[i][j] += k * a[i] * b[j]


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


class TetherFixer:
    """The fix from (length, tension, exit angles) with the ground station's tether
    beliefs: weight per metre ``w_n_m`` [N/m], axial stiffness ``ea_n`` [N], diameter
    ``diameter_m`` [m] (for the wind's drag)."""

    def __init__(self, params: TetherFixParams, w_n_m: float, ea_n: float,
                 diameter_m: float) -> None:
        self.p = params
        self.w = float(w_n_m)
        self.ea = float(ea_n)
        #: the line's drag per metre per (m/s)^2 of wind across it [N s^2/m^3]
        self.drag = 0.5 * params.air_density_kg_m3 * params.drag_coeff * diameter_m
        #: the design wind's drag per metre of line [N/m]
        self.q_wind = self.drag * params.design_wind_m_s ** 2

    def _end(self, L: float, T: float, az: float, el: float, w: float,
             wind: tuple[float, float] = (0.0, 0.0), on_ground: bool = False,
             ground_fraction: float = 0.0, height_m: float | None = None) -> Vec3:
        load = (wind[0], wind[1], -w)
        if not on_ground:
            return line_end(L, T, az, el, load, self.ea)
        c, s = math.cos(az), math.sin(az)
        if height_m is not None:
            z = max(height_m, 0.0)
            a = T / w
            hang = min(math.sqrt(z * z + 2.0 * a * z), L)
            d = L - hang + a * math.acosh(1.0 + z / a) if a > 0.0 else L - hang
            # the wind's drag blows the hanging part sideways by about its share of the
            # load over its length
            k = hang / math.hypot(w, 1e-12)
            return (c * d + wind[0] * k, s * d + wind[1] * k, z)
        lg = ground_fraction * L
        top = line_end(L - lg, T, az, 0.0, load, self.ea)
        k = lg * (1.0 + T / self.ea if self.ea > 0 else 1.0)
        return (c * k + top[0], s * k + top[1], top[2])

    def weight_spread(self, length_m: float, tension_n: float, height_m: float | None
                      ) -> float:
        """How far [N/m] the winder's weight estimate may be off for the error
        ``weight_height_sigma_m`` of the reported height ``height_m`` [m] it is computed
        with: the estimate is ``w = 2 T (z - L sin(el)) / (L^2 - z^2)`` (the exit tension
        ``tension_n`` [N], the paid-out ``length_m`` [m]; ``groundstation.lbar``), so
        ``dw/dz = 2 (T + w z) / (L^2 - z^2)``, which grows without bound as the line
        straightens (z -> L: a steep, taut line says little of its weight). 0 without a
        height; infinite for a line no longer than the height."""
        if height_m is None or not math.isfinite(height_m) or height_m <= 0.0:
            return 0.0
        den = length_m * length_m - height_m * height_m
        if den <= 0.0:
            return math.inf
        return (2.0 * (max(tension_n, 0.0) + self.w * height_m) / den
                * self.p.weight_height_sigma_m)

    def weight(self, w_n_m: float | None = None, spread_n_m: float = 0.0
               ) -> tuple[float, float]:
        """(the weight per metre the fix uses [N/m], its standard deviation [N/m]) given
        the winder's estimate ``w_n_m`` [N/m] (None or not positive: none) and how far it
        may be off by its geometry, ``spread_n_m`` [N/m] (:meth:`weight_spread`). The fix
        uses the belief moved to within a band of the estimate, the larger of
        ``weight_band_fraction`` of the belief (the estimate wanders on a line as designed,
        which the belief then fixes exactly) and ``spread_n_m``; the weight used is thus
        off the estimate by a known ``w - w_hat``, and the estimate is off the truth by
        about ``weight_uncertainty_fraction``: the standard deviation is
        ``hypot(fraction w, w - w_hat)`` (docs/estimation.md §10)."""
        w = self.w
        frac = self.p.weight_uncertainty_fraction
        if w_n_m is None or not w_n_m > 0.0 or not math.isfinite(w_n_m):
            return w, frac * w
        band = max(self.p.weight_band_fraction * w, spread_n_m)
        off = float(w_n_m) - w
        w += math.copysign(max(abs(off) - band, 0.0), off)
        # the central differences take w -+ sigma: kept to half the weight
        return w, min(math.hypot(frac * w, w - float(w_n_m)), 0.5 * w)

    def weight_n_m(self, w_n_m: float | None) -> float:
        """The weight per metre [N/m] the fix uses (:meth:`weight`'s first value)."""
        return self.weight(w_n_m)[0]

    def suspended_end(self, length_m: float, tension_n: float, azimuth_rad: float,
                      elevation_rad: float, w_n_m: float | None = None) -> Vec3:
        """The far end [m] of the line taken as hanging clear of the ground from the exit
        (the fix's mean for a suspended line, without its covariance: cheap enough for
        every winder period). An elevation below the horizontal is taken as level: where
        part of the line lies on the ground the true end is no nearer than this (the part
        lying flat is straight), so as a distance it errs short, never long."""
        return line_end(max(length_m, 0.0), max(tension_n, 1e-3), azimuth_rad,
                        max(elevation_rad, 0.0), (0.0, 0.0, -self.weight_n_m(w_n_m)),
                        self.ea)

    def on_ground(self, elevation_rad: float) -> bool:
        """Whether an exit elevation [rad] is taken as the line lying on the ground at the
        exit (``ground_elevation_rad``): the fix's ground regime."""
        return elevation_rad < self.p.ground_elevation_rad

    def readable(self, tension_n: float, elevation_rad: float) -> bool:
        """Whether a fix can be made of a tension [N] and exit elevation [rad]: a line on
        the ground always, a suspended one only with at least ``suspended_min_tension_n``
        (NaN: no)."""
        return self.on_ground(elevation_rad) or tension_n >= self.p.suspended_min_tension_n

    def position(self, length_m: float, tension_n: float, azimuth_rad: float,
                 elevation_rad: float, reported_m: Vec3 | None = None,
                 w_n_m: float | None = None) -> tuple[Vec3, Cov3, bool]:
        """(position [m], covariance [m^2], on the ground) of the line's far end;
        ``reported_m`` [m] the UAV's position as the vehicle reports it (None: unknown),
        used when the line lies on the ground, and its height for how far the weight
        estimate may be off (:meth:`weight_spread`); ``w_n_m`` [N/m] the line's weight per
        metre as estimated (the winder's, docs/control.md §3), used beyond
        ``weight_band_fraction`` off the belief (None: the belief)."""
        uav_height_m = reported_m[2] if reported_m is not None else None
        p = self.p
        L = max(length_m, 0.0)
        T = max(tension_n, 1e-3)
        w, sigma_w = self.weight(w_n_m, self.weight_spread(L, T, uav_height_m))
        az, el = azimuth_rad, elevation_rad
        ground = self.on_ground(el)
        if ground:
            el = 0.0
        acc = [[0.0] * 3 for _ in range(3)]
        z_known = ground and uav_height_m is not None and math.isfinite(uav_height_m)
        zh = uav_height_m if z_known else None
        if z_known:
            mean = self._end(L, T, az, el, w, on_ground=True, height_m=zh)
            hi = self._end(L, T, az, el, w, on_ground=True,
                           height_m=zh + p.reported_height_sigma_m)
            lo = self._end(L, T, az, el, w, on_ground=True,
                           height_m=zh - p.reported_height_sigma_m)
            d = (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1]), 0.0)
            _outer(d, d, 1.0, acc)
            acc[2][2] += p.ground_vertical_sigma_m ** 2
            # the line straight along the ground is the farthest the UAV can be; a slack
            # line may lie in curves and end nearer: then the reported distance is kept
            # below that bound (the fix must not follow the winch's own pay-out outward)
            out = math.hypot(mean[0], mean[1])
            rep = math.hypot(reported_m[0], reported_m[1])
            if rep < out and out > 0.0 and p.ground_straight_tension_n > T:
                k = rep / out
                mean = (mean[0] * k, mean[1] * k, mean[2])
        elif ground:
            # the line all on the ground to a vehicle on the ground at its end (where a
            # line lying out ends at take-off and landing), the spread of the other
            # touchdowns about it as the covariance
            ends = [self._end(L, T, az, el, w, on_ground=True, ground_fraction=f)
                    for f in _GROUND_NODES]
            n = len(ends)
            mean = ends[-1]
            for e in ends:
                d = _sub(e, mean)
                _outer(d, d, 1.0 / n, acc)
        else:
            mean = self._end(L, T, az, el, w)

        def at(dL: float = 0.0, dT: float = 0.0, daz: float = 0.0, delv: float = 0.0,
               dw: float = 0.0, wind: tuple[float, float] = (0.0, 0.0)) -> Vec3:
            e = max(el + delv, 0.0) if ground else el + delv
            return self._end(max(L + dL, 0.0), max(T + dT, 1e-3), az + daz, e,
                             w + dw, wind, ground, 0.5, zh)

        sigma_angle = math.hypot(p.angle_noise_rad, p.angle_bias_rad)
        sigma_t = math.hypot(p.tension_noise_n, p.tension_noise_fraction * T)
        for kw, sigma in (("dL", p.length_noise_m), ("dT", sigma_t), ("daz", sigma_angle),
                          ("delv", sigma_angle), ("dw", sigma_w)):
            if sigma <= 0.0:
                continue
            hi, lo = at(**{kw: sigma}), at(**{kw: -sigma})
            d = (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1]), 0.5 * (hi[2] - lo[2]))
            _outer(d, d, 1.0, acc)
        if self.q_wind > 0.0 and ground:
            base = at()
            c, s = math.cos(az), math.sin(az)
            for wx, wy in ((c, s), (-s, c)):     # along the line's azimuth, and across
                d = _sub(at(wind=(self.q_wind * wx, self.q_wind * wy)), base)
                _outer(d, d, 0.5, acc)
        elif self.q_wind > 0.0:
            # the design wind from the four directions along and across the line's azimuth,
            # its drag normal to the line and sheared with height (module docstring)
            u = p.design_wind_m_s
            c, s = math.cos(az), math.sin(az)
            args = (L, T, az, el, w, self.ea)
            shape = (self.drag, p.wind_reference_height_m, p.wind_shear_exponent,
                     p.wind_min_height_m, p.wind_steps)
            base = line_end_in_wind(*args, (0.0, 0.0), *shape)
            for wx, wy in ((c, s), (-c, -s), (-s, c), (s, -c)):
                d = _sub(line_end_in_wind(*args, (u * wx, u * wy), *shape), base)
                _outer(d, d, 0.25, acc)
        floor = p.min_sigma_m ** 2
        for i in range(3):
            acc[i][i] += floor
        cov: Cov3 = tuple(tuple(0.5 * (acc[i][j] + acc[j][i]) for j in range(3))
                          for i in range(3))  # type: ignore[assignment]
        return mean, cov, ground  # type: ignore[return-value]
