"""The tether fix: where the UAV is, from what the winch measures, through the ground
station's own tether model (docs/estimation.md §10, §11).

Inputs: the paid-out (unstretched) length ``L`` [m] (the drum's encoder), the tension at the
exit ``T0`` [N] (the load cell) and the direction the tether leaves the fairlead, azimuth
``psi`` and elevation ``eps`` [rad] (the guide arm's encoders); and what bends the line as
the station is given it: the line's weight per metre (the winder's estimate, within a band
of the belief: :meth:`TetherFixer.weight`) and the wind (an estimate with its covariance, or
none: calm air, with the design wind in the covariance; the winch gives it the vehicle's
own estimate, low-passed, with ``wind_source = "vehicle"``: :class:`ReportedWind`).

A line leaving the exit above the ground is the model of :mod:`tuavdefs.line_shape`: the
static elastic line under its weight and the cross-flow drag of the wind (the closed-form
catenary in calm air), with the drag per metre of the controllers' tether parameters
(normal drag coefficient on the diameter, in air).

When the exit angle cannot be told from flat (``eps`` below ``ground_elevation_rad``) the
line lies on the ground for a length ``L_g`` (frictionless: the tension along it is
``T0``) and hangs from there with its lowest point at the touchdown, ``a = T0/w``. With the
UAV's height ``z`` as the vehicle reports it, the hanging part is ``s = sqrt(z^2 + 2 a z)``
long and ``a acosh(1 + z/a)`` wide, so the UAV is at most ``L - s + a acosh(1 + z/a)`` out
along the azimuth (the line straight on the ground; lying in curves it ends nearer). A line
pulling ``ground_straight_tension_n`` or more (the winch's ground pre-tension) lies
straight: the fix is that end; a slacker one's fix is the reported distance kept below it,
on the azimuth. It says nothing of the height (its vertical variance is
``ground_vertical_sigma_m^2``) and the reported height's uncertainty enters its horizontal.
Without a reported height, the fix is the end of the line all on the ground (a vehicle on
the ground), and the spread of the other touchdowns (``L_g`` uniform in [0, L]) about it
is its covariance. The ground regime's model is windless whatever wind is given (a
uniform horizontal load of the design wind in its covariance).

The covariance is every uncertain input's standard deviation propagated through the model:
for a suspended line ``sum_k (J_k sigma_k)(J_k sigma_k)'`` over the length, tension and
angle noises, the arm's biases, the weight per metre (whose standard deviation covers its
distance to the winder's estimate) and the drag per metre (central differences over each
sigma: :func:`tuavdefs.line_shape.end_differences`), plus the wind's share (its Gaussian
error through an eight-point rule; without a wind given, the design wind from the four
directions along and across the line), plus a floor. It grows where the fix is weak: a long
or slack line, the line near the vertical (the azimuth's lever vanishes, the elevation's
does not), the line on the ground, strong or poorly known wind. What the static model cannot
see, the line's sway, the winch adds from the fix's own recent scatter about the vehicle's
reported position (:class:`FixScatter`).

Pure arithmetic, no I/O; ``Winch`` calls :meth:`TetherFixer.position` at ``rate_hz``.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from groundstation.lbar import line_weight_n_m
from tuavdefs import line_shape
from tuavdefs.component_link import TETHER_FIX_RATE_HZ
from tuavdefs.line_shape import Column, LineModel, line_end
from tuavdefs.params import EnvironmentParams, TetherParams
from tuavdefs.paramspec import Params, quantity

Vec3 = tuple[float, float, float]
Cov3 = tuple[tuple[float, float, float], tuple[float, float, float],
             tuple[float, float, float]]

#: Ground-contact lengths the ground regime averages over (fractions of L).
_GROUND_NODES = (0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)


class WindSource(enum.Enum):
    """Which wind the fix's model is given (``TetherFixParams.wind_source``)."""

    NONE = "none"           #: calm air; the design wind in the covariance
    VEHICLE = "vehicle"     #: the vehicle's own estimate (its WIND), low-passed


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
        3.0, "m/s", "without a wind given: the wind on the line the covariance allows for "
        "(its drag bends the line, which the calm model ignores), as blowing at "
        "wind_reference_height_m from any direction", ge=0)
    wind_reference_height_m: float = quantity(
        10.0, "m", "the height at which a wind given and design_wind_m_s blow (the "
        "meteorological 10 m)", gt=0)
    wind_shear_exponent: float = quantity(
        1.0 / 7.0, "1", "the wind's power-law profile, U(z) = U_ref (z/z_ref)^alpha "
        "(1/7: open terrain; 0: uniform)", ge=0, le=1)
    wind_min_height_m: float = quantity(
        1.0, "m", "heights below this take the profile's wind at this height", gt=0)
    wind_steps: int = quantity(
        32, "1", "steps of the line's integration under the wind's drag (classical RK4)",
        ge=4, le=1000)
    drag_uncertainty_fraction: float = quantity(
        0.25, "1", "uncertainty of the line's drag per metre (its normal drag coefficient "
        "on its diameter: 1.0-1.3 for a cylinder across the flow at the line's Reynolds "
        "numbers)", ge=0)
    given_wind_sigma_m_s: float = quantity(
        1.0, "m/s", "the standard deviation of each horizontal component of a wind the fix "
        "is given without its covariance", ge=0)
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
    scatter_window_s: float = quantity(
        5.0, "s", "the window of the fix's own recent scatter about the vehicle's reported "
        "position (FixScatter: the line's sway and axial waves, which the static model "
        "does not see)", gt=0)
    scatter_gain: float = quantity(
        4.0, "1", "the scatter's covariance is added this many times to a suspended fix's "
        "(the sway's errors are correlated over 0.3-1.4 s while the fixes are fused at "
        "rate_hz as white; 0: no scatter allowance)", ge=0)
    scatter_min_fixes: int = quantity(
        10, "1", "fixes in the window before their scatter is counted", ge=3)
    wind_source: str = quantity(
        "vehicle", "1", "the wind the fix's model is given (WindSource): vehicle (the "
        "vehicle's own estimate, its WIND_COV on the component link, low-passed, with its "
        "covariance: ReportedWind; a real line feels the wind's drag) or none (calm air, the "
        "design wind in the covariance: right only where the line feels no drag, as the "
        "plant's catenary truth)",
        choices=tuple(m.value for m in WindSource))
    wind_filter_s: float = quantity(
        20.0, "s", "the time constant of the low-pass on the vehicle's wind reports (its "
        "estimate carries the position loop's and the turbulence's seconds-long swings)",
        gt=0)
    wind_max_speed_m_s: float = quantity(
        3.0, "m/s", "a vehicle wind reported while the vehicle's reported horizontal speed is "
        "above this is not taken (without the drag fusion the vehicle's estimate is its "
        "position loop's disturbance read as drag, which a manoeuvre's unmodelled forces "
        "pollute; the shipped circles fly at 2 m/s: with the wind's covariance and the "
        "weight's drag bias taken off, circle-windy-gnss's estimate is 0.45 m off given "
        "the wind while circling, 0.95 m with a 1 m/s gate, which ages the wind out)",
        gt=0)
    reported_wind_sigma_m_s: float = quantity(
        2.0, "m/s", "the standard deviation of each horizontal component of the vehicle's "
        "reported wind (ReportedWind) as the wind on the line, beside the reports' own "
        "scatter: without the drag fusion it is the position loop's disturbance read as "
        "drag, in which the tether's model error shows as wind (4.1 m/s reported in "
        "hover-gnss-loss's 2.4 m/s); the gusts along the line, the profile (the tight "
        "fusion's gust_sigma_m_s is 2 m/s for the same reasons). At 1 m/s a climb's fixes "
        "on the lumped line were 0.5-0.8 m off at a NEES of 38, the calm fix's design-wind "
        "allowance having held them", ge=0)
    wind_max_age_s: float = quantity(
        5.0, "s", "a vehicle wind not reported for this long is no longer given (WIND "
        "comes at 1 Hz)", gt=0)


