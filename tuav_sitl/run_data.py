"""A run folder's contents as arrays: the time series, the scenario and the metrics.

A run folder written by :mod:`tuav_sitl.offline` (or imported from a ``tuav-sitl up`` run by
:mod:`tuav_sitl.run_import`) holds ``timeseries.npz``, ``metrics.json`` and
``scenario.toml``; the figures (:mod:`tuav_sitl.figures`), the animation and the live view's
replay read it through :func:`load_run`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tuav_sitl.scenario import ScenarioParams
from tuavdefs.paramspec import load_toml

__all__ = ["RunData", "has_data", "load_run"]

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
