"""The first result as a user gets it: ``tuav-sitl run circle`` as a command, timed.

Rows: the run on a cold numba cache (an empty ``NUMBA_CACHE_DIR``: the first run after an
install, compiling every kernel; goal <= 30 s), and on a warm cache the run with its
figures and animation (goal <= 10 s) against the same run with ``--no-figures``, the two
interleaved (goal: at most twice as long). ``--quick`` times a 6 s circle once each and
leaves out the cold run (it compiles for a minute).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Goals [s] and the ratio goal (docs/performance.md).
COLD_GOAL_S = 30.0
WARM_GOAL_S = 10.0
RATIO_GOAL = 2.0


def _run(out: Path, *extra: str, env: dict[str, str] | None = None) -> float:
    """Wall time [s] of ``tuav-sitl run circle --out OUT EXTRA...`` in a fresh interpreter."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "circle", "--quiet",
                    "--out", str(out), *extra], cwd=ROOT, env=env or dict(os.environ),
                   check=True, capture_output=True, timeout=900)
    return time.perf_counter() - t0


def bench_first_result(quick: bool) -> list:
    """The rows of this benchmark (``benchmarks.__main__.Row``)."""
    from benchmarks.__main__ import Row

    rows = []
    extra = ("--duration", "6") if quick else ()
    with tempfile.TemporaryDirectory(prefix="tuav-first-") as tmp:
        out = Path(tmp) / "circle"
        if quick:
            rows.append(Row("first run, cold numba cache (circle, no figures)", float("nan"),
                            "", note="skipped in --quick (it compiles for a minute)"))
        else:
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba-cache"))
            cold = _run(out, "--no-figures", env=env)
            rows.append(Row("first run, cold numba cache (circle, no figures)", cold, "s",
                            note="an empty NUMBA_CACHE_DIR: every kernel compiled, the "
                                 "plant's and the controllers' in two processes at once",
                            goal=f"<= {COLD_GOAL_S:g} s: "
                                 f"{'met' if cold <= COLD_GOAL_S else 'NOT met'}"))
        if not quick:
            _run(out, "--no-figures")                # the cache warm for what follows
        plain, full = [], []
        for _ in range(1 if quick else 3):
            plain.append(_run(out, "--no-figures", *extra))
            full.append(_run(out, *extra))
    p, f = statistics.median(plain), statistics.median(full)
    what = "6 s circle" if quick else "circle, 75 s"
    rows.append(Row(f"first result: run with figures + animation ({what})", f, "s",
                    reference=p, ratio_text=f"{f / p:.2f}x the --no-figures run "
                    f"(goal <= {RATIO_GOAL:g}x: {'met' if f <= RATIO_GOAL * p else 'NOT met'})",
                    note="warm cache, the whole command",
                    goal=f"<= {WARM_GOAL_S:g} s: {'met' if f <= WARM_GOAL_S else 'NOT met'}"))
    rows.append(Row(f"  the same run with --no-figures ({what})", p, "s"))
    return rows