class TetherFix(NamedTuple):
    """A fix: the UAV's tether attachment position [m] (z-up frame, origin at the exit), its
    covariance [m^2], the winch's sample time [ms] (full, unwrapped), whether the line was
    taken as lying on the ground at the exit."""

    pos_m: Vec3
    cov_m2: Cov3
    sample_time_ms: int
    on_ground: bool


class ReportedWind:
    """The vehicle's wind estimate as the fix takes it (docs/estimation.md §10, *The
    wind*): each report (the air's velocity at the vehicle [m/s], z-up, the vehicle's
    reported height [m]) brought to ``wind_reference_height_m`` by the fix's own profile,
    ``U_ref = U(z) (z_ref / max(z, z_min))^alpha``, and low-passed over ``wind_filter_s``
    (first order, on the reports' own times, its first reports weighted equally: their
    mean), their scatter about it kept beside it for the wind's covariance
    (:meth:`covariance_m2_s2`). Nothing onboard is the truth: this is what
    the vehicle says (ArduPilot's WIND), as a ground station would hear it."""

    def __init__(self, params: TetherFixParams) -> None:
        self.p = params
        self._wind: tuple[float, float] | None = None
        #: the reports' low-passed scatter about the low-passed wind [m^2/s^2] (2 x 2)
        self._scatter = np.zeros((2, 2))
        #: reports taken since the filter (re)started
        self._n = 0
        self._t_s = -math.inf

    def reset(self) -> None:
        """Forget the wind (a new flight, a reboot)."""
        self._wind = None
        self._scatter = np.zeros((2, 2))
        self._n = 0
        self._t_s = -math.inf

    def report(self, t_s: float, wind_m_s: Vec3, height_m: float | None,
               speed_m_s: float = 0.0) -> None:
        """A report at ``t_s`` [s] of the wind ``wind_m_s`` [m/s] (z-up) at the vehicle's
        height ``height_m`` [m] (None: taken at the reference height) while it moves at
        the horizontal speed ``speed_m_s`` [m/s] it reports; not finite, or the speed
        above ``wind_max_speed_m_s``: ignored (the wind given ages out); a time going back
        starts the filter again."""
        wx, wy = float(wind_m_s[0]), float(wind_m_s[1])
        if not (math.isfinite(wx) and math.isfinite(wy) and math.isfinite(t_s)):
            return
        p = self.p
        if not speed_m_s <= p.wind_max_speed_m_s:
            return
        if height_m is not None and math.isfinite(height_m):
            z = max(height_m, p.wind_min_height_m)
            k = (p.wind_reference_height_m / z) ** p.wind_shear_exponent
            wx, wy = wx * k, wy * k
        if self._wind is None or t_s < self._t_s:
            self._wind = (wx, wy)
            self._scatter = np.zeros((2, 2))
            self._n = 1
        else:
            # equal weights over the first reports (their mean and variance, Welford's),
            # then the first-order lag: a first report is not the whole past (a vehicle's
            # disturbance estimate starts from zero; weighted as a 20 s history it held the
            # wind given at 1.4 of 7.6 m/s for the first 5 s of a 9 m/s hover)
            self._n += 1
            a = max(1.0 - math.exp(-(t_s - self._t_s) / p.wind_filter_s), 1.0 / self._n)
            ox, oy = self._wind
            d = np.array((wx - ox, wy - oy))
            self._wind = (ox + a * d[0], oy + a * d[1])
            # the exponentially weighted covariance of the reports about their mean
            self._scatter = (1.0 - a) * (self._scatter + a * np.outer(d, d))
        self._t_s = t_s

    def wind_m_s(self, t_s: float) -> tuple[float, float] | None:
        """The low-passed wind at the reference height [m/s] (horizontal), None without a
        report within ``wind_max_age_s`` of ``t_s`` [s]."""
        if self._wind is None or not 0.0 <= t_s - self._t_s <= self.p.wind_max_age_s:
            return None
        return self._wind

    def covariance_m2_s2(self) -> np.ndarray:
        """The 2 x 2 covariance [m^2/s^2] of the wind given (:meth:`wind_m_s`):
        ``reported_wind_sigma_m_s`` on each component plus the reports' own scatter about
        their low-passed mean (a vehicle estimate swinging by metres per second, as its
        position loop's disturbance does while the line lifts off the ground or the
        turbulence is strong, says its mean is not the wind on the line to better than
        that)."""
        return np.eye(2) * self.p.reported_wind_sigma_m_s ** 2 + self._scatter


