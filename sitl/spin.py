"""Bounded busy waiting before a blocking wait, for the plant's lockstep waits.

In lockstep the plant waits every control period for the companion's answer, and once a
winder cycle for the ground station's torque. Both usually arrive within a few tens of
microseconds. A process that sleeps for them must be woken: the sender's write then pays
for the wake-up of the plant's CPU (on a virtual machine an inter-processor interrupt that
exits to the hypervisor, and the idle CPU's return from its halt), and the plant starts
late by the time the wake-up takes. Spinning for a short while instead, with a readiness
check that costs a ``poll(0)``, takes both off the companion's CPU, which in lockstep on two
CPUs was the one that set the pace (docs/performance.md). It is for a plant with a CPU of
its own: ``tuav-sitl up`` in lockstep now puts the companion on the plant's CPU
(:func:`tuav_sitl.realtime.cpu_split`), where the hand-over is a context switch and a spin
would only keep the companion waiting, so ``up`` does not spin.

A spin that runs out of its budget gives up, and the next spins are skipped for 1, 2, 4 ...
up to :data:`BACKOFF_MAX` waits while they keep missing, so that a machine on which the
answers are slow (a busy host) sees the plant sleep as before. What crosses the links is
the same either way; only when the process notices its input changes.
"""

from __future__ import annotations

import time
from collections.abc import Callable

#: The most waits skipped after spins that missed, one after the other.
BACKOFF_MAX = 64


class SpinWait:
    """Spin for at most ``budget_s`` [s] of wall time until a readiness check is true (0:
    never spin), backing off after misses (see the module)."""

    def __init__(self, budget_s: float) -> None:
        if not budget_s >= 0.0:
            raise ValueError(f"spin budget must be >= 0 s, got {budget_s!r}")
        self.budget_s = float(budget_s)
        #: Spins that ended with the input there (hits) and in all.
        self.hits = 0
        self.spins = 0
        self._skip = 0
        self._backoff = 0

    def until(self, ready: Callable[[], object]) -> bool:
        """Spin until ``ready()`` is true (True) or the budget is spent, or skip the spin
        while backing off (False): the caller then waits blocking, as without a spin."""
        if self.budget_s <= 0.0:
            return False
        if self._skip:
            self._skip -= 1
            return False
        self.spins += 1
        clock = time.perf_counter
        end = clock() + self.budget_s
        while not ready():
            if clock() >= end:
                self._backoff = min(max(1, 2 * self._backoff), BACKOFF_MAX)
                self._skip = self._backoff
                return False
        self.hits += 1
        self._backoff = 0
        return True
