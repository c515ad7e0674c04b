"""The plant process's loop: the clock, the plant's stepping, and the loop's peers.

:class:`PlantLoop` runs one session of the simulator link (conventions in
:mod:`tuavdefs.simlink`) over a :class:`sitl.simlink_server.SimLinkServer`, the winder's
CAN node (:class:`sitl.winder_node.WinderCanNode`, optional) and the truth log
(:class:`sitl.truth_log.TruthLog`, optional)::

    k = 0, t = t0
    repeat:
        wait for period k's wall time (real time, or lockstep paced at N x)
        send HIL_GPS (when due, 10 Hz), HIL_STATE_QUATERNION, HIL_SENSOR, stamped t
        wait for the HIL_ACTUATOR_CONTROLS with time_usec == t
        hold its rotor commands and armed flag, and the CAN node's winder inputs, for
        N = T / dt physics steps of the plant; t += T

In **lockstep** (the default) the plant waits as long as it takes: the simulation runs as
fast as the two processes allow and is deterministic; **paced** lockstep (the server's
``speedup`` N) also waits for the wall time ``w0 + k T / N`` before period k's batch. In
**real time** the batch for period k goes out at wall time ``w0 + k T`` and the answer must
arrive before ``w0 + (k + 1) T``; if it does not, the plant steps with the commands it holds
and counts a missed deadline (a late answer still replaces the held commands when it
arrives). If the plant itself falls more than a period behind the wall clock it re-anchors
its schedule and counts an overrun. The mode is the server's (``real_time``, ``speedup``:
the link's convention, which the companion follows).

The peers' work for each state a control period reaches (the CAN node's frames, serviced
and emitted with the simulated time; the truth log's row; the caller's ``on_step``) runs
once before the next period's physics steps: in lockstep just after the batch describing
that state has gone out (so that it overlaps the companion's computing), in real time once
the answer is in (so that what arrived while waiting, such as a torque command, applies as
early as possible). Just before each period's physics steps, once the answer is in, the
loop takes the winder's inputs from the CAN node (in lockstep the last moment to wait for
the ground station's torque) and calls the caller's ``before_physics``.

A disconnect of the companion, :meth:`PlantLoop.stop` (or the ``stop_event`` given) or
``max_sim_time_s`` ends :meth:`PlantLoop.run` with a
:class:`sitl.simlink_server.ServeSummary`.
"""

from __future__ import annotations

import math
import threading
import time
from array import array
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from sitl.simlink_server import (
    STOP_POLL_S,
    DisconnectedError,
    ServeSummary,
    SimLinkServer,
    StoppedError,
    WinderInputs,
)
from tuavdefs import simlink as sl

if TYPE_CHECKING:
    from sitl.truth_log import TruthLog
    from sitl.winder_node import WinderCanNode

#: Longest a real-time wait spins before a batch's due time [s].
_SPIN_MAX_S = 0.001


