"""The plant's missed real-time deadlines, read from the last line of its log (the summary
``python -m sitl`` prints at its end), for the benchmarks that fly ``tuav-sitl up``.

What a missed deadline is (``sitl/plant_loop.py``): in real time the batch describing
period k goes out at wall time ``w0 + k T``; if the companion's HIL_ACTUATOR_CONTROLS
stamped with that period's time has not arrived by ``w0 + (k + 1) T``, the plant steps
the period's physics on the commands it holds and counts one. The plant's clock starts
when the companion connects, and until the companion's first answer (its start-up) every
period counts as missed: the goal (< 0.1 %) is about the periods *from the first answer*
(``ServeSummary.missed_fraction``, "in service"), which the rows report; the start-up's
periods are said beside them.

``python -m benchmarks.deadlines [--quick]``: the rows of the real-time deadlines in one
command — :mod:`benchmarks.view` (``up`` without a recorder, recording, ``--view web``;
and its ``run circle`` ratio) and :mod:`benchmarks.flood` (a hover, each flood, all at
once) — for a quiet host (about 25 minutes; root, for the private network namespace).
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class PlantDeadlines:
    """The deadlines of one real-time flight: periods and misses from the companion's
    first answer (``*_in_service``) and in all (the start-up's included)."""

    missed_in_service: int
    periods_in_service: int
    missed: int
    periods: int

    @property
    def percent(self) -> float:
        """Missed deadlines in service [% of the periods in service]."""
        return 100.0 * self.missed_in_service / max(self.periods_in_service, 1)

    @property
    def startup_missed(self) -> int:
        """Periods missed before the companion's first answer (its start-up)."""
        return self.missed - self.missed_in_service


def parse_plant_summary(last_line: str) -> PlantDeadlines:
    """The deadlines of the plant's summary line (real time); ValueError if it is not
    one."""
    periods = re.search(r"(\d+) periods,", last_line)
    missed = re.search(r"(\d+) missed deadlines", last_line)
    service = re.search(r"missed deadlines ([\d.]+) % of (\d+) periods from the first "
                        r"answer", last_line)
    if periods is None or missed is None or service is None:
        raise ValueError(f"not a real-time summary of the plant: {last_line}")
    n = int(service.group(2))
    # (the line gives the fraction to 0.001 %: exact as a count below 100,000 periods)
    return PlantDeadlines(round(float(service.group(1)) * n / 100.0), n,
                          int(missed.group(1)), int(periods.group(1)))


def total(flights: list[PlantDeadlines]) -> PlantDeadlines:
    """Several flights' deadlines summed."""
    return PlantDeadlines(sum(f.missed_in_service for f in flights),
                          sum(f.periods_in_service for f in flights),
                          sum(f.missed for f in flights), sum(f.periods for f in flights))


def main(argv: list[str] | None = None) -> int:
    """Fly the view's and the floods' benchmarks and print their rows."""
    from benchmarks.flood import bench_flood
    from benchmarks.view import bench_view

    ap = argparse.ArgumentParser(prog="python -m benchmarks.deadlines", description=__doc__)
    ap.add_argument("--quick", action="store_true", help="one short flight of each")
    args = ap.parse_args(argv)
    for r in [*bench_view(args.quick), *bench_flood(args.quick)]:
        value = f"{r.value:12.4g}" if r.value == r.value else f"{'-':>12s}"
        ref = f"{r.reference:10.3g}" if r.reference is not None else " " * 10
        print(f"{r.name:64s} {value} {r.unit:10s} {ref}  {r.note}"
              + (f"; goal {r.goal}" if r.goal else ""), flush=True)
    return 0


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.exit(main())
