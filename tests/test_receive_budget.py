"""The autopilot's receive budget (companion/autopilot.py) on a clock the test drives (each
reading of it advances it by a fixed step, so the work a call may do is counted in clock
readings, not wall time): a flood of COMMAND_LONG over TCP is handled at most
RECEIVE_BUDGET_S in each BUDGET_WINDOW_S of that clock however often ``receive`` is
called, at least one message a call, in order, every one in the end; while the budget is
spent the control loop waits on the winch alone (none here) until the window that brings
it back."""

from __future__ import annotations

import select
import socket
import time
import types

from gcs_util import wait_msg
from pymavlink import mavutil

import companion.autopilot as autopilot_module
from companion.autopilot import BUDGET_WINDOW_S, RECEIVE_BUDGET_S, Autopilot
from companion.mavlink_io import MavlinkEndpoints
from companion.navigation import NavigationParams, Navigator
from tuavdefs.simlink import HOME_DEFAULT

M = mavutil.mavlink
#: How far each reading of the test's clock advances it [s].
STEP_S = 1e-4
FLOOD = 120


class StepClock:
    """``perf_counter`` for the autopilot: ``t`` [s], advanced by :data:`STEP_S` at each
    reading."""

    def __init__(self) -> None:
        self.t = 1000.0

    def perf_counter(self) -> float:
        self.t += STEP_S
        return self.t


def test_a_flood_is_handled_within_the_budget_of_each_window(monkeypatch):
    clock = StepClock()
    monkeypatch.setattr(autopilot_module, "time", types.SimpleNamespace(
        perf_counter=clock.perf_counter, monotonic=time.monotonic))
    ep = MavlinkEndpoints(0, [])
    nav = Navigator(NavigationParams(), 0.2, 60.0)
    ap = Autopilot(ep, nav, HOME_DEFAULT, [], log=lambda text: None)
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{ep.tcp_port}", source_system=255)
    try:
        # the budget's windows start at the first reading: [anchor + k W, anchor + (k+1) W)
        anchor = clock.t + STEP_S
        ap.wait_s(0.05)
        while not ep.links():                            # the connection
            ap.receive(select.select(ap.selectables(), [], [], 2.0)[0])
        for _ in range(FLOOD):
            gcs.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 0,
                                      0, 0, 0, 0, 0, 0, 0)
        # the whole flood read at once (TCP: wait until the socket holds all of it)
        frame = len(M.MAVLink_command_long_message(
            1, 1, M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 0, 0, 0, 0, 0, 0, 0, 0).pack(gcs.mav))
        sock = ep._tcp[next(iter(ep._tcp))]
        deadline = time.monotonic() + 10.0
        while (len(sock.recv(1 << 20, socket.MSG_PEEK)) < FLOOD * frame
               and time.monotonic() < deadline):
            time.sleep(0.01)
        # a fresh window: the next reading half a step into it
        clock.t = anchor + 100 * BUDGET_WINDOW_S - 0.5 * STEP_S
        counts = ap.counters

        window_from = clock.t
        ap.receive(select.select(ap.selectables(), [], [], 2.0)[0])
        first = counts["commands"]
        # one window's budget in clock readings, a reading or two per message
        most = round(RECEIVE_BUDGET_S / STEP_S) + 1
        assert 1 <= first <= most
        assert not ap.backlogged                         # spent, though messages wait
        assert ap.watched() == [] and ap.watched() is not ap.selectables()
        assert 0.0 < ap.wait_s(0.05) <= 2 * BUDGET_WINDOW_S
        # called again and again in the same window: a message a call, no more
        for k in range(3):
            ap.receive([])
            assert counts["commands"] == first + k + 1
        # the budget back after the wait
        wait = ap.wait_s(0.05)      # (read before the clock: the call itself reads it)
        clock.t += wait
        assert ap.backlogged and ap.watched() is ap.selectables()
        for _ in range(10_000):
            if counts["commands"] == FLOOD:
                break
            if not ap.backlogged:
                wait = ap.wait_s(0.05)
                clock.t += wait
            ap.receive([])
        assert counts["commands"] == FLOOD and not ap.backlogged
        # the clock's time the flood took: at least its work at the budget's rate
        windows = (clock.t - window_from) / BUDGET_WINDOW_S
        assert windows >= FLOOD / (most + 3) - 1
        acks = 0
        while wait_msg(gcs, "COMMAND_ACK", timeout=2.0) is not None:
            acks += 1
            if acks == FLOOD:
                break
        assert acks == FLOOD                             # every one answered
    finally:
        gcs.close()
        ep.close()
