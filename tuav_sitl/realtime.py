"""Real-time scheduling for the processes of a real-time run.

Paced by the wall clock, the plant and the companion must each get the CPU within a
fraction of a 4 ms control period. Under the default scheduler a process woken while busy
processes run can wait a whole scheduler tick (4 ms at HZ=250), so ``tuav-sitl up`` gives
them SCHED_FIFO where the system permits it (root, CAP_SYS_NICE or an rtprio limit), as
flight stacks on Linux do; docs/performance.md has the measurements. They block on their
sockets most of the time, and the kernel's real-time throttling keeps 5 % of each core for
everything else whatever happens.
"""

from __future__ import annotations

import os

#: SCHED_FIFO priority given to the processes (1 lowest .. 99 highest; low on purpose).
RT_PRIORITY = 10


def set_real_time(pid: int, priority: int = RT_PRIORITY) -> str | None:
    """Give every thread of process ``pid`` SCHED_FIFO at ``priority``; None when done,
    else why not (the process then keeps its normal scheduling)."""
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO is not available on this system"
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        tids = [pid]
    try:
        for tid in tids:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    except PermissionError:
        return "not permitted (needs root, CAP_SYS_NICE or an rtprio limit)"
    except ProcessLookupError:
        return "the process has gone"
    except OSError as exc:
        return str(exc)
    return None
