"""A late CAN bus under ``tuav-sitl up --faults``: the winder's frames 100 ms late from 8 s
of simulated time while the vehicle hovers. A pymavlink ground station records what the
vehicle says and when (the simulated time of the telemetry around it) until it has landed
and disarmed. Run inside a private network namespace; prints one JSON line."""

import json
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
M = mavutil.mavlink


def main() -> int:
    base = Path(sys.argv[1])
    faults = base / "faults.toml"
    faults.write_text('[[faults]]\nkind = "can"\ndelay_ms = 100.0\nstart_s = 8.0\n')
    logdir = base / "runs"
    p = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                          "--logdir", str(logdir), "--speedup", "max", "--position", "4",
                          "0", "8", "--faults", str(faults), "--no-recording"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in p.stdout:
        if "Ctrl-C stops all three" in line:
            break
    out: dict = {"texts": []}
    try:
        m = mavutil.mavlink_connection("tcp:127.0.0.1:5760", source_system=255,
                                       source_component=190)
        t_ms = 0
        was_armed = False
        end = time.monotonic() + 600.0          # a generous deadline for a busy machine
        while time.monotonic() < end:
            msg = m.recv_match(blocking=True, timeout=0.5)
            if msg is None:
                continue
            if hasattr(msg, "time_boot_ms"):
                t_ms = max(t_ms, msg.time_boot_ms)
            kind = msg.get_type()
            if kind == "STATUSTEXT":
                out["texts"].append((t_ms * 1e-3, msg.get_srcComponent(), msg.text))
            elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
                if was_armed and not armed:
                    out["disarmed_s"] = t_ms * 1e-3
                    break
                was_armed = armed
        m.close()
    finally:
        p.send_signal(2)
        _, se = p.communicate(timeout=60)
    out["rc"], out["stderr"] = p.returncode, se[-3000:]
    run = next(logdir.iterdir())
    lines = (run / "truth.csv").read_text().splitlines()
    cols = lines[0].split(",")
    rows = [dict(zip(cols, map(float, r.split(",")), strict=True)) for r in lines[1:]
            if r.count(",") == len(cols) - 1]
    out["min_slack_m"] = min(r["tether_length_m"] - (r["x_m"] ** 2 + r["y_m"] ** 2
                                                      + r["z_m"] ** 2) ** 0.5 for r in rows)
    out["last"] = {k: rows[-1][k] for k in ("t_s", "x_m", "y_m", "z_m", "armed")}
    out["plant_log"] = (run / "plant.log").read_text()[-2000:]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
