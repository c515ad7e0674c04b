"""DO_WINCH through the real stack: the plant (``python -m sitl --can``, lockstep), the
companion and the ground station as OS processes, with this script on the component link
between them: the ground station connects to this script's TCP server, which connects to
the companion's component port and forwards every MAVLink message both ways unchanged (as
the companion will forward ground stations' traffic), and injects DO_WINCH commands from a
ground station (system 255, component 190) at chosen simulated times (the companion's
LOCAL_POSITION_NED ``time_boot_ms``). Run inside a private network namespace; prints one
JSON line for tests/test_groundstation_process.py."""

from __future__ import annotations

import csv
import json
import math
import select
import socket
import subprocess
import sys
import time
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

from tests.gcs_util import free_port
from tests.netns import paper_law

ROOT = Path(__file__).resolve().parents[2]
POSITION = (8.0, 3.0, 14.0)
TETHER_M = 17.0
DURATION_S = 20.0
NAN = math.nan
# (simulated time [s], name, message kind, target component, param1..param4)
SCRIPT = [
    (2.0, "length", "long", 169, (0, 1, 1.0, 0.5)),
    (5.5, "hold", "int", 0, (0, 5, NAN, NAN)),
    (8.0, "relax", "long", 1, (0, 0, NAN, NAN)),
    (11.0, "retract", "long", 169, (0, 6, NAN, NAN)),
    (16.0, "relax2", "int", 169, (0, 0, NAN, NAN)),
]



def connect(port: int, timeout_s: float) -> socket.socket:
    end = time.monotonic() + timeout_s
    while True:
        try:
            return socket.create_connection(("127.0.0.1", port), timeout=0.5)
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.05)


def main() -> int:
    out_dir = Path(sys.argv[1])
    sim_port, comp_port, proxy_port = free_port(), free_port(), free_port()
    log = out_dir / "truth.csv"
    py = sys.executable
    plant = subprocess.Popen(
        [py, "-m", "sitl", "--port", str(sim_port), "--duration", str(DURATION_S),
         "--can", "udp_multicast", "--no-noise", "--position", *map(str, POSITION),
         "--tether-length", str(TETHER_M), "--truth-log", str(log), "--log-every", "1"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ready = plant.stdout.readline()
    listener = socket.socket()
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", proxy_port))
    listener.listen(1)
    # the paper's law and the governor for it: RELAXED is checked back on L-bar, and the
    # UAV's 0.2 m hold was measured with them (on the catenary, python -m sitl's own line)
    law = paper_law.write(out_dir)
    gs = subprocess.Popen([py, "-m", "groundstation", "--can", "udp_multicast", "--mavlink",
                           f"127.0.0.1:{proxy_port}", "--control", str(law["control"]),
                           # on the lockstep plant's time, as up runs it: a stall of the
                           # plant on a busy host is then no lost encoder (a braked drum)
                           "--clock", "frames"],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    listener.settimeout(60.0)
    gs_sock, _ = listener.accept()
    time.sleep(0.5)
    # on the simulator's state: the test holds the UAV's place to 0.2 m while the winch moves
    comp = subprocess.Popen([py, "-m", "companion", "--sim", f"127.0.0.1:{sim_port}",
                             "--state", "truth", "--component-port", str(comp_port),
                             "--nav", str(law["nav"])],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    comp_sock = connect(comp_port, 60.0)
    for s in (gs_sock, comp_sock):
        s.setblocking(True)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    from_comp = mavlink2.MAVLink(None)
    from_gs = mavlink2.MAVLink(None)
    gcs = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    sim_t = 0.0
    script = list(SCRIPT)
    sent: dict[str, float] = {}
    seen: list[tuple[float, str, dict]] = []       # (sim time, type, fields) from the winch
    forwarded = {"to_gs": 0, "to_companion": 0}
    socks = [gs_sock, comp_sock]
    while socks:
        readable, _, _ = select.select(socks, [], [], 0.5)
        readable = [s for s in readable if s in socks]
        if not readable and plant.poll() is not None:
            break
        for s in readable:
            try:
                data = s.recv(65536)
            except OSError:
                data = b""
            if not data:
                socks.remove(s)
                continue
            if s is comp_sock:
                for m in from_comp.parse_buffer(data) or []:
                    if m.get_type() == "LOCAL_POSITION_NED":
                        sim_t = m.time_boot_ms / 1000.0
                    gs_sock.sendall(m.get_msgbuf())            # forwarded unchanged
                    forwarded["to_gs"] += 1
                while script and sim_t >= script[0][0]:
                    _, name, kind, target, p = script.pop(0)
                    if kind == "long":
                        msg = gcs.command_long_encode(1, target, mavlink2.MAV_CMD_DO_WINCH, 0,
                                                      *p, 0.0, 0.0, 0.0)
                    else:
                        msg = gcs.command_int_encode(1, target, 0, mavlink2.MAV_CMD_DO_WINCH,
                                                     0, 0, *p, 0, 0, 0.0)
                    gs_sock.sendall(msg.pack(gcs))
                    sent[name] = sim_t
            else:
                try:
                    comp_sock.sendall(data)                       # forwarded unchanged
                except OSError:                                   # the companion has ended
                    socks = []
                forwarded["to_companion"] += 1
                for m in from_gs.parse_buffer(data) or []:
                    d = m.to_dict()
                    d["src"] = [m.get_srcSystem(), m.get_srcComponent()]
                    if m.get_type() == "STATUSTEXT":
                        d["text"] = m.text
                    seen.append((sim_t, m.get_type(), d))
    plant_out = plant.communicate(timeout=120)[0]
    comp_out = comp.communicate(timeout=60)[0]
    gs.terminate()
    gs_out = gs.communicate(timeout=30)[0]
    gs_sock.close()
    listener.close()
    with open(log) as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    keep = ("t_s", "x_m", "y_m", "z_m", "tether_length_m", "drum_rate_rad_s")
    print(json.dumps({"ready": ready.strip(), "plant": plant_out, "companion": comp_out,
                      "groundstation": gs_out, "sent": sent, "forwarded": forwarded,
                      "seen": [[t, k, d] for t, k, d in seen if k != "WINCH_STATUS"],
                      "status": [[t, d["line_length"], d["status"]] for t, k, d in seen
                                 if k == "WINCH_STATUS"],
                      "rows": [{k: r[k] for k in keep} for r in rows]}, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
