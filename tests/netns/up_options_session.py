"""``tuav-sitl up -I 1 --home CMAC --out udp:127.0.0.1:14600`` inside a private network
namespace: what a ground station listening on the --out port receives (the vehicle's
identity, where it is, how it faces), and whether instance 1's TCP port answers. Prints one
JSON line."""

import json
import math
import signal
import sys
from pathlib import Path

from pymavlink import mavutil

from tests.netns.up_session import processes_mentioning, up, wait_banner


def main() -> int:
    logdir = Path(sys.argv[1])
    p = up(logdir, "-I", "1", "--home", "CMAC", "--out", "udp:127.0.0.1:14600",
           "--speedup", "4", "--no-recording")
    out: dict = {"banner": wait_banner(p)}
    try:
        rx = mavutil.mavlink_connection("udpin:127.0.0.1:14600")
        hb = rx.recv_match(type="HEARTBEAT", blocking=True, timeout=30,
                           condition="HEARTBEAT.get_srcComponent() == 1")
        g = rx.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=30)
        a = rx.recv_match(type="ATTITUDE", blocking=True, timeout=30)
        out["out"] = {"heartbeat": None if hb is None else [hb.get_srcSystem(), hb.autopilot],
                      "lat_lon": None if g is None else [g.lat * 1e-7, g.lon * 1e-7],
                      "yaw_deg": None if a is None else math.degrees(a.yaw) % 360.0}
        rx.close()
        tcp = mavutil.mavlink_connection("tcp:127.0.0.1:5770")
        out["tcp_5770"] = tcp.recv_match(type="HEARTBEAT", blocking=True, timeout=30) \
            is not None
        tcp.close()
    finally:
        p.send_signal(signal.SIGINT)
        _, se = p.communicate(timeout=60)
    out["up_rc"], out["up_stderr"] = p.returncode, se[-2000:]
    out["left"] = processes_mentioning(str(logdir))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
