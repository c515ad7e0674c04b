"""The summary of a sweep (``tuav-sitl sweep``): failures by kind with the failure rate's
exact binomial interval, the metrics' percentiles, what the failures correlate with, and,
for a sweep with an ``[envelope]``, the envelope over one drawn quantity: a table by its
bins (the worst run of each) and the values where each limit is first passed (the pull
at the UAV, the rotors' saturation, the tether taut or on the ground, the vehicle no longer
controlled). Written as ``summary.json`` and ``summary.md``; docs/usage.md."""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from tuav_sitl.sweep import METRIC_COLUMNS, Distribution, EnvelopeParams, FailureKind, SweepParams


def binomial_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) confidence interval of a rate seen as ``k`` of ``n``."""
    from scipy.stats import beta

    a = 1.0 - confidence
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


PERCENTILES = (5, 50, 95, 100)


def summarise(sweep: SweepParams, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Failures by kind, the failure rate and its 95 % interval, each metric's percentiles,
    and for each drawn quantity how the failures depend on it."""
    n = len(rows)
    failed = np.array([r["failed"] for r in rows], dtype=bool)
    k = int(failed.sum())
    by_kind = {f.value: sum(f.value in r["failures"].split(";") for r in rows)
               for f in FailureKind}
    lo, hi = binomial_interval(k, n) if n else (math.nan, math.nan)
    pct: dict[str, dict[str, float]] = {}
    for c in METRIC_COLUMNS:
        vals = np.array([r[c] for r in rows if r[c] is not None], dtype=float)
        vals = vals[np.isfinite(vals)]
        if len(vals):
            pct[c] = {f"p{p}": float(np.percentile(vals, p)) for p in PERCENTILES}
    corr: dict[str, Any] = {}
    for v in sweep.vary:
        col = [r[v.parameter] for r in rows]
        if v.kind.is_label or v.dist is Distribution.CHOICE:
            corr[v.parameter] = {"failure_rate_by_value": {
                str(val): _rate(failed[[c == val for c in col]])
                for val in sorted(set(col), key=str)}}
            continue
        x = np.array(col, dtype=float)
        r = (float(np.corrcoef(x, failed)[0, 1])
             if n > 2 and x.std() > 0 and 0 < k < n else None)
        med = float(np.median(x)) if n else math.nan
        corr[v.parameter] = {"correlation_with_failure": r,
                            "failure_rate_below_median": _rate(failed[x <= med]),
                            "failure_rate_above_median": _rate(failed[x > med])}
    for i, f in enumerate(sweep.faults):
        had = np.array([r[f.columns(i)[0]] is not None for r in rows], dtype=bool)
        corr[f"fault{i}_{f.fault.kind}"] = {"failure_rate_by_value": {
            "with": _rate(failed[had]), "without": _rate(failed[~had])}}
    out = {"sweep": sweep.name, "scenario": sweep.scenario, "runs": n, "failed": k,
           "failure_rate": k / n if n else None, "failure_rate_95ci": [lo, hi],
           "failures_by_kind": by_kind, "percentiles": pct, "failures_against": corr}
    if sweep.envelope.over:
        out["envelope"] = envelope(sweep.envelope, rows)
    return out


def _rate(x: np.ndarray) -> float | None:
    return float(x.mean()) if len(x) else None


def summary_text(s: dict[str, Any]) -> str:
    """The summary as Markdown."""
    lo, hi = s["failure_rate_95ci"]
    rate = s["failure_rate"]
    lines = [f"# sweep {s['sweep']} over {s['scenario']}: {s['runs']} runs", "",
             f"failed: {s['failed']} of {s['runs']} ({_pct(rate)}; 95 % interval "
             f"{_pct(lo)} to {_pct(hi)})", "", "| failure | runs |", "|---|---|"]
    lines += [f"| {kind} | {cnt} |" for kind, cnt in s["failures_by_kind"].items()]
    lines += ["", "| metric | " + " | ".join(f"p{p}" for p in PERCENTILES) + " |",
              "|---|" + "---|" * len(PERCENTILES)]
    for c, q in s["percentiles"].items():
        lines.append(f"| {c} | " + " | ".join(f"{q[f'p{p}']:.4g}" for p in PERCENTILES)
                     + " |")
    lines += ["", "| drawn | failures against it |", "|---|---|"]
    for name, c in s["failures_against"].items():
        if "failure_rate_by_value" in c:
            text = ", ".join(f"{k}: {_pct(v)}" for k, v in c["failure_rate_by_value"].items())
        else:
            r = c["correlation_with_failure"]
            text = (f"correlation {r:+.2f}, " if r is not None else "") + (
                f"failure rate {_pct(c['failure_rate_below_median'])} below the median, "
                f"{_pct(c['failure_rate_above_median'])} above")
        lines.append(f"| {name} | {text} |")
    if "envelope" in s:
        lines += envelope_text(s["envelope"])
    return "\n".join(lines) + "\n"


