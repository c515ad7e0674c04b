"""Every telemetry stream of the companion as an ArduCopter's, against real plant and
companion processes driven by pymavlink: GET_MESSAGE_INTERVAL answers each stream's
interval with MESSAGE_INTERVAL, SET_MESSAGE_INTERVAL and REQUEST_DATA_STREAM change it, and
the messages arrive at that rate of simulated time (counted against ATTITUDE's, whose
time_boot_ms is the clock: no wall-clock rates). The winch's WINCH_STATUS (a pymavlink
component 169 on the component link here) obeys the same requests."""

from __future__ import annotations

import socket
import threading
import time

import pytest
from gcs_util import Vehicle, command, free_port, wait_msg
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as apm2

from companion.telemetry import DEFAULT_RATES_HZ, FORWARDED, STREAM_GROUPS

M = mavutil.mavlink
STREAMED = [n for n in DEFAULT_RATES_HZ if n not in FORWARDED and n != "HOME_POSITION"]


def msg_id(name: str) -> int:
    return getattr(apm2, f"MAVLINK_MSG_ID_{name}")


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("streams")
    component_port = free_port()
    veh = Vehicle(tmp, udp_port=free_port(socket.SOCK_DGRAM),
                  extra=("--component-port", str(component_port)))
    winch = mavutil.mavlink_connection(f"tcp:127.0.0.1:{component_port}", source_system=1,
                                       source_component=169)
    stop = threading.Event()
    packer = apm2.MAVLink(None, srcSystem=1, srcComponent=169)   # WINCH_STATUS is MAVLink 2

    def beat() -> None:      # a winch reporting at 50 Hz of wall time
        while not stop.is_set():
            winch.write(apm2.MAVLink_winch_status_message(0, 10.0, 0.0, 0.5, 48.0, 1.0, 30,
                                                          1).pack(packer))
            stop.wait(0.02)

    t = threading.Thread(target=beat, daemon=True)
    t.start()
    try:
        yield {"veh": veh, "m": veh.connect()}
    finally:
        stop.set()
        t.join(2)
        winch.close()
        veh.stop()


def get_interval(m, name: str) -> int:
    m.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, msg_id(name), 0, 0, 0,
                            0, 0, 0)
    seen: list = []
    ack = wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_GET_MESSAGE_INTERVAL,
                   5, seen)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    answers = [x for x in seen if x.get_type() == "MESSAGE_INTERVAL"
               and x.message_id == msg_id(name)]
    assert answers, name
    return answers[-1].interval_us


def counts_over(m, seconds_sim: float) -> dict[str, int]:
    """How many of each message type arrive while ATTITUDE's clock advances
    ``seconds_sim`` [s of simulated time]."""
    first = wait_msg(m, "ATTITUDE", timeout=10)
    counts: dict[str, int] = {}
    end = time.monotonic() + 120
    while time.monotonic() < end:
        msg = m.recv_match(blocking=True, timeout=1)
        if msg is None:
            continue
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
        if (msg.get_type() == "ATTITUDE"
                and msg.time_boot_ms - first.time_boot_ms >= seconds_sim * 1000):
            return counts
    raise AssertionError("ATTITUDE's clock did not advance")


def test_get_message_interval_answers_every_stream_at_its_default(stack):
    m = stack["m"]
    for name, rate in DEFAULT_RATES_HZ.items():
        assert get_interval(m, name) == round(1e6 / rate), name
    assert get_interval(m, "HEARTBEAT") == 1_000_000
    # a message this vehicle does not stream: "not available"
    m.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0,
                            M.MAVLINK_MSG_ID_HIGH_LATENCY2, 0, 0, 0, 0, 0, 0)
    assert wait_msg(m, "MESSAGE_INTERVAL",
                    lambda x: x.message_id == M.MAVLINK_MSG_ID_HIGH_LATENCY2).interval_us == 0


def test_every_stream_arrives_at_its_default_rate(stack):
    m = stack["m"]
    counts = counts_over(m, 10.0)
    for name in STREAMED:
        expected = DEFAULT_RATES_HZ[name] * 10.0
        assert abs(counts.get(name, 0) - expected) <= 0.15 * expected + 1.5, (name, counts)
    assert counts.get("WINCH_STATUS", 0) > 0


def test_set_message_interval_moves_every_stream_and_get_reads_it_back(stack):
    m = stack["m"]
    for name in STREAMED:
        if name == "ATTITUDE":
            continue
        ack = command(m, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id(name), 200_000)   # 5 Hz
        assert ack.result == M.MAV_RESULT_ACCEPTED
        assert get_interval(m, name) == 200_000
    counts = counts_over(m, 6.0)
    for name in STREAMED:
        if name != "ATTITUDE":
            assert 24 <= counts.get(name, 0) <= 36, (name, counts)
    for name in STREAMED:       # back to the defaults
        command(m, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id(name), 0)
        assert get_interval(m, name) == round(1e6 / DEFAULT_RATES_HZ[name])


