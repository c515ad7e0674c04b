"""The companion's ground-station receive is a duty cycle (issue: the stack holds under
floods): reading and handling messages spend a credit refilled at RECEIVE_SHARE of wall
time; a flood that outruns it waits with its sockets unwatched, so the control loop is
never kept spinning on it. Checked on a real Autopilot and a pymavlink client, on a clock
the test moves (each handled message costs a fixed time on it)."""

from __future__ import annotations

import select
import socket
import time

from pymavlink import mavutil

from companion.autopilot import RECEIVE_BUDGET_S, RECEIVE_SHARE, Autopilot
from companion.component_server import ComponentServer
from companion.mavlink_io import MavlinkEndpoints
from companion.navigation import NavigationParams, Navigator
from tuavdefs.simlink import HOME_DEFAULT

M = mavutil.mavlink
COST_S = 0.0002          # what one message's handling costs on the test's clock


def test_a_flood_is_handled_at_the_receive_share_and_its_sockets_wait_meanwhile():
    clock = [100.0]
    ep = MavlinkEndpoints(0, [])
    comp = ComponentServer(0)
    nav = Navigator(NavigationParams(), 0.2, 60.0)
    ap = Autopilot(ep, nav, HOME_DEFAULT, [], component=comp, log=lambda text: None,
                   clock=lambda: clock[0])
    handled: list[str] = []
    inner = ap.handle

    def costly(peer, msg):
        handled.append(msg.get_type())
        clock[0] += COST_S
        inner(peer, msg)

    ap.handle = costly
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{ep.tcp_port}", source_system=255)
    try:
        while not ep.links():
            ap.receive(select.select(ap.selectables(), [], [], 2.0)[0])
        gcs_sockets = set(ep.sockets())
        n = 200
        for k in range(n):
            gcs.mav.param_request_read_send(1, 1, b"", k)
        time.sleep(0.3)                          # all of it in the socket's buffer
        deadline = time.monotonic() + 5.0
        while ap.receive_wait_s() > 0.0 and not ap.backlogged:   # all of it read
            ready = select.select(ap.selectables(), [], [], 0.5)[0]
            ap.receive(ready)
            assert time.monotonic() < deadline
        first = len(handled)
        # the credit (RECEIVE_BUDGET_S) bought this many, the last one overrunning it
        assert first == int(RECEIVE_BUDGET_S / COST_S) or \
            first == int(RECEIVE_BUDGET_S / COST_S) + 1
        assert ap.backlogged
        # spent: the ground stations' sockets are not watched, the winch's still is
        assert ap.selectables() == [comp.selectable]
        wait = ap.receive_wait_s()
        assert wait > 0.0
        ap.receive(list(gcs_sockets))            # nothing is read or handled meanwhile
        assert len(handled) == first
        # over a long flood the handling takes RECEIVE_SHARE of the wall time, no more
        start_clock, start_n = clock[0], len(handled)
        while ap.backlogged:
            wait = ap.receive_wait_s()
            clock[0] += wait                     # the loop's wait for the credit
            ap.receive(ap.selectables())
        share = (len(handled) - start_n) * COST_S / (clock[0] - start_clock)
        assert share <= RECEIVE_SHARE * 1.05
        # and nothing was lost, in order
        assert handled.count("PARAM_REQUEST_READ") == n
    finally:
        gcs.close()
        ep.close()
        comp.close()



def test_a_burst_is_parsed_a_bounded_number_at_a_time_and_nothing_is_lost():
    """300 PARAM_SETs in one TCP write: each receive parses at most the number asked
    (the rest waits in the link's parser, the socket unread meanwhile), and every
    message comes out once, in order."""
    ep = MavlinkEndpoints(0, [])
    client = socket.create_connection(("127.0.0.1", ep.tcp_port))
    try:
        while not ep.links():
            ep.receive(select.select(ep.sockets(), [], [], 2.0)[0])
        mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
        n = 300
        client.sendall(b"".join(
            M.MAVLink_param_set_message(1, 1, b"WPNAV_SPEED", float(k), 9).pack(mav)
            for k in range(n)))
        time.sleep(0.3)
        got: list[float] = []
        deadline = time.monotonic() + 10.0
        while len(got) < n:
            ready = select.select(ep.sockets(), [], [], 0.2)[0]
            out = ep.receive(ready, 32)
            assert len(out) <= 32
            got += [m.param_value for _, m in out]
            assert time.monotonic() < deadline
        assert got == [float(k) for k in range(n)]
        assert not ep.unparsed
    finally:
        client.close()
        ep.close()
