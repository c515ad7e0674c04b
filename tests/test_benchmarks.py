"""The benchmarks are not tests; this runs each once in a tiny configuration so they keep
working (speed is never asserted). The process benchmarks need a private network
namespace (root); without one they print a skip note, which is checked instead."""

import subprocess
import sys
from pathlib import Path

from netns_util import netns_available

ROOT = Path(__file__).resolve().parents[1]


def test_benchmarks_run_quick():
    res = subprocess.run([sys.executable, "-m", "tuav_sitl", "bench", "--quick"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    for row in ("tether solve, cold", "tether solve, warm-started",
                "plant step, physics 500 Hz, control 100 Hz",
                "plant step, physics 1000 Hz, control 250 Hz",
                "plant step, physics 2000 Hz, control 500 Hz",
                "offline closed loop (circle)", "share: plant physics (Plant.advance)",
                "share: flight controller (FlightController.update)",
                "share: winder host (WinderHost.update)",
                "three-process lockstep stack", "real time 250 Hz, both cores busy",
                "real time 500 Hz, both cores busy", "Set_Input_Torque -> applied",
                "COMMAND_LONG -> COMMAND_ACK"):
        assert row in out, row
    assert "faster than MoorPy" in out
    assert "goal >= 100x" in out and "goal >= 20x" in out or "skipped" in out
    assert "needs the ground-station endpoints (issue 4)" in out
    if netns_available():
        for row in ("where the time goes: plant", "where the time goes: companion",
                    "where the time goes: groundstation"):
            assert row in out, row
        assert "failed" not in out, out
    else:
        assert "skipped: needs root" in out
