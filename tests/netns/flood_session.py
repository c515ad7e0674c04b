"""A ground-station flood against a hovering stack: ``tuav-sitl up`` (real time, or
``--speedup`` N), the vehicle hovering where it starts in the air, and one flooder per
kind sending as fast as ``RATE_HZ`` allows once the stack runs:

- ``param_set``: valid PARAM_SETs (WPNAV_SPEED between two values) on TCP 5760;
- ``param_list``: PARAM_REQUEST_LIST, each asking for the whole table again;
- ``command``: COMMAND_LONG REQUEST_MESSAGE (AUTOPILOT_VERSION) and a refused command;
- ``mission``: MISSION_COUNT uploads begun and abandoned, MISSION_REQUEST_LIST;
- ``interval``: SET_MESSAGE_INTERVAL and REQUEST_DATA_STREAM changes;
- ``peers``: heartbeats from ``PEERS`` UDP source ports, round robin, to port 14550.

Usage: ``python -m tests.netns.flood_session LOGDIR KINDS SECONDS [SPEEDUP]`` (KINDS comma
separated, SECONDS simulated), inside a private network namespace. Prints one JSON line:
what was sent and answered per kind, the truth's largest distance from where the flood
found the vehicle (its drift), the plant's own summary (missed deadlines and periods),
up's exit."""

from __future__ import annotations

import csv
import json
import math
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as M  # noqa: N812 - MAVLink's usual name

from tests.netns.up_session import processes_mentioning, wait_banner

ROOT = Path(__file__).resolve().parents[2]
POSITION = (6.0, 2.0, 12.0)
#: The kinds of flood (the module docstring), in the order they are sent.
KINDS = ("param_set", "param_list", "command", "mission", "interval", "peers")
RATE_HZ = 1000.0           # per kind, wall
PEERS = 300
INSTANCE = 7
FLOOD_AFTER_S = 5.0        # simulated: the hover settled


def _flood_one(kind: str, i: int, gcs: mavutil.mavfile, udp: socket.socket,
               peers: list[socket.socket]) -> None:
    mav = gcs.mav
    if kind == "param_set":
        mav.param_set_send(1, 1, b"WPNAV_SPEED", 500.0 + (i % 2) * 10.0,
                           M.MAV_PARAM_TYPE_REAL32)
    elif kind == "param_list":
        mav.param_request_list_send(1, 1)
    elif kind == "command":
        if i % 2:
            mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                  M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        else:
            mav.command_long_send(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0)   # unknown: refused
    elif kind == "mission":
        if i % 2:
            mav.mission_count_send(1, 1, 5, M.MAV_MISSION_TYPE_MISSION)
        else:
            mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    elif kind == "interval":
        if i % 2:
            mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                  M.MAVLINK_MSG_ID_ATTITUDE, 20000 + (i % 7) * 1000,
                                  0, 0, 0, 0, 0)
        else:
            mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4 + i % 3, 1)
    elif kind == "peers":
        hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        frame = hb.pack(M.MAVLink(None, srcSystem=200 + i % 50, srcComponent=190))
        peers[i % len(peers)].sendto(frame, ("127.0.0.1", 14550 + 10 * INSTANCE))
    else:
        raise ValueError(f"no flood kind {kind!r}")


def main() -> int:
    logdir = Path(sys.argv[1])
    kinds = [k for k in sys.argv[2].split(",") if k]
    seconds = float(sys.argv[3])
    speedup = sys.argv[4] if len(sys.argv) > 4 else "1"
    up = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "up", "--speedup", speedup, "--can",
         "udp_multicast", "--position", *map(str, POSITION), "--duration", str(seconds),
         "--logdir", str(logdir), "--instance", str(INSTANCE), "--no-recording"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict = {"banner": wait_banner(up), "kinds": kinds}
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{5760 + 10 * INSTANCE}",
                                     source_system=255, source_component=190)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peers = []
    if "peers" in kinds:
        for _ in range(PEERS):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            peers.append(s)
    sent = dict.fromkeys(kinds, 0)
    heard: dict[str, int] = {}
    sim_t = 0.0
    flood_from = flood_to = None
    next_send = time.monotonic()
    end_wall = time.monotonic() + seconds * 20 + 300
    while up.poll() is None and time.monotonic() < end_wall:
        now = time.monotonic()
        flooding = sim_t >= FLOOD_AFTER_S and sim_t < seconds - 2.0
        if flooding and flood_from is None:
            flood_from = sim_t
        if flooding:
            flood_to = sim_t
            try:
                while next_send <= now:
                    for k in kinds:
                        _flood_one(k, sent[k], gcs, udp, peers)
                        sent[k] += 1
                    next_send += 1.0 / RATE_HZ
            except ConnectionError:
                out["link_closed_sim_s"] = sim_t
                break
        else:
            next_send = now
        try:
            m = gcs.recv_match(blocking=True, timeout=0.0005 if flooding else 0.05)
            while m is not None:
                kind = m.get_type()
                heard[kind] = heard.get(kind, 0) + 1
                if hasattr(m, "time_boot_ms"):
                    sim_t = max(sim_t, m.time_boot_ms * 1e-3)
                m = gcs.recv_match(blocking=False)
        except ConnectionError:
            # the companion closed the link: the run's end (up's exit and the plant's
            # periods say whether it was), or a failure the checks then show
            out["link_closed_sim_s"] = sim_t
            break
    gcs.close()
    for s in (udp, *peers):
        s.close()
    if up.poll() is None:
        up.send_signal(signal.SIGINT)
    so, se = up.communicate(timeout=120)
    run = next(logdir.iterdir())
    far = 0.0          # the largest distance from where the flood found the vehicle
    at_start = None
    with open(run / "truth.csv") as f:
        for r in csv.DictReader(f):
            t = float(r["t_s"])
            if flood_from is not None and flood_from <= t <= (flood_to or t):
                p = (float(r["x_m"]), float(r["y_m"]), float(r["z_m"]))
                at_start = at_start or p
                far = max(far, math.dist(p, at_start))
    last = (run / "plant.log").read_text().strip().splitlines()[-1]
    periods = re.search(r"(\d+) periods", last)
    missed = re.search(r"(\d+) missed deadlines", last)
    out.update(sent=sent, heard=heard, flood_from_s=flood_from, flood_to_s=flood_to,
               max_drift_m=far, plant_summary=last,
               periods=int(periods.group(1)) if periods else None,
               missed=int(missed.group(1)) if missed else None,
               up_rc=up.returncode, up_stderr=se[-3000:],
               left=processes_mentioning(str(logdir)))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
