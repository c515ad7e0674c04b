"""The ground side of a crash through the real stack: the plant (``python -m sitl --can``,
lockstep, hovering at 1.5 m, 2 m east of the winder), the companion (on the simulator's
state) and the ground station as OS processes, this script on the component link between
them (forwarding every message both ways unchanged, as in stack_winch_session.py). Rotor 1
fails at ``FAIL_S`` (the plant's ``--faults``): the vehicle rolls over and falls. From
``WRONG_S`` on, the script rewrites the companion's LOCAL_POSITION_NED to the winch as a
diverged estimate would have it: climbing away at 6 m/s from where the vehicle lies (the
first flight of issue 35: the drum then paid out 2.4 -> 49.5 m in 8 s). Run inside a
private network namespace; prints one JSON line for tests/test_crash_ground.py."""

from __future__ import annotations

import csv
import json
import select
import socket
import subprocess
import sys
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

from tests.gcs_util import free_port
from tests.netns.stack_winch_session import connect

ROOT = Path(__file__).resolve().parents[2]
POSITION = (2.0, 0.0, 1.5)
TETHER_M = 2.6
DURATION_S = 25.0
FAIL_S = 3.0
WRONG_S = 5.0
CLIMB_M_S = 6.0
FAULTS = f"""[[faults]]
kind = "motor"
start_s = {FAIL_S}
motor = 0
thrust_multiplier = 0.0
"""


def main() -> int:
    out_dir = Path(sys.argv[1])
    sim_port, comp_port, proxy_port = free_port(), free_port(), free_port()
    log = out_dir / "truth.csv"
    faults = out_dir / "faults.toml"
    faults.write_text(FAULTS)
    py = sys.executable
    plant = subprocess.Popen(
        [py, "-m", "sitl", "--port", str(sim_port), "--duration", str(DURATION_S),
         "--can", "udp_multicast", "--no-noise", "--position", *map(str, POSITION),
         "--tether-length", str(TETHER_M), "--faults", str(faults),
         "--truth-log", str(log), "--log-every", "1"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    plant.stdout.readline()
    listener = socket.socket()
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    listener.bind(("127.0.0.1", proxy_port))
    listener.listen(1)
    gs = subprocess.Popen([py, "-m", "groundstation", "--can", "udp_multicast", "--mavlink",
                           f"127.0.0.1:{proxy_port}", "--clock", "frames"],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    listener.settimeout(60.0)
    gs_sock, _ = listener.accept()
    comp = subprocess.Popen([py, "-m", "companion", "--sim", f"127.0.0.1:{sim_port}",
                             "--state", "truth", "--component-port", str(comp_port)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    comp_sock = connect(comp_port, 60.0)
    for s in (gs_sock, comp_sock):
        s.setblocking(True)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    from_comp = mavlink2.MAVLink(None)
    from_gs = mavlink2.MAVLink(None)
    # the rewritten reports go out under the autopilot's ids, as the companion's did
    forger = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    texts: list[tuple[float, str]] = []
    sim_t = 0.0
    wrong_from: tuple[float, float, float] | None = None
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
                        if sim_t >= WRONG_S:
                            if wrong_from is None:
                                wrong_from = (m.x, m.y, m.z)
                            x, y, z0 = wrong_from
                            z = z0 - CLIMB_M_S * (sim_t - WRONG_S)      # NED: up is -z
                            m = forger.local_position_ned_encode(m.time_boot_ms, x, y, z,
                                                                 0.0, 0.0, -CLIMB_M_S)
                            gs_sock.sendall(m.pack(forger))
                            continue
                    gs_sock.sendall(m.get_msgbuf())            # forwarded unchanged
            else:
                try:
                    comp_sock.sendall(data)                       # forwarded unchanged
                except OSError:                                   # the companion has ended
                    socks = []
                for m in from_gs.parse_buffer(data) or []:
                    if m.get_type() == "STATUSTEXT":
                        texts.append((sim_t, m.text))
    plant_out = plant.communicate(timeout=120)[0]
    comp.communicate(timeout=60)
    gs.terminate()
    gs_out = gs.communicate(timeout=30)[0]
    gs_sock.close()
    listener.close()
    with open(log) as f:
        rows = [[float(r[k]) for k in ("t_s", "x_m", "y_m", "z_m", "tether_length_m",
                                        "roll_rad")] for r in csv.DictReader(f)]
    print(json.dumps({"plant": plant_out, "groundstation": gs_out, "texts": texts,
                      "rows": rows[::5]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
