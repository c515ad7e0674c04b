"""The runs a sweep keeps: its worst failed runs flown again into run folders.

A sweep's rows are metrics only. So that its failures can be looked at as any run is (its
figures, ``tuav-sitl plot``, its ``recording.rrd`` in ``tuav-sitl view``), ``tuav-sitl
sweep --keep N`` flies the N failed runs with the largest position error again, each with
the draws of its index (:func:`tuav_sitl.sweep.run_scenario_of`: a run depends only on the
sweep and its index, so the folder is the run the row counted), into
``OUT/runs/run-INDEX/``. A run that did not fly (refused, error) has nothing to keep.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from tuavdefs.paramspec import ParameterError

#: How many failed runs ``tuav-sitl sweep`` keeps unless told (``--keep``).
DEFAULT_KEEP = 3


def runs_to_keep(rows: list[dict[str, Any]], n: int) -> list[dict[str, Any]]:
    """The ``n`` failed rows that flew, the largest position error first (then by index)."""
    def error(row: dict[str, Any]) -> float:
        e = row.get("position_max_error_m")
        return e if e is not None and math.isfinite(e) else math.inf

    flew = [r for r in rows if r.get("failed") and r.get("position_rmse_m") is not None]
    return sorted(flew, key=lambda r: (-error(r), r["index"]))[:max(n, 0)]


def kept_folder(out_dir: Path, index: int) -> Path:
    """The run folder of run ``index`` in the sweep's output folder ``out_dir``."""
    return Path(out_dir) / "runs" / f"run-{index:04d}"


def keep_runs(sweep: Any, sc: Any, rows: list[dict[str, Any]], out_dir: Path, n: int,
              recording: bool = True) -> list[Path]:
    """Fly :func:`runs_to_keep` again into their run folders under ``out_dir`` (each with
    its ``recording.rrd`` where rerun-sdk is installed and ``recording``); their paths."""
    from tuav_sitl.offline import run_scenario
    from tuav_sitl.sweep import run_scenario_of

    if n < 0:
        raise ParameterError("--keep", f"must be >= 0, got {n}")
    kept = []
    for row in runs_to_keep(rows, n):
        folder = kept_folder(out_dir, row["index"])
        result = run_scenario(run_scenario_of(sweep, sc, row["index"]), folder,
                              progress=None, recording=recording)
        if result.recording is not None:
            result.recording.wait()
        kept.append(folder)
    return kept
