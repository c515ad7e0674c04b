"""MAVProxy, as its users drive it, against real plant and companion processes: its shell
fed line by line on stdin (headless), TCP 5760-style. The truths are MAVProxy's own
printouts (its param module's table, its `param help` from the apm.pdef.xml metadata, its
wp module's upload and list) and the companion's log."""

from __future__ import annotations

import re
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
from gcs_util import Vehicle

from companion.param_metadata import SHIPPED, default_defs

pytestmark = pytest.mark.skipif(shutil.which("mavproxy.py") is None,
                                reason="MAVProxy is a test extra")

WPL = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.5456205\t488\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t10\t1
2\t0\t3\t16\t0\t0\t0\t0\t47.39779\t8.5456205\t10\t1
3\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1
"""


class MavProxy:
    """mavproxy.py connected to ``port``, its shell on a pipe; ``say(cmd, until)`` types a
    command and waits for a line of output containing ``until``."""

    def __init__(self, port: int, cwd: Path) -> None:
        self.p = subprocess.Popen(
            ["mavproxy.py", "--master", f"tcp:127.0.0.1:{port}", "--no-state",
             "--default-modules", "param,wp,mode,arm,cmdlong,log,fence,rally,misc,rc"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            cwd=cwd)
        self.lines: list[str] = []
        self._cond = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in iter(self.p.stdout.readline, ""):
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()

    def wait_for(self, text: str, since: int = 0, timeout_s: float = 60.0) -> str:
        end = time.monotonic() + timeout_s
        with self._cond:
            while True:
                for line in self.lines[since:]:
                    if text in line:
                        return line
                left = end - time.monotonic()
                if left <= 0 or self.p.poll() is not None:
                    raise AssertionError(f"no {text!r} from MAVProxy:\n" + "".join(self.lines))
                self._cond.wait(left)

    def send(self, command: str) -> None:
        self.p.stdin.write(command + "\n")
        self.p.stdin.flush()

    def say(self, command: str, until: str, timeout_s: float = 60.0) -> str:
        since = len(self.lines)
        self.send(command)
        return self.wait_for(until, since, timeout_s)

    def output_since(self, since: int) -> str:
        with self._cond:
            return "".join(self.lines[since:])

    def close(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mavproxy")
    # in real time, as a MAVProxy user's vehicle flies: nothing here flies, and a lockstep
    # vehicle (speedup max) would run its simulation flat out on a core and more all the
    # while MAVProxy reads and prints (~1.5 CPU-s per second of wall on a quiet host)
    veh = Vehicle(tmp, speedup="1")
    mp = MavProxy(veh.tcp_port, tmp)
    try:
        mp.wait_for(f"Received {len(default_defs())} parameters")
        yield {"mp": mp, "veh": veh, "tmp": tmp}
    finally:
        mp.close()
        veh.stop()


def shown(line: str, name: str) -> float:
    """The value MAVProxy printed for ``name`` in ``line`` (after its prompt)."""
    m = re.search(rf"\b{name}\s+(-?[\d.]+)", line)
    assert m is not None, line
    return float(m.group(1))


def test_param_show_lists_arducopter_names_in_arducopter_units(session):
    mp = session["mp"]
    assert shown(mp.say("param show RTL_ALT", "RTL_ALT "), "RTL_ALT") == 1000.0
    assert shown(mp.say("param show WPNAV_SPEED", "WPNAV_SPEED "), "WPNAV_SPEED") == 200.0
    assert shown(mp.say("param show DISARM_DELAY", "DISARM_DELAY "), "DISARM_DELAY") == 10
    mp.send("param set RTL_ALT 1500")
    # the same value under its newer metre name, once MAVProxy has read it again
    end = time.monotonic() + 30
    while True:
        mp.send("param fetch RTL_ALT_M")
        time.sleep(0.5)
        if shown(mp.say("param show RTL_ALT_M", "RTL_ALT_M "), "RTL_ALT_M") == 15.0:
            break
        assert time.monotonic() < end, mp.output_since(0)


def test_param_help_reads_ranges_units_and_descriptions_from_the_metadata(session):
    mp = session["mp"]
    since = len(mp.lines)
    mp.send(f"param set_xml_filepath {SHIPPED}")
    mp.say("param help WPNAV_SPEED", "Units")
    out = mp.output_since(since)
    assert "Horizontal speed of waypoint and guided moves" in out
    assert "Range : 0 2000" in out and "Units : cm/s" in out


def test_wp_load_of_a_qgc_wpl_file_uploads_the_mission(session):
    mp, veh, tmp = session["mp"], session["veh"], session["tmp"]
    (tmp / "mission.txt").write_text(WPL)
    mp.say(f"wp load {tmp / 'mission.txt'}", "Loaded 4 waypoints")
    end = time.monotonic() + 30
    while "mission of 3 items accepted" not in veh.comp_log.read_text():
        assert time.monotonic() < end, veh.comp_log.read_text()
        time.sleep(0.1)
    since = len(mp.lines)
    mp.say("wp list", "Requesting 4 waypoints")
    # each item as "COMMAND FRAME LAT LON ALT p1=..."; the landing (21) is the last
    line = mp.wait_for("21 3 ", since)
    while "cur=" not in line:
        line = mp.wait_for("cur=", since)
    time.sleep(0.5)
    listed = [ln.split() for ln in mp.output_since(since).splitlines()
              if ln[:1].isdigit() and " p1=" in ln]
    assert [int(f[0]) for f in listed] == [16, 22, 16, 21]


def test_fence_list_gets_an_answer(session):
    mp = session["mp"]
    mp.say("fence list", "Requesting 0 fence items")


def test_fence_present_enabled_and_listed_agree_as_arducopter_has_them(session):
    """MAVProxy's fence module says "fence present" from SYS_STATUS's geofence bit; as in
    ArduCopter (AC_Fence::present) that is FENCE_TYPE's altitude or circle fence, which are
    parameters and no fence items, or uploaded polygons: so with the defaults it says
    "fence present" and `fence list` answers 0 items. "fence enabled" follows
    FENCE_ENABLE."""
    mp = session["mp"]
    mp.wait_for("fence present")
    fence_type = int(shown(mp.say("param show FENCE_TYPE", "FENCE_TYPE "), "FENCE_TYPE"))
    line = mp.say("fence list", "fence items")
    m = re.search(r"Requesting (\d+) fence items", line)
    assert m is not None, line
    assert fence_type & 3 or int(m.group(1)) > 0, (fence_type, line)
    since = len(mp.lines)
    mp.send("param set FENCE_ENABLE 1")
    mp.wait_for("fence enabled", since)
    since = len(mp.lines)
    mp.send("param set FENCE_ENABLE 0")
    mp.wait_for("fence disabled", since)
