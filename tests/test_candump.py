"""``tuav-sitl candump`` prints a live bus exactly as can-utils' candump does, and its -L
output decodes with cantools and the project's DBC."""

import re

import pytest
from netns_util import netns_available, run_session

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


@pytest.fixture(scope="module")
def dump(tmp_path_factory) -> dict:
    return run_session("tests.netns.candump_session", str(tmp_path_factory.mktemp("dump")),
                       timeout_s=180)


def test_exact_lines(dump):
    assert all(re.match(r"^\(\d{10}\.\d{6}\) ", ln) for ln in dump["L"])
    body = [re.sub(r"^\(\d{10}\.\d{6}\) ", "", ln) for ln in dump["L"]]
    assert body[0] == "udpmc0 00E#0000C03F00000000"          # 1.5 N m, little-endian f32
    assert body[1] == "udpmc0 009#000010400000" + "00BF"     # 2.25 rev, -0.5 rev/s
    assert body[2] == "udpmc0 01C#R8"                        # remote request, DLC 8
    assert body[3] == "udpmc0 002#"                          # zero length
    assert body[4] == "udpmc0 602#000048410000803E"          # 12.5 m, 0.25 m/s
    assert dump["log_file"] == dump["L"]


def test_default_format_with_decode(dump):
    d = dump["default"]
    assert d[0].startswith("  udpmc0  00E   [8]  00 00 C0 3F 00 00 00 00")
    assert "Set_Input_Torque" in d[0] and "1.5" in d[0]
    assert d[2] == "  udpmc0  01C   [8]  remote request"
    assert d[3].startswith("  udpmc0  002   [0] ")              # trailing space kept
    assert d[3].endswith("Estop()")


def test_cantools_decodes_the_log_output(dump):
    assert dump["cantools_rc"] == 0
    text = dump["cantools"]
    assert "Input_Torque: 1.5" in text
    assert "2.25" in text and "-0.5" in text
    assert "12.5" in text


def test_a_stopped_recorder_logs_what_is_still_queued(dump):
    """SIGTERM to a recorder asleep between bursts (up's, at idle priority, may be behind):
    the frames queued on its socket are logged before it exits, none lost."""
    assert dump["recorder_rc"] == 0
    strip = [re.sub(r"^\(\d{10}\.\d{6}\) ", "", ln) for ln in dump["recorder_log"]]
    assert strip == [re.sub(r"^\(\d{10}\.\d{6}\) ", "", ln) for ln in dump["L"]]