def _quantile(sorted_values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (nearest rank) of ascending values; NaN for none."""
    if not sorted_values:
        return math.nan
    k = min(len(sorted_values) - 1, max(0, math.ceil(q * len(sorted_values)) - 1))
    return float(sorted_values[k])


class PlantLoop:
    """The plant's loop over its simulator-link ``server`` (which holds the plant, stepped
    in place, and the pacing: lockstep, real time, or lockstep paced at N x) and its peers:
    the winder's CAN ``node`` (None: the winder keeps the server's ``winder_inputs``,
    braked by default) and the ``truth_log`` (None: none written).

    ``on_step(server)``, if given, is called for each state a control period reaches, after
    the node's and the log's work; ``before_physics(server)`` just before each period's
    physics steps, after the winder's inputs are taken from the node. ``stop_event`` (None:
    the loop's own) ends :meth:`run` when set, as :meth:`stop` does.
    """

    def __init__(self, server: SimLinkServer, node: WinderCanNode | None = None,
                 truth_log: TruthLog | None = None,
                 on_step: Callable[[SimLinkServer], None] | None = None,
                 before_physics: Callable[[SimLinkServer], None] | None = None,
                 stop_event: threading.Event | None = None) -> None:
        self.server = server
        self.plant = server.plant
        self.node = node
        self.truth_log = truth_log
        self.on_step = on_step
        self.before_physics = before_physics
        self._stop = stop_event if stop_event is not None else threading.Event()
        #: In real time, the wait for a batch's due time ends awake, spinning for this long
        #: [s]: an eighth of the period, at most 1 ms.
        self.spin_s = min(_SPIN_MAX_S, server.period_us * 1e-6 / 8.0)

    @property
    def pacing(self) -> str:
        """"real-time", "lockstep" or "lockstep at Nx" (the server's)."""
        return self.server.pacing

    @property
    def steps(self) -> int:
        """Control periods advanced by the running (or last) :meth:`run`."""
        return self.server.steps

    # ----- lifecycle
    def stop(self) -> None:
        """Ask :meth:`run` to end (within :data:`sitl.simlink_server.STOP_POLL_S` of wall
        time; its summary's ``end_reason`` is then "stopped"). Safe from a signal handler
        or another thread."""
        self._stop.set()

    def close(self) -> None:
        """Close the server (its socket file goes with it), the truth log's stream and the
        CAN node's bus, in that order."""
        try:
            self.server.close()
        finally:
            try:
                if self.truth_log is not None:
                    self.truth_log.close()
            finally:
                if self.node is not None:
                    self.node.link.close()

    def __enter__(self) -> PlantLoop:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- the loop
    def run(self, max_sim_time_s: float | None = None,
            accept_timeout_s: float | None = None) -> ServeSummary:
        """Accept one companion and run the loop until it disconnects, :meth:`stop` is
        called, or ``max_sim_time_s`` [s] of simulated time have passed in this call.
        Without a connection within ``accept_timeout_s`` [s] (None: wait) returns at once
        (``end_reason`` "no_client", or "stopped")."""
        server = self.server
        plant = self.plant
        stop = self._stop
        ignored = late = missed = overruns = 0
        if not server.accept(stop, accept_timeout_s):
            return self._summary(0.0, 0, 0, 0, 0, "stopped" if stop.is_set() else "no_client")
        # the period's calls, bound once
        send_batch = server.send_batch
        wait_answer = server.wait_answer
        advance = server.advance
        node = self.node
        service = tick = node_inputs = None
        if node is not None:
            service, tick, node_inputs = node.service, node.tick, node.inputs
        record = self.truth_log.record if self.truth_log is not None else None
        on_step = self.on_step
        before_physics = self.before_physics
        step_work = service is not None or record is not None or on_step is not None

        def reached() -> None:
            # the peers' work for the state the last period reached
            if service is not None:
                t = plant.t_s
                service(t)
                tick(t)  # type: ignore[misc]
            if record is not None:
                record(server)
            if on_step is not None:
                on_step(server)

        real_time = server.real_time
        speedup = server.speedup
        period_us = server.period_us
        wall0 = time.monotonic()
        t0_us = sl.time_usec(plant.t_s)
        max_steps = (None if max_sim_time_s is None
                     else math.ceil(max_sim_time_s * 1e6 / period_us - 1e-9))
        reason = "disconnected"
        sched0 = wall0       # wall time of period 0's batch (real time)
        pending = False      # the peers' work is due for the state the last period reached
        # real time: the wall time between batches, and each batch's time after its due time
        intervals: array[float] = array("d")
        lateness: array[float] = array("d")
        last_sent: float | None = None
        in_service = False
        service_steps = service_missed = 0
        try:
            while True:
                if stop.is_set():
                    reason = "stopped"
                    break
                if max_steps is not None and server.steps >= max_steps:
                    reason = "max_sim_time"
                    break
                t_us = t0_us + server.steps * period_us
                if real_time:
                    due = sched0 + server.steps * period_us * 1e-6
                    now = time.monotonic()
                    if now > due + period_us * 1e-6:
                        overruns += 1
                        sched0 = now - server.steps * period_us * 1e-6
                        due = now
                    elif now < due:
                        self._sleep_until(due)
                    deadline: float | None = due + period_us * 1e-6
                else:
                    deadline = None
                    if speedup is not None:
                        due = sched0 + server.steps * period_us * 1e-6 / speedup
                        now = time.monotonic()
                        if now < due:
                            self._sleep_until(due)
                        elif now > due + 0.1:
                            # fell behind (a slow step): resume the pace, don't sprint
                            sched0 = now - server.steps * period_us * 1e-6 / speedup
                send_batch(t_us)
                if real_time and in_service:
                    sent = time.monotonic()
                    if last_sent is not None:
                        intervals.append(sent - last_sent)
                    lateness.append(sent - due)
                    last_sent = sent
                if pending and not real_time:
                    # lockstep: the peers' work for the state just reached (the winder's
                    # CAN traffic, the truth log) runs while the companion computes its
                    # answer, off the critical path
                    pending = False
                    reached()
                answered, n_late, n_ignored = wait_answer(t_us, deadline, stop)
                if pending:
                    # real time: just before the physics steps, so that whatever the
                    # node received meanwhile (a torque command) applies from them on
                    pending = False
                    reached()
                late += n_late
                ignored += n_ignored
                if not answered:
                    missed += 1
                if in_service:
                    service_steps += 1
                    service_missed += not answered
                # the pacing's statistics start once the companion has answered (before
                # that it is still starting up)
                in_service = in_service or answered or n_late > 0
                if node_inputs is not None:
                    # (in lockstep: the last moment to wait for the ground station's torque)
                    inputs = node_inputs(plant.t_s)
                    if server.winder_inputs != inputs:   # (a new tuple only if new)
                        server.winder_inputs = WinderInputs(*inputs)
                if before_physics is not None:
                    before_physics(server)
                advance()
                server.steps += 1
                pending = step_work
        except DisconnectedError:
            reason = "disconnected"
        except StoppedError:
            reason = "stopped"
        finally:
            try:
                if pending:
                    reached()
            finally:
                server.close_client()
        return self._summary(time.monotonic() - wall0, missed, overruns, late, ignored, reason,
                             intervals, lateness, service_steps, service_missed)

    def _summary(self, wall: float, missed: int, overruns: int, late: int, ignored: int,
                 reason: str, intervals: Sequence[float] = (),
                 lateness: Sequence[float] = (), service_steps: int = 0,
                 service_missed: int = 0) -> ServeSummary:
        """The run's :class:`ServeSummary`: wall time ``wall`` [s], the counts, the end's
        reason, and the real-time intervals between batches and their lateness [s]."""
        server = self.server
        period = server.period_us * 1e-6
        jitter = sorted(abs(d - period) for d in intervals)
        behind = sorted(lateness)
        return ServeSummary(
            steps=server.steps, sim_time_s=server.steps * period, wall_time_s=wall,
            missed_deadlines=missed, overruns=overruns, bad_frames=server.bad_frames,
            bad_bytes=server.bad_bytes, late_answers=late, ignored_messages=ignored,
            pacing=server.pacing, end_reason=reason,
            jitter_p50_s=_quantile(jitter, 0.5), jitter_p99_s=_quantile(jitter, 0.99),
            jitter_max_s=jitter[-1] if jitter else math.nan,
            lateness_p99_s=_quantile(behind, 0.99),
            lateness_max_s=behind[-1] if behind else math.nan,
            periods_in_service=service_steps, missed_in_service=service_missed)

    def _sleep_until(self, t: float) -> None:
        """Wait until wall time ``t`` [s] (or :meth:`stop`): sleep to :attr:`spin_s`
        before it, then spin.

        A sleeping process is woken by the scheduler, which on a busy machine first lets the
        task on the CPU finish its slice (up to a few milliseconds): the last stretch is
        spent awake, so the batch goes out on time whenever the process holds a CPU then.
        """
        spin = self.spin_s
        stop = self._stop
        while True:
            now = time.monotonic()
            left = t - now
            if left <= 0 or stop.is_set():
                return
            if left <= spin:
                while time.monotonic() < t:
                    pass
                return
            time.sleep(min(left - spin, STOP_POLL_S))
