"""A full disk under a flying stack: ``tuav-sitl up`` (lockstep paced at 5x, the vehicle
hovering where it starts in the air) with its run folder on a small filesystem that a
filler file has left ``FREE_BYTES`` of room on, so that the run's logs (truth.csv,
flight.tlog, can.log, the onboard .bin, the recording) fill it within seconds; a ground
station on pymavlink watches. Run inside a private network namespace and a private mount
namespace whose tmpfs is ``argv[1]`` (tests/test_disk_full.py sets them up); prints one
JSON line: what up said and returned, the STATUSTEXTs heard, the vehicle's local
positions, the disk's free space at the end."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from tests.netns.up_session import processes_mentioning, wait_banner

ROOT = Path(__file__).resolve().parents[2]
POSITION = (6.0, 2.0, 12.0)
DURATION_S = 60.0      # simulated
FREE_BYTES = 1_500_000
INSTANCE = 6


def main() -> int:
    disk = Path(sys.argv[1])
    logdir = disk / "runs"
    logdir.mkdir()
    free = shutil.disk_usage(disk).free
    with open(disk / "filler", "wb") as f:
        f.truncate(0)
        block = b"\0" * (1 << 16)
        left = max(free - FREE_BYTES, 0)
        while left > 0:
            left -= f.write(block[:min(left, len(block))])
    up = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "up", "--speedup", "5", "--can", "udp_multicast",
         "--position", *map(str, POSITION), "--duration", str(DURATION_S),
         "--logdir", str(logdir), "--instance", str(INSTANCE)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict = {"banner": wait_banner(up), "free_at_start": FREE_BYTES}
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{5760 + 10 * INSTANCE}",
                                     source_system=255, source_component=190)
    texts: list[tuple[float, int, str]] = []
    positions: list[tuple[float, float, float, float]] = []
    sim_t = 0.0
    end_wall = time.monotonic() + 400.0
    while up.poll() is None and time.monotonic() < end_wall:
        m = gcs.recv_match(blocking=True, timeout=0.1)
        if m is None:
            continue
        if hasattr(m, "time_boot_ms"):
            sim_t = max(sim_t, m.time_boot_ms * 1e-3)
        kind = m.get_type()
        if kind == "STATUSTEXT":
            texts.append((sim_t, m.severity, m.text))
        elif kind == "LOCAL_POSITION_NED" and m.get_srcComponent() == 1:
            positions.append((sim_t, m.x, m.y, m.z))
    gcs.close()
    if up.poll() is None:
        up.send_signal(signal.SIGINT)
    so, se = up.communicate(timeout=60)
    out.update(up_rc=up.returncode, up_stdout=so[-3000:], up_stderr=se[-5000:],
               texts=texts, positions=positions[::10], last_sim_s=sim_t,
               free_at_end=shutil.disk_usage(disk).free,
               left=processes_mentioning(str(logdir)))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
