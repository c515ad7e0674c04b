"""A new user's first contact: a fresh ``tuav-sitl up`` at a speed-up, and one client
started the moment ``up`` prints its banner (no wait), run to its end; then ``up`` is
stopped. Run inside a private network namespace (the clients use the default ports).

``python -m tests.netns.first_contact_session DIR CLIENT SPEEDUP [--heads N]``; the
clients are the README's three snippets, run as written (``readme-pymavlink``,
``readme-native``, ``readme-grpc``), and the scripts of ``tests/netns/clients``, run
unchanged (``takeoff-and-land``, ``mission-raw``, ``arm-on-first-position``). With
``--heads N``, N fresh pymavlink connections then run the README snippet's first lines
(to its targets) at once, and print whom they address.

Prints :data:`BANNER_SEEN` as the client starts, and last one JSON line: the client's exit
and output, ``up``'s exit and what it left running, and what the run's ``flight.tlog``
says of readiness: every answer to an arm (its result, and which reports had already said
"ready" when it went out) and the first time [s of simulated time] each said so."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from tests.netns.readme_session import python_blocks, run
from tests.netns.up_session import processes_mentioning, up, wait_banner

ROOT = Path(__file__).resolve().parents[2]
CLIENTS_DIR = Path(__file__).resolve().parent / "clients"
README_CLIENTS = ("readme-pymavlink", "readme-native", "readme-grpc")
SCRIPT_CLIENTS = ("takeoff-and-land", "mission-raw", "arm-on-first-position")
CLIENTS = README_CLIENTS + SCRIPT_CLIENTS
#: Wall time a client may take [s] (a real-time flight takes under a minute).
CLIENT_TIMEOUT_S = 240.0
#: The line printed as soon as ``up`` has printed its banner (the client starting).
BANNER_SEEN = "first contact: up is ready, the client starts"

M = mavutil.mavlink
#: SYS_STATUS's health bits that say "ready" (MAVSDK: is_armable, is_global_position_ok
#: and is_local_position_ok; the AHRS: the estimate).
_READY_BITS = {"PREARM_CHECK": M.MAV_SYS_STATUS_PREARM_CHECK,
               "SENSOR_GPS": M.MAV_SYS_STATUS_SENSOR_GPS, "AHRS": M.MAV_SYS_STATUS_AHRS}
#: EKF_STATUS_REPORT's PRED_POS_HORIZ_ABS: the README's snippet waits for it.
_EKF_READY = 512


def client_code(name: str) -> str:
    """The script the client ``name`` runs: a README snippet as written, or a script of
    tests/netns/clients as it is."""
    if name in README_CLIENTS:
        return python_blocks()[README_CLIENTS.index(name)]
    return (CLIENTS_DIR / f"{name.replace('-', '_')}.py").read_text()


def readiness(tlog: Path) -> dict:
    """From an ``up`` run's ``flight.tlog``: the first simulated time [s] each readiness
    report said "ready" (HOME_POSITION and LOCAL_POSITION_NED: was sent), and every arm's
    answer with what had said "ready" before it."""
    first: dict[str, float] = {}
    arms: list[dict] = []
    t_s = 0.0
    log = mavutil.mavlink_connection(str(tlog), dialect="ardupilotmega")
    while (msg := log.recv_match()) is not None:
        kind = msg.get_type()
        if msg.get_srcSystem() != 1 or msg.get_srcComponent() != 1:
            continue                   # a ground station's frame, or the winch's
        if hasattr(msg, "time_boot_ms"):
            t_s = msg.time_boot_ms / 1000.0
        said = []
        if kind in ("HOME_POSITION", "LOCAL_POSITION_NED"):
            said = [kind]
        elif kind == "EKF_STATUS_REPORT" and msg.flags & _EKF_READY:
            said = ["EKF_STATUS_REPORT 512"]
        elif kind == "SYS_STATUS":
            said = [f"SYS_STATUS {n}" for n, bit in _READY_BITS.items()
                    if msg.onboard_control_sensors_health & bit]
        elif kind == "COMMAND_ACK" and msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM:
            arms.append({"t_s": t_s, "result": msg.result, "ready_before": sorted(first)})
        for name in said:
            first.setdefault(name, t_s)
    log.close()
    return {"first_ready_s": first, "arms": arms}


def heads(n: int, base: Path) -> list[dict]:
    """``n`` pymavlink connections at once, each running the README snippet's first lines
    and printing whom it then addresses and its mode map."""
    head = python_blocks()[0].split("m.target_system, m.target_component = 1, 1\n", 1)[0]
    probe = head + (
        "m.target_system, m.target_component = 1, 1\n"
        "import json\n"
        "print(json.dumps([m.target_system, m.target_component,\n"
        "                  sorted((m.mode_mapping() or {}).items())]))\n")
    paths = []
    for i in range(n):
        paths.append(base / f"head{i}.py")
        paths[-1].write_text(probe)
    procs = [subprocess.Popen([sys.executable, str(p)], cwd=base, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for p in paths]
    out = []
    for p in procs:
        try:
            so, se = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            p.kill()
            so, se = p.communicate()
        out.append({"rc": p.returncode, "stdout": so, "stderr": se[-2000:]})
    return out


def main() -> int:
    base, name, speedup = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    n_heads = int(sys.argv[5]) if len(sys.argv) > 5 and sys.argv[4] == "--heads" else 0
    base.mkdir(parents=True, exist_ok=True)
    code = client_code(name)
    logdir = base / "runs"
    t0 = time.monotonic()
    p = up(logdir, "--speedup", speedup)
    banner = wait_banner(p)
    t_banner = time.monotonic()
    print(BANNER_SEEN, flush=True)     # for whoever starts flights one after another
    out: dict = {"client": name, "speedup": speedup, "banner": banner,
                 "banner_wall_s": t_banner - t0}
    try:
        out.update(run(code, base / f"{name.replace('-', '_')}.py", CLIENT_TIMEOUT_S))
        out["client_wall_s"] = time.monotonic() - t_banner
        if n_heads:
            out["heads"] = heads(n_heads, base)
    finally:
        p.send_signal(signal.SIGINT)
        try:
            _, se = p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            _, se = p.communicate()
    out["up_rc"], out["up_stderr"] = p.returncode, se[-2000:]
    out["left"] = processes_mentioning(str(logdir))
    run_dirs = sorted(logdir.glob("up-*"))
    if run_dirs:
        out.update(readiness(run_dirs[-1] / "flight.tlog"))
        if out["rc"] != 0:
            out["logs"] = {f.name: f.read_text(errors="replace")[-1500:]
                           for f in sorted(run_dirs[-1].glob("*.log")) if f.name != "can.log"}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
