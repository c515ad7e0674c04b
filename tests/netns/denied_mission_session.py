"""``tuav-sitl up`` with no GNSS at all (the plant's receiver lost from 0 s), the UAV on the
ground 2 m east of the winder: a pymavlink ground station on TCP 5760 waits for the
filter's horizontal position (EKF_STATUS_REPORT), asks to arm until the vehicle accepts,
takes off in GUIDED, uploads the mission-gnss-denied mission (take-off, a loiter circle,
three waypoints, land) and flies it in AUTO to the disarm, then stops the stack. Prints one
JSON line: the arming answers, STATUSTEXTs, the items reached with the vehicle's time, the
EKF flags, and the plant's truth.csv. Run inside a private network namespace.

The flight's phase depends on when the arm is first accepted, which the wall clock sets
(``--speedup max``: 0.5 s of wall time between asks is seconds of the vehicle's). An
optional second argument, a vehicle time [s], asks first at that time and then every
20 ms of wall time, to fly a given phase again (a CI run's, from its arm time)."""

import json
import math
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from tests.netns.up_session import wait_banner

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples"))
from fly_mission import CIRCLE, TAKEOFF_M, WAYPOINTS, Flight, latlon_e7  # noqa: E402

M = mavutil.mavlink
POS_HORIZ_ABS = 16


def main() -> int:
    base = Path(sys.argv[1])
    faults = base / "faults.toml"
    faults.write_text('[[faults]]\nkind = "gnss_loss"\nstart_s = 0.0\n')
    logdir = base / "runs"
    up = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast", "--logdir",
         str(logdir), "--speedup", "max", "--duration", "400", "--gnss", "gnss",
         "--faults", str(faults)], cwd=ROOT, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    banner = wait_banner(up)
    port = int(re.search(r"tcp:127\.0\.0\.1:(\d+)\n", banner.split("MAVLink", 1)[1]).group(1))
    out: dict = {"arm": [], "ekf": [], "reached": [], "gps_fix_types": []}
    f = Flight(f"tcp:127.0.0.1:{port}", 600.0)
    m = f.m

    def vehicle_ms() -> int:
        g = m.messages.get("GLOBAL_POSITION_INT")
        return g.time_boot_ms if g is not None else 0

    def note(msg) -> None:
        kind = msg.get_type()
        if kind == "EKF_STATUS_REPORT":
            out["ekf"].append([vehicle_ms() * 1e-3, msg.flags])
        elif kind == "GPS_RAW_INT":
            out["gps_fix_types"].append(msg.fix_type)
        elif kind == "MISSION_ITEM_REACHED":
            out["reached"].append([msg.seq, vehicle_ms() * 1e-3])

    note_flight = f._note

    def noting(msg) -> None:
        note_flight(msg)
        note(msg)

    f._note = noting
    f.wait("EKF_STATUS_REPORT", lambda e: e.flags & POS_HORIZ_ABS, 120.0)
    lp = f.wait("LOCAL_POSITION_NED")
    gp = f.wait("GLOBAL_POSITION_INT")
    origin_lat = gp.lat * 1e-7 - math.degrees(lp.x / 6378137.0)
    origin_lon = gp.lon * 1e-7 - math.degrees(
        lp.y / (6378137.0 * math.cos(math.radians(origin_lat))))
    f.set_mode("GUIDED")
    arm_at_s = float(sys.argv[2]) if len(sys.argv) > 2 else None
    if arm_at_s is not None:
        f.wait("GLOBAL_POSITION_INT", lambda g: g.time_boot_ms >= arm_at_s * 1000, 120.0)
    # as a ground station waits for "EKF OK": arming asked again while it is refused
    end = time.monotonic() + 120.0
    while time.monotonic() < end:
        result = f.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        out["arm"].append([vehicle_ms() * 1e-3, result])
        if result == M.MAV_RESULT_ACCEPTED:
            break
        time.sleep(0.5 if arm_at_s is None else 0.02)
    out["armed"] = out["arm"][-1][1] == M.MAV_RESULT_ACCEPTED
    if out["armed"]:
        f.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, TAKEOFF_M)
        f.wait("GLOBAL_POSITION_INT", lambda g: g.relative_alt > (TAKEOFF_M - 0.3) * 1000,
               120)
        cx, cy, cz, r = CIRCLE
        items = [(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, TAKEOFF_M),
                 (M.MAV_CMD_NAV_LOITER_TURNS, 1, 0, -r, 0,
                  *latlon_e7(origin_lat, origin_lon, cx, cy), cz)]
        items += [(M.MAV_CMD_NAV_WAYPOINT, 0, 0.5, 0, math.nan,
                   *latlon_e7(origin_lat, origin_lon, x, y), z) for x, y, z in WAYPOINTS]
        items.append((M.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, 0, 0, 0))
        f.upload(items)
        f.set_mode("AUTO")
        f.wait("HEARTBEAT", lambda h: h.get_srcComponent() == 1
               and not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 600.0)
        out["disarmed_s"] = vehicle_ms() * 1e-3
        # the land detector's report after the disarm
        ext = m.messages.get("EXTENDED_SYS_STATE")
        out["landed_state"] = None if ext is None else ext.landed_state
    out["texts"] = f.record["texts"]
    m.close()
    up.send_signal(signal.SIGINT)
    so, se = up.communicate(timeout=60)
    out["rc"], out["stderr"] = up.returncode, se[-2000:]
    run = next(logdir.iterdir())
    rows = (run / "truth.csv").read_text().splitlines()
    names = rows[0].split(",")
    truth = [dict(zip(names, map(float, r.split(",")), strict=True)) for r in rows[1:]]
    out["truth"] = [[r["t_s"], r["x_m"], r["y_m"], r["z_m"], r["tether_length_m"]]
                    for r in truth]
    out["plant_log"] = (run / "plant.log").read_text()[-2000:]
    out["companion_log"] = (run / "companion.log").read_text()[-3000:]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
