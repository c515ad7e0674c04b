"""The whole stack through ``tuav-sitl up`` (plant, ground station, companion as processes,
the winder on the CAN bus) hovering through a GNSS loss on the tether fix, watched by a
pymavlink ground station (in a private network namespace, as root)."""

import math

import pytest
from netns_util import netns_available, run_session

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")

POS_HORIZ_ABS = 16


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return run_session("tests.netns.tether_aid_session",
                       str(tmp_path_factory.mktemp("tether_aid")), timeout_s=400)


def test_the_stack_holds_position_through_a_gnss_loss(session):
    assert session["rc"] == 0, session["stderr"]
    texts = [t for _, t in session["texts"]]
    assert "EKF: GNSS lost, tether fix in use" in texts, session["companion_log"]
    i = texts.index("EKF: GNSS lost, tether fix in use")
    assert any(t.startswith("EKF: GNSS in use") for t in texts[i + 1:])
    assert not any("Failsafe" in t for t in texts)
    # the ground station's EKF_STATUS_REPORT keeps a horizontal position all through
    during = [flags for t, flags, _ in session["ekf"] if 16.0 <= t <= 35.0]
    assert during and all(f & POS_HORIZ_ABS for f in during)
    # the truth: within 0.5 m of the hold horizontally once settled, the tether never taut
    for t, x, y, z, length in session["truth"]:
        assert length > math.dist((x, y, z), (0.0, 0.0, 0.0))
        if t >= 10.0:
            assert math.hypot(x - 8.0, y - 4.0) <= 0.5, t

