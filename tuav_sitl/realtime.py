"""Scheduling of the stack's processes: SCHED_FIFO in real time; in lockstep CPU affinity,
idle priority for the bus recorder and a lower one for the ground station.

Paced by the wall clock, the plant and the companion must each get the CPU within a
fraction of a 4 ms control period. Under the default scheduler a process woken while busy
processes run can wait a whole scheduler tick (4 ms at HZ=250), so ``tuav-sitl up`` gives
them SCHED_FIFO where the system permits it (root, CAP_SYS_NICE or an rtprio limit), as
flight stacks on Linux do; docs/performance.md has the measurements. They block on their
sockets most of the time, and the kernel's real-time throttling keeps 5 % of each core for
everything else whatever happens.

:func:`set_priority` gives the other schedulings the real-time experiments compare
(:data:`PRIORITIES`); unlike the ``set_*`` functions above it raises when it cannot.
"""

from __future__ import annotations

import os
from collections.abc import Callable

#: SCHED_FIFO priority given to the processes (1 lowest .. 99 highest; low on purpose).
RT_PRIORITY = 10


def _each_thread(pid: int, apply: Callable[[int], object]) -> str | None:
    """``apply(tid)`` for every thread of process ``pid``; None when done, else why not."""
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        tids = [pid]
    try:
        for tid in tids:
            apply(tid)
    except PermissionError:
        return "not permitted (needs root, CAP_SYS_NICE or an rtprio limit)"
    except ProcessLookupError:
        return "the process has gone"
    except OSError as exc:
        return str(exc)
    return None


def set_real_time(pid: int, priority: int = RT_PRIORITY) -> str | None:
    """Give every thread of process ``pid`` SCHED_FIFO at ``priority``; None when done,
    else why not (the process then keeps its normal scheduling)."""
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO is not available on this system"
    param = os.sched_param(priority)
    return _each_thread(pid, lambda tid: os.sched_setscheduler(tid, os.SCHED_FIFO, param))


def cpu_split(available: set[int] | None = None) -> dict[str, set[int]] | None:
    """CPUs for the stack's processes in lockstep: the plant and the companion on one CPU,
    the ground station and the bus recorder (a :data:`BACKGROUND` process) on the others
    (``available``: the CPUs this process may use, by default its own affinity). None with
    fewer than 2 CPUs.

    In lockstep the plant and the companion take turns on the simulation's critical path:
    the plant waits for the companion's rotor commands, the companion for the plant's next
    state. On one CPU each hands it to the other by a context switch; on two, each send
    must wake the other's idle CPU, which on this KVM guest costs tens of microseconds a
    period (an interrupt to a halted virtual CPU). Together they ran the mission at
    18.6-19.4x where the plant on a CPU of its own, the companion beside the ground
    station, ran it at 15.9-16.3x in the same hour, and each spent about a quarter less CPU
    time per period (docs/performance.md). The ground station answers an encoder frame
    for the next control period's physics, so it has a period of slack: it and the
    recorder take the other CPUs."""
    cpus = sorted(available if available is not None else os.sched_getaffinity(0))
    if len(cpus) < 2:
        return None
    pair, rest = {cpus[0]}, set(cpus[1:])
    return {"plant": pair, "companion": pair, "groundstation": rest, "candump": rest}


#: A spin for the plant's lockstep waits [us] (``python -m sitl --lockstep-spin-us``,
#: :mod:`sitl.spin`; ``python -m benchmarks.stack --no-pin --spin``): the senders then need
#: not wake the plant's CPU. When the plant had a CPU of its own it took 7-15 % of the
#: companion's CPU time per period, but on a host busy with other work the flights were
#: slower; :func:`cpu_split` now puts the companion on the plant's CPU, where a spin would
#: only keep it waiting, so ``up`` does not pass it (docs/performance.md).
LOCKSTEP_SPIN_US = 200.0

#: Processes that only use CPU time the others leave (:func:`set_background`; in lockstep
#: and in real time): the bus recorder, which reads in bursts and keeps each frame's kernel
#: receive time.
BACKGROUND = frozenset({"candump"})

