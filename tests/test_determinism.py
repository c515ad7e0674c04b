"""Two identical offline runs give identical results: nothing onboard or in the winch reads
a clock of its own (the winch's notices, status and re-arm run on the time it is handed:
simulated time offline, the process's monotonic clock in ``python -m groundstation``)."""

import numpy as np

from sitl.faults import FaultParams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario


def _marginal():
    """A short hover in wind through a GNSS loss and a CAN outage (the winder's axis
    disarms on its watchdog and the winch re-arms it): the paths with timers."""
    sc = load_scenario("hover-gnss-loss")
    faults = (FaultParams(kind="gnss_loss", start_s=3.0, end_s=9.0),
              FaultParams(kind="can_loss", start_s=5.0, end_s=5.4))
    return sc.replace(duration_s=12.0, faults=faults)


def _run():
    runner = OfflineRunner(_marginal())
    res = runner.run()
    return res, runner.ground.notices, runner.ground.winch.rearms


def test_two_identical_offline_runs_give_identical_series():
    (a, notices_a, rearms_a), (b, notices_b, rearms_b) = _run(), _run()
    assert a.series.keys() == b.series.keys()
    for name in a.series:
        assert np.array_equal(a.series[name], b.series[name], equal_nan=True), name
    assert [(k, v, t) for k, v, t in a.events] == [(k, v, t) for k, v, t in b.events]
    assert notices_a == notices_b
    assert rearms_a == rearms_b
    # the faults happened
    assert a.metrics["faults"] and any("can_loss" in line for line in a.metrics["faults"])