def test_repeated_stream_requests_keep_the_rate_and_its_phase(stack):
    """A ground station repeating REQUEST_DATA_STREAM (ten times a simulated second here, a
    flood in benchmarks/flood.py) gets the rate it asks, not a message at each request: a
    stream already at that rate keeps its phase."""
    m = stack["m"]
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_RC_CHANNELS, 1, 1)
    assert get_interval(m, "RC_CHANNELS") == 1_000_000
    first = wait_msg(m, "ATTITUDE", timeout=10)
    n, end = 0, time.monotonic() + 120
    while time.monotonic() < end:
        msg = m.recv_match(blocking=True, timeout=1)
        if msg is None:
            continue
        if msg.get_type() == "RC_CHANNELS":
            n += 1
        elif msg.get_type() == "ATTITUDE":      # 10 Hz: a request after each
            m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_RC_CHANNELS, 1, 1)
            if msg.time_boot_ms - first.time_boot_ms >= 6000:
                break
    assert 4 <= n <= 8, n
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_RC_CHANNELS, 2, 1)
    assert get_interval(m, "RC_CHANNELS") == 500_000


def test_request_data_stream_all_off_stops_everything_including_the_winch(stack):
    m = stack["m"]
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 0, 0)
    wait_msg(m, "HEARTBEAT")
    wait_msg(m, "HEARTBEAT")
    for names in STREAM_GROUPS.values():
        for name in names:
            assert get_interval(m, name) == -1, name
    seen: list = []
    for _ in range(3):          # three seconds of simulated time, the winch reporting
        wait_msg(m, "HEARTBEAT", seen=seen)
    kinds = {x.get_type() for x in seen}
    # HOME_POSITION is in no group (as in ArduPilot): SET_MESSAGE_INTERVAL alone moves it
    assert kinds <= {"HEARTBEAT", "STATUSTEXT", "COMMAND_ACK", "MESSAGE_INTERVAL",
                     "HOME_POSITION"}, kinds
    # the winch's status alone, at 2 Hz of simulated time: at most that, at least some
    command(m, M.MAV_CMD_SET_MESSAGE_INTERVAL, apm2.MAVLINK_MSG_ID_WINCH_STATUS, 500_000)
    seen = []
    first = wait_msg(m, "WINCH_STATUS", timeout=10, seen=seen)
    assert first is not None and first.get_srcComponent() == 169
    for _ in range(4):
        wait_msg(m, "HEARTBEAT", seen=seen)
    n = sum(x.get_type() == "WINCH_STATUS" for x in seen)
    assert 4 <= n <= 10, n
    # the groups back on at their rates
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
    assert get_interval(m, "RC_CHANNELS") == 250_000
    assert wait_msg(m, "SERVO_OUTPUT_RAW", timeout=10) is not None


@pytest.mark.parametrize("length", [49, 50, 51, 100, 137])
def test_long_statustext_goes_in_chunks_a_receiver_reassembles(length):
    """As MAVLink 2 defines it: up to 50 characters in one message of id 0; longer, one id,
    chunk_seq 0, 1, ..., the text ending at the first chunk shorter than 50 characters (an
    empty one after an exact multiple of 50)."""
    from companion.autopilot import Autopilot
    from companion.mavlink_io import MavlinkEndpoints
    from companion.navigation import NavigationParams, Navigator

    port = free_port(socket.SOCK_DGRAM)
    rx = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega")
    io = MavlinkEndpoints(None, [("127.0.0.1", port)])
    try:
        ap = Autopilot(io, Navigator(NavigationParams(), 0.2, 50.0), (0.0, 0.0, 0.0), [],
                       log=lambda _t: None)
        text = "".join(chr(ord("a") + i % 26) for i in range(length))
        ap.statustext(M.MAV_SEVERITY_INFO, text)
        chunks = []
        while True:
            s = rx.recv_match(type="STATUSTEXT", blocking=True, timeout=5)
            assert s is not None
            chunks.append(s)
            if s.id == 0 or len(s.text) < 50:
                break
        if length <= 50:
            assert chunks[0].id == 0 and chunks[0].text == text
        else:
            assert len({c.id for c in chunks}) == 1 and chunks[0].id != 0
            assert [c.chunk_seq for c in chunks] == list(range(len(chunks)))
            assert "".join(c.text for c in chunks) == text
    finally:
        io.close()
        rx.close()
