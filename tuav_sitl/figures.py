"""Figures of an offline run: the paper's plots, drawn from a run folder.

A run folder written by :mod:`tuav_sitl.offline` (or imported from a ``tuav-sitl up`` run by
:mod:`tuav_sitl.run_import`) holds ``timeseries.npz``, ``metrics.json`` and
``scenario.toml``. :func:`make_figures` reads it and writes one PNG per figure into its
``figures/`` sub-folder (skipping those whose series the run lacks, :data:`FIGURE_NEEDS`);
:func:`build_figures` does the drawing from the arrays and the
scenario alone and returns matplotlib :class:`~matplotlib.figure.Figure` objects (no pyplot
global state and no backend switch: a bare Figure renders with Agg when saved).
:data:`FIGURE_CAPTIONS` gives each figure's caption for the documentation.

The 3-D helpers (:func:`reference_geometry`, :func:`scene_bounds`, :func:`quad_outline`,
:class:`TetherDrawer`, ...) are shared with :mod:`tuav_sitl.animation`.

Frame: z up, x east, y north, origin at the winder's tether exit point on the ground.
Angles are stored in radians and shown in degrees.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from sitl.catenary import CatenaryRegime
from sitl.tether import Tether
from tuav_sitl.scenario import ScenarioParams
from tuavdefs.paramspec import load_toml

__all__ = [
    "DPI",
    "FIGURE_CAPTIONS",
    "FIGURE_NAMES",
    "FIGURE_NEEDS",
    "FIG_SIZE_IN",
    "ReferenceGeometry",
    "RunData",
    "TetherDrawer",
    "build_figures",
    "has_data",
    "length_error",
    "load_run",
    "make_figures",
    "missing_series",
    "quad_outline",
    "reached_indices",
    "reference_geometry",
    "save_figures",
    "scene_bounds",
    "snapshot_indices",
    "spread_instants",
]

#: Size [in] and resolution [dots per inch] of the time-series figures.
FIG_SIZE_IN = (10.0, 7.0)
DPI = 110

#: Figure name (file stem) -> caption.
FIGURE_CAPTIONS: dict[str, str] = {
    "states": (
        "State evolution: the UAV's position x, y, z, its attitude (roll, pitch, yaw, in "
        "degrees) and the paid-out tether length L over time; dashed lines are the references "
        "(position reference, attitude command, desired length L-bar)."),
    "errors": (
        "Errors over time: position error (actual minus reference) per axis, attitude error "
        "(measured minus the filtered command, yaw wrapped to +-180 deg) and tether length "
        "error L - L-bar, taken at the instants the ground station updates L-bar (between "
        "updates the logged L-bar is held while L moves on)."),
    "position_tracking": (
        "Position tracking: the UAV's x, y and z (solid) against the reference trajectory "
        "(dashed)."),
    "attitude_tracking": (
        "Attitude tracking: measured roll, pitch and yaw (solid) against the attitude command "
        "after the command filter (dashed) and the position loop's desired attitude before "
        "the filter (dotted)."),
    "path_3d": (
        "3-D path of the UAV (solid) against the reference path (dashed), with the winder at "
        "the origin, the ground plane z = 0 and the catenary tether drawn at a few instants; "
        "equal scale on all three axes."),
    "tether_length": (
        "Tether length tracking: the desired length L-bar, the paid-out length L, the "
        "straight-line distance |p| from the winder to the UAV and the altitude z; the lengths "
        "stay above the distance, which stays above the altitude."),
    "snapshots": (
        "Snapshots of the flight at four instants: the quadrotor (drawn enlarged, with its "
        "attitude; red arms at the front), the catenary tether from the winder, the path flown "
        "so far (trail), and the goal, waypoints (filled once reached) or circle to track."),
    "lyapunov": (
        "Lyapunov functions of the position loop, the attitude loop (both in the compensated "
        "errors of command-filtered backstepping) and the winder loop on a logarithmic scale "
        "over time; docs/control.md proves each decays, and §5 says when its reference "
        "counts as constant."),
    "tension_and_winder": (
        "Tether tension at the UAV (top) and at the winder drum, the winder motor torque "
        "(dotted lines: its limits, when approached) and the drum rate over time; shaded "
        "spans, if any, are "
        "times when part of the tether lies on the ground."),
    "estimate": (
        "The onboard navigation filter against the truth: its position error (estimate "
        "minus truth) per axis with the filter's own 3-sigma band, and the horizontal "
        "speed error; runs flown on the estimate only."),
}
#: The figures :func:`build_figures` draws, in order.
FIGURE_NAMES: tuple[str, ...] = tuple(FIGURE_CAPTIONS)
#: Series a figure cannot do without (all of them): a run folder imported from
#: ``tuav-sitl up`` (:mod:`tuav_sitl.run_import`) has no reference, attitude command or
#: Lyapunov functions, which stay NaN; :func:`make_figures` skips these figures there.
FIGURE_NEEDS: dict[str, tuple[str, ...]] = {
    "errors": ("ref_pos", "att_cmd"),
    "position_tracking": ("ref_pos",),
    "attitude_tracking": ("att_cmd",),
    "lyapunov": ("v_pos", "v_att", "v_win"),
    "estimate": ("est_pos", "est_pos_sigma"),
}

# Tether regimes with part of the line on the ground.
_GROUND_REGIMES = (int(CatenaryRegime.TOUCHDOWN), int(CatenaryRegime.SLACK),
                   int(CatenaryRegime.FLAT))
_AXIS_COLOURS = ("C0", "C1", "C2")
_PATH_COLOUR = "C0"
_REF_COLOUR = "k"
_TETHER_COLOUR = "#8c564b"
_UAV_COLOUR = "#d62728"
_GOAL_COLOUR = "#9467bd"
_GROUND_COLOUR = "#9acd9a"


# --------------------------------------------------------------------------------------
# Loading


@dataclass(frozen=True)
class RunData:
    """What a run folder holds: the time series, the scenario and (if present) the metrics."""

    series: dict[str, np.ndarray]
    scenario: ScenarioParams
    metrics: dict[str, Any] | None = None


def load_run(run_dir: Path) -> RunData:
    """Read ``timeseries.npz``, ``scenario.toml`` and ``metrics.json`` from ``run_dir``."""
    run_dir = Path(run_dir)
    with np.load(run_dir / "timeseries.npz") as npz:
        series = {k: np.asarray(npz[k]) for k in npz.files}
    scenario = load_toml(ScenarioParams, run_dir / "scenario.toml")
    metrics_file = run_dir / "metrics.json"
    metrics = json.loads(metrics_file.read_text()) if metrics_file.is_file() else None
    return RunData(series, scenario, metrics)


def has_data(series: Mapping[str, np.ndarray], name: str) -> bool:
    """Whether the run has the series ``name`` with at least one finite value."""
    v = series.get(name)
    return v is not None and bool(np.isfinite(np.asarray(v, dtype=float)).any())


def missing_series(series: Mapping[str, np.ndarray], name: str) -> list[str]:
    """The series the figure ``name`` needs (:data:`FIGURE_NEEDS`) that the run lacks."""
    return [k for k in FIGURE_NEEDS.get(name, ()) if not has_data(series, k)]


# --------------------------------------------------------------------------------------
# Geometry shared with the animation


@dataclass(frozen=True)
class ReferenceGeometry:
    """What the scenario asks the UAV to reach: goal or waypoints, or a circle."""

    points: np.ndarray          # (k, 3) goal or waypoints [m] (k may be 0)
    labels: tuple[str, ...]     # one per point
    circle: np.ndarray | None   # (n, 3) the circle to track [m], or None
    acceptance_m: float         # distance at which a waypoint counts as reached [m]


def reference_geometry(sc: ScenarioParams, n_circle: int = 121) -> ReferenceGeometry:
    """The goal (set-point and line), waypoints (waypoint missions) or circle of ``sc``."""
    tr = sc.trajectory
    circle = None
    if tr.kind in ("setpoint", "line"):
        points = np.array([tr.goal_m], dtype=float)
        labels: tuple[str, ...] = ("goal",)
    elif tr.kind == "waypoints":
        points = np.array([w.position_m for w in tr.waypoints], dtype=float).reshape(-1, 3)
        labels = tuple(f"WP{i + 1}" for i in range(len(points)))
    else:
        points = np.zeros((0, 3))
        labels = ()
    if tr.kind == "circle":
        a = np.linspace(0.0, 2.0 * math.pi, n_circle)
        circle = np.column_stack((tr.centre_m[0] + tr.radius_m * np.cos(a),
                                  tr.centre_m[1] + tr.radius_m * np.sin(a),
                                  np.full_like(a, tr.altitude_m)))
    return ReferenceGeometry(points, labels, circle, tr.acceptance_radius_m)


def reached_indices(series: Mapping[str, np.ndarray], geo: ReferenceGeometry,
                    metrics: Mapping[str, Any] | None = None) -> list[int]:
    """Sample indices at which the waypoints were reached in turn; shorter than the
    waypoint list if the run ended before reaching them all.

    Taken from the run's ``metrics["waypoints_reached"]`` when given, else found the way
    the mission logic decides it: the reference has come to rest on the waypoint and the
    UAV is within the acceptance radius of it (where the run has no reference, as an
    imported ``tuav-sitl up`` run: the UAV within the acceptance radius).
    """
    t = series["t"]
    if metrics and metrics.get("waypoints_reached") is not None:
        times = [float(r["t_s"]) for r in metrics["waypoints_reached"]
                 if r.get("t_s") is not None]   # None: an up run's event it could not time
        return [int(min(np.searchsorted(t, ts - 1e-6), len(t) - 1)) for ts in times]
    pos, ref = series["pos"], series["ref_pos"]
    out: list[int] = []
    start = 0
    for p in geo.points:
        at_rest = np.linalg.norm(ref[start:] - p, axis=1) <= 1e-4
        at_rest |= ~np.isfinite(ref[start:]).all(axis=1)   # no reference: proximity alone
        near = np.linalg.norm(pos[start:] - p, axis=1) <= geo.acceptance_m * (1.0 + 1e-9)
        hit = np.nonzero(at_rest & near)[0]
        if len(hit) == 0:
            break
        start += int(hit[0])
        out.append(start)
    return out


def snapshot_indices(series: Mapping[str, np.ndarray], sc: ScenarioParams,
                     count: int = 4, metrics: Mapping[str, Any] | None = None) -> list[int]:
    """Sample indices of ``count`` instants worth a snapshot.

    For a waypoint mission that reached enough waypoints: the instants it reached them
    (evenly picked if there are more than ``count``). Otherwise: the instants at which the
    UAV had flown 0, 1/(count-1), ..., all of its path (the last one when 99.5 % of it was
    flown, so that a run that settles early does not end on its idle tail; fractions of
    the run's time if it hardly moved).
    """
    n = len(series["t"])
    if sc.trajectory.kind == "waypoints":
        reached = reached_indices(series, reference_geometry(sc), metrics)
        if len(reached) >= min(3, count):
            pick = np.round(np.linspace(0, len(reached) - 1, min(count, len(reached))))
            return [reached[int(i)] for i in pick]
    fractions = np.linspace(0.0, 1.0, count) if count > 1 else np.ones(1)
    step = np.linalg.norm(np.diff(series["pos"], axis=0), axis=1)
    s = np.concatenate(([0.0], np.cumsum(step)))
    moved = s[-1] > 1e-3
    idx = (np.searchsorted(s, fractions * 0.995 * s[-1]) if moved
           else np.round(fractions * (n - 1)))
    return [int(min(i, n - 1)) for i in idx]


def scene_bounds(series: Mapping[str, np.ndarray], geo: ReferenceGeometry,
                 margin: float = 0.08, min_ratio: float = 0.45
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Axis limits (low, high) [m] covering the winder, the path, the reference and the
    goals, with the ground (z = 0) as the floor; each span at least ``min_ratio`` of the
    largest so that a flat or narrow scene stays legible."""
    parts = [np.zeros((1, 3)), series["pos"], series["ref_pos"], geo.points]
    if geo.circle is not None:
        parts.append(geo.circle)
    pts = np.vstack([p for p in parts if len(p)])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    lo[2] = 0.0
    span = hi - lo
    big = max(float(span.max()), 1.0)
    lo = lo - margin * big
    hi = hi + margin * big
    lo[2] = 0.0
    for i in range(3):
        need = min_ratio * big - (hi[i] - lo[i])
        if need > 0:
            if i == 2:
                hi[i] += need
            else:
                lo[i] -= need / 2
                hi[i] += need / 2
    return lo, hi


def euler_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Body-to-world rotation R = Rz(yaw) Ry(pitch) Rx(roll) (z up, body x forward, y left)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


_RING = np.linspace(0.0, 2.0 * math.pi, 17)


def quad_outline(pos: np.ndarray, euler: np.ndarray, arm_m: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Polylines [m] of an X quadrotor at ``pos`` with attitude ``euler`` (roll, pitch, yaw
    [rad]) and arms ``arm_m`` long: (front, rest), each an (n, 3) array whose pieces are
    separated by NaN rows. ``front`` holds the two front arms, ``rest`` the rear arms, the
    four rotor discs and a short thrust axis."""
    d = arm_m / math.sqrt(2.0)
    r_disc = 0.45 * arm_m
    nan = np.full((1, 3), np.nan)
    rotors = np.array([[d, d, 0.0], [d, -d, 0.0], [-d, d, 0.0], [-d, -d, 0.0]])
    front = np.vstack((rotors[0], [0.0, 0.0, 0.0], rotors[1]))
    pieces = [np.vstack((rotors[2], [0.0, 0.0, 0.0], rotors[3])), nan,
              np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.6 * arm_m]])]
    ring = np.column_stack((r_disc * np.cos(_RING), r_disc * np.sin(_RING),
                            np.zeros_like(_RING)))
    for c in rotors:
        pieces += [nan, ring + c]
    rest = np.vstack(pieces)
    rot = euler_matrix(*(float(a) for a in euler))
    p = np.asarray(pos, dtype=float)
    return front @ rot.T + p, rest @ rot.T + p


def drawn_arm_m(sc: ScenarioParams, lo: np.ndarray, hi: np.ndarray,
                fraction: float = 0.045) -> float:
    """The arm length to draw: the real one, or ``fraction`` of the scene if larger."""
    return max(sc.vehicle.arm_length_m, fraction * float(np.max(hi - lo)))


class TetherDrawer:
    """The tether as points to draw: the lumped tether's recorded nodes when the run has
    them (series ``line_t``, ``line_nodes``: the truth, a sample at the animation's frame
    rate), else the plant's catenary (:class:`sitl.tether.Tether`) solved for the UAV's
    position and the paid-out length."""

    def __init__(self, sc: ScenarioParams, n_points: int = 60,
                 series: Mapping[str, np.ndarray] | None = None) -> None:
        self.tether = Tether(sc.tether, sc.environment.gravity_m_s2)
        self.n_points = n_points
        self.line_t = self.line_nodes = None
        if series is not None and "line_nodes" in series and len(series["line_t"]):
            self.line_t = np.asarray(series["line_t"])
            self.line_nodes = np.asarray(series["line_nodes"])

    @property
    def lumped(self) -> bool:
        """Whether the points are the lumped tether's nodes."""
        return self.line_t is not None

    def points(self, pos: np.ndarray, length_m: float, t_s: float | None = None
               ) -> np.ndarray:
        """(n, 3) points [m] from the winder exit (origin) to the UAV: the lumped tether's
        nodes last recorded at or before ``t_s`` [s], or the catenary to the UAV at
        ``pos`` with ``length_m`` paid out (a straight line if it cannot be solved)."""
        if self.line_t is not None and t_s is not None:
            i = max(0, int(np.searchsorted(self.line_t, t_s + 1e-9)) - 1)
            nodes = self.line_nodes[i]
            return np.asarray(nodes[np.isfinite(nodes[:, 0])], dtype=float)
        x, y, z = (float(v) for v in pos)
        z = max(z, 0.0)
        try:
            self.tether.forces(x, y, z, length_m)
            return self.tether.shape(x, y, z, length_m, self.n_points)
        except (ValueError, RuntimeError):
            self.tether.reset_warm_start()
            s = np.linspace(0.0, 1.0, self.n_points)[:, None]
            return s * np.array([[x, y, z]])


def draw_ground(ax: Any, lo: np.ndarray, hi: np.ndarray) -> None:
    """The ground plane z = 0 over the scene and the winder at the origin."""
    quad = [[(lo[0], lo[1], 0.0), (hi[0], lo[1], 0.0), (hi[0], hi[1], 0.0),
             (lo[0], hi[1], 0.0)]]
    ax.add_collection3d(Poly3DCollection(quad, facecolor=_GROUND_COLOUR, alpha=0.35,
                                         edgecolor="none"))
    ax.plot([0.0], [0.0], [0.0], "ks", markersize=7, label="winder")


def set_scene(ax: Any, lo: np.ndarray, hi: np.ndarray, zoom: float = 1.0,
              small: bool = False) -> None:
    """Fixed limits with equal scale on the three axes, labelled in metres (``small``:
    fewer ticks and smaller text, for panels of a grid)."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    span = hi - lo
    if span[2] > 1.4 * max(span[0], span[1]):
        zoom *= 0.85  # a tall box overflows the axes' square at zoom 1
    ax.set_box_aspect(tuple(span), zoom=zoom)
    if small:
        ax.set_xlabel("x [m]", fontsize=8, labelpad=-2)
        ax.set_ylabel("y [m]", fontsize=8, labelpad=-2)
        ax.set_zlabel("z [m]", fontsize=8, labelpad=-2)
    else:
        ax.set_xlabel("x (east) [m]", labelpad=6)
        ax.set_ylabel("y (north) [m]", labelpad=6)
        ax.set_zlabel("z (up) [m]", labelpad=10)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(4 if small else 6))
    if small:
        ax.tick_params(labelsize=7, pad=0)


def draw_goals(ax: Any, geo: ReferenceGeometry, reached: int | None = None,
               label: bool = True, circle: bool = True) -> None:
    """Goal or waypoints (filled once reached when ``reached`` is given) and the circle."""
    if circle and geo.circle is not None:
        c = geo.circle
        ax.plot(c[:, 0], c[:, 1], c[:, 2], color=_GOAL_COLOUR, lw=1.0, ls=":",
                label="circle to track" if label else None)
    if not len(geo.points):
        return
    name = "goal" if geo.labels == ("goal",) else "waypoints"
    done = len(geo.points) if reached is None else reached
    p = geo.points
    ax.scatter(p[:done, 0], p[:done, 1], p[:done, 2], marker="*", s=110, color=_GOAL_COLOUR,
               depthshade=False, label=name if label else None)
    if done < len(p):
        ax.scatter(p[done:, 0], p[done:, 1], p[done:, 2], marker="*", s=110,
                   facecolors="none", edgecolors=_GOAL_COLOUR, depthshade=False,
                   label=(name + " (to reach)") if label else None)
    if len(p) > 1:
        for q, text in zip(p, geo.labels, strict=True):
            ax.text(q[0], q[1], q[2], "   " + text, fontsize=8, color=_GOAL_COLOUR)


# --------------------------------------------------------------------------------------
# The figures


#: The time-series figures' margins [in]: left (tick labels and the y label), right, top
#: (the title), bottom (the time axis's label), and between panels (an axes title or the
#: tick labels of the panel below; the y label of the right-hand column).
_MARGINS_IN = {"left": 0.95, "right": 0.15, "top": 0.6, "bottom": 0.5, "between": 0.5,
               "columns": 1.0}


def _new_figure(size: tuple[float, float] = FIG_SIZE_IN, rows: int = 1, cols: int = 1
                ) -> Figure:
    """A figure for a ``rows`` x ``cols`` grid of time-series panels, with fixed margins
    (:data:`_MARGINS_IN`).

    Fixed, not matplotlib's constrained layout: that lays every tick label out once more
    before drawing, 40 % of a figure's drawing time, for margins that hardly change from
    one run to the next."""
    fig = Figure(figsize=size, dpi=DPI)
    w, h = size
    m = _MARGINS_IN
    inner_w = w - m["left"] - m["right"]
    inner_h = h - m["top"] - m["bottom"]
    # subplots_adjust's gaps are fractions of the mean panel's height and width
    panel_h = (inner_h - (rows - 1) * m["between"]) / rows
    panel_w = (inner_w - (cols - 1) * m["columns"]) / cols
    fig.subplots_adjust(left=m["left"] / w, right=1.0 - m["right"] / w,
                        bottom=m["bottom"] / h, top=1.0 - m["top"] / h,
                        hspace=m["between"] / panel_h, wspace=m["columns"] / panel_w)
    return fig


def _title(fig: Figure, sc: ScenarioParams, what: str) -> None:
    fig.suptitle(f"{sc.name}: {what}", fontsize=13, fontweight="bold")


#: A time-series line with more than twice this many samples is drawn as its envelope in
#: this many runs of samples (:func:`envelope`).
_ENVELOPE_BINS = 2000


def envelope(x: np.ndarray, y: np.ndarray, bins: int = _ENVELOPE_BINS
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` thinned to the first and last samples and the minimum and the maximum of
    ``y`` in each of ``bins`` runs of consecutive samples, in time order (``x`` ascending).

    A figure about 1000 pixels wide shows a run of ``len(x) / bins`` samples within one
    pixel column, which a line through its extremes covers exactly; every peak and every
    NaN gap (a bin holding a NaN keeps one) stays. Shorter series are returned as they are.
    """
    n = len(x)
    if n <= 2 * bins:
        return x, y
    m = -(-n // bins)                      # samples a bin
    pad = m * (-(-n // m)) - n             # the last bin padded with its last sample
    yp = np.concatenate((y, np.full(pad, y[-1]))).reshape(-1, m)
    nan = np.isnan(yp)
    base = np.arange(yp.shape[0]) * m
    imin = base + np.argmin(np.where(nan, np.inf, yp), axis=1)
    imax = base + np.argmax(np.where(nan, -np.inf, yp), axis=1)
    gaps = nan.any(axis=1)                 # a bin holding a NaN keeps one: the gap stays
    inan = (base + np.argmax(nan, axis=1))[gaps]
    ends = np.array([0, n - 1])            # the line spans the same time
    keep = np.unique(np.minimum(np.concatenate((ends, imin, imax, inan)), n - 1))
    return x[keep], y[keep]


def _thin_lines(ax: Axes) -> None:
    """Each long line of ``ax`` replaced by its :func:`envelope`."""
    for line in ax.get_lines():
        x = np.asarray(line.get_xdata(), dtype=float)
        if len(x) > 2 * _ENVELOPE_BINS and np.all(np.diff(x) >= 0):
            line.set_data(*envelope(x, np.asarray(line.get_ydata(), dtype=float)))


def _finish(ax: Axes, ylabel: str, legend: bool = True, xlabel: bool = False) -> None:
    lines = ax.get_lines()
    if lines:
        t = np.asarray(lines[0].get_xdata(), dtype=float)
        if len(t) > 1 and t[-1] > t[0]:
            ax.set_xlim(t[0], t[-1])
    _thin_lines(ax)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    if legend:
        ax.legend(loc="best", fontsize=8, framealpha=0.8)
    if xlabel:
        ax.set_xlabel("time [s]")


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _angles_deg(s: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured, commanded and desired attitude [deg]; yaw unwrapped along the command so
    that no curve jumps by 360 deg."""
    cmd = s["att_cmd"].copy()
    meas = s["euler"].copy()
    if not np.isfinite(cmd[:, 2]).any():   # no command logged (an imported up run)
        meas[:, 2] = np.unwrap(meas[:, 2])
        return np.degrees(meas), np.degrees(cmd), np.degrees(s["att_des"])
    cmd[:, 2] = np.unwrap(cmd[:, 2])
    meas[:, 2] = cmd[:, 2] + _wrap(meas[:, 2] - cmd[:, 2])
    des = s["att_des"].copy()
    des[:, 2] = cmd[:, 2] + _wrap(des[:, 2] - cmd[:, 2])
    return np.degrees(meas), np.degrees(cmd), np.degrees(des)


def length_error(s: Mapping[str, np.ndarray], sc: ScenarioParams
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Tether length error L - L-bar [m] and its times [s], at the samples where both were
    taken at the same instant.

    The ground station computes L-bar at the winder rate and the log holds it between
    updates, while L is logged at the control rate; their difference at the other samples
    is mostly the hold (L moves on, L-bar does not), a saw-tooth of about
    (pay-out speed) / (winder rate). Only samples whose time is a multiple of the winder
    period are kept (all of them if none is).
    """
    t = s["t"]
    phase = t * sc.winder_control.rate_hz
    same = np.abs(phase - np.round(phase)) < 1e-6 * np.maximum(1.0, np.abs(phase))
    if same.sum() < 2:
        same = np.ones_like(t, dtype=bool)
    return t[same], (s["length"] - s["lbar"])[same]


def fig_states(s: Mapping[str, np.ndarray], sc: ScenarioParams,
               metrics: Mapping[str, Any] | None = None) -> Figure:
    """x, y, z, roll, pitch, yaw and tether length against time."""
    fig = _new_figure((10.0, 8.0), rows=4, cols=2)
    _title(fig, sc, "state evolution over time")
    gs = fig.add_gridspec(4, 2)
    t = s["t"]
    meas, cmd, _ = _angles_deg(s)
    first = None
    for i, name in enumerate("xyz"):
        ax = fig.add_subplot(gs[i, 0], sharex=first)
        first = first or ax
        ax.plot(t, s["pos"][:, i], color=_AXIS_COLOURS[i], label=name)
        if has_data(s, "ref_pos"):
            ax.plot(t, s["ref_pos"][:, i], "k--", lw=1.0, label=f"{name} reference")
        _finish(ax, f"{name} [m]")
    for i, name in enumerate(("roll", "pitch", "yaw")):
        ax = fig.add_subplot(gs[i, 1], sharex=first)
        ax.plot(t, meas[:, i], color=_AXIS_COLOURS[i], label=name)
        if has_data(s, "att_cmd"):
            ax.plot(t, cmd[:, i], "k--", lw=1.0, label=f"{name} command")
        _finish(ax, f"{name} [deg]")
    ax = fig.add_subplot(gs[3, :], sharex=first)
    ax.plot(t, s["length"], color=_TETHER_COLOUR, label="tether length L")
    ax.plot(t, s["lbar"], "k--", lw=1.0, label="desired length L-bar")
    _finish(ax, "L [m]", xlabel=True)
    return fig


def fig_errors(s: Mapping[str, np.ndarray], sc: ScenarioParams,
               metrics: Mapping[str, Any] | None = None) -> Figure:
    """Position, attitude and tether length errors against time."""
    fig = _new_figure(rows=3)
    _title(fig, sc, "errors over time")
    axs = fig.subplots(3, 1, sharex=True)
    t = s["t"]
    e_pos = s["pos"] - s["ref_pos"]
    e_att = s["euler"] - s["att_cmd"]
    e_att[:, 2] = _wrap(e_att[:, 2])
    for i, name in enumerate("xyz"):
        axs[0].plot(t, e_pos[:, i], color=_AXIS_COLOURS[i], label=f"e_{name}")
    _finish(axs[0], "position error [m]")
    axs[0].set_title("position error p - p_ref", fontsize=10)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[1].plot(t, np.degrees(e_att[:, i]), color=_AXIS_COLOURS[i], label=f"e_{name}")
    _finish(axs[1], "attitude error [deg]")
    axs[1].set_title("attitude error (measured - command)", fontsize=10)
    t_l, e_l = length_error(s, sc)
    axs[2].plot(t_l, e_l, color=_TETHER_COLOUR,
                label=f"e_L = L - L-bar (at the winder's {sc.winder_control.rate_hz:g} Hz "
                      "updates of L-bar)")
    _finish(axs[2], "length error [m]", xlabel=True)
    axs[2].set_title("tether length error", fontsize=10)
    for ax in axs:
        ax.axhline(0.0, color="k", lw=0.6)
    return fig


def fig_position_tracking(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                          metrics: Mapping[str, Any] | None = None) -> Figure:
    """x, y, z against their references."""
    fig = _new_figure(rows=3)
    _title(fig, sc, "position tracking")
    axs = fig.subplots(3, 1, sharex=True)
    for i, name in enumerate("xyz"):
        axs[i].plot(s["t"], s["pos"][:, i], color=_AXIS_COLOURS[i], lw=1.8,
                    label=f"{name} actual")
        axs[i].plot(s["t"], s["ref_pos"][:, i], "k--", lw=1.0, label=f"{name} reference")
        _finish(axs[i], f"{name} [m]", xlabel=i == 2)
    return fig


def fig_attitude_tracking(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                          metrics: Mapping[str, Any] | None = None) -> Figure:
    """Roll, pitch, yaw against the filtered command and the desired attitude."""
    fig = _new_figure(rows=3)
    _title(fig, sc, "attitude tracking")
    axs = fig.subplots(3, 1, sharex=True)
    meas, cmd, des = _angles_deg(s)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[i].plot(s["t"], meas[:, i], color=_AXIS_COLOURS[i], lw=1.8,
                    label=f"{name} measured")
        axs[i].plot(s["t"], cmd[:, i], "k--", lw=1.0, label=f"{name} command (filtered)")
        axs[i].plot(s["t"], des[:, i], color="0.45", ls=":", lw=1.0,
                    label=f"{name} desired (before filter)")
        _finish(axs[i], f"{name} [deg]", xlabel=i == 2)
    return fig


def spread_instants(pos: np.ndarray, count: int, candidates: int = 400) -> list[int]:
    """``count`` sample indices whose positions are far apart (greedy farthest-point
    choice from the start), in time order: instants at which tethers drawn together do
    not overlap, even on a path that goes round several times."""
    n = len(pos)
    cand = np.unique(np.round(np.linspace(0, n - 1, min(candidates, n))).astype(int))
    pts = pos[cand]
    chosen = [0]
    dist = np.linalg.norm(pts - pts[0], axis=1)
    while len(chosen) < min(count, len(cand)):
        j = int(np.argmax(dist))
        if dist[j] <= 1e-9:
            break
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[j], axis=1))
    return sorted(int(cand[j]) for j in chosen)


def fig_path_3d(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                metrics: Mapping[str, Any] | None = None) -> Figure:
    """The 3-D path, the reference, the winder, the ground and the tether at a few
    instants."""
    fig = Figure(figsize=(10.0, 8.0), dpi=DPI, layout="constrained")
    _title(fig, sc, "3-D path with the tether")
    ax = fig.add_subplot(projection="3d")
    geo = reference_geometry(sc)
    lo, hi = scene_bounds(s, geo)
    draw_ground(ax, lo, hi)
    pos, ref = s["pos"], s["ref_pos"]
    ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], color=_PATH_COLOUR, lw=2.2, label="UAV path")
    if has_data(s, "ref_pos"):
        ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "--", color=_REF_COLOUR, lw=0.9,
                label="reference path")
    draw_goals(ax, geo, label=True, circle=False)
    drawer = TetherDrawer(sc, series=s)
    instants = spread_instants(pos, 5)
    for j, k in enumerate(instants):
        pts = drawer.points(pos[k], float(s["length"][k]), float(s["t"][k]))
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=_TETHER_COLOUR, lw=1.3,
                marker="o" if drawer.lumped else None, markersize=2.5,
                label=("tether (lumped nodes)" if drawer.lumped else "tether")
                if j == 0 else None)
        ax.scatter([pos[k, 0]], [pos[k, 1]], [pos[k, 2]], color=_UAV_COLOUR, s=25,
                   depthshade=False, label="UAV at tether instants" if j == 0 else None)
        ax.text(pos[k, 0], pos[k, 1], pos[k, 2], f"t = {s['t'][k]:.0f} s   ", fontsize=8,
                ha="right", va="top")
    ax.scatter([pos[0, 0]], [pos[0, 1]], [pos[0, 2]], marker="o", facecolors="none",
               edgecolors="k", s=70, depthshade=False, label="start")
    set_scene(ax, lo, hi)
    ax.view_init(elev=24, azim=-60)
    ax.legend(loc="upper left", fontsize=8)
    return fig


