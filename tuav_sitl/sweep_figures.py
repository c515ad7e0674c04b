"""Figures of a sweep (``tuav-sitl sweep``): the metrics' distributions and the failures
against the drawn parameters, drawn from the table's rows into ``figures/`` of the sweep's
folder (bare matplotlib Figures, rendered with Agg when saved)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from tuav_sitl.figure_style import DPI
from tuav_sitl.sweep import FailureKind, SweepParams

#: The metrics whose distributions are drawn (when the table has them).
CDF_METRICS = ("position_rmse_m", "position_max_error_m", "min_tether_slack_m",
               "tether_ground_contact_fraction", "motor_saturation_fraction",
               "estimate_position_rmse_m")


def fig_cdfs(sweep: SweepParams, rows: list[dict[str, Any]]) -> Figure:
    """Empirical CDF of each metric over the runs, its target where it has one."""
    targets = {"position_rmse_m": sweep.targets.position_rmse_m,
               "min_tether_slack_m": sweep.targets.min_tether_slack_m,
               "motor_saturation_fraction": sweep.targets.motor_saturation_fraction,
               "position_max_error_m": sweep.targets.diverged_error_m}
    shown = [m for m in CDF_METRICS if any(r.get(m) is not None for r in rows)]
    fig = Figure(figsize=(10, 2.6 * ((len(shown) + 1) // 2)))
    for i, name in enumerate(shown):
        ax = fig.add_subplot((len(shown) + 1) // 2, 2, i + 1)
        v = np.sort([r[name] for r in rows if r.get(name) is not None])
        v = v[np.isfinite(v)]
        ax.step(v, np.arange(1, len(v) + 1) / len(v), where="post")
        if name in targets:
            ax.axvline(targets[name], color="C3", ls="--", label="target")
            ax.legend(loc="lower right", fontsize=8)
        ax.set_xlabel(name, fontsize=9)
        ax.set_ylabel("fraction of runs", fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle(f"sweep {sweep.name}: {len(rows)} runs of {sweep.scenario}")
    fig.tight_layout()
    return fig


def fig_failures_against(sweep: SweepParams, rows: list[dict[str, Any]]) -> Figure:
    """Each drawn parameter against the position RMSE (log scale), a run's colour by its
    first failure kind (passed runs grey)."""
    vary = sweep.vary
    n = max(len(vary), 1)
    cols = min(n, 3)
    fig = Figure(figsize=(4.2 * cols, 3.2 * ((n + cols - 1) // cols)))
    kinds = [k.value for k in FailureKind]
    for i, v in enumerate(vary):
        ax = fig.add_subplot((n + cols - 1) // cols, cols, i + 1)
        labels = sorted({str(r[v.parameter]) for r in rows}) if v.kind.is_label else None
        for kind in ["", *kinds]:
            sel = [r for r in rows if (r["failures"].split(";")[0] == kind)]
            if not sel:
                continue
            x = ([labels.index(str(r[v.parameter])) for r in sel] if labels is not None
                 else [r[v.parameter] for r in sel])
            y = [max(r["position_rmse_m"] or np.nan, 1e-4) for r in sel]
            ax.scatter(x, y, s=12, color="0.6" if kind == "" else f"C{kinds.index(kind)}",
                       label=kind or "passed")
        if labels is not None:
            ax.set_xticks(range(len(labels)), labels)
        ax.axhline(sweep.targets.position_rmse_m, color="C3", ls="--", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel(v.parameter, fontsize=9)
        ax.set_ylabel("position RMSE [m]", fontsize=9)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7)
    fig.suptitle(f"sweep {sweep.name}: failures against the drawn parameters "
                 "(colour: the first failure kind)")
    fig.tight_layout()
    return fig


#: The envelope figure's panels: (the row's metric, its label, the scale to draw it in,
#: the limit's source: a SweepParams attribute path, or None).
ENVELOPE_PANELS = (
    ("tension_peak_flying_n", "pull at the UAV, peak in flight [N]", 1.0,
     "envelope.pull_limit_n"),
    ("tension_p99_flying_n", "pull at the UAV, p99 in flight [N]", 1.0,
     "envelope.pull_limit_n"),
    ("motor_saturation_fraction", "rotors saturated [% of the flight]", 100.0,
     "envelope.saturation_limit_fraction"),
    ("min_tether_slack_m", "tether's least slack [m]", 1.0, "targets.min_tether_slack_m"),
    ("ground_flying_s", "tether on the ground in flight [s]", 1.0, None),
    ("position_rmse_m", "position RMSE [m]", 1.0, "targets.position_rmse_m"),
    ("position_max_error_m", "largest position error [m]", 1.0, "targets.diverged_error_m"),
    ("max_tilt_deg", "largest tilt [deg]", 1.0, "targets.max_tilt_deg"),
    ("position_loop_saturation_fraction", "position loop at its limit [% of the flight]",
     100.0, None),
)


def fig_envelope(sweep: SweepParams, rows: list[dict[str, Any]]) -> Figure:
    """Each envelope metric of every run against the envelope's quantity, its limit
    dashed; the runs whose vehicle was not controlled in red."""
    from tuav_sitl.sweep_summary import controlled

    over = sweep.envelope.over
    fig = Figure(figsize=(12, 2.7 * ((len(ENVELOPE_PANELS) + 2) // 3)))
    ok = [controlled(r) for r in rows]
    for i, (col, label, scale, limit) in enumerate(ENVELOPE_PANELS):
        ax = fig.add_subplot((len(ENVELOPE_PANELS) + 2) // 3, 3, i + 1)
        for good, colour, name in ((True, "0.35", "controlled"), (False, "C3", "not")):
            sel = [r for r, g in zip(rows, ok, strict=True) if g == good
                   and r.get(col) is not None]
            ax.scatter([r[over] for r in sel], [scale * r[col] for r in sel], s=9,
                       color=colour, label=name)
        if limit is not None:
            group, field = limit.split(".")
            ax.axhline(scale * getattr(getattr(sweep, group), field), color="C3", ls="--",
                       lw=1)
        ax.set_xlabel(over, fontsize=9)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=7)
    fig.suptitle(f"sweep {sweep.name}: the envelope over {over} ({len(rows)} runs of "
                 f"{sweep.scenario}; dashed: the limit)")
    fig.tight_layout()
    return fig


def make_sweep_figures(sweep: SweepParams, rows: list[dict[str, Any]], out_dir: Path
                       ) -> list[Path]:
    """Write ``cdfs.png``, ``failures.png`` and, for a sweep with an envelope,
    ``envelope.png`` into ``out_dir/figures``."""
    folder = out_dir / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    figs = [("cdfs.png", fig_cdfs(sweep, rows)),
            ("failures.png", fig_failures_against(sweep, rows))]
    if sweep.envelope.over:
        figs.append(("envelope.png", fig_envelope(sweep, rows)))
    for name, fig in figs:
        path = folder / name
        fig.savefig(path, dpi=DPI)
        written.append(path)
    return written
