"""A new user's first minutes, with the real clients against a real ``tuav-sitl up`` in a
private network namespace, at ``--speedup 1``, ``5`` and ``max``, each client started the
moment ``up`` prints its banner: the README's three snippets as written (pymavlink, MAVSDK's
native binding, ``mavsdk_grpc``), MAVSDK's takeoff-and-land and mission_raw examples as
MAVSDK's Python examples fly them (they wait for the global position and home, not for
the pre-arm checks), and a pymavlink script that arms on its first GLOBAL_POSITION_INT
(tests/netns/clients). One flight per speed and client (tests/netns/first_contact_session.py;
each flight in a namespace of its own, several at once).

What the vehicle reports as ready (HOME_POSITION, SYS_STATUS's pre-arm, GPS and AHRS
health, EKF_STATUS_REPORT's PRED_POS_HORIZ_ABS) comes from the check arming runs, so every
flight's ``flight.tlog`` shows no arm refused after any of them said "ready"; as ArduPilot
streams GLOBAL_POSITION_INT before its EKF is ready, an arm on the first one may be refused,
but only with a PreArm text and before anything said "ready"."""

from __future__ import annotations

import json
import os
import subprocess
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from netns_util import PYTHON, SETUP, netns_available
from pymavlink import mavutil

from tests.netns.first_contact_session import BANNER_SEEN, CLIENTS

ROOT = Path(__file__).resolve().parents[1]

M = mavutil.mavlink
SPEEDS = ("1", "5", "max")
#: The suite flies each client once, the speeds in turn (each speed twice), to keep within
#: its 15 minutes on two cores; ``TUAV_STRESS=1`` flies every client at every speed (18
#: flights, about 9 CPU-minutes).
STRESS = os.environ.get("TUAV_STRESS") == "1"
MATRIX = ([(c, s) for s in SPEEDS for c in CLIENTS] if STRESS else
          [(c, SPEEDS[i % len(SPEEDS)]) for i, c in enumerate(CLIENTS)])
#: Flights started at once (each ``up`` compiles or loads its kernels in four processes:
#: the CPU a start costs), and flying at once (a real-time one mostly waits for the clock).
STARTS_AT_ONCE = 2
FLIGHTS_AT_ONCE = 3
#: Wall time a flight's session may take [s].
SESSION_TIMEOUT_S = 600.0
#: The real-time pymavlink flight also runs the README snippet's first lines on this many
#: fresh connections at once.
HEADS = 10

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


