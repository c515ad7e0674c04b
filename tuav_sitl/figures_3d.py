"""The run's 3-D figures: the path with the tether at a few instants, and snapshots of
the flight (quadrotor, tether, trail, goals). The scene's pieces are
:mod:`tuav_sitl.figure_scene`, shared with the animation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from tuav_sitl.figure_scene import (
    TetherDrawer,
    draw_goals,
    draw_ground,
    drawn_arm_m,
    quad_outline,
    reached_indices,
    reference_geometry,
    scene_bounds,
    set_scene,
    snapshot_indices,
    spread_instants,
)
from tuav_sitl.figure_style import DPI, PATH_COLOUR, REF_COLOUR, TETHER_COLOUR, UAV_COLOUR, title
from tuav_sitl.run_data import has_data
from tuav_sitl.scenario import ScenarioParams

__all__ = ["fig_path_3d", "fig_snapshots"]


def fig_path_3d(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                metrics: Mapping[str, Any] | None = None) -> Figure:
    """The 3-D path, the reference, the winder, the ground and the tether at a few
    instants."""
    fig = Figure(figsize=(10.0, 8.0), dpi=DPI, layout="constrained")
    title(fig, sc, "3-D path with the tether")
    ax = fig.add_subplot(projection="3d")
    geo = reference_geometry(sc)
    lo, hi = scene_bounds(s, geo)
    draw_ground(ax, lo, hi)
    pos, ref = s["pos"], s["ref_pos"]
    ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], color=PATH_COLOUR, lw=2.2, label="UAV path")
    if has_data(s, "ref_pos"):
        ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "--", color=REF_COLOUR, lw=0.9,
                label="reference path")
    draw_goals(ax, geo, label=True, circle=False)
    drawer = TetherDrawer(sc, series=s)
    instants = spread_instants(pos, 5)
    for j, k in enumerate(instants):
        pts = drawer.points(pos[k], float(s["length"][k]), float(s["t"][k]))
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=TETHER_COLOUR, lw=1.3,
                marker="o" if drawer.lumped else None, markersize=2.5,
                label=("tether (lumped nodes)" if drawer.lumped else "tether")
                if j == 0 else None)
        ax.scatter([pos[k, 0]], [pos[k, 1]], [pos[k, 2]], color=UAV_COLOUR, s=25,
                   depthshade=False, label="UAV at tether instants" if j == 0 else None)
        ax.text(pos[k, 0], pos[k, 1], pos[k, 2], f"t = {s['t'][k]:.0f} s   ", fontsize=8,
                ha="right", va="top")
    ax.scatter([pos[0, 0]], [pos[0, 1]], [pos[0, 2]], marker="o", facecolors="none",
               edgecolors="k", s=70, depthshade=False, label="start")
    set_scene(ax, lo, hi)
    ax.view_init(elev=24, azim=-60)
    ax.legend(loc="upper left", fontsize=8)
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
    title(fig, sc, "snapshots of the flight")
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
        ax.plot(pos[: k + 1, 0], pos[: k + 1, 1], pos[: k + 1, 2], color=PATH_COLOUR,
                lw=1.6, label="trail")
        pts = drawer.points(pos[k], float(s["length"][k]), float(s["t"][k]))
        ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=TETHER_COLOUR, lw=1.6,
                marker="o" if drawer.lumped else None, markersize=2.5, label="tether")
        front, rest = quad_outline(pos[k], s["euler"][k], arm)
        ax.plot(rest[:, 0], rest[:, 1], rest[:, 2], color="k", lw=1.2)
        ax.plot(front[:, 0], front[:, 1], front[:, 2], color=UAV_COLOUR, lw=2.0,
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
