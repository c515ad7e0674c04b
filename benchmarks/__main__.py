"""``python -m benchmarks``: every benchmark, one table of medians and same-run ratios.

Machines here are noisy, so each figure that has a reference is measured against it in
the same run, interleaved, and reported as a ratio of medians. ``--quick`` runs each
benchmark once in a tiny configuration (the test suite does this to keep them working).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class Row:
    """One line of the table."""

    name: str
    value: float
    unit: str
    reference: float | None = None
    ratio_text: str = ""
    note: str = ""


def _median_time_us(fn: Callable[[], object], repeats: int) -> float:
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - t0) * 1e6)
    return statistics.median(samples)


def _tether_cases(n: int, seed: int = 7) -> list[tuple[float, float, float, float, float]]:
    """Random (span, height, length, EA, w) across suspended, taut, touchdown, slack and
    near-vertical regimes."""
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        span, height = rng.uniform(0.0, 60.0), rng.uniform(0.5, 50.0)
        chord = math.hypot(span, height)
        kind = i % 5
        if kind == 0:      # taut, stretched
            length = chord * rng.uniform(0.97, 0.999)
        elif kind == 1:    # suspended
            length = chord * rng.uniform(1.001, 1.05)
        elif kind == 2:    # touchdown / slack
            length = rng.uniform(chord * 1.05, span + height + 10.0)
        elif kind == 3:    # near vertical
            span = height * rng.uniform(0.0, 0.01)
            length = math.hypot(span, height) * rng.uniform(0.98, 1.3)
        else:              # the project's tether
            length = chord * rng.uniform(1.001, 1.3)
        ea = 1.1e5 if kind == 4 else 10 ** rng.uniform(3, 7)
        w = 0.034 * 9.81 if kind == 4 else rng.uniform(0.05, 2.0)
        cases.append((span, height, max(length, 0.5), ea, w))
    return cases


def bench_tether(quick: bool) -> list[Row]:
    """The project's catenary against MoorPy's on the same cases, cold and warm."""
    from sitl.catenary import catenary_end_forces

    try:
        from moorpy.Catenary import catenary as moorpy_catenary
    except ImportError:  # MoorPy is a test extra
        moorpy_catenary = None
    cases = _tether_cases(20 if quick else 1000)
    rounds = 1 if quick else 5
    ours_cold, ours_warm, mp_cold, mp_warm, disagreement = [], [], [], [], 0.0
    below_ground = 0
    for case in cases:
        r = catenary_end_forces(*case)
        info = r[4]
        moved = (case[0] + 1e-3, case[1] + 1e-3, case[2] + 1e-3, case[3], case[4])
        ours_cold.append(_median_time_us(lambda c=case: catenary_end_forces(*c), rounds))
        ours_warm.append(_median_time_us(
            lambda c=moved, h=info.hf_n, v=info.vf_n: catenary_end_forces(*c, hf0=h, vf0=v),
            rounds))
        if moorpy_catenary is None:
            continue
        try:
            m = moorpy_catenary(*case, CB=0, Tol=1e-10)
        except Exception:  # noqa: BLE001 - MoorPy's own failures are skipped, not ours
            continue
        scale = max(max(abs(f) for f in m[:4]), 1e-4)
        if m[1] < -1e-9 * scale:
            # MoorPy pulls the bottom end down: its line passes below the ground, where this
            # solver lays it on the ground instead (docs/model.md); not comparable
            below_ground += 1
        else:
            disagreement = max(disagreement, max(abs(a - b) for a, b in zip(
                r[:4], m[:4], strict=True)) / scale)
        mp_cold.append(_median_time_us(lambda c=case: moorpy_catenary(*c, CB=0), rounds))
        hf, vf = abs(m[4].get("HF", 0.0)), abs(m[4].get("VF", 0.0))
        mp_warm.append(_median_time_us(
            lambda c=moved, h=hf, v=vf: moorpy_catenary(*c, CB=0, HF0=h, VF0=v), rounds))
    rows = [Row("tether solve, cold", statistics.median(ours_cold), "us"),
            Row("tether solve, warm-started", statistics.median(ours_warm), "us")]
    if mp_cold:
        rows[0].reference = statistics.median(mp_cold)
        rows[1].reference = statistics.median(mp_warm)
        for r in rows:
            r.ratio_text = f"{r.reference / r.value:.0f}x faster than MoorPy"
        rows.append(Row("tether: largest relative disagreement", disagreement, "",
                        note=f"{len(mp_cold) - below_ground} cases at MoorPy Tol 1e-10; "
                             f"{below_ground} where MoorPy's line goes below the ground "
                             "left out"))
    return rows


def bench_plant_step(quick: bool) -> list[Row]:
    """One RK4 step of the full truth model (UAV, tether, winder, wind) in hover trim."""
    from sitl.plant import Plant
    from sitl.trim import hover_trim
    from tuavdefs.params import SystemParams, WindParams

    params = SystemParams().replace(wind=WindParams(steady_m_s=(3.0, 0.0, 0.0),
                                                    turbulence="moderate"))
    x, u = hover_trim(params, (10.0, 4.0, 20.0), 24.0)
    rows = []
    n = 50 if quick else 3000
    per_sim_s = {}
    for rate in (1000.0, 2000.0):
        plant = Plant(params, dt_s=1.0 / rate, state=x)
        for _ in range(5):  # compile (or load) the kernel before timing
            plant.step(u)
        t0 = time.perf_counter()
        for _ in range(n):
            plant.step(u)
        us = (time.perf_counter() - t0) / n * 1e6
        per_sim_s[rate] = us * rate / 1e6
        rows.append(Row(f"plant step at {rate:.0f} Hz physics", us, "us",
                        note=f"{1.0 / (us * rate / 1e6):.1f}x real time for the plant alone"))
    rows[1].reference = rows[0].value
    rows[1].ratio_text = (f"{per_sim_s[2000.0] / per_sim_s[1000.0]:.2f}x the cost per "
                          "simulated second of 1 kHz")
    return rows


def bench_offline(quick: bool) -> list[Row]:
    """``tuav-sitl run circle``: simulated seconds per wall second, and where time goes."""
    import cProfile
    import pstats

    from tuav_sitl.offline import OfflineRunner
    from tuav_sitl.scenario import load_scenario

    duration = 1.0 if quick else 20.0
    sc = load_scenario("circle").replace(duration_s=duration, metrics_after_s=0.0)
    runner = OfflineRunner(sc)
    t0 = time.perf_counter()
    runner.run()
    wall = time.perf_counter() - t0
    rows = [Row("offline closed loop (circle)", duration / wall, "sim s / wall s",
                note=f"{duration:.0f} s simulated in {wall:.2f} s; physics 1 kHz, "
                     "control 250 Hz, winder 100 Hz")]
    prof = cProfile.Profile()
    runner = OfflineRunner(sc.replace(duration_s=min(duration, 5.0)))
    prof.enable()
    runner.run()
    prof.disable()
    stats = pstats.Stats(prof)
    total = max(stats.total_tt, 1e-9)
    shares: dict[str, float] = {}
    wanted = {"plant physics": ("sitl/plant.py", "step"),
              "position loop": ("companion/position.py", "update"),
              "attitude loop": ("companion/attitude.py", "update"),
              "onboard tether model": ("companion/tether_model.py", "estimate"),
              "L-bar estimator": ("groundstation/lbar.py", "estimate"),
              "winder law": ("groundstation/winder_control.py", "update"),
              "mixer": ("tuavdefs/airframe.py", "mix"),
              "reference": ("tuav_sitl/offline.py", "sample")}
    for (file, _line, func), stat in stats.stats.items():  # type: ignore[attr-defined]
        for label, (suffix, fname) in wanted.items():
            if file.endswith(suffix) and func == fname:
                shares[label] = shares.get(label, 0.0) + stat[3] / total
    for label, share in sorted(shares.items(), key=lambda kv: -kv[1]):
        rows.append(Row(f"  share: {label}", 100.0 * share, "% of run time"))
    return rows


NOT_YET = [
    "three-process lockstep stack (needs tuav-sitl up)",
    "real-time control-loop jitter (needs the companion process)",
    "COMMAND_LONG -> COMMAND_ACK and Set_Input_Torque latency (needs the processes)",
]


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks and print the table."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    ap.add_argument("--quick", action="store_true", help="tiny configuration, for tests")
    args = ap.parse_args(argv)
    rows: list[Row] = []
    for bench in (bench_tether, bench_plant_step, bench_offline):
        rows.extend(bench(args.quick))
    print(f"tuav-sitl benchmarks{' (quick)' if args.quick else ''}: "
          f"{platform.python_implementation()} {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} cores")
    print(f"{'benchmark':56s} {'median':>12s} {'unit':16s} {'reference':>10s}  ratio / note")
    for r in rows:
        ref = f"{r.reference:10.3g}" if r.reference is not None else " " * 10
        extra = "; ".join(x for x in (r.ratio_text, r.note) if x)
        print(f"{r.name:56s} {r.value:12.4g} {r.unit:16s} {ref}  {extra}")
    for item in NOT_YET:
        print(f"{item:56s} {'-':>12s} {'':16s} {'':10s}  not measured yet")
    return 0


if __name__ == "__main__":
    sys.exit(main())