class FixScatter:
    """The fix's own recent scatter (docs/estimation.md §10, *The line's sway*): the
    sample covariance [m^2] of the residuals ``fix - reported`` (the suspended fix less
    the position the vehicle reports) over the last ``scatter_window_s``, about their mean,
    added ``scatter_gain`` times to the fix's covariance. The static model takes the line
    as still; a swaying line moves the exit's reading, and the fix with it, by far more
    than the sensors' noise (in calm air on the lumped line 0.9 m across the line at
    17.8 m, claimed 0.54 m). The window's mean is taken off, so a slow offset (the fix's
    bias, the report's delay on a moving vehicle) does not count; the reported position
    is the vehicle's smooth estimate, so what scatters is the fix."""

    def __init__(self, params: TetherFixParams) -> None:
        self.p = params
        self._t: deque[float] = deque()
        self._r: deque[tuple[float, float, float]] = deque()

    def reset(self) -> None:
        """Forget the window (a new flight, a reboot)."""
        self._t.clear()
        self._r.clear()

    def add(self, t_s: float, pos_m: Vec3, reported_m: Vec3) -> None:
        """A suspended fix ``pos_m`` [m] at ``t_s`` [s] against the position the vehicle
        reports ``reported_m`` [m]; residuals older than the window leave it (a time
        going back clears it)."""
        if self._t and t_s < self._t[-1]:
            self.reset()
        self._t.append(t_s)
        self._r.append(_sub(pos_m, reported_m))
        start = t_s - self.p.scatter_window_s
        while self._t[0] < start:
            self._t.popleft()
            self._r.popleft()

    def covariance(self) -> np.ndarray | None:
        """The residuals' sample covariance over the window [m^2] times ``scatter_gain``,
        None with fewer than ``scatter_min_fixes`` of them or a zero gain."""
        if self.p.scatter_gain <= 0.0 or len(self._r) < self.p.scatter_min_fixes:
            return None
        r = np.array(self._r)
        return self.p.scatter_gain * np.cov(r, rowvar=False)

    def widen(self, t_s: float, pos_m: Vec3, cov_m2: Cov3, reported_m: Vec3 | None,
              on_ground: bool) -> Cov3:
        """The covariance [m^2] of the fix ``pos_m`` [m] made at ``t_s`` [s] with the
        scatter's share added (:meth:`covariance`); the fix joins the window when it is
        of a suspended line and the vehicle reports a finite position ``reported_m`` [m]
        (a fix on the ground is the reported position's own: not added, not widened)."""
        if on_ground:
            return cov_m2
        if reported_m is not None and all(math.isfinite(v) for v in reported_m):
            self.add(t_s, pos_m, reported_m)
        extra = self.covariance()
        if extra is None:
            return cov_m2
        out = np.array(cov_m2) + extra
        return tuple(tuple(float(v) for v in row) for row in out)  # type: ignore[return-value]


