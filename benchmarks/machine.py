"""How busy the rest of the machine was while a benchmark ran (Linux ``/proc/stat``).

The benchmarks' figures move with whatever else runs on the machine (other processes, and
on a virtual machine the host taking the CPU: *steal*). :class:`LoadMeter` takes a
snapshot before and after: the CPU time the whole machine used, minus this process's and
its waited-for descendants' own (``getrusage``), is what other processes used. Interrupt
and softirq time is counted as the machine's, so a little of the benchmarks' own network
work (loopback) shows up as "other" too: read small figures (a few per cent) as zero.
"""

from __future__ import annotations

import os
import resource
import time
from dataclasses import dataclass
from pathlib import Path


def _machine_s() -> tuple[float, float]:
    """(busy, steal) CPU time [s] of the whole machine since boot, summed over cores
    (0, 0 where ``/proc/stat`` is missing)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    except OSError:
        return 0.0, 0.0
    ticks = [int(f) for f in fields[:8]] + [0] * max(0, 8 - len(fields))
    user, nice, system, _idle, _iowait, irq, softirq, steal = ticks[:8]
    hz = os.sysconf("SC_CLK_TCK")
    return (user + nice + system + irq + softirq) / hz, steal / hz


def _own_s() -> float:
    """CPU time [s] of this process and of its children that have been waited for."""
    total = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        r = resource.getrusage(who)
        total += r.ru_utime + r.ru_stime
    return total


@dataclass
class Load:
    """What the machine did during an interval: ``wall_s`` [s], ``other_s`` [s] of CPU
    used by other processes, ``steal_s`` [s] of CPU taken by the host, on ``cores``."""

    wall_s: float
    other_s: float
    steal_s: float
    cores: int

    @property
    def other_fraction(self) -> float:
        """Other processes' CPU as a share [0..1] of all the cores' time."""
        return self.other_s / (self.wall_s * self.cores) if self.wall_s > 0 else 0.0

    @property
    def steal_fraction(self) -> float:
        """The host's steal as a share [0..1] of all the cores' time."""
        return self.steal_s / (self.wall_s * self.cores) if self.wall_s > 0 else 0.0


class LoadMeter:
    """Snapshot at construction; :meth:`load` gives the interval since."""

    def __init__(self) -> None:
        self._t = time.monotonic()
        self._busy, self._steal = _machine_s()
        self._own = _own_s()

    def load(self) -> Load:
        """The machine's load since the snapshot (children must have been waited for)."""
        busy, steal = _machine_s()
        other = max(0.0, (busy - self._busy) - (_own_s() - self._own))
        return Load(time.monotonic() - self._t, other, steal - self._steal,
                    os.cpu_count() or 1)
