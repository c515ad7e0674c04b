"""End to end, inside a private network namespace: ``tuav-sitl up --speedup max`` as a
subprocess, the pymavlink example mission flown against it, then Ctrl-C; prints one JSON
line with what the test checks (the run folder, the example's record, stop time, leftover
processes, the CAN capture decoded by cantools, the tlog parsed by pymavlink)."""

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from tests.netns import paper_law
from tests.netns.up_session import processes_mentioning, wait_banner

ROOT = Path(__file__).resolve().parents[2]
DBC = ROOT / "tuavdefs" / "data" / "tuav_winder.dbc"


def winch_commands(port: int) -> dict:
    """MAV_CMD_DO_WINCH through the companion's endpoint, to the winch (169) and to the
    autopilot (1): who answered, with what, to whom; and what pymavlink took for the
    vehicle while the winch's heartbeats were also arriving."""
    m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                   source_component=190)
    m.wait_heartbeat(timeout=10)
    res: dict = {}
    for name, comp, action in (("hold_169", 169, 5), ("relax_1", 1, 0), ("bad_1", 1, 4)):
        m.mav.command_long_send(1, comp, mavutil.mavlink.MAV_CMD_DO_WINCH, 0, 1, action, 0,
                                0, 0, 0, 0)
        ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5,
                           condition="COMMAND_ACK.command==42600")
        res[name] = None if ack is None else [ack.get_srcComponent(), ack.result,
                                              ack.target_system, ack.target_component]
        time.sleep(0.3)
    hb = {}
    end = time.monotonic() + 5
    while time.monotonic() < end and len(hb) < 2:
        h = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
        if h is not None:
            hb[h.get_srcComponent()] = [h.type, h.autopilot]
    res["heartbeats"] = {str(k): v for k, v in hb.items()}
    res["flightmode"] = m.flightmode
    res["vehicle_sysid"] = m.sysid
    m.close()
    return res


def main() -> int:
    base = Path(sys.argv[1])
    out: dict = {}
    logdir = base / "e2e"
    # the paper's law, its governor and the catenary truth: the test checks L-bar and the
    # stop lead's bound, and the line's shape on the catenary (the defaults: the tension
    # law, governor 2, the lumped line)
    law = paper_law.write(base / "law")
    up = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--speedup", "max",
                           "--can", "udp_multicast", "--logdir", str(logdir), "--instance", "2",
                           "--ground-params", str(law["control"]), "--parm", str(law["parm"]),
                           "--tether-model", "catenary", "--no-recording"],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    banner = wait_banner(up)
    out["banner"] = banner
    port = int(re.search(r"tcp:127\.0\.0\.1:(\d+)\n", banner.split("MAVLink", 1)[1]).group(1))
    rec = base / "record.json"
    t0 = time.monotonic()
    fly = subprocess.run([sys.executable, "examples/fly_mission.py", "--connect",
                          f"tcp:127.0.0.1:{port}", "--record", str(rec), "--timeout", "400"],
                         cwd=ROOT, capture_output=True, text=True, timeout=500)
    out["fly"] = {"rc": fly.returncode, "stdout": fly.stdout, "stderr": fly.stderr[-3000:],
                  "wall_s": time.monotonic() - t0}
    out["record"] = json.loads(rec.read_text()) if rec.exists() else None
    out["winch_cmd"] = winch_commands(port)
    time.sleep(1.0)
    t0 = time.monotonic()
    up.send_signal(signal.SIGINT)
    so, se = up.communicate(timeout=30)
    out["stop_s"] = time.monotonic() - t0
    out["up_rc"], out["up_stdout"], out["up_stderr"] = up.returncode, so, se
    out["left"] = processes_mentioning(str(logdir))
    run = next(logdir.iterdir())
    out["run_dir"] = str(run)
    out["files"] = sorted(f.name for f in run.iterdir())
    decoded = subprocess.run([sys.executable, "-m", "cantools", "decode", "--single-line",
                              str(DBC)],
                             input=(run / "can.log").read_text(), capture_output=True,
                             text=True, timeout=120)
    lines = decoded.stdout.splitlines()
    out["can"] = {"rc": decoded.returncode, "lines": len(lines),
                  "torque": sum("Set_Input_Torque" in ln for ln in lines),
                  "encoder": sum("Get_Encoder_Estimates" in ln for ln in lines),
                  "undecoded": sum(" :: " not in ln or "Unknown frame" in ln
                                   for ln in lines),
                  "torques_nm": [float(ln.split("Input_Torque: ")[1].split()[0])
                                 for ln in lines if "Set_Input_Torque(" in ln][::50],
                  "log_lines": len((run / "can.log").read_text().splitlines()),
                  "sample": [ln for ln in lines if "Set_Input_Torque" in ln][:3]}
    tlog = mavutil.mavlink_connection(str(run / "flight.tlog"))
    kinds: dict = {}
    ekf: list = []
    local: list = []
    texts: list = []
    while True:
        msg = tlog.recv_match()
        if msg is None:
            break
        kinds[msg.get_type()] = kinds.get(msg.get_type(), 0) + 1
        if msg.get_type() == "STATUSTEXT":
            texts.append(msg.text)
        elif msg.get_type() == "EKF_STATUS_REPORT":
            ekf.append([msg.flags, msg.pos_horiz_variance])
        elif msg.get_type() == "LOCAL_POSITION_NED":
            local.append([msg.time_boot_ms * 1e-3, msg.x, msg.y, msg.z])
    out["tlog_kinds"] = kinds
    out["statustexts"] = texts
    out["ekf_status"] = ekf
    out["local_ned"] = local
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