def _outer(a: Vec3, b: Vec3, k: float, acc: list[list[float]]) -> None:
    for i in range(3):
        for j in range(3):
            acc[i][j] += k * a[i] * b[j]


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


class TetherFixer:
    """The fix from (length, tension, exit angles) with the ground station's tether
    beliefs: weight per metre ``w_n_m`` [N/m], axial stiffness ``ea_n`` [N], diameter
    ``diameter_m`` [m] and normal drag coefficient ``normal_drag_coeff`` (for the wind's
    drag, in air of ``air_density_kg_m3`` [kg/m^3]; both default to the parameters'
    defaults, :class:`TetherParams` and :class:`EnvironmentParams`)."""

    def __init__(self, params: TetherFixParams, w_n_m: float, ea_n: float,
                 diameter_m: float,
                 normal_drag_coeff: float = TetherParams.normal_drag_coeff,
                 air_density_kg_m3: float = EnvironmentParams.air_density_kg_m3) -> None:
        self.p = params
        self.w = float(w_n_m)
        self.ea = float(ea_n)
        #: the line's drag per metre per (m/s)^2 of wind across it [N s^2/m^3]
        self.drag = line_shape.drag_per_metre(normal_drag_coeff, diameter_m,
                                              air_density_kg_m3)
        #: the line as the fix models it (the weight is replaced per fix)
        self.model = LineModel(self.w, self.drag, self.ea, params.wind_reference_height_m,
                               params.wind_shear_exponent, params.wind_min_height_m,
                               params.wind_steps)
        #: the design wind's drag per metre of line [N/m]
        self.q_wind = self.drag * params.design_wind_m_s ** 2

    @classmethod
    def for_tether(cls, params: TetherFixParams, tether: TetherParams, gravity_m_s2: float,
                   air_density_kg_m3: float = EnvironmentParams.air_density_kg_m3
                   ) -> TetherFixer:
        """The fixer on the tether parameters ``tether`` (the controllers' model's)."""
        return cls(params, tether.linear_density_kg_m * gravity_m_s2,
                   tether.axial_stiffness_n, tether.diameter_m, tether.normal_drag_coeff,
                   air_density_kg_m3)

    def _ground_end(self, L: float, T: float, az: float, w: float,
                    wind: tuple[float, float] = (0.0, 0.0), ground_fraction: float = 0.0,
                    height_m: float | None = None) -> Vec3:
        """The far end [m] of a line lying on the ground from the exit (module docstring)
        under its weight ``w`` [N/m] and the horizontal load ``wind`` [N/m]: hanging to
        the reported height ``height_m`` [m], or (None) with ``ground_fraction`` of it on
        the ground, the rest hanging from there."""
        load = (wind[0], wind[1], -w)
        c, s = math.cos(az), math.sin(az)
        if height_m is not None:
            z = min(max(height_m, 0.0), L)
            a = T / w
            if z > 0.0:
                # a line hanging to z from a touchdown at the exit has a = (L^2 - z^2)/2z:
                # one pulling harder would leave the exit rising, which the arm says it
                # does not (a dynamic line's tension, the pull of a line whose part on
                # the ground friction holds): the exit is then its touchdown, and the end
                # no farther than such a line reaches (without it, a taut line read flat
                # put the end beyond the straight line's reach, 17 m off at 10 m up)
                a = min(a, 0.5 * (L * L - z * z) / z)
            hang = math.sqrt(z * z + 2.0 * a * z)
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

    def weight_drag_bias(self, length_m: float, tension_n: float, azimuth_rad: float,
                         elevation_rad: float, wind_m_s: tuple[float, float]) -> float:
        """How far [N/m] the winder's weight estimate reads off the belief on a line bent
        by the wind ``wind_m_s`` [m/s] (at ``wind_reference_height_m``): the estimate
        (``groundstation.lbar.line_weight_n_m``) is a calm line's, and the drag changes
        the height the line reaches from the exit's tension and elevation, which it takes
        for weight. The model's line of the belief's weight in that wind, read by the same
        estimate, less the belief (0 where it says nothing). A fix given the wind takes
        this off the winder's estimate, or it would count the drag twice (in 5 m/s along
        a 29 m line the estimate read 0.40-0.54 N/m on a line of 0.33)."""
        model = self.model
        x = line_shape.inputs(max(length_m, 0.0), max(tension_n, 1e-3), azimuth_rad,
                              max(elevation_rad, 0.0), model, wind_m_s)
        top = line_shape.end(model, x)
        w = line_weight_n_m(max(tension_n, 1e-3), elevation_rad, length_m, top[2])
        return w - self.w if math.isfinite(w) else 0.0

    def weight_n_m(self, w_n_m: float | None) -> float:
        """The weight per metre [N/m] the fix uses (:meth:`weight`'s first value)."""
        return self.weight(w_n_m)[0]

    def suspended_end(self, length_m: float, tension_n: float, azimuth_rad: float,
                      elevation_rad: float, w_n_m: float | None = None,
                      wind_m_s: tuple[float, float] | None = None) -> Vec3:
        """The far end [m] of the line taken as hanging clear of the ground from the exit
        (the fix's mean for a suspended line, without its covariance: cheap enough for
        every winder period). An elevation below the horizontal is taken as level: where
        part of the line lies on the ground the true end is no nearer than this (the part
        lying flat is straight), so as a distance it errs short, never long. ``wind_m_s``
        [m/s]: the wind as :meth:`position` takes it (None: calm)."""
        model = self.model.with_weight(self.weight_n_m(w_n_m))
        return line_shape.end(model, line_shape.inputs(
            max(length_m, 0.0), max(tension_n, 1e-3), azimuth_rad, max(elevation_rad, 0.0),
            model, wind_m_s or (0.0, 0.0)))

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
                 w_n_m: float | None = None, wind_m_s: tuple[float, float] | None = None,
                 wind_cov_m2_s2: np.ndarray | None = None) -> tuple[Vec3, Cov3, bool]:
        """(position [m], covariance [m^2], on the ground) of the line's far end;
        ``reported_m`` [m] the UAV's position as the vehicle reports it (None: unknown),
        used when the line lies on the ground, and its height for how far the weight
        estimate may be off (:meth:`weight_spread`); ``w_n_m`` [N/m] the line's weight per
        metre as estimated (the winder's, docs/control.md §3), used beyond
        ``weight_band_fraction`` off the belief (None: the belief); ``wind_m_s`` [m/s] the
        horizontal wind as estimated, as blowing at ``wind_reference_height_m``, with its
        2 x 2 covariance ``wind_cov_m2_s2`` [m^2/s^2] (None: ``given_wind_sigma_m_s`` on
        each component); no wind given: calm air, the design wind from any direction in
        the covariance (a line hanging clear of the ground; on the ground the windless
        model and its allowance hold either way)."""
        uav_height_m = reported_m[2] if reported_m is not None else None
        p = self.p
        L = max(length_m, 0.0)
        T = max(tension_n, 1e-3)
        az, el = azimuth_rad, elevation_rad
        ground = self.on_ground(el)
        if wind_m_s is not None and not ground and w_n_m is not None:
            w_n_m = w_n_m - self.weight_drag_bias(L, T, az, el, wind_m_s)
        w, sigma_w = self.weight(w_n_m, self.weight_spread(L, T, uav_height_m))
        if not ground:
            mean, cov = self._suspended(L, T, az, el, w, sigma_w, wind_m_s, wind_cov_m2_s2)
            return mean, cov, False
        acc = [[0.0] * 3 for _ in range(3)]
        z_known = uav_height_m is not None and math.isfinite(uav_height_m)
        zh = uav_height_m if z_known else None
        if z_known:
            mean = self._ground_end(L, T, az, w, height_m=zh)
            hi = self._ground_end(L, T, az, w, height_m=zh + p.reported_height_sigma_m)
            lo = self._ground_end(L, T, az, w, height_m=zh - p.reported_height_sigma_m)
            d = (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1]), 0.0)
            _outer(d, d, 1.0, acc)
            acc[2][2] += p.ground_vertical_sigma_m ** 2
            # the line straight along the ground is the farthest the UAV can be; a slack
            # line may lie in curves and end nearer: then the reported distance is kept
            # below that bound (the fix must not follow the winch's own pay-out outward)
            out = math.hypot(mean[0], mean[1])
            rep = math.hypot(reported_m[0], reported_m[1])  # type: ignore[index]
            if rep < out and out > 0.0 and p.ground_straight_tension_n > T:
                k = rep / out
                mean = (mean[0] * k, mean[1] * k, mean[2])
        else:
            # the line all on the ground to a vehicle on the ground at its end (where a
            # line lying out ends at take-off and landing), the spread of the other
            # touchdowns about it as the covariance
            ends = [self._ground_end(L, T, az, w, ground_fraction=f)
                    for f in _GROUND_NODES]
            n = len(ends)
            mean = ends[-1]
            for e in ends:
                d = _sub(e, mean)
                _outer(d, d, 1.0 / n, acc)

        def at(dL: float = 0.0, dT: float = 0.0, daz: float = 0.0, dw: float = 0.0,
               wind: tuple[float, float] = (0.0, 0.0)) -> Vec3:
            return self._ground_end(max(L + dL, 0.0), max(T + dT, 1e-3), az + daz, w + dw,
                                    wind, 0.5, zh)

        sigma_angle = math.hypot(p.angle_noise_rad, p.angle_bias_rad)
        sigma_t = math.hypot(p.tension_noise_n, p.tension_noise_fraction * T)
        # (the ground's model is of a level exit: the elevation reading has no share)
        for kw, sigma in (("dL", p.length_noise_m), ("dT", sigma_t), ("daz", sigma_angle),
                          ("dw", sigma_w)):
            if sigma <= 0.0:
                continue
            hi, lo = at(**{kw: sigma}), at(**{kw: -sigma})
            d = (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1]), 0.5 * (hi[2] - lo[2]))
            _outer(d, d, 1.0, acc)
        if self.q_wind > 0.0:
            base = at()
            c, s = math.cos(az), math.sin(az)
            for wx, wy in ((c, s), (-s, c)):     # along the line's azimuth, and across
                d = _sub(at(wind=(self.q_wind * wx, self.q_wind * wy)), base)
                _outer(d, d, 0.5, acc)
        return mean, self._finish(np.array(acc)), True

    def _finish(self, acc: np.ndarray) -> Cov3:
        """The covariance [m^2]: ``acc`` with the floor on its diagonal, symmetrised."""
        acc = acc + np.eye(3) * self.p.min_sigma_m ** 2
        acc = 0.5 * (acc + acc.T)
        return tuple(tuple(float(v) for v in row) for row in acc)  # type: ignore[return-value]

    def _suspended(self, L: float, T: float, az: float, el: float, w: float, sigma_w: float,
                   wind_m_s: tuple[float, float] | None, wind_cov_m2_s2: np.ndarray | None
                   ) -> tuple[Vec3, Cov3]:
        """(the end [m], its covariance [m^2]) of the line hanging clear of the ground
        (:mod:`tuavdefs.line_shape`) in the wind given (None: calm) on the weight ``w``
        [N/m] of standard deviation ``sigma_w``: each input's standard deviation through
        the line's central differences over it, ``sum_k (J_k sigma_k)(J_k sigma_k)'``,
        the wind's through :func:`tuavdefs.line_shape.wind_covariance` (or, no wind given,
        the design wind's through :func:`~tuavdefs.line_shape.wind_speed_covariance`), and
        the floor."""
        p = self.p
        model = self.model.with_weight(w)
        x = line_shape.inputs(L, T, az, el, model, wind_m_s or (0.0, 0.0))
        sigma = np.zeros(line_shape.N_COLUMNS)
        sigma[Column.LENGTH] = p.length_noise_m
        sigma[Column.TENSION] = math.hypot(p.tension_noise_n, p.tension_noise_fraction * T)
        sigma[Column.AZIMUTH] = sigma[Column.ELEVATION] = p.angle_noise_rad
        sigma[Column.AZIMUTH_BIAS] = sigma[Column.ELEVATION_BIAS] = p.angle_bias_rad
        sigma[Column.WEIGHT] = sigma_w
        sigma[Column.DRAG] = p.drag_uncertainty_fraction * model.drag_n_s2_m3
        cols = np.zeros((3, line_shape.N_COLUMNS))
        mean = line_shape.differences(model, x, sigma, cols)
        cols *= sigma                                  # J_k sigma_k
        acc = cols @ cols.T
        if wind_m_s is None:
            acc += line_shape.wind_speed_spread(model, x, p.design_wind_m_s)
        else:
            cov = (np.eye(2) * p.given_wind_sigma_m_s ** 2 if wind_cov_m2_s2 is None
                   else np.asarray(wind_cov_m2_s2, dtype=float))
            acc += line_shape.wind_spread(model, x, cov)
        return mean, self._finish(acc)
