"""A soak: ``tuav-sitl up --speedup max`` hovering for a long wall time (an hour by
default), in a private network namespace. Measured: each process's resident memory a tenth
of the way in (past the start-up) and at the end, and its largest (sampled every
``SAMPLE_S``), the plant's missed deadlines and periods from its own summary, the simulated
time flown, and each log's size, with the logs' volume per simulated hour (docs/usage.md
quotes it).

``python -m benchmarks.soak [--wall-s S]`` prints the rows; ``python -m benchmarks --soak``
adds them to the table. Not a test: it takes its wall time by design.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_S = 10.0
#: Memory is compared with the sample at this fraction (1/N) of the flight, past the
#: start-up (whose first samples are the kernels loading or compiling).
SETTLED = 10
#: The processes whose memory is followed: their command lines' module.
PROCESSES = {"plant": "-m sitl", "companion": "-m companion",
             "groundstation": "-m groundstation", "recorder": "tuav_sitl candump"}
LOGS = ("truth.csv", "flight.tlog", "can.log", "recording.rrd", "logs")

_SESSION = r"""
import json, os, signal, subprocess, sys, time
from pathlib import Path
sys.path.insert(0, {root!r})
from benchmarks.soak import PROCESSES, SAMPLE_S, rss_mb
logdir, wall = Path(sys.argv[1]), float(sys.argv[2])
up = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--speedup", "max",
                       "--can", "udp_multicast", "--headless", "--position", "6", "2", "12",
                       "--logdir", str(logdir), "--instance", "8"], cwd={root!r},
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
samples = []
t0 = time.monotonic()
while up.poll() is None and time.monotonic() - t0 < wall:
    time.sleep(SAMPLE_S)
    samples.append(rss_mb(logdir))
up.send_signal(signal.SIGINT)
so, se = up.communicate(timeout=120)
print(json.dumps({{"samples": samples, "rc": up.returncode, "stderr": se[-2000:]}}))
"""


def rss_mb(logdir: Path) -> dict[str, float]:
    """Resident memory [MB] of each of :data:`PROCESSES` of the run under ``logdir`` running
    now (by command line: each names a file of its run folder)."""
    out: dict[str, float] = {}
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            continue
        for name, marker in PROCESSES.items():
            if marker in cmd and str(logdir) in cmd:
                m = re.search(r"VmRSS:\s+(\d+) kB", status)
                if m:
                    out[name] = int(m.group(1)) / 1024.0
    return out


def soak(wall_s: float) -> dict:
    """Fly the soak; its measurements."""
    from tuav_sitl.netns import run_in_netns

    with tempfile.TemporaryDirectory(prefix="tuav-soak-") as work:
        logdir = Path(work) / "runs"
        script = Path(work) / "session.py"
        script.write_text(_SESSION.format(root=str(ROOT)))
        res = run_in_netns([sys.executable, str(script), str(logdir), repr(wall_s)],
                           timeout_s=wall_s + 600, cwd=str(ROOT))
        if res.returncode != 0:
            raise RuntimeError(res.stderr.strip()[-500:])
        session = json.loads(res.stdout.strip().splitlines()[-1])
        run = next(logdir.iterdir())
        last = (run / "plant.log").read_text().strip().splitlines()[-1]
        sim = re.search(r"([\d.]+) s simulated", last)
        periods = re.search(r"(\d+) periods", last)
        missed = re.search(r"(\d+) missed deadlines", last)
        sizes = {}
        for name in LOGS:
            p = run / name
            if p.is_dir():
                sizes[name] = sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
            elif p.exists():
                sizes[name] = p.stat().st_size
    samples = session["samples"]
    memory = {}
    for name in PROCESSES:
        seen = [s[name] for s in samples if name in s]
        if seen:
            # (the first samples are the start-up's: its kernels loaded, or compiled)
            memory[name] = {"first_mb": seen[0], "settled_mb": seen[len(seen) // SETTLED],
                            "last_mb": seen[-1], "max_mb": max(seen)}
    sim_s = float(sim.group(1)) if sim else float("nan")
    return {"wall_s": wall_s, "sim_s": sim_s, "memory": memory,
            "periods": int(periods.group(1)) if periods else None,
            "missed": int(missed.group(1)) if missed else None,
            "log_bytes": sizes,
            "mb_per_sim_hour": {k: (v / 1e6 * 3600.0 / sim_s if sim_s > 0.0 else math.nan)
                                for k, v in sizes.items()},
            "up_rc": session["rc"], "plant_summary": last}


def bench_soak(quick: bool, wall_s: float | None = None) -> list:
    """The rows of this benchmark (``benchmarks.__main__.Row``)."""
    from benchmarks.__main__ import Row
    from tuav_sitl.netns import netns_available

    why = netns_available()
    if why is not None:
        return [Row("soak: up --speedup max", float("nan"), "", note=f"skipped: {why}")]
    wall = wall_s if wall_s is not None else (60.0 if quick else 3600.0)
    t0 = time.monotonic()
    try:
        r = soak(wall)
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        return [Row("soak: up --speedup max", float("nan"), "", note=f"failed: {exc}")]
    rows = [Row(f"soak: up --speedup max for {wall:.0f} s of wall time", r["sim_s"],
                "s simulated",
                note=(f"{r['periods']} periods, {r['missed']} missed deadlines; up exit "
                      f"{r['up_rc']}; {time.monotonic() - t0:.0f} s in all"))]
    for name, m in r["memory"].items():
        rows.append(Row(f"soak: {name} resident memory, end (a tenth in)", m["last_mb"],
                        "MB", reference=m["settled_mb"],
                        note=f"largest {m['max_mb']:.0f} MB, first sample "
                             f"{m['first_mb']:.0f} MB (the start-up)"))
    for name, per_hour in r["mb_per_sim_hour"].items():
        rows.append(Row(f"soak: {name} per simulated hour", per_hour, "MB",
                        note=f"{r['log_bytes'][name] / 1e6:.1f} MB over {r['sim_s']:.0f} s"))
    return rows


def main(argv: list[str] | None = None) -> int:
    """Run the soak alone and print its rows."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.soak", description=__doc__)
    ap.add_argument("--wall-s", type=float, default=3600.0, help="wall time to fly [s]")
    args = ap.parse_args(argv)
    for r in bench_soak(False, args.wall_s):
        value = f"{r.value:12.4g}" if r.value == r.value else f"{'-':>12s}"
        ref = f"{r.reference:10.3g}" if r.reference is not None else " " * 10
        print(f"{r.name:56s} {value} {r.unit:14s} {ref}  {r.note}")
    return 0


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(main())
