"""The plant, the companion and the ground station as three OS processes: MAVLink between
plant and companion (simulator link) and between companion and winch (component link), CAN
between plant and ground station; the ground station on the paper's law, the companion's
governor for it (tests/netns/paper_law.py). Run inside a private network namespace; prints
one JSON line for tests/test_three_processes.py."""

import csv
import json
import subprocess
import sys
import time
from pathlib import Path

from tests.gcs_util import free_port
from tests.netns import paper_law

ROOT = Path(__file__).resolve().parents[2]



def main() -> int:
    out_dir = Path(sys.argv[1])
    goal = [float(v) for v in sys.argv[2:5]]
    duration = sys.argv[5]
    pacing = ["--real-time"] if len(sys.argv) > 6 and sys.argv[6] == "real-time" else []
    sim_port, comp_port = free_port(), free_port()
    log = out_dir / "truth.csv"
    py = sys.executable
    plant = subprocess.Popen(
        [py, "-m", "sitl", "--port", str(sim_port), "--duration", duration, *pacing,
         "--can", "udp_multicast", "--no-noise", "--position", "4", "0", "10",
         "--tether-length", "12.5", "--truth-log", str(log),
         # in lockstep its waits spin first (sitl/spin.py): the same flight
         *([] if pacing else ["--lockstep-spin-us", "200"])],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ready = plant.stdout.readline()
    # the paper's law and the governor for it: the test checks L-bar and the stop lead's
    # bound (on the catenary: python -m sitl's truth line with no --params)
    law = paper_law.write(out_dir)
    gs = subprocess.Popen([py, "-m", "groundstation", "--can", "udp_multicast", "--mavlink",
                           f"127.0.0.1:{comp_port}", "--control", str(law["control"]),
                           # in lockstep on the plant's time, as up runs it: a stall of the
                           # plant on a busy host is then no lost encoder (a braked drum)
                           *([] if pacing else ["--clock", "frames"])],
                          cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    time.sleep(0.5)
    # on the simulator's state: the test holds the goal to 2 cm and L-bar to millimetres
    comp = subprocess.Popen([py, "-m", "companion", "--sim", f"127.0.0.1:{sim_port}",
                             "--state", "truth", "--nav", str(law["nav"]),
                             "--component-port", str(comp_port), "--gcs-tcp", "0",
                             "--gcs-udp", "none", "--goto", *map(str, goal)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    plant_out = plant.communicate(timeout=300)[0]
    comp_out = comp.communicate(timeout=60)[0]
    gs.terminate()
    gs_out = gs.communicate(timeout=30)[0]
    with open(log) as f:
        rows = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
    print(json.dumps({"ready": ready.strip(), "plant": plant_out, "companion": comp_out,
                      "groundstation": gs_out, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
