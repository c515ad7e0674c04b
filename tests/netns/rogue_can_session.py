"""A rogue CAN host against the whole stack: ``tuav-sitl up`` (lockstep paced at 2x, the
vehicle hovering where it starts in the air) on a real udp_multicast bus, a ground station
on pymavlink watching the vehicle, and a second CAN host, python-can's own
``udp_multicast`` bus, sending ``Set_Input_Torque`` of +/-4 N m to the winder's axis
(``ROGUE_FRAMES`` frames, every ``ROGUE_PERIOD_S`` of wall time) once the vehicle has
hovered ``ATTACK_AT_S`` of simulated time. Run inside a private network namespace; prints
one JSON line for tests/test_rogue_can.py: the truth series (slack, attitude, height),
what the ground station heard (STATUSTEXT, WINCH_STATUS flags, HEARTBEAT modes) and how
many frames the rogue sent."""

from __future__ import annotations

import csv
import json
import math
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import can
from pymavlink import mavutil

from tests.netns.up_session import processes_mentioning, wait_banner
from tuavdefs import can_protocol as cp
from tuavdefs.canbus import DEFAULT_GROUP

ROOT = Path(__file__).resolve().parents[2]
POSITION = (8.0, 3.0, 14.0)
DURATION_S = 40.0          # simulated
ATTACK_AT_S = 8.0          # simulated
ROGUE_FRAMES = 1500
ROGUE_PERIOD_S = 0.002     # wall: 500 Hz for 3 s (6 s of simulated time at 2x): the
#: stack's own torque (one per encoder frame, 10 ms of simulated time) is rarely the last
ROGUE_TORQUE_NM = 4.0
ROGUE_SWITCH = 250         # frames between sign changes (0.5 s of wall time): winding in
#: for as long as paying out
INSTANCE = 4


def main() -> int:
    logdir = Path(sys.argv[1])
    up = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "up", "--speedup", "2", "--can", "udp_multicast",
         "--position", *map(str, POSITION), "--duration", str(DURATION_S),
         "--logdir", str(logdir), "--instance", str(INSTANCE), "--no-recording"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict = {"banner": wait_banner(up)}
    port = 5760 + 10 * INSTANCE
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                     source_component=190)
    texts: list[tuple[float, int, int, str]] = []
    flags: list[tuple[float, int]] = []
    modes: list[tuple[float, int, int]] = []
    sim_t = 0.0
    rogue: can.BusABC | None = None
    sent = 0
    next_send = 0.0
    end_wall = time.monotonic() + 600.0
    torque_id = cp.frame_id(cp.AXIS_NODE_ID_DEFAULT, cp.Cmd.SET_INPUT_TORQUE)
    while up.poll() is None and time.monotonic() < end_wall:
        m = gcs.recv_match(blocking=True, timeout=0.005)
        now = time.monotonic()
        if rogue is None and sim_t >= ATTACK_AT_S:
            # the second host: python-can's bus on the stack's group (instance 4's own)
            base, last = DEFAULT_GROUP.rsplit(".", 1)
            group = f"{base}.{int(last) + INSTANCE}"
            rogue = can.Bus(interface="udp_multicast", channel=group, hop_limit=0)
            out["rogue_group"] = group
            out["attack_sim_s"] = sim_t
            next_send = now
        if rogue is not None and sent < ROGUE_FRAMES and now >= next_send:
            tau = ROGUE_TORQUE_NM * (-1 if (sent // ROGUE_SWITCH) % 2 == 0 else 1)
            rogue.send(can.Message(arbitration_id=torque_id, is_extended_id=False,
                                   data=struct.pack("<f", tau) + bytes(4)))
            sent += 1
            next_send += ROGUE_PERIOD_S
            if sent == ROGUE_FRAMES:
                out["attack_end_sim_s"] = sim_t
        if m is None:
            continue
        kind = m.get_type()
        if hasattr(m, "time_boot_ms"):
            sim_t = max(sim_t, m.time_boot_ms * 1e-3)
        if kind == "STATUSTEXT":
            texts.append((sim_t, m.get_srcComponent(), m.severity, m.text))
        elif kind == "WINCH_STATUS":
            flags.append((sim_t, m.status))
        elif (kind == "HEARTBEAT" and m.get_srcComponent() == 1
              and (not modes or modes[-1][1:] != (m.custom_mode, m.base_mode & 128))):
            modes.append((sim_t, m.custom_mode, m.base_mode & 128))
    if rogue is not None:
        rogue.shutdown()
    gcs.close()
    if up.poll() is None:
        up.send_signal(signal.SIGINT)
    so, se = up.communicate(timeout=60)
    out.update(rogue_sent=sent, up_rc=up.returncode, up_stderr=se[-3000:],
               texts=texts, flags=flags, modes=modes,
               left=processes_mentioning(str(logdir)))
    run = next(logdir.iterdir())
    rows = []
    with open(run / "truth.csv") as f:
        for r in csv.DictReader(f):
            x, y, z = float(r["x_m"]), float(r["y_m"]), float(r["z_m"])
            rows.append([float(r["t_s"]), x, y, z, float(r["tether_length_m"]),
                         float(r["roll_rad"]), float(r["pitch_rad"])])
    out["rows"] = rows[::5]
    out["min_slack_m"] = min(r[4] - math.sqrt(r[1] ** 2 + r[2] ** 2 + r[3] ** 2)
                             for r in rows)
    gs_log = run / "groundstation.log"
    out["gs_log"] = gs_log.read_text()[-4000:] if gs_log.exists() else ""
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
