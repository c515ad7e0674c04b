"""``tuav-sitl up --ground-params FILE`` with ``[winder_control] law = "tension"`` inside a
private network namespace, in lockstep for a few simulated seconds: which law the ground
station says it runs (its log, and its STATUSTEXT as the vehicle's tlog recorded it) and
the run folder's copy of the file. Prints one JSON line."""

import json
import sys
from pathlib import Path

from pymavlink import mavutil

from tests.netns.up_session import processes_mentioning, up


def main() -> int:
    base = Path(sys.argv[1])
    gp = base / "gs.toml"
    gp.write_text('[winder_control]\nlaw = "tension"\n')
    logdir = base / "runs"
    p = up(logdir, "--speedup", "max", "--duration", "4", "--ground-params", str(gp))
    so, se = p.communicate(timeout=240)
    run = next(logdir.iterdir())
    texts = []
    tlog = mavutil.mavlink_connection(str(run / "flight.tlog"))
    while (m := tlog.recv_match(type="STATUSTEXT")) is not None:
        texts.append(m.text)
    print(json.dumps({"rc": p.returncode, "stderr": se[-2000:],
                      "gs_log": (run / "groundstation.log").read_text()[-4000:],
                      "gs_toml": (run / "groundstation.toml").read_text(),
                      "statustexts": texts, "left": processes_mentioning(str(logdir))}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