def fig_tether_length(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                      metrics: Mapping[str, Any] | None = None) -> Figure:
    """L-bar, L, distance and altitude on one axis."""
    fig = _new_figure()
    _title(fig, sc, "tether length tracking")
    ax = fig.add_subplot()
    t = s["t"]
    ax.plot(t, s["lbar"], color="k", ls="--", lw=1.4, label="desired length L-bar", zorder=3)
    ax.plot(t, s["length"], color=_TETHER_COLOUR, lw=2.2, label="tether length L")
    ax.plot(t, np.linalg.norm(s["pos"], axis=1), color="C0", lw=1.2, ls="-.",
            label="distance |p| winder-UAV")
    ax.plot(t, s["pos"][:, 2], color="C2", lw=1.5, label="altitude z")
    _finish(ax, "length, distance, altitude [m]", xlabel=True)
    return fig


def fig_snapshots(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                  metrics: Mapping[str, Any] | None = None, count: int = 4) -> Figure:
    """``count`` 3-D snapshots: quadrotor, tether, trail, goals."""
    geo = reference_geometry(sc)
    lo, hi = scene_bounds(s, geo)
    span = hi - lo
    if span[2] > 1.4 * max(span[0], span[1]):
        # a tall scene: one row of tall panels, the box enlarged into their spare height
        rows, cols, panel_w, panel_h, zoom = 1, count, 3.6, 5.6, 1.25
    else:
        cols = min(count, 2)
        rows, panel_w, panel_h, zoom = math.ceil(count / cols), 5.25, 4.9, 1.0
    height = panel_h * rows + 0.6
    fig = Figure(figsize=(panel_w * cols, height), dpi=DPI)
    fig.subplots_adjust(left=0.0, right=0.97, bottom=0.03, top=1.0 - 1.0 / height,
                        wspace=0.0, hspace=0.08)
    _title(fig, sc, "snapshots of the flight")
    arm = drawn_arm_m(sc, lo, hi)
    drawer = TetherDrawer(sc, series=s)
    idx = snapshot_indices(s, sc, count, metrics)
    waypoints = sc.trajectory.kind == "waypoints"
    reached = reached_indices(s, geo, metrics) if waypoints else []
    pos, ref = s["pos"], s["ref_pos"]
    for j, k in enumerate(idx):
        ax = fig.add_subplot(rows, cols, j + 1, projection="3d")
        draw_ground(ax, lo, hi)
        if has_data(s, "ref_pos"):
            ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "--", color="0.55", lw=0.8,
                    label="reference path")
        n_reached = sum(1 for r in reached if r <= k) if waypoints else None
        draw_goals(ax, geo, reached=n_reached)
        ax.plot(pos[: k + 1, 0], pos[: k + 1, 1], pos[: k + 1, 2], color=_PATH_COLOUR,
                lw=1.6, label="trail")
        pts = drawer.points(pos[k], float(s["length"][k]), float(s["t"][k]))
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=_TETHER_COLOUR, lw=1.6,
                marker="o" if drawer.lumped else None, markersize=2.5, label="tether")
        front, rest = quad_outline(pos[k], s["euler"][k], arm)
        ax.plot(rest[:, 0], rest[:, 1], rest[:, 2], color="k", lw=1.2)
        ax.plot(front[:, 0], front[:, 1], front[:, 2], color=_UAV_COLOUR, lw=2.0,
                label="UAV (front red)")
        set_scene(ax, lo, hi, zoom=zoom, small=True)
        ax.view_init(elev=22, azim=-60)
        ax.set_title(f"t = {s['t'][k]:.1f} s, L = {s['length'][k]:.1f} m", fontsize=10,
                     y=1.06 if rows == 1 else 0.97)
        if j == 0:
            handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=4, fontsize=8,
               bbox_to_anchor=(0.5, 1.0 - 0.45 / fig.get_figheight()), frameon=False)
    return fig


