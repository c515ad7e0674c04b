"""The 3-D scene of a run, shared by the figures (:mod:`tuav_sitl.figures_3d`) and the
animation (:mod:`tuav_sitl.animation`): the goals or the circle to reach, the instants worth
a snapshot, the scene's bounds, the quadrotor's outline, the tether's points, the ground.

Frame: z up, x east, y north, origin at the winder's tether exit point on the ground.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from sitl.tether import Tether
from tuav_sitl.scenario import ScenarioParams

__all__ = [
    "ReferenceGeometry",
    "TetherDrawer",
    "draw_goals",
    "draw_ground",
    "drawn_arm_m",
    "euler_matrix",
    "quad_outline",
    "reached_indices",
    "reference_geometry",
    "scene_bounds",
    "set_scene",
    "snapshot_indices",
    "spread_instants",
]

GOAL_COLOUR = "#9467bd"
GROUND_COLOUR = "#9acd9a"



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
    ax.add_collection3d(Poly3DCollection(quad, facecolor=GROUND_COLOUR, alpha=0.35,
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
        ax.plot(c[:, 0], c[:, 1], c[:, 2], color=GOAL_COLOUR, lw=1.0, ls=":",
                label="circle to track" if label else None)
    if not len(geo.points):
        return
    name = "goal" if geo.labels == ("goal",) else "waypoints"
    done = len(geo.points) if reached is None else reached
    p = geo.points
    ax.scatter(p[:done, 0], p[:done, 1], p[:done, 2], marker="*", s=110, color=GOAL_COLOUR,
               depthshade=False, label=name if label else None)
    if done < len(p):
        ax.scatter(p[done:, 0], p[done:, 1], p[done:, 2], marker="*", s=110,
                   facecolors="none", edgecolors=GOAL_COLOUR, depthshade=False,
                   label=(name + " (to reach)") if label else None)
    if len(p) > 1:
        for q, text in zip(p, geo.labels, strict=True):
            ax.text(q[0], q[1], q[2], "   " + text, fontsize=8, color=GOAL_COLOUR)


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
