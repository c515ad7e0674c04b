"""Pairing the two clocks of a ``tuav-sitl up`` run: wall-clock time and simulated time.

The tlog and the CAN log of an up run are stamped with the wall clock [s since the epoch],
the plant's truth with simulated time [s]. The vehicle's telemetry pairs the two: each
:data:`TELEMETRY_CLOCK` message carries ``time_boot_ms``, which is simulated time [ms], and
is stamped by the tlog with the wall clock when it was sent (:func:`clock_pair`).
:class:`ClockMap` interpolates between those pairs (the telemetry streams at 10 Hz of
simulated time by default, so an event's simulated time is known to about 0.1 s). Frames
more than :attr:`ClockMap.EDGE_S` of wall time outside the telemetry's span cannot be
placed: they map to NaN and are left out.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = ["TELEMETRY_CLOCK", "ClockMap", "clock_pair"]

#: The vehicle's telemetry whose ``time_boot_ms`` [ms] is simulated time, and so pairs the
#: tlog's wall-clock stamp with the simulated clock.
TELEMETRY_CLOCK = ("ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")


def clock_pair(msg: Any, wall_s: float) -> tuple[float, float] | None:
    """The pair (wall-clock time [s since the epoch], simulated time [s]) that the
    vehicle's message ``msg`` (a pymavlink message) stamped ``wall_s`` gives, or None if
    it is not one of :data:`TELEMETRY_CLOCK`."""
    if msg.get_type() not in TELEMETRY_CLOCK:
        return None
    return wall_s, msg.time_boot_ms * 1e-3


class ClockMap:
    """Wall-clock time [s since the epoch] to simulated time [s], from pairs of the two:
    piecewise linear between them; up to :attr:`EDGE_S` of wall time beyond the first or
    last pair (an event just after the last telemetry) extrapolated at the mean rate of the
    nearest :attr:`EDGE_PAIRS` pairs; NaN further out, which cannot be placed."""

    #: How far beyond the pairs' span an instant is still placed [s of wall time].
    EDGE_S = 1.0
    #: Pairs whose mean rate extrapolates beyond the span.
    EDGE_PAIRS = 10

    def __init__(self, wall_s: Iterable[float], sim_s: Iterable[float]) -> None:
        w = np.asarray(list(wall_s), dtype=float)
        s = np.asarray(list(sim_s), dtype=float)
        if len(w) != len(s):
            raise ValueError("wall_s and sim_s must have the same length")
        order = np.argsort(w, kind="stable")
        w, s = w[order], s[order]
        if len(s):
            s = np.maximum.accumulate(s)
        # one pair per wall stamp (the latest simulated time stamped with it)
        keep = np.ones(len(w), dtype=bool)
        keep[:-1] = w[1:] > w[:-1]
        self.wall_s, self.sim_s = w[keep], s[keep]

    @classmethod
    def from_pairs(cls, pairs: Sequence[tuple[float, float]]) -> ClockMap:
        """The map of ``pairs`` of (wall-clock time [s since the epoch], simulated time
        [s]), as :func:`clock_pair` gives them; no pairs give an empty map."""
        if not pairs:
            return cls([], [])
        return cls(*zip(*pairs, strict=True))

    def __len__(self) -> int:
        return len(self.wall_s)

    def sim(self, wall_s: np.ndarray | float) -> np.ndarray:
        """Simulated time [s] of wall-clock instants ``wall_s`` [s]."""
        w = np.asarray(wall_s, dtype=float)
        ws, ss = self.wall_s, self.sim_s
        if len(ws) < 2:
            return np.full(w.shape, np.nan)
        out = np.interp(w, ws, ss)
        k = min(self.EDGE_PAIRS, len(ws) - 1)
        rate_lo = (ss[k] - ss[0]) / (ws[k] - ws[0])
        rate_hi = (ss[-1] - ss[-1 - k]) / (ws[-1] - ws[-1 - k])
        out = np.where(w < ws[0], ss[0] + (w - ws[0]) * rate_lo, out)
        out = np.where(w > ws[-1], ss[-1] + (w - ws[-1]) * rate_hi, out)
        inside = (w >= ws[0] - self.EDGE_S) & (w <= ws[-1] + self.EDGE_S)
        return np.where(inside, out, np.nan)
