"""The simulator's fault parameters set at run time by a pymavlink ground station on
``tuav-sitl up``: SIM_WIND_SPD / SIM_WIND_DIR change the plant's wind (its truth log),
SIM_GPS_DISABLE stops GPS_RAW_INT's fixes and gives them back, and out-of-range values and
unknown names are refused. Run inside a private network namespace; prints one JSON line."""

import json
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
M = mavutil.mavlink


def wait(m, mtype, cond=None, timeout=30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = m.recv_match(type=mtype, blocking=True, timeout=0.5)
        if msg is not None and (cond is None or cond(msg)):
            return msg
    return None


def param(m, name: str, value: float | None = None, ptype=M.MAV_PARAM_TYPE_REAL32,
          texts: list | None = None) -> float | None:
    """Set (or, ``value`` None, read) a parameter; the value the vehicle answers with (the
    STATUSTEXTs seen meanwhile appended to ``texts``)."""
    if value is None:
        m.mav.param_request_read_send(1, 1, name.encode(), -1)
    else:
        m.mav.param_set_send(1, 1, name.encode(), value, ptype)
    end = time.monotonic() + 30.0
    while time.monotonic() < end:
        msg = m.recv_match(type=["PARAM_VALUE", "STATUSTEXT"], blocking=True, timeout=0.5)
        if msg is None:
            continue
        if msg.get_type() == "STATUSTEXT":
            if texts is not None:
                texts.append(msg.text)
        elif msg.param_id == name:
            return msg.param_value
    return None


def gps_fix(m) -> int | None:
    msg = wait(m, "GPS_RAW_INT")
    return None if msg is None else msg.fix_type


def main() -> int:
    base = Path(sys.argv[1])
    out: dict = {}
    p = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                          "--logdir", str(base), "--speedup", "2", "--position", "4", "0",
                          "8", "--no-recording"], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    for line in p.stdout:
        if "Ctrl-C stops all three" in line:
            break
    run = next(base.iterdir())
    try:
        m = mavutil.mavlink_connection("tcp:127.0.0.1:5760", source_system=255,
                                       source_component=190)
        assert wait(m, "HEARTBEAT") is not None
        out["wind_spd_0"] = param(m, "SIM_WIND_SPD")
        out["fix_0"] = gps_fix(m)
        texts: list = []
        out["wind_dir"] = param(m, "SIM_WIND_DIR", 90.0, texts=texts)
        out["wind_spd"] = param(m, "SIM_WIND_SPD", 5.0, texts=texts)
        out["wind_set_wall"] = time.monotonic()
        out["wind_too_strong"] = param(m, "SIM_WIND_SPD", 100.0, texts=texts)
        out["gps_disable_2"] = param(m, "SIM_GPS_DISABLE", 2, M.MAV_PARAM_TYPE_INT32,
                                     texts=texts)
        out["unknown"] = param(m, "SIM_NO_SUCH", 1.0, texts=texts)
        out["gps_disable"] = param(m, "SIM_GPS_DISABLE", 1, M.MAV_PARAM_TYPE_INT32,
                                   texts=texts)
        # the receiver silent: no fix in GPS_RAW_INT within ArduPilot's 4 s timeout (2 s
        # of wall time at 2x; the deadline is generous for a busy machine)
        lost = wait(m, "GPS_RAW_INT", lambda g: g.fix_type < 3, timeout=60.0)
        out["fix_lost"] = None if lost is None else lost.fix_type
        out["gps_enable"] = param(m, "SIM_GPS_DISABLE", 0, M.MAV_PARAM_TYPE_INT32,
                                  texts=texts)
        back = wait(m, "GPS_RAW_INT", lambda g: g.fix_type >= 3, timeout=60.0)
        out["fix_back"] = None if back is None else back.fix_type
        out["texts"] = texts
        m.close()
    finally:
        p.send_signal(2)
        _, se = p.communicate(timeout=60)
    out["rc"], out["stderr"] = p.returncode, se[-3000:]
    out["plant_log"] = (run / "plant.log").read_text()
    lines = (run / "truth.csv").read_text().splitlines()
    cols = lines[0].split(",")
    rows = [dict(zip(cols, map(float, r.split(",")), strict=True)) for r in lines[1:]
            if r.count(",") == len(cols) - 1]
    out["wind"] = [(r["t_s"], r["wind_x_m_s"], r["wind_y_m_s"], r["z_m"]) for r in rows]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