def _pct(v: float | None, digits: int = 1) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{100 * v:.{digits}f} %"




# --- the envelope ------------------------------------------------------------------------

#: The failures that say the vehicle was not controlled: its position error beyond bounds,
#: down on its gear in flight, tilted beyond its bound, or it could not fly at all.
LOST_CONTROL = (FailureKind.DIVERGED, FailureKind.CRASHED, FailureKind.TILTED,
                FailureKind.ERROR, FailureKind.REFUSED)


def controlled(row: dict[str, Any]) -> bool:
    """Whether the run's vehicle stayed controlled (none of :data:`LOST_CONTROL`)."""
    kinds = set(row["failures"].split(";"))
    return not any(k.value in kinds for k in LOST_CONTROL)


class Limit(enum.Enum):
    """A limit the envelope finds the drawn quantity's value of."""

    PULL = "pull"                  #: the pull at the UAV's peak in flight above its limit
    SATURATION = "saturation"      #: the rotors saturated more than their limit
    TAUT = "taut"                  #: the tether taut (its least slack at or below target)
    GROUND = "ground"              #: the tether on the ground while the vehicle flies
    LOST_CONTROL = "lost_control"  #: the vehicle not controlled (:func:`controlled`)

    def passed(self, row: dict[str, Any], env: EnvelopeParams) -> bool:
        """Whether run ``row`` passes this limit (a metric the run lacks: not passed,
        except control, which a run that did not fly has lost)."""
        def above(col: str, limit: float) -> bool:
            v = row.get(col)
            return v is not None and math.isfinite(v) and v > limit

        if self is Limit.PULL:
            return above("tension_peak_flying_n", env.pull_limit_n)
        if self is Limit.SATURATION:
            return above("motor_saturation_fraction", env.saturation_limit_fraction)
        if self is Limit.TAUT:
            return above("taut_time_s", 0.0)
        if self is Limit.GROUND:
            return above("ground_flying_s", 0.0)
        return not controlled(row)


def _describe(limit: Limit, env: EnvelopeParams) -> str:
    return {Limit.PULL: f"the pull at the UAV above {env.pull_limit_n:g} N",
            Limit.SATURATION: "the rotors saturated above "
                              f"{100 * env.saturation_limit_fraction:g} % of the flight",
            Limit.TAUT: "the tether taut",
            Limit.GROUND: "the tether on the ground in flight",
            Limit.LOST_CONTROL: "the vehicle not controlled"}[limit]