def _fly(base: Path, client: str, speed: str, starting: threading.Semaphore) -> dict:
    """One flight, in a network namespace of its own unless this runs inside one already;
    ``starting`` is held from its start until its ``up`` is ready (starts are what costs
    the CPU). A failure of the session itself is the flight's result, for its test."""
    args = [str(base / f"{client}-{speed}"), client, speed]
    if client == "readme-pymavlink" and speed == "1":
        args += ["--heads", str(HEADS)]
    cmd = [PYTHON, "-m", "tests.netns.first_contact_session", *args]
    if os.environ.get("NETNS_RUN_INSIDE") != "1":
        cmd = ["unshare", "--net", "--", "sh", "-c", SETUP, "netns", *cmd]
    with starting:
        p = subprocess.Popen(cmd, cwd=ROOT, env=dict(os.environ, NETNS_RUN_INSIDE="1"),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        watchdog = threading.Timer(SESSION_TIMEOUT_S, p.kill)
        watchdog.start()
        stderr: list[str] = []
        drain = threading.Thread(target=lambda: stderr.append(p.stderr.read()), daemon=True)
        drain.start()
        lines = []
        for line in p.stdout:
            lines.append(line)
            if line.strip() == BANNER_SEEN:
                break
    lines += p.stdout.readlines()
    p.wait()
    watchdog.cancel()
    drain.join()
    try:
        return json.loads(lines[-1])
    except (IndexError, ValueError):
        return {"client": client, "speedup": speed, "rc": None,
                "stdout": "".join(lines)[-3000:], "up_rc": None, "left": [], "arms": [],
                "stderr": f"session ended {p.returncode}: " + "".join(stderr)[-3000:],
                "up_stderr": ""}


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> dict[tuple[str, str], dict]:
    pytest.importorskip("mavsdk.asyncio", reason="MAVSDK's native binding is a test extra")
    pytest.importorskip("mavsdk_grpc", reason="MAVSDK-Python (mavsdk-grpc) is a test extra")
    base = tmp_path_factory.mktemp("first-contact")
    keys = sorted(MATRIX, key=lambda k: SPEEDS.index(k[1]))   # the long real-time ones first
    # inside a namespace already, flights cannot each have their own: one at a time
    alone = os.environ.get("NETNS_RUN_INSIDE") == "1"
    starting = threading.Semaphore(1 if alone else STARTS_AT_ONCE)
    with ThreadPoolExecutor(1 if alone else FLIGHTS_AT_ONCE) as pool:
        futures = {key: pool.submit(_fly, base, *key, starting) for key in keys}
        return {key: f.result() for key, f in futures.items()}


def _flight(flights: dict, client: str, speed: str) -> dict:
    """The flight of ``client`` at ``speed``, or the test skipped where the suite's matrix
    leaves it to the stress run."""
    if (client, speed) not in flights:
        pytest.skip(f"{client} at --speedup {speed}: in the stress run (TUAV_STRESS=1)")
    return flights[client, speed]


def _failure(out: dict) -> str:
    """A flight's failure as the assertion says it: the client's output, up's, the logs."""
    logs = "".join(f"\n--- {name}\n{text}" for name, text in out.get("logs", {}).items())
    return (f"{out.get('client')} at --speedup {out.get('speedup')}\n" + out["stdout"]
            + out["stderr"] + "\n--- up\n" + out["up_stderr"] + logs)


def _flew(out: dict) -> None:
    """The client ended well and ``up`` stopped cleanly, leaving nothing running."""
    assert out["rc"] == 0, _failure(out)
    assert out["up_rc"] == 0 and out["left"] == [], _failure(out)


@pytest.mark.parametrize("speed", SPEEDS)
def test_readme_pymavlink_snippet_takes_off_flies_and_reads_the_winch(flights, speed):
    out = _flight(flights, "readme-pymavlink", speed)
    _flew(out)
    got = [line for line in out["stdout"].splitlines() if line.startswith("tether paid out")]
    assert got, _failure(out)
    # just after the climb to 10 m beside the winder (2 m east): about the distance, paid
    # out as the vehicle climbed (the report can lag the climb by a few decimetres)
    length_m = float(got[0].split(":")[1].split()[0])
    assert 9.0 < length_m < 20.0


def test_pymavlink_snippet_addresses_the_autopilot_on_every_connection(flights):
    """The winch (1/169) beats on the same link: the snippet must lock on component 1 and
    so get the copter's mode map (GUIDED = 4), ten connections out of ten."""
    heads = _flight(flights, "readme-pymavlink", "1").get("heads", [])
    assert len(heads) == HEADS
    for h in heads:
        assert h["rc"] == 0, h["stderr"]
        target_system, target_component, modes = json.loads(h["stdout"].splitlines()[-1])
        assert (target_system, target_component) == (1, 1)
        assert dict(modes)["GUIDED"] == 4 and dict(modes)["RTL"] == 6


@pytest.mark.parametrize("speed", SPEEDS)
def test_readme_mavsdk_native_snippet_sets_rtl_altitude_and_finishes_its_mission(flights,
                                                                                  speed):
    out = _flight(flights, "readme-native", speed)
    _flew(out)
    assert "RTL altitude: 12.0 m" in out["stdout"]
    assert "mission finished" in out["stdout"]
    assert "Mission: complete" in out["stderr"]       # MAVSDK's log of the STATUSTEXT


@pytest.mark.parametrize("speed", SPEEDS)
def test_readme_mavsdk_grpc_snippet_flies_its_mission_to_the_end(flights, speed):
    out = _flight(flights, "readme-grpc", speed)
    _flew(out)
    assert "mission finished" in out["stdout"]


@pytest.mark.parametrize("speed", SPEEDS)
def test_mavsdk_takeoff_and_land_arms_once_global_position_and_home_are_ok(flights, speed):
    """MAVSDK's own pattern: no COMMAND_DENIED once it reports the global position and
    home OK; the calibrations OK as ArduPilot reports its calibrated sensors."""
    out = _flight(flights, "takeoff-and-land", speed)
    _flew(out)
    assert "calibration ok: gyro True, accelerometer True, magnetometer True" in out["stdout"]
    assert out["stdout"].rstrip().endswith("landed")


@pytest.mark.parametrize("speed", SPEEDS)
def test_mavsdk_mission_raw_flies_to_its_end_and_lands(flights, speed):
    out = _flight(flights, "mission-raw", speed)
    _flew(out)
    assert "mission progress 4/4" in out["stdout"]
    assert out["stdout"].rstrip().endswith("mission finished, landed")


@pytest.mark.parametrize("speed", SPEEDS)
def test_an_arm_on_the_first_position_is_accepted_or_refused_before_any_ready(flights,
                                                                              speed):
    """As ArduPilot: GLOBAL_POSITION_INT flows before the EKF is ready, so the first arm
    may be refused, with a PreArm text, when nothing has said the vehicle is ready; then
    the arm once the pre-arm checks pass is accepted, and the flight ends landed."""
    out = _flight(flights, "arm-on-first-position", speed)
    _flew(out)
    seen = json.loads(out["stdout"].splitlines()[-1])
    if seen["first_arm"] != M.MAV_RESULT_ACCEPTED:
        assert seen["ready_before"] == [], _failure(out)
        assert seen["refusals"] and all(t.startswith("PreArm: EKF") for t in seen["refusals"])
    assert "landed and disarmed" in out["stdout"]


@pytest.mark.parametrize("speed", SPEEDS)
@pytest.mark.parametrize("client", CLIENTS)
def test_nothing_said_ready_while_arming_was_refused(flights, client, speed):
    """The run's flight.tlog: every arm answered after any readiness report said "ready"
    (or LOCAL_POSITION_NED, which ArduPilot sends only once its EKF has a position, and
    MAVSDK takes for is_local_position_ok, was sent) was accepted, and each of them did
    say it before the flight ended."""
    out = _flight(flights, client, speed)
    assert out.get("arms"), _failure(out)
    for arm in out["arms"]:
        if arm["result"] != M.MAV_RESULT_ACCEPTED:
            assert arm["ready_before"] == [], (arm, out["first_ready_s"])
    assert sorted(out["first_ready_s"]) == [
        "EKF_STATUS_REPORT 512", "HOME_POSITION", "LOCAL_POSITION_NED", "SYS_STATUS AHRS",
        "SYS_STATUS PREARM_CHECK", "SYS_STATUS SENSOR_GPS"]