#: Niceness in lockstep (:func:`set_nice`): the ground station's torque answers an encoder
#: frame for the next control period's physics, so it has a period of slack where the
#: companion's answer has none; wherever they meet on a CPU (a mission client, a ground
#: station's tools), it yields. (A higher niceness needs no privilege.)
NICENESS = {"groundstation": 5}


def set_nice(pid: int, niceness: int) -> str | None:
    """Give every thread of process ``pid`` the ``niceness`` (-20 .. 19); None when done,
    else why not."""
    if not hasattr(os, "setpriority"):
        return "niceness is not available on this system"
    return _each_thread(pid, lambda tid: os.setpriority(os.PRIO_PROCESS, tid, niceness))


def set_background(pid: int) -> str | None:
    """Give every thread of process ``pid`` SCHED_IDLE: it runs only when its CPUs have
    nothing else to run (unprivileged); None when done, else why not."""
    if not hasattr(os, "SCHED_IDLE"):
        return "SCHED_IDLE is not available on this system"
    param = os.sched_param(0)
    return _each_thread(pid, lambda tid: os.sched_setscheduler(tid, os.SCHED_IDLE, param))


def set_affinity(pid: int, cpus: set[int]) -> str | None:
    """Restrict every thread of process ``pid`` to ``cpus``; None when done, else why not."""
    if not hasattr(os, "sched_setaffinity"):
        return "CPU affinity is not available on this system"
    return _each_thread(pid, lambda tid: os.sched_setaffinity(tid, cpus))


#: Scheduling the stack's processes can be given for experiments (``--priority`` of the
#: benchmarks, :func:`benchmarks.stack.run_stack`; :func:`set_priority`): ``fifo``:
#: SCHED_FIFO at :data:`RT_PRIORITY` (root, or CAP_SYS_NICE / RLIMIT_RTPRIO); ``nice``:
#: nice -10 (the same); ``slice``: a 0.1 ms EEVDF slice (``sched_setattr``
#: ``sched_runtime`` of a SCHED_OTHER task, Linux 6.12 and later, unprivileged), which lets
#: a woken process preempt a task running a longer slice.
PRIORITIES = ("fifo", "nice", "slice")
#: The requested slice of ``slice`` [ns].
SLICE_NS = 100_000
#: The ``sched_setattr`` system call's number, by machine.
_SYS_SCHED_SETATTR = {"x86_64": 314, "aarch64": 274}


def _set_slice(tid: int, slice_ns: int) -> None:
    """Ask for an EEVDF slice of ``slice_ns`` [ns] for thread ``tid`` (SCHED_OTHER, nice 0)."""
    import ctypes
    import platform
    import struct

    number = _SYS_SCHED_SETATTR.get(platform.machine())
    if number is None:
        raise OSError(f"sched_setattr: unknown system call number on {platform.machine()}")
    # struct sched_attr (SCHED_ATTR_SIZE_VER1, 56 bytes): size, policy, flags, nice,
    # priority, runtime, deadline, period, util_min, util_max
    attr = ctypes.create_string_buffer(struct.pack("IIQiIQQQII", 56, 0, 0, 0, 0, slice_ns,
                                                   0, 0, 0, 0))
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.syscall(number, tid, attr, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"sched_setattr: {os.strerror(err)}")


def set_priority(pid: int, how: str) -> None:
    """Give every thread of process ``pid`` the scheduling ``how`` (:data:`PRIORITIES`);
    raises OSError when the system refuses it, ValueError for an unknown ``how``."""
    for tid in map(int, os.listdir(f"/proc/{pid}/task")):
        if how == "fifo":    # what tuav-sitl up gives in real time (set_real_time)
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
        elif how == "nice":
            os.setpriority(os.PRIO_PROCESS, tid, -10)
        elif how == "slice":
            _set_slice(tid, SLICE_NS)
        else:
            raise ValueError(f"unknown priority {how!r}")
