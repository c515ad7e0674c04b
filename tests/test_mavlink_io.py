"""The ground-station endpoints' UDP peer table: bounded, and expiring (real UDP sockets
on 127.0.0.1, pymavlink frames)."""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import common as mavlink2

from companion.mavlink_io import MAX_UDP_PEERS, UDP_PEER_TIMEOUT_S, MavlinkEndpoints
from tests.gcs_util import free_port


def _heartbeat(sysid: int) -> bytes:
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=190)
    return mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
                                0).pack(mav)


def _read_all(io: MavlinkEndpoints, wait_s: float = 1.0) -> list:
    got, end = [], time.monotonic() + wait_s
    while time.monotonic() < end:
        got += io.receive(io.udp)
        time.sleep(0.01)
    return got


def test_udp_peers_are_bounded_and_expire():
    """Twenty senders from twenty ports: telemetry goes to the push target and the eight
    heard from last; every forgotten one is said as closed (so its streams are dropped);
    silent for the timeout, the rest are forgotten too; a sender writing again is back."""
    target = ("127.0.0.1", free_port(socket.SOCK_DGRAM))
    io = MavlinkEndpoints(None, [target])
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(20)]
    try:
        port = io.udp[0].getsockname()[1]
        for i, s in enumerate(senders):
            s.sendto(_heartbeat(200 + i), ("127.0.0.1", port))
            time.sleep(0.002)       # one after the other: an order of last hearing
        got = _read_all(io)
        assert len(got) == 20                                   # every frame was read
        links = io.links()
        assert len(links) == 1 + MAX_UDP_PEERS
        kept = {p[2][1] for p in links if p[2] != target}
        last = {s.getsockname()[1] for s in senders[-MAX_UDP_PEERS:]}
        assert kept == last
        closed = io.pop_closed()
        assert len(closed) == 20 - MAX_UDP_PEERS
        io.expire_udp_peers(time.monotonic() + UDP_PEER_TIMEOUT_S + 1.5)
        assert io.links() == [("udp", 0, target)]
        assert len(io.pop_closed()) == MAX_UDP_PEERS
        senders[0].sendto(_heartbeat(200), ("127.0.0.1", port))
        _read_all(io, 0.3)
        assert len(io.links()) == 2
    finally:
        for s in senders:
            s.close()
        io.close()
