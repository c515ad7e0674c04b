"""``tuav-sitl up`` supervised from outside: a normal end, Ctrl-C, a process dying, a port
in use. Run inside a private network namespace; prints one JSON line."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def processes_mentioning(text: str) -> list[int]:
    pids = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if text in cmd and "up_session" not in cmd:
            pids.append(int(pid))
    return pids


def up(logdir: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                             "--logdir", str(logdir), *extra], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_banner(proc: subprocess.Popen) -> str:
    lines = []
    while True:
        line = proc.stdout.readline()
        if not line:
            return "".join(lines)
        lines.append(line)
        if "Ctrl-C stops all three" in line:
            return "".join(lines)


def kill_one(logdir: Path, name: str) -> dict:
    """Start up in ``logdir``, SIGKILL its processes whose command line names ``name``;
    up's exit code, stderr, how many were killed and what was left running."""
    p = up(logdir)
    wait_banner(p)
    victims = [pid for pid in processes_mentioning(str(logdir))
               if name in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")]
    for pid in victims:
        os.kill(pid, signal.SIGKILL)
    _, se = p.communicate(timeout=30)
    return {"rc": p.returncode, "stderr": se, "killed": len(victims),
            "left": processes_mentioning(str(logdir))}


def main() -> int:
    base = Path(sys.argv[1])
    out: dict = {}
    # 1. a normal end: the plant's --duration
    d1 = base / "normal"
    p = up(d1, "--speedup", "max", "--duration", "3", "--position", "4", "0", "10", "--goto",
           "5", "1", "11")
    so, se = p.communicate(timeout=120)
    run = next(d1.iterdir())
    decoded = subprocess.run([sys.executable, "-m", "cantools", "decode",
                              str(ROOT / "tuavdefs" / "data" / "tuav_winder.dbc")],
                             input=(run / "can.log").read_text(), capture_output=True,
                             text=True, timeout=60).stdout
    out["normal"] = {"rc": p.returncode, "stdout": so, "stderr": se,
                     "can_decoded_torques": decoded.count("Input_Torque:"),
                     "files": sorted(f.name for f in run.iterdir()),
                     "truth_rows": len((run / "truth.csv").read_text().splitlines()) - 1,
                     "left": processes_mentioning(str(d1))}
    # 2. Ctrl-C in real time
    d2 = base / "sigint"
    p = up(d2, "--sim-link", "tcp")
    banner = wait_banner(p)
    t0 = time.monotonic()
    p.send_signal(signal.SIGINT)
    so, se = p.communicate(timeout=30)
    run2 = next(d2.iterdir())
    out["sigint"] = {"rc": p.returncode, "banner": banner, "stop_s": time.monotonic() - t0,
                     "stdout": so, "stderr": se, "left": processes_mentioning(str(d2)),
                     "logs": {n: (run2 / f"{n}.log").read_text()
                              for n in ("plant", "companion", "groundstation")}}
    # 3. one process dies: the others are stopped and the exit code says so
    out["dies"] = kill_one(base / "dies", "groundstation")
    # 3b. the bus recorder dies: up says so and stops (can.log would stay silent)
    out["recorder_dies"] = kill_one(base / "recorder-dies", "candump")
    # 4. a port in use, and the simulator link's socket name in use
    with socket.socket() as s:
        s.bind(("127.0.0.1", 5762 + 10 * 3))
        s.listen(1)
        p = up(base / "busy", "--instance", "3")
        so, se = p.communicate(timeout=60)
    out["busy"] = {"rc": p.returncode, "stderr": se}
    with socket.socket(socket.AF_UNIX) as s:
        s.bind("\0tuav-sitl-sim-3")
        s.listen(1)
        p = up(base / "busy-sim", "--instance", "3")
        so, se = p.communicate(timeout=60)
    out["busy_sim"] = {"rc": p.returncode, "stderr": se}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