def fig_lyapunov(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                 metrics: Mapping[str, Any] | None = None) -> Figure:
    """The three Lyapunov functions on a log scale."""
    fig = _new_figure()
    _title(fig, sc, "Lyapunov functions")
    ax = fig.add_subplot()
    t = s["t"]
    curves = (("v_pos", "V_pos = |ē1|^2/2 + |ē2|^2/2 (position loop, compensated errors)",
               "C0"),
              ("v_att", "V_att = |ē_eta|^2/2 + ē_w' J ē_w/2 (attitude loop, compensated)",
               "C1"),
              ("v_win", "V_win = c e_L^2/2 + I_w e_w^2/2 (winder loop)", "C2"))
    values = []
    for key, label, colour in curves:
        v = np.asarray(s[key], dtype=float)
        v = np.where(v > 0.0, v, np.nan)
        if np.any(np.isfinite(v)):
            ax.plot(t, v, color=colour, lw=1.3, label=label)
            values.append(v[np.isfinite(v)])
    if values:
        ax.set_yscale("log")
        v = np.concatenate(values)
        # a single near-zero sample (a start in exact trim) must not squash the plot
        top = float(v.max())
        bottom = max(float(np.percentile(v, 0.2)) / 3.0, top * 1e-18)
        ax.set_ylim(bottom, top * 3.0)
    _thin_lines(ax)
    ax.set_ylabel("V (log scale) [m^2/s^2, rad^2, J]")
    ax.set_xlabel("time [s]")
    ax.grid(True, which="major", alpha=0.4)
    ax.grid(True, which="minor", alpha=0.12)
    ax.legend(loc="best", fontsize=8)
    return fig


