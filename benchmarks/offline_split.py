"""Where a control period of the offline loop goes: thread CPU time around each named step.

``python -m benchmarks.offline_split [--scenario circle-rtk] [--seconds 20] [--rounds 3]
[--tether-model lumped|catenary] [--law tension|paper] [--governor N]`` flies the scenario
(after a short warm-up run; the options override its truth tether, winder law and tether
governor) with a timer around each step of
:meth:`tuav_sitl.offline.OfflineRunner.run` and, inside them, around the parts that cost
most (the filter, the navigator, flight control; the winch fed its frames; the sensor
batch), and prints each one's CPU time per control period [us] and its share of the
loop's, the median over ``rounds`` runs. CPU time of this thread (``time.thread_time``),
not wall time: what the rest of the machine does moves it little. Each timer costs a few
tenths of a microsecond, counted in "the loop". Compare two trees by running this in
each, alternately (docs/performance.md).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import ScenarioParams, load_scenario

#: (label, path of the object from the runner, method name, parent label or None); a
#: label may time several methods (the onboard step: ``Companion.begin`` and ``finish``)
STEPS: tuple[tuple[str, str, str, str | None], ...] = (
    ("winder period", "", "_winder_period", None),
    ("  the winch fed its frames", "ground", "period", "winder period"),
    ("  WINCH_STATUS to the vehicle", "companion", "winch_report", "winder period"),
    ("control period", "", "_control_period", None),
    ("  sensor batch", "sensors", "read", "control period"),
    ("  onboard step", "companion", "begin", "control period"),
    ("  onboard step", "companion", "finish", "control period"),
    ("    the filter", "companion", "estimate", "  onboard step"),
    ("    the navigator", "companion.nav", "step", "  onboard step"),
    ("      its tether governor", "companion.nav.governor", "slow_clock", "    the navigator"),
    ("      its tether governor", "companion.nav.governor", "check", "    the navigator"),
    ("    flight control", "companion.flight", "update", "  onboard step"),
    ("log row", "", "_record", None),
    ("physics", "", "_advance", None),
)


def _labels() -> list[str]:
    """The step labels, once each, in order."""
    return list(dict.fromkeys(label for label, *_ in STEPS))


def _timed(obj: Any, name: str, acc: dict[str, float], label: str) -> None:
    """Wrap ``obj.name`` so that its thread CPU time adds to ``acc[label]``."""
    inner: Callable[..., Any] = getattr(obj, name)
    clock = time.thread_time

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = clock()
        try:
            return inner(*args, **kwargs)
        finally:
            acc[label] += clock() - t0

    setattr(obj, name, wrapper)


def scenario_variant(name: str, seconds: float, tether_model: str | None = None,
                     law: str | None = None, governor: int | None = None) -> ScenarioParams:
    """Scenario ``name`` for ``seconds`` of simulated time (metrics from the start), with
    the truth's and the model's tether ``tether_model``, the winder's ``law`` and the
    ``governor`` (TUAV_TETH_GOV) where given."""
    sc = load_scenario(name).replace(duration_s=seconds, metrics_after_s=0.0)
    if tether_model is not None:
        sc = sc.with_tether_model(tether_model)
    if law is not None:
        sc = sc.replace(winder_control=sc.winder_control.replace(law=law))
    if governor is not None:
        sc = sc.replace(navigation=sc.navigation.replace(tether_governor=governor))
    return sc


def split(sc: ScenarioParams) -> tuple[dict[str, float], int]:
    """One run of ``sc``: CPU time [s] per step label (and "total"), and the control
    periods."""
    runner = OfflineRunner(sc)
    acc = dict.fromkeys(_labels(), 0.0)
    for label, path, name, _ in STEPS:
        obj: Any = runner
        for part in filter(None, path.split(".")):
            obj = getattr(obj, part)
        if obj is not None:
            _timed(obj, name, acc, label)
    c0 = time.thread_time()
    runner.run()
    acc["total"] = time.thread_time() - c0
    return acc, runner.log.i


def main(argv: list[str] | None = None) -> int:
    """Print the split (module docstring)."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.offline_split",
                                 description=__doc__)
    ap.add_argument("--scenario", default="circle-rtk")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--tether-model", choices=("lumped", "catenary"),
                    help="the truth's and the model's tether (default: the scenario's)")
    ap.add_argument("--law", choices=("tension", "paper"),
                    help="the winder's law (default: the scenario's)")
    ap.add_argument("--governor", type=int, choices=(0, 1, 2),
                    help="the tether governor, TUAV_TETH_GOV (default: the scenario's)")
    args = ap.parse_args(argv)
    variant = (args.tether_model, args.law, args.governor)
    OfflineRunner(scenario_variant(args.scenario, 1.0, *variant)).run()   # warm
    runs = [split(scenario_variant(args.scenario, args.seconds, *variant))
            for _ in range(args.rounds)]
    periods = runs[0][1]
    med = {k: statistics.median(r[0][k] for r in runs) for k in runs[0][0]}
    total = med["total"]
    top = sum(med[label] for label in _labels() if label == label.lstrip())
    sc = scenario_variant(args.scenario, args.seconds, *variant)
    described = (f"{args.scenario} ({sc.plant.tether.model} truth, law "
                 f"{sc.winder_control.law}, governor {sc.navigation.tether_governor})")
    print(f"{described}, {args.seconds:g} s, {periods} control periods, median of "
          f"{args.rounds}: {1e6 * total / periods:.1f} us of CPU a period, "
          f"{args.seconds / total:.1f}x real time per CPU second")
    for label in _labels():
        print(f"{label:32s} {1e6 * med[label] / periods:8.1f} us {100 * med[label] / total:6.1f} %")
    rest = total - top
    print(f"{'the loop (and the timers)':32s} {1e6 * rest / periods:8.1f} us "
          f"{100 * rest / total:6.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
