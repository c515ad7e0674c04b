"""A full disk ends the logs, not the flight: ``tuav-sitl up`` with its run folder on a
real tmpfs (a private mount namespace) that fills a few seconds into a hover at 5x flies
to the end of its run; up says the disk is full, the vehicle says which logs ended
(STATUSTEXT ``Logging: ...``), and it holds its place (tests/netns/disk_full_session.py).
ArduPilot keeps flying when its log fails; before, the plant died with ``OSError: [Errno
28] No space left on device`` and up stopped everything."""

from __future__ import annotations

import json
import math
import shutil

import pytest
from netns_util import PYTHON, ROOT, netns_available, run_in_netns

needs_root = pytest.mark.skipif(not netns_available() or shutil.which("mount") is None,
                                reason="needs root (unshare, mount) for private namespaces")


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> dict:
    disk = tmp_path_factory.mktemp("disk")
    script = (f"mount -t tmpfs -o size=8m tmpfs {disk} && "
              f"exec {PYTHON} -m tests.netns.disk_full_session {disk}")
    res = run_in_netns(["unshare", "--mount", "--propagation", "private", "--", "sh", "-c",
                        script], timeout_s=600, cwd=str(ROOT))
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


@needs_root
def test_the_stack_flies_to_the_end_of_its_run_on_a_full_disk(session):
    out = session
    assert out["free_at_end"] < 64 * 1024, "the logs must have filled the disk"
    assert out["up_rc"] == 0, out["up_stderr"]
    assert "plant finished" in out["up_stdout"], out["up_stdout"] + out["up_stderr"]
    assert out["last_sim_s"] >= 55.0
    assert out["left"] == []


@needs_root
def test_up_and_the_vehicle_say_the_logs_ended(session):
    out = session
    assert "is full" in out["up_stderr"], out["up_stderr"]
    said = [t for _, sev, t in out["texts"] if t.startswith("Logging:")]
    assert any("flight.tlog" in t for t in said), out["texts"]
    assert all(sev <= 3 for _, sev, t in out["texts"] if t.startswith("Logging:"))
    assert len(said) == len(set(said)), "each log's end is said once"


@needs_root
def test_the_vehicle_holds_its_place_while_the_disk_fills(session):
    positions = [p for p in session["positions"] if p[0] > 5.0]
    assert positions
    # LOCAL_POSITION_NED: north = y, east = x, down = -z of the start (6, 2, 12) m
    far = max(math.dist((n, e, -d), (2.0, 6.0, 12.0)) for _, n, e, d in positions)
    assert far < 0.5, far
