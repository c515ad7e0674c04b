"""``tuav-sitl up`` hovering at (8, 4, 15) m in 3 m/s wind on the consumer receiver, GNSS
lost from 15 s to 35 s of simulated time, watched by a pymavlink ground station on UDP
14550: its STATUSTEXTs and EKF_STATUS_REPORT flags with the vehicle's time, then the plant's
truth.csv. Run inside a private network namespace; prints one JSON line."""

import json
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    base = Path(sys.argv[1])
    faults = base / "faults.toml"
    faults.write_text('[[faults]]\nkind = "gnss_loss"\nstart_s = 15.0\nend_s = 35.0\n')
    gcs = mavutil.mavlink_connection("udpin:127.0.0.1:14550", source_system=255,
                                     source_component=190)
    proc = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast", "--logdir",
         str(base / "runs"), "--speedup", "max", "--duration", "45", "--position", "8", "4",
         "15", "--goto", "8", "4", "15", "--gnss", "gnss", "--wind", "3,270", "--faults",
         str(faults), "--headless",
         # the catenary truth, as the hover-gnss-loss scenario (issue 33: on the lumped line
         # the tether fix does not yet hold the hover to 0.5 m)
         "--tether-model", "catenary", "--no-recording"], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    texts, ekf, t_ms = [], [], 0
    deadline = time.monotonic() + 300
    while proc.poll() is None and time.monotonic() < deadline:
        m = gcs.recv_match(blocking=True, timeout=0.5)
        if m is None:
            continue
        kind = m.get_type()
        if hasattr(m, "time_boot_ms"):
            t_ms = m.time_boot_ms
        if kind == "STATUSTEXT" and m.get_srcComponent() == 1:
            texts.append([t_ms / 1000.0, m.text])
        elif kind == "EKF_STATUS_REPORT":
            ekf.append([t_ms / 1000.0, m.flags, m.pos_horiz_variance])
    so, se = proc.communicate(timeout=60)
    run = next((base / "runs").iterdir())
    rows = (run / "truth.csv").read_text().splitlines()
    names = rows[0].split(",")
    truth = [dict(zip(names, map(float, r.split(",")), strict=True)) for r in rows[1:]]
    print(json.dumps({"rc": proc.returncode, "stderr": se[-2000:], "texts": texts,
                      "ekf": ekf, "truth": [[r["t_s"], r["x_m"], r["y_m"], r["z_m"],
                                             r["tether_length_m"]] for r in truth[::25]],
                      "companion_log": (run / "companion.log").read_text()[-3000:]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