def thresholds(env: EnvelopeParams, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """For each :class:`Limit`: the least value of the envelope's quantity among the runs
    that pass it (``first``, None if none does), how many of the runs do (``runs``), and
    among the runs at or above ``first`` the fraction that do (``fraction_from_first``)."""
    out: dict[str, Any] = {}
    xs = [r[env.over] for r in rows]
    for limit in Limit:
        hit = [limit.passed(r, env) for r in rows]
        at = [x for x, h in zip(xs, hit, strict=True) if h]
        first = min(at) if at else None
        beyond = [h for x, h in zip(xs, hit, strict=True) if first is not None and x >= first]
        out[limit.value] = {"first": first, "runs": len(at),
                            "fraction_from_first": (sum(beyond) / len(beyond) if beyond
                                                    else None)}
    return out


#: The envelope table's columns: (name, the row's metric, how a bin's runs combine).
ENVELOPE_COLUMNS: tuple[tuple[str, str, Callable[[list[float]], float]], ...] = (
    ("pull_peak_n", "tension_peak_flying_n", max),
    ("pull_p99_n", "tension_p99_flying_n", max),
    ("saturation_fraction", "motor_saturation_fraction", max),
    ("least_slack_m", "min_tether_slack_m", min),
    ("taut_s", "taut_time_s", max),
    ("ground_s", "ground_flying_s", max),
    ("position_rmse_m", "position_rmse_m", max),
    ("position_max_error_m", "position_max_error_m", max),
    ("max_tilt_deg", "max_tilt_deg", max),
    ("position_loop_saturation_fraction", "position_loop_saturation_fraction", max),
)


def envelope_table(env: EnvelopeParams, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The runs by bins of ``env.bin_width`` of the envelope's quantity (from the multiple
    of the width at or below the least value): each bin's bounds, its runs, how many were
    controlled and met every target, and the worst of its runs in each of
    :data:`ENVELOPE_COLUMNS` (None where no run of the bin has the metric). Empty bins
    are left out."""
    xs = np.array([r[env.over] for r in rows], dtype=float)
    if not len(xs):
        return []
    w = env.bin_width
    k0 = math.floor(xs.min() / w)
    index = np.floor(xs / w).astype(int) - k0
    table = []
    for i in range(int(index.max()) + 1):
        sel = [r for r, j in zip(rows, index, strict=True) if j == i]
        if not sel:
            continue
        lo = (k0 + i) * w
        entry: dict[str, Any] = {"low": lo, "high": lo + w, "runs": len(sel),
                                 "controlled": sum(controlled(r) for r in sel),
                                 "passed": sum(not r["failed"] for r in sel)}
        for name, col, worst in ENVELOPE_COLUMNS:
            vals = [r[col] for r in sel if r.get(col) is not None and math.isfinite(r[col])]
            entry[name] = float(worst(vals)) if vals else None
        table.append(entry)
    return table


def envelope(env: EnvelopeParams, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The envelope's part of the summary: its settings, table and thresholds."""
    return {"over": env.over, "bin_width": env.bin_width, "pull_limit_n": env.pull_limit_n,
            "saturation_limit_fraction": env.saturation_limit_fraction,
            "range": ([min(r[env.over] for r in rows), max(r[env.over] for r in rows)]
                      if rows else None),
            "table": envelope_table(env, rows), "thresholds": thresholds(env, rows)}


def envelope_text(e: dict[str, Any]) -> list[str]:
    """The envelope's lines of the summary's Markdown."""
    env = EnvelopeParams(over=e["over"], bin_width=e["bin_width"],
                         pull_limit_n=e["pull_limit_n"],
                         saturation_limit_fraction=e["saturation_limit_fraction"])
    over = e["over"]
    lo, hi = e["range"] or (math.nan, math.nan)
    lines = ["", f"**Envelope over {over}** (runs from {lo:.3g} to {hi:.3g}): where a "
             "limit is first passed (the least value among the runs that pass it; how many "
             "do, and the share of the runs from there on):", ""]
    for limit in Limit:
        t = e["thresholds"][limit.value]
        what = _describe(limit, env)
        if t["first"] is None:
            lines.append(f"- {what}: in no run (up to {hi:.3g})")
        else:
            lines.append(f"- {what}: from {t['first']:.3g} ({t['runs']} runs; "
                         f"{_pct(t['fraction_from_first'])} of the runs from there on)")
    lines += ["", f"The worst run of each bin of {over} (the pull at the UAV, its peak and "
              "99th percentile in flight after the lead-in; the rotors' saturation; the "
              "tether's least slack, time taut and time on the ground in flight; the "
              "position error; the largest tilt; the position loop at its tilt or thrust "
              "limit):", "",
              f"| {over} | runs | controlled | passed | pull peak [N] | pull p99 [N] | "
              "rotors saturated | least slack [m] | taut [s] | on ground [s] | position "
              "RMSE [m] | max error [m] | max tilt [deg] | position loop at its limit |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for b in e["table"]:
        cells = [_num(b["pull_peak_n"], ".1f"), _num(b["pull_p99_n"], ".1f"),
                 _pct(b["saturation_fraction"], 2), _num(b["least_slack_m"], ".3f"),
                 _num(b["taut_s"], ".2f"), _num(b["ground_s"], ".2f"),
                 _num(b["position_rmse_m"], ".3f"), _num(b["position_max_error_m"], ".2f"),
                 _num(b["max_tilt_deg"], ".1f"),
                 _pct(b["position_loop_saturation_fraction"], 1)]
        lines.append(f"| {b['low']:g}–{b['high']:g} | {b['runs']} | {b['controlled']} | "
                     f"{b['passed']} | " + " | ".join(cells) + " |")
    return lines


def _num(v: float | None, fmt: str) -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)