def _shade_ground_contact(ax: Axes, t: np.ndarray, regime: np.ndarray, label: bool) -> None:
    ground = np.isin(regime, _GROUND_REGIMES).astype(int)
    if not ground.any():
        return
    edges = np.diff(np.concatenate(([0], ground, [0])))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    for j, (a, b) in enumerate(zip(starts, ends, strict=True)):
        ax.axvspan(t[a], t[b], color="0.85", zorder=0,
                   label="tether on the ground" if label and j == 0 else None)


def fig_tension_and_winder(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                           metrics: Mapping[str, Any] | None = None) -> Figure:
    """Tensions, winder torque and drum rate."""
    fig = _new_figure(rows=3)
    _title(fig, sc, "tether tension and winder")
    axs = fig.subplots(3, 1, sharex=True)
    t = s["t"]
    for j, ax in enumerate(axs):
        _shade_ground_contact(ax, t, s["regime"], label=j == 0)
    axs[0].plot(t, s["top_tension"], color="C3", label="tension at the UAV (top)")
    axs[0].plot(t, s["drum_tension"], color="C0", label="tension at the drum")
    if has_data(s, "winch_tension"):   # an imported up run: what the winch reported
        axs[0].plot(t, s["winch_tension"], color="C1", ls=":", lw=1.2,
                    label="tension reported by the winch (WINCH_STATUS)")
    _finish(axs[0], "tension [N]")
    axs[1].plot(t, s["winder_torque"], color="C4", label="winder motor torque")
    if not has_data(s, "winder_torque"):
        axs[1].text(0.5, 0.5, "winder torque not recorded (no CAN log)",
                    transform=axs[1].transAxes, ha="center", va="center", color="0.4")
    lim = sc.winder.motor_torque_limit_n_m
    w_max = (float(np.nanmax(np.abs(s["winder_torque"])))
             if has_data(s, "winder_torque") else 0.0)
    if w_max > 0.5 * lim:
        for sign in (1, -1):
            axs[1].axhline(sign * lim, color="C4", ls=":", lw=1.0,
                           label="torque limit" if sign > 0 else None)
    axs[1].axhline(0.0, color="k", lw=0.6)
    _finish(axs[1], "torque [N m]")
    axs[2].plot(t, s["drum_rate"], color="C2", label="drum rate (+ pays out)")
    axs[2].axhline(0.0, color="k", lw=0.6)
    _finish(axs[2], "drum rate [rad/s]", xlabel=True)
    return fig


