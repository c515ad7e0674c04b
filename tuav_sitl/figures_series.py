"""The run's time-series figures: states, errors, tracking, the tether's length, the
Lyapunov functions, tension and winder, the onboard estimate.

Each ``fig_*`` draws one figure from a run's arrays and its scenario (the registry, the
captions and the files are :mod:`tuav_sitl.figures`). Angles are stored in radians and shown
in degrees.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sitl.catenary import CatenaryRegime
from tuav_sitl.figure_style import (
    AXIS_COLOURS,
    TETHER_COLOUR,
    finish,
    new_figure,
    thin_lines,
    title,
)
from tuav_sitl.run_data import has_data
from tuav_sitl.scenario import ScenarioParams

__all__ = [
    "fig_attitude_tracking",
    "fig_errors",
    "fig_estimate",
    "fig_lyapunov",
    "fig_position_tracking",
    "fig_states",
    "fig_tension_and_winder",
    "fig_tether_length",
    "length_error",
]

# Tether regimes with part of the line on the ground.
_GROUND_REGIMES = (int(CatenaryRegime.TOUCHDOWN), int(CatenaryRegime.SLACK),
                   int(CatenaryRegime.FLAT))


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
    fig = new_figure((10.0, 8.0), rows=4, cols=2)
    title(fig, sc, "state evolution over time")
    gs = fig.add_gridspec(4, 2)
    t = s["t"]
    meas, cmd, _ = _angles_deg(s)
    first = None
    for i, name in enumerate("xyz"):
        ax = fig.add_subplot(gs[i, 0], sharex=first)
        first = first or ax
        ax.plot(t, s["pos"][:, i], color=AXIS_COLOURS[i], label=name)
        if has_data(s, "ref_pos"):
            ax.plot(t, s["ref_pos"][:, i], "k--", lw=1.0, label=f"{name} reference")
        finish(ax, f"{name} [m]")
    for i, name in enumerate(("roll", "pitch", "yaw")):
        ax = fig.add_subplot(gs[i, 1], sharex=first)
        ax.plot(t, meas[:, i], color=AXIS_COLOURS[i], label=name)
        if has_data(s, "att_cmd"):
            ax.plot(t, cmd[:, i], "k--", lw=1.0, label=f"{name} command")
        finish(ax, f"{name} [deg]")
    ax = fig.add_subplot(gs[3, :], sharex=first)
    ax.plot(t, s["length"], color=TETHER_COLOUR, label="tether length L")
    ax.plot(t, s["lbar"], "k--", lw=1.0, label="desired length L-bar")
    finish(ax, "L [m]", xlabel=True)
    return fig


def fig_errors(s: Mapping[str, np.ndarray], sc: ScenarioParams,
               metrics: Mapping[str, Any] | None = None) -> Figure:
    """Position, attitude and tether length errors against time."""
    fig = new_figure(rows=3)
    title(fig, sc, "errors over time")
    axs = fig.subplots(3, 1, sharex=True)
    t = s["t"]
    e_pos = s["pos"] - s["ref_pos"]
    e_att = s["euler"] - s["att_cmd"]
    e_att[:, 2] = _wrap(e_att[:, 2])
    for i, name in enumerate("xyz"):
        axs[0].plot(t, e_pos[:, i], color=AXIS_COLOURS[i], label=f"e_{name}")
    finish(axs[0], "position error [m]")
    axs[0].set_title("position error p - p_ref", fontsize=10)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[1].plot(t, np.degrees(e_att[:, i]), color=AXIS_COLOURS[i], label=f"e_{name}")
    finish(axs[1], "attitude error [deg]")
    axs[1].set_title("attitude error (measured - command)", fontsize=10)
    t_l, e_l = length_error(s, sc)
    axs[2].plot(t_l, e_l, color=TETHER_COLOUR,
                label=f"e_L = L - L-bar (at the winder's {sc.winder_control.rate_hz:g} Hz "
                      "updates of L-bar)")
    finish(axs[2], "length error [m]", xlabel=True)
    axs[2].set_title("tether length error", fontsize=10)
    for ax in axs:
        ax.axhline(0.0, color="k", lw=0.6)
    return fig


def fig_position_tracking(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                          metrics: Mapping[str, Any] | None = None) -> Figure:
    """x, y, z against their references."""
    fig = new_figure(rows=3)
    title(fig, sc, "position tracking")
    axs = fig.subplots(3, 1, sharex=True)
    for i, name in enumerate("xyz"):
        axs[i].plot(s["t"], s["pos"][:, i], color=AXIS_COLOURS[i], lw=1.8,
                    label=f"{name} actual")
        axs[i].plot(s["t"], s["ref_pos"][:, i], "k--", lw=1.0, label=f"{name} reference")
        finish(axs[i], f"{name} [m]", xlabel=i == 2)
    return fig


def fig_attitude_tracking(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                          metrics: Mapping[str, Any] | None = None) -> Figure:
    """Roll, pitch, yaw against the filtered command and the desired attitude."""
    fig = new_figure(rows=3)
    title(fig, sc, "attitude tracking")
    axs = fig.subplots(3, 1, sharex=True)
    meas, cmd, des = _angles_deg(s)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[i].plot(s["t"], meas[:, i], color=AXIS_COLOURS[i], lw=1.8,
                    label=f"{name} measured")
        axs[i].plot(s["t"], cmd[:, i], "k--", lw=1.0, label=f"{name} command (filtered)")
        axs[i].plot(s["t"], des[:, i], color="0.45", ls=":", lw=1.0,
                    label=f"{name} desired (before filter)")
        finish(axs[i], f"{name} [deg]", xlabel=i == 2)
    return fig


def fig_tether_length(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                      metrics: Mapping[str, Any] | None = None) -> Figure:
    """L-bar, L, distance and altitude on one axis."""
    fig = new_figure()
    title(fig, sc, "tether length tracking")
    ax = fig.add_subplot()
    t = s["t"]
    ax.plot(t, s["lbar"], color="k", ls="--", lw=1.4, label="desired length L-bar", zorder=3)
    ax.plot(t, s["length"], color=TETHER_COLOUR, lw=2.2, label="tether length L")
    ax.plot(t, np.linalg.norm(s["pos"], axis=1), color="C0", lw=1.2, ls="-.",
            label="distance |p| winder-UAV")
    ax.plot(t, s["pos"][:, 2], color="C2", lw=1.5, label="altitude z")
    finish(ax, "length, distance, altitude [m]", xlabel=True)
    return fig


def fig_lyapunov(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                 metrics: Mapping[str, Any] | None = None) -> Figure:
    """The three Lyapunov functions on a log scale."""
    fig = new_figure()
    title(fig, sc, "Lyapunov functions")
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
    thin_lines(ax)
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
    fig = new_figure(rows=3)
    title(fig, sc, "tether tension and winder")
    axs = fig.subplots(3, 1, sharex=True)
    t = s["t"]
    for j, ax in enumerate(axs):
        _shade_ground_contact(ax, t, s["regime"], label=j == 0)
    axs[0].plot(t, s["top_tension"], color="C3", label="tension at the UAV (top)")
    axs[0].plot(t, s["drum_tension"], color="C0", label="tension at the drum")
    if has_data(s, "winch_tension"):   # an imported up run: what the winch reported
        axs[0].plot(t, s["winch_tension"], color="C1", ls=":", lw=1.2,
                    label="tension reported by the winch (WINCH_STATUS)")
    finish(axs[0], "tension [N]")
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
    finish(axs[1], "torque [N m]")
    axs[2].plot(t, s["drum_rate"], color="C2", label="drum rate (+ pays out)")
    axs[2].axhline(0.0, color="k", lw=0.6)
    finish(axs[2], "drum rate [rad/s]", xlabel=True)
    return fig


def fig_estimate(s: Mapping[str, np.ndarray], sc: ScenarioParams,
                 metrics: Mapping[str, Any] | None = None) -> Figure:
    """Estimate minus truth per axis with the filter's 3-sigma band; the speed error."""
    fig = new_figure(rows=4)
    title(fig, sc, "onboard estimate against the truth")
    t = s["t"]
    err = s["est_pos"] - s["pos"]
    sig = 3.0 * s["est_pos_sigma"]
    axes = fig.subplots(4, 1, sharex=True)
    for i, (ax, name) in enumerate(zip(axes[:3], ("x (east)", "y (north)", "z (up)"),
                                       strict=True)):
        ax.fill_between(t, -sig[:, i], sig[:, i], color=AXIS_COLOURS[i], alpha=0.2,
                        label="filter's 3 sigma")
        ax.plot(t, err[:, i], color=AXIS_COLOURS[i], lw=1.0, label=f"{name} error")
        finish(ax, "[m]")
    dv = np.linalg.norm(s["est_vel"][:, :2], axis=1) - np.linalg.norm(s["vel"][:, :2],
                                                                      axis=1)
    axes[3].plot(t, dv, color="k", lw=0.8, label="horizontal speed error")
    finish(axes[3], "[m/s]", xlabel=True)
    return fig

