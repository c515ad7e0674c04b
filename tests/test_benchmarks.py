"""The benchmarks are not tests; this runs each once in a tiny configuration so they keep
working (speed is never asserted). The suite runs the benchmarks that start no process
(``tuav-sitl bench --quick --no-processes``: the solvers, the plant step, the filter, the
offline loop, the peer, the first result, the sweep); the stress run (``TUAV_STRESS=1``)
runs them all, the process benchmarks too: their flights (the lockstep stack flying the
scripted mission, real-time pacing with both cores busy, the torque and command latencies,
``up --view web`` and the ground-station floods in real time) are the suite's own flights
again (tests/test_e2e.py, test_up.py, test_view_live.py, test_flood.py ...), timed, about
130 CPU-s of the suite's 1,500. The process benchmarks need a private network namespace
(root); without one they print a skip note, which is checked instead. The command-latency
benchmark (plant + companion over TCP) needs none and always runs."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from netns_util import netns_available

ROOT = Path(__file__).resolve().parents[1]
STRESS = os.environ.get("TUAV_STRESS") == "1"
#: The rows of the benchmarks that start no process.
ROWS = ("tether solve, cold", "tether solve, warm-started",
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
        "the same run with --no-figures")
#: The rows of the process benchmarks.
PROCESS_ROWS = ("three-process lockstep stack (scripted mission)",
                "real time 250 Hz, both cores busy", "real time 500 Hz, both cores busy",
                "real time 250 Hz, both cores busy (normal scheduling)",
                "Set_Input_Torque -> applied",
                "COMMAND_LONG -> COMMAND_ACK, real time 250 Hz, p50",
                "COMMAND_LONG -> COMMAND_ACK, lockstep, p50")


def _bench(*extra: str) -> str:
    """``tuav-sitl bench --quick EXTRA...``: it ends well; its table."""
    res = subprocess.run([sys.executable, "-m", "tuav_sitl", "bench", "--quick", *extra],
                         cwd=ROOT, capture_output=True, text=True,
                         timeout=1800)  # (a hang's bound)
    assert res.returncode == 0, res.stderr
    return res.stdout


def _check_the_benchmarks_without_processes(out: str) -> None:
    for row in ROWS:
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


def test_benchmarks_run_quick():
    _check_the_benchmarks_without_processes(_bench("--no-processes"))


@pytest.mark.skipif(not STRESS, reason="the process benchmarks: in the stress run "
                                       "(TUAV_STRESS=1)")
def test_the_process_benchmarks_run_quick():
    out = _bench()
    _check_the_benchmarks_without_processes(out)
    for row in PROCESS_ROWS:
        assert row in out, row
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
