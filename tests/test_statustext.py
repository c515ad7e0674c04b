"""STATUSTEXT as ArduPilot sends it: a long text in MAVLink 2 chunks (``id``,
``chunk_seq``) that a real pymavlink receiver reassembles into the text sent, and
repeating texts at most once per kind every few seconds, whether the navigator or the
autopilot says them. Truths: MAVLink's STATUSTEXT definition (every chunk but the last 50
characters, the same non-zero id), ArduPilot's 256-character buffer, and the clock."""

from __future__ import annotations

import socket

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from companion.autopilot import Autopilot
from companion.mavlink_io import MavlinkEndpoints
from companion.navigation import NavEvent, NavigationParams, Navigator
from companion.statustext import (
    MAX_TEXT_BYTES,
    TEXT_KIND_INTERVAL_S,
    Notice,
    TextKind,
    TextRateLimit,
)

M = mavlink2


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Receiver:
    """A pymavlink UDP receiver that puts chunked STATUSTEXTs back together as MAVLink
    defines it: chunks of one non-zero id in chunk_seq order, the text ending at the first
    chunk shorter than 50 characters; a text of id 0 is whole."""

    def __init__(self, port: int) -> None:
        self.m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="ardupilotmega")
        self.chunks: list[object] = []

    def text(self, timeout_s: float = 5.0) -> tuple[str, list[object]]:
        parts: dict[int, str] = {}
        got = []
        while True:
            s = self.m.recv_match(type="STATUSTEXT", blocking=True, timeout=timeout_s)
            assert s is not None, "no STATUSTEXT"
            got.append(s)
            if s.id == 0:
                assert not parts
                return s.text, got
            parts[s.chunk_seq] = s.text
            if len(s.text) < 50:
                assert sorted(parts) == list(range(len(parts)))
                return "".join(parts[i] for i in sorted(parts)), got

    def silent(self, timeout_s: float = 0.5) -> bool:
        return self.m.recv_match(type="STATUSTEXT", blocking=True, timeout=timeout_s) is None


@pytest.fixture
def vehicle():
    port = _free_udp_port()
    rx = Receiver(port)
    io = MavlinkEndpoints(None, [("127.0.0.1", port)])
    nav = Navigator(NavigationParams(), 0.2, 50.0)
    ap = Autopilot(io, nav, (0.0, 0.0, 0.0), [], log=lambda _t: None)
    try:
        yield ap, rx
    finally:
        io.close()
        rx.m.close()


@pytest.mark.parametrize("length", [1, 50, 51, 99, 100, 150, 256, 300])
def test_a_long_text_goes_in_chunks_a_pymavlink_receiver_reassembles(vehicle, length):
    ap, rx = vehicle
    text = "".join(chr(ord("A") + i % 26) for i in range(length))
    ap.statustext(M.MAV_SEVERITY_WARNING, text)
    got, msgs = rx.text()
    assert got == text[:MAX_TEXT_BYTES]
    assert {m.severity for m in msgs} == {M.MAV_SEVERITY_WARNING}
    if length <= 50:
        assert len(msgs) == 1 and msgs[0].id == 0
        return
    assert len({m.id for m in msgs}) == 1 and msgs[0].id != 0
    assert [m.chunk_seq for m in msgs] == list(range(len(msgs)))
    assert all(len(m.text) == 50 for m in msgs[:-1]) and len(msgs[-1].text) < 50
    # the next long text is another id
    ap.statustext(M.MAV_SEVERITY_INFO, text)
    again, msgs2 = rx.text()
    assert again == got and msgs2[0].id != msgs[0].id


def test_a_repeating_text_at_most_once_per_kind_every_few_seconds(vehicle):
    ap, rx = vehicle
    nav = ap.nav
    braking = Notice(TextKind.TETHER_BRAKING, "Tether: braking at 10.00 m from the winder")
    for t in (0.0, 1.0, 4.9):
        nav._t = t
        nav._emit(NavEvent.WARNING, braking)
    nav._t = 4.9     # another kind is not held back by it
    nav._emit(NavEvent.WARNING, Notice(TextKind.TETHER_RESUMING, "Tether: room again"))
    nav._t = 5.0
    nav._emit(NavEvent.WARNING, braking)
    said = [str(v) for _, v in nav.pop_events()]       # at 0, 4.9 and 5 s
    assert said == [str(braking), "Tether: room again", str(braking)]
    # the autopilot's own repeating texts share the limiter (simulated time)
    nav._t = 10.0
    breach = Notice(TextKind.FENCE_BREACH, "Fence breach: circle")
    ap.statustext(M.MAV_SEVERITY_CRITICAL, breach)
    assert rx.text()[0] == "Fence breach: circle"
    nav._t = 12.0
    ap.statustext(M.MAV_SEVERITY_CRITICAL, breach)
    assert rx.silent()
    nav._t = 10.0 + TEXT_KIND_INTERVAL_S
    ap.statustext(M.MAV_SEVERITY_CRITICAL, breach)
    assert rx.text()[0] == "Fence breach: circle"
    # plain texts (a refusal, an item reached) are never held back
    for _ in range(3):
        ap.statustext(M.MAV_SEVERITY_INFO, "Reached command #2")
        assert rx.text()[0] == "Reached command #2"


def test_the_rate_limit_starts_afresh_when_the_clock_goes_back():
    lim = TextRateLimit(3.0)
    assert lim.allow(TextKind.TETHER_SLOWING, 100.0)
    assert not lim.allow(TextKind.TETHER_SLOWING, 102.9)
    assert lim.allow(TextKind.TETHER_SLOWING, 0.5)        # a reboot's clock
    assert lim.allow(TextKind.TETHER_SLOWING, 3.5)
