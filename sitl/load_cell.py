"""The winch's load cell at the fairlead: the tension the ``Winch_Tension`` frame carries.

A strain-gauge load cell and its amplifier: the truth is the line's tension at the drum
(``sitl.tether.TetherForces.drum_tension_n``); the amplifier low-passes it (its
anti-aliasing filter, first order, run at the sample rate), the reading arrives
``latency_s`` after the tension it measured (the amplifier's conversion and its bus
frame), and carries white noise (the bridge's, the line's flutter on the sheave). A
tension below zero cannot be read: the cell rests on its stop at 0 N plus the noise's
positive part.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from tuavdefs.paramspec import Params, quantity

#: Readings whose noise is drawn at once.
_BLOCK = 256


@dataclass(frozen=True)
class LoadCellParams(Params):
    """The load cell and its amplifier."""

    noise_n: float = quantity(
        0.01, "N", "standard deviation of the white noise of each reading (0.02 % of a "
        "50 N cell; the tether fix refuses a suspended line below 0.05 N)", ge=0)
    filter_s: float = quantity(
        0.01, "s", "time constant of the amplifier's first-order low-pass (0: none)", ge=0)
    latency_s: float = quantity(
        0.01, "s", "how long after the tension it measured a reading is sent", ge=0)
    seed: int = quantity(11, "", "seed of the noise", ge=0)


class LoadCell:
    """Tension readings [N] of the winch's load cell (module docstring), sampled by
    :meth:`read` at the sensor node's rate."""

    def __init__(self, params: LoadCellParams | None = None) -> None:
        self.p = p = params or LoadCellParams()
        self._rng = np.random.default_rng(p.seed)
        self._noise: list[float] = []
        self._next = 0
        self._filtered = math.nan
        self._last_t = math.nan
        self._delayed: deque[tuple[float, float]] = deque()

    def _draw(self) -> float:
        if self._next >= len(self._noise):
            self._noise = self._rng.normal(0.0, self.p.noise_n, _BLOCK).tolist()
            self._next = 0
        n = self._noise[self._next]
        self._next += 1
        return n

    def read(self, t_s: float, tension_n: float) -> float:
        """The reading [N] sent at ``t_s`` [s], the line's tension being ``tension_n`` [N]
        now (NaN: a failed cell, passed through)."""
        if not math.isfinite(tension_n):
            return tension_n
        p = self.p
        if math.isnan(self._filtered) or p.filter_s <= 0.0:
            self._filtered = tension_n
        else:
            dt = max(t_s - self._last_t, 0.0)
            self._filtered += (1.0 - math.exp(-dt / p.filter_s)) * (tension_n - self._filtered)
        self._last_t = t_s
        q = self._delayed
        q.append((t_s, self._filtered))
        # the newest value at least latency_s old (the oldest one at the start)
        while len(q) > 1 and q[1][0] <= t_s - p.latency_s + 1e-9:
            q.popleft()
        value = q[0][1]
        noise = self._draw() if p.noise_n > 0.0 else 0.0
        return max(value + noise, 0.0)