def fig_estimate(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                 metrics: Mapping[str, Any] | None = None) -> Figure:
    """Estimate minus truth per axis with the filter's 3-sigma band; the speed error."""
    fig = _new_figure(rows=4)
    _title(fig, sc, "onboard estimate against the truth")
    t = s["t"]
    err = s["est_pos"] - s["pos"]
    sig = 3.0 * s["est_pos_sigma"]
    axes = fig.subplots(4, 1, sharex=True)
    for i, (ax, name) in enumerate(zip(axes[:3], ("x (east)", "y (north)", "z (up)"),
                                       strict=True)):
        ax.fill_between(t, -sig[:, i], sig[:, i], color=_AXIS_COLOURS[i], alpha=0.2,
                        label="filter's 3 sigma")
        ax.plot(t, err[:, i], color=_AXIS_COLOURS[i], lw=1.0, label=f"{name} error")
        _finish(ax, "[m]")
    dv = np.linalg.norm(s["est_vel"][:, :2], axis=1) - np.linalg.norm(s["vel"][:, :2],
                                                                      axis=1)
    axes[3].plot(t, dv, color="k", lw=0.8, label="horizontal speed error")
    _finish(axes[3], "[m/s]", xlabel=True)
    return fig


_BUILDERS = {
    "states": fig_states,
    "errors": fig_errors,
    "position_tracking": fig_position_tracking,
    "attitude_tracking": fig_attitude_tracking,
    "path_3d": fig_path_3d,
    "tether_length": fig_tether_length,
    "snapshots": fig_snapshots,
    "lyapunov": fig_lyapunov,
    "tension_and_winder": fig_tension_and_winder,
    "estimate": fig_estimate,
}


