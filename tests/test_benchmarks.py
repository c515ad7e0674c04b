"""The benchmarks are not tests; this runs each once in a tiny configuration so they keep
working (speed is never asserted). The process benchmarks need a private network
namespace (root); without one they print a skip note, which is checked instead. The
command-latency benchmark (plant + companion over TCP) needs none and always runs."""

import re
import subprocess
import sys
from pathlib import Path

from netns_util import netns_available

ROOT = Path(__file__).resolve().parents[1]


def test_benchmarks_run_quick():
    res = subprocess.run([sys.executable, "-m", "tuav_sitl", "bench", "--quick"], cwd=ROOT,
                         capture_output=True, text=True, timeout=1800)  # (a hang's bound)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    for row in ("tether solve, cold", "tether solve, warm-started",
                "plant step, physics 500 Hz, control 100 Hz",
                "plant step, physics 1000 Hz, control 250 Hz",
                "plant step, physics 2000 Hz, control 500 Hz",
                "plant step, lumped tether, physics 1000 Hz, control 250 Hz",
                "offline closed loop (circle)", "offline closed loop (circle, lumped tether)",
                "offline closed loop (circle-rtk, EKF)",
                "offline closed loop (circle-rtk, EKF, lumped tether)",
                "share: plant physics (Plant.advance_held)",
                "share: flight controller (FlightController.update)",
                "share: winder host (WinderHost.update)",
                "first run, cold numba cache (circle, no figures)",
                "first result: run with figures + animation",
                "the same run with --no-figures",
                "three-process lockstep stack (scripted mission)",
                "real time 250 Hz, both cores busy", "real time 500 Hz, both cores busy",
                "real time 250 Hz, both cores busy (normal scheduling)",
                "Set_Input_Torque -> applied",
                "COMMAND_LONG -> COMMAND_ACK, real time 250 Hz, p50",
                "COMMAND_LONG -> COMMAND_ACK, lockstep, p50"):
        assert row in out, row
    assert "faster than MoorPy" in out
    # the peer: RotorPy's own quadrotor flown in the same run (or a note why not)
    peer = next(ln for ln in out.splitlines() if ln.startswith("peer: our loop"))
    try:
        import rotorpy  # noqa: F401
        assert "RotorPy at its 100 Hz" in peer and "goal >= 20x" in peer, peer
    except ImportError:
        assert "skipped: rotorpy is not installed" in peer, peer
    assert "the rest of the machine meanwhile" in out and "host steal" in out
    assert "goal >= 100x" in out and "goal >= 20x" in out or "skipped" in out
    # the command latency: every command answered, in both modes
    cmd_rows = [ln for ln in out.splitlines() if ln.startswith("COMMAND_LONG -> COMMAND_ACK")]
    assert len(cmd_rows) == 2, out
    for ln in cmd_rows:
        assert re.search(r"\d ms, max [\d.]+ ms over 30 commands;", ln), ln
        assert "failed" not in ln and "unanswered" not in ln, ln
    if netns_available():
        flood = next(ln for ln in out.splitlines() if ln.startswith("flood of all kinds"))
        assert "failed" not in flood and "% missed" in flood, flood
        for row in ("where the time goes: plant", "where the time goes: companion",
                    "where the time goes: groundstation",
                    "where the time goes: mission client (pymavlink)"):
            assert row in out, row
        # the scripted mission (its --short hop) was flown to the end, over MAVLink TCP
        stack_row = next(ln for ln in out.splitlines()
                         if ln.startswith("three-process lockstep stack"))
        assert "examples/fly_mission.py --short over MAVLink TCP" in stack_row, stack_row
        assert "landed and disarmed; items reached: [1, 2, 3]" in stack_row, stack_row
        assert "mission client (pymavlink)" in stack_row, stack_row
        assert "failed" not in out, out
    else:
        assert "skipped: needs root" in out


def test_priority_experiments_apply():
    """The scheduling the real-time experiments can give the processes
    (``python -m benchmarks.session --priority``) is applied to every thread."""
    import os

    import pytest

    from tuav_sitl.realtime import set_priority

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        try:
            set_priority(child.pid, "slice")   # unprivileged, Linux 6.12 and later
        except OSError as exc:
            pytest.skip(f"no custom EEVDF slices here: {exc}")
        if os.geteuid() == 0:
            set_priority(child.pid, "nice")
            assert os.getpriority(os.PRIO_PROCESS, child.pid) == -10
            set_priority(child.pid, "fifo")
            assert os.sched_getscheduler(child.pid) == os.SCHED_FIFO
        with pytest.raises(ValueError):
            set_priority(child.pid, "turbo")
    finally:
        child.kill()
        child.wait()
