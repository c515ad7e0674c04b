"""The project's udp_multicast bus speaks python-can's wire format: frames go both ways
between :class:`tuavdefs.canbus.CanLink` and ``can.Bus(interface="udp_multicast")``, and a
link never sees its own frames (in a private network namespace, as root)."""


import pytest
from netns_util import netns_available, run_session

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


def test_canlink_and_python_can_understand_each_other():
    out = run_session("tests.netns.can_interop_session", timeout_s=120)
    assert out["b"] == [[0x29, "010203", False, False], [0x2A, "00" * 8, True, False],
                        [0x123, "aabb", False, False], [0x1ABCDE, "05", False, True]]
    assert out["a"] == [[0x123, "aabb"], [0x1ABCDE, "05"]]
    assert out["a_extra"] is False and out["own_dropped"] == 2
    assert out["pc"] == [[0x29, "010203", False, 3], [0x2A, "", True, 8]]
    assert out["stamp_ok"] is True
    # send_frames: python-can's frames, in order; recv_ready: all of them at once
    assert out["burst_sent"] == 3
    assert out["burst"] == [[0x31, "01", False, False], [0x32, "00" * 8, True, False],
                            [0x33, "", False, False]]
    assert out["burst_pc"] == [[0x31, "01", False, 1], [0x32, "", True, 8], [0x33, "", False, 0]]
    assert out["empty_ready"] == [] and out["fileno_ok"] is True
