"""``tuav-sitl up --signing-passphrase`` driven by pymavlink clients: the vehicle and the
winch sign, the winch obeys a signed DO_WINCH and ignores an unsigned one, and a new key set
by SETUP_SIGNING reaches the winch. Run inside a private network namespace; prints one
JSON line."""

import json
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from tuavdefs import component_link as cl
from tuavdefs import signing as sg

ROOT = Path(__file__).resolve().parents[2]
M = mavutil.mavlink
PASSPHRASE = "tethered-uav-signing"
KEY = sg.key_from_passphrase(PASSPHRASE)
NEW_KEY = sg.key_from_passphrase("the-next-key")


def wait(m, mtype, cond=None, timeout=20.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = m.recv_match(type=mtype, blocking=True, timeout=0.5)
        if msg is not None and (cond is None or cond(msg)):
            return msg
    return None


def client(port: int, key: bytes | None, sysid: int):
    c = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=sysid,
                                   source_component=190)
    # after the first frame: pymavlink makes a new MAVLink 2 parser (without the key) then
    assert wait(c, "HEARTBEAT", timeout=30) is not None
    if key is not None:
        c.setup_signing(key, sign_outgoing=True)
    return c


def winch_ack(c, result_of: list, timeout=5.0):
    ack = wait(c, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_WINCH
               and a.get_srcComponent() == 169, timeout)
    result_of.append(None if ack is None else ack.result)


def signed_winch(c) -> dict:
    """What a client on the key sees of the winch, and its answer to DO_WINCH RELAXED."""
    status = wait(c, "WINCH_STATUS", lambda s: s.get_srcComponent() == 169)
    hb = wait(c, "HEARTBEAT", lambda h: h.get_srcComponent() == 169)
    c.mav.command_long_send(1, 169, M.MAV_CMD_DO_WINCH, 0, 1, 0, 0, 0, 0, 0, 0)
    results: list = []
    winch_ack(c, results)
    return {"status_signed": status is not None and status.get_signed(),
            "heartbeat_signed": hb is not None and hb.get_signed(),
            "ack": results[0]}


def main() -> int:
    base = Path(sys.argv[1])
    out: dict = {}
    p = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                          "--logdir", str(base), "--speedup", "max", "--position", "4", "0",
                          "8", "--signing-passphrase", PASSPHRASE, "--no-recording"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    banner = []
    for line in p.stdout:
        banner.append(line)
        if "Ctrl-C stops all three" in line:
            break
    out["banner"] = "".join(banner)
    try:
        run = next(base.iterdir())
        out["key_file"] = (run / "signing.key").read_text().strip()
        m = client(5760, KEY, 255)
        hb = wait(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1)
        out["vehicle_signed"] = hb is not None and hb.get_signed()
        out["winch"] = signed_winch(m)
        # an unsigned client: LOCK and a force disarm, both ignored
        u = client(5760, None, 254)
        u.mav.command_long_send(1, 169, M.MAV_CMD_DO_WINCH, 0, 1, 3, 0, 0, 0, 0, 0)
        u.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0,
                                0, 0)
        out["unsigned_ack"] = wait(u, "COMMAND_ACK", timeout=4.0) is not None
        u.close()
        hb = wait(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1)
        out["still_armed"] = bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        status = wait(m, "WINCH_STATUS", lambda s: s.get_srcComponent() == 169)
        out["winch_locked"] = bool(status.status & cl.winch_status_flag("LOCKED"))
        # a new key: the winch is handed it on the component link
        m.mav.setup_signing_send(1, 1, list(NEW_KEY), sg.timestamp_now())
        m.close()
        time.sleep(0.5)
        m2 = client(5760, NEW_KEY, 253)
        out["winch_new_key"] = signed_winch(m2)
        m2.close()
        time.sleep(1.0)
        out["key_file_after"] = (run / "signing.key").read_text().strip()
    finally:
        p.send_signal(2)
        _, se = p.communicate(timeout=30)
    out["rc"], out["stderr"] = p.returncode, se
    out["groundstation_log"] = (run / "groundstation.log").read_text()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
