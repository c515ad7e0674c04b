"""``tuav-sitl up --view web`` live, in real time in a private network namespace
(tests/netns/view_session.py): the banner's URL serves Rerun's web viewer (drawn by
headless Chromium where it is installed), Ctrl-C ends it cleanly, and the run's
recording.rrd, read back with rerun's own reader, holds every truth row, the estimate, the
fixes, the tether and the messages. (A module of its own: the suite's two workers take a
module each, and this flight is as long as the rest of tests/test_view.py.)"""

from __future__ import annotations

import pytest
from netns_util import netns_available, run_session

pytest.importorskip("rerun")

from tuav_sitl.view.recording import ROTOR_PLOTS, SHAPE_RATE_HZ, Entity  # noqa: E402


@pytest.mark.skipif(not netns_available(),
                    reason="needs root for a private network namespace (the CAN bus)")
def test_up_view_web_serves_the_live_view_and_records(tmp_path):
    """``up --view web`` in real time: the banner's URL serves the web viewer (drawn by
    Chromium where it is installed), Ctrl-C ends it cleanly, and recording.rrd holds every
    truth row, the estimate, the fixes, the tether and the messages."""
    out = run_session("tests.netns.view_session", str(tmp_path / "logs"),
                      str(tmp_path / "live.png"), timeout_s=900)
    assert "live view (Rerun's web viewer): http://127.0.0.1:9090/?url=" in out["view_line"]
    assert out["http_status"] == 200
    assert out["rc"] == 0, out["stderr"]
    assert out["left"] == []
    rows, n = out["rows"], out["truth_rows"]
    assert n > 50
    assert rows["/" + Entity.VEHICLE] == n, (rows, n)
    for path in (Entity.TENSION_TOP, Entity.LENGTH, Entity.LBAR, *ROTOR_PLOTS):
        assert rows["/" + path] == n, path
    assert rows["/" + Entity.TETHER] >= 0.25 * n * SHAPE_RATE_HZ / 50.0
    assert rows.get("/" + Entity.ESTIMATE, 0) > 0
    # the estimate against the truth interpolated at its instants
    assert 0 < rows.get("/plots/error/estimate_x", 0) <= rows["/" + Entity.ESTIMATE]
    assert rows.get("/" + Entity.GNSS_FIX, 0) > 0
    # the winch's tether fixes (ODOMETRY at 10 Hz, recorded in the tlog) and the filter's
    # ellipsoid (LOCAL_POSITION_NED_COV at 2 Hz), at their rates over the n / 50 s flown
    flown_s = n / 50.0
    assert 0.5 * flown_s * 10.0 <= rows.get("/" + Entity.TETHER_FIX, 0) <= flown_s * 10.0 + 5
    assert rows.get("/" + Entity.TETHER_FIX + "/accuracy", 0) == rows["/" + Entity.TETHER_FIX]
    assert 0.5 * flown_s * 2.0 <= rows.get("/" + Entity.ELLIPSOID, 0) <= flown_s * 2.0 + 2
    assert rows.get("/" + Entity.STATUS, 0) > 0
    assert f"{n} truth rows" in out["view_log"]
    if "shot" in out:       # taken as soon as it showed this, or after its 120 s
        from tests.netns.view_session import shows_the_scene

        assert shows_the_scene(out["shot"]), out["shot"]
