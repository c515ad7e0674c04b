"""MAVProxy driven non-interactively, as scripts and sim_vehicle.py users drive it: one
``mavproxy.py --non-interactive --cmd "..."`` per step against real plant and companion
processes. MAVProxy runs ``--cmd`` before it has seen a heartbeat, so the vehicle is named
with ``--target-system 1 --target-component 1`` (as for any vehicle whose ids are known); the
requests then leave at once, addressed to the autopilot, and the vehicle must answer them.

The truths are MAVProxy's own printouts (its param module's ``NAME = value``, its wp and
fence modules' upload acknowledgements and listings, its log module's ``Log N`` lines) and
the companion's log; what one process uploads, the next one reads back."""

from __future__ import annotations

import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
from gcs_util import Vehicle
from test_mavproxy import WPL

pytestmark = pytest.mark.skipif(shutil.which("mavproxy.py") is None,
                                reason="MAVProxy is a test extra")

#: An inclusion circle of 30 m and an exclusion circle of 3 m (MAV_CMD_NAV_FENCE_CIRCLE_*).
FENCE = """QGC WPL 110
0\t0\t0\t5003\t30\t0\t0\t0\t47.397742\t8.5456205\t0\t1
1\t0\t0\t5004\t3\t0\t0\t0\t47.3978\t8.5457\t0\t1
"""


def mavproxy_cmd(port: int, cmd: str, until: tuple[str, ...], cwd: Path,
                 timeout_s: float = 60.0) -> str:
    """Run ``mavproxy.py --non-interactive --cmd CMD`` until every text of ``until`` has
    been printed (then stop it); its output. An AssertionError with the output if MAVProxy
    exits or the time runs out first."""
    p = subprocess.Popen(
        ["mavproxy.py", "--master", f"tcp:127.0.0.1:{port}", "--no-state", "--non-interactive",
         "--target-system", "1", "--target-component", "1",
         "--default-modules", "param,wp,mode,arm,cmdlong,log,fence,rally,misc,rc",
         "--cmd", cmd],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
        cwd=cwd)
    lines: list[str] = []
    done = threading.Event()

    def read() -> None:
        for line in iter(p.stdout.readline, ""):
            lines.append(line)
            if all(u in "".join(lines) for u in until):
                done.set()
        done.set()

    threading.Thread(target=read, daemon=True).start()
    done.wait(timeout_s)
    p.terminate()
    try:
        p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()
    out = "".join(lines)
    missing = [u for u in until if u not in out]
    assert not missing, f"MAVProxy --cmd {cmd!r} never printed {missing}:\n{out}"
    return out


def wait_log(veh: Vehicle, text: str, count: int = 1, timeout_s: float = 30.0) -> None:
    """Until the companion's log holds ``text`` ``count`` times."""
    end = time.monotonic() + timeout_s
    while veh.comp_log.read_text().count(text) < count:
        assert time.monotonic() < end, veh.comp_log.read_text()
        time.sleep(0.1)


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mavproxy_cmd")
    # in real time: nothing here flies (see test_mavproxy.py's vehicle)
    veh = Vehicle(tmp, speedup="1", extra=("--log-dir", str(tmp / "logs")))
    try:
        yield veh
    finally:
        veh.stop()


def test_param_fetch(vehicle):
    # (``param set`` needs the parameter's type, which MAVProxy learns only from a fetch:
    # it is a command for the shell, test_mavproxy.py)
    out = mavproxy_cmd(vehicle.tcp_port, "param fetch RTL_ALT; param fetch RTL_ALT_M",
                       ("RTL_ALT = 1000", "RTL_ALT_M = 10"), vehicle.tmp)
    assert "RTL_ALT = 1000.0" in out and "RTL_ALT_M = 10.0" in out   # cm, and metres


def test_wp_load_then_wp_list(vehicle):
    (vehicle.tmp / "mission.txt").write_text(WPL)
    out = mavproxy_cmd(vehicle.tcp_port, "wp load mission.txt",
                       ("Got MISSION_ACK: TYPE_MISSION: ACCEPTED",), vehicle.tmp)
    assert "Sent all 4 waypoints" in out
    wait_log(vehicle, "mission of 3 items accepted")
    out = mavproxy_cmd(vehicle.tcp_port, "wp list", ("\n21 3 ",), vehicle.tmp)   # to the land
    commands = [int(ln.split()[0]) for ln in out.splitlines() if " p1=" in ln]
    assert commands == [16, 22, 16, 21]


def test_fence_load_then_fence_list(vehicle):
    (vehicle.tmp / "fence.txt").write_text(FENCE)
    out = mavproxy_cmd(vehicle.tcp_port, "fence load fence.txt",
                       ("Got MISSION_ACK: TYPE_FENCE: ACCEPTED",), vehicle.tmp)
    assert "Sent all 2 fence items" in out
    out = mavproxy_cmd(vehicle.tcp_port, "fence list", ("\n5004 ",), vehicle.tmp)
    commands = [int(ln.split()[0]) for ln in out.splitlines() if " p1=" in ln]
    assert commands == [5003, 5004]


def test_log_list(vehicle):
    out = mavproxy_cmd(vehicle.tcp_port, "log list", ("numLogs",), vehicle.tmp)
    entries = [ln for ln in out.splitlines() if ln.startswith("Log ")]
    assert entries and all(int(ln.split()[5]) > 0 for ln in entries)   # sizes in bytes


def test_reboot(vehicle):
    before = vehicle.comp_log.read_text().count("Rebooting")
    mavproxy_cmd(vehicle.tcp_port, "reboot", ("Got COMMAND_ACK: PREFLIGHT_REBOOT_SHUTDOWN",),
                 vehicle.tmp)
    wait_log(vehicle, "Rebooting", before + 1)