def build_figures(series: Mapping[str, np.ndarray], scenario: ScenarioParams,
                  names: Iterable[str] | None = None,
                  metrics: Mapping[str, Any] | None = None) -> dict[str, Figure]:
    """Draw the figures ``names`` (default: all of :data:`FIGURE_NAMES`) from a run's
    arrays and its scenario (and its metrics, used for the instants waypoints were reached
    if given); returns name -> Figure, nothing written."""
    chosen = FIGURE_NAMES if names is None else tuple(names)
    unknown = [n for n in chosen if n not in _BUILDERS]
    if unknown:
        raise ValueError(f"unknown figure(s) {unknown}; known: {', '.join(FIGURE_NAMES)}")
    if len(series["t"]) < 2:
        raise ValueError("the time series needs at least two samples")
    return {n: _BUILDERS[n](series, scenario, metrics) for n in chosen}


def save_figures(figures: Mapping[str, Figure], out_dir: Path) -> list[Path]:
    """Write each figure as ``out_dir/<name>.png``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures.items():
        path = out_dir / f"{name}.png"
        # zlib level 1: a fifth of level 6's encoding time for ~10 % more bytes
        fig.savefig(path, dpi=fig.dpi, pil_kwargs={"compress_level": 1})
        paths.append(path)
    return paths


def make_figures(run_dir: Path, names: Iterable[str] | None = None,
                 skipped: list[str] | None = None) -> list[Path]:
    """Read the run folder ``run_dir`` and write its figures into ``run_dir/figures/``;
    returns the PNG paths in :data:`FIGURE_NAMES` order. A figure whose data the run does
    not have (:func:`missing_series`) is not drawn; a one-line note on it is appended to
    ``skipped`` if given."""
    run = load_run(Path(run_dir))
    out = Path(run_dir) / "figures"
    paths: list[Path] = []
    for name in FIGURE_NAMES if names is None else tuple(names):
        lacking = missing_series(run.series, name) if name in _BUILDERS else []
        if lacking:
            if skipped is not None:
                skipped.append(f"{name}: the run has no {', '.join(lacking)}")
            continue
        # one figure at a time keeps memory low for long runs
        paths += save_figures(build_figures(run.series, run.scenario, [name], run.metrics), out)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``python -m tuav_sitl.figures RUN_DIR [NAME ...]``: write the figures, list them."""
    import argparse
    import time

    p = argparse.ArgumentParser(description="Write the figures of an offline run.")
    p.add_argument("run_dir", type=Path)
    p.add_argument("names", nargs="*", help=f"figures (default all): {', '.join(FIGURE_NAMES)}")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    skipped: list[str] = []
    for path in make_figures(a.run_dir, a.names or None, skipped):
        print(path)
    for note in skipped:
        print(f"skipped {note}")
    print(f"{time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
