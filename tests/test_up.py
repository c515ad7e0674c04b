"""``tuav-sitl up`` starts, supervises and stops the three processes (in a private network
namespace for the CAN bus)."""

import os

import pytest
from netns_util import netns_available, run_session

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> dict:
    base = tmp_path_factory.mktemp("up")
    return run_session("tests.netns.up_session", str(base), timeout_s=400)


def test_a_run_ends_cleanly_with_its_folder(session):
    n = session["normal"]
    assert n["rc"] == 0, n["stderr"]
    assert "plant, companion and ground station are running" in n["stdout"]
    assert "plant finished" in n["stdout"]
    assert "simulator link (plant <-> companion): unix:@tuav-sitl-sim-0" in n["stdout"]
    assert {"plant.log", "companion.log", "groundstation.log", "truth.csv",
            "params.toml", "can.log"} <= set(n["files"])
    assert n["can_decoded_torques"] > 10     # the bus recording decodes with the DBC
    assert n["truth_rows"] >= 140          # 3 s at 50 Hz
    assert n["left"] == []
    if len(os.sched_getaffinity(0)) >= 2:   # lockstep: the plant and the companion on a CPU
        assert "scheduling: plant and companion on CPU" in n["stdout"]
        assert "recorder at idle priority" in n["stdout"]
        assert "ground station (nice 5)" in n["stdout"]


def test_ctrl_c_stops_all_three_within_3_s(session):
    """Ctrl-C: every process ends by itself within up's grace of 2 s after its SIGTERM
    (up kills, and says so, whatever is left then: so all are gone within 3 s of an
    unloaded machine's time; on a busy one the wall clock stretches, so the bound is checked
    through up's own word, not timed here beyond a hang's minute)."""
    s = session["sigint"]
    assert "tcp:127.0.0.1:4560" in s["banner"] and "clock: real time" in s["banner"], s
    assert "scheduling: SCHED_FIFO priority 10" in s["banner"]   # root in CI
    assert s["rc"] == 0
    assert "killed" not in s["stderr"], s["stderr"]
    assert "tuav-sitl up: stopped" in s["stdout"]
    # each process's own summary, which it prints as it ends by itself (a killed one does
    # not)
    for name, summary in (("plant", " periods, "), ("companion", " control periods; "),
                          ("groundstation", " encoder frames, ")):
        last = s["logs"][name].rstrip().splitlines()[-1]
        assert last.startswith(f"{name}: ") and summary in last, s["logs"][name][-2000:]
    assert s["stop_s"] < 60.0
    assert s["left"] == []


def test_a_dying_process_stops_the_others(session):
    d = session["dies"]
    assert d["killed"] == 1
    assert d["rc"] != 0
    assert "groundstation exited" in d["stderr"]
    assert d["left"] == []


def test_a_dying_bus_recorder_stops_up_with_an_error(session):
    """The recorder killed: up does not run on with a silent can.log and exit 0."""
    d = session["recorder_dies"]
    assert d["killed"] == 1
    assert d["rc"] == 1
    assert "bus recorder (candump) exited" in d["stderr"]
    assert d["left"] == []


def test_a_busy_port_names_the_port_and_the_way_out(session):
    b = session["busy"]
    assert b["rc"] == 1
    assert "port 5792 is in use" in b["stderr"] and "--instance 4" in b["stderr"]
    b = session["busy_sim"]
    assert b["rc"] == 1
    assert "unix:@tuav-sitl-sim-3 is in use" in b["stderr"] and "--instance 4" in b["stderr"]
