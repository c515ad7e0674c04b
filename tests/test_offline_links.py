"""The offline runner's links with and without their bytes give the same run.

``OfflineRunner(sc, wire=True)`` packs every link message into its bytes and parses them
with the receiving process's own parser (pymavlink's, the simulator-link client's, the
winch link's); the default hands the fields' values at the fields' resolution. The
messages' values are checked against pymavlink's parser, and whole runs bit for bit.
"""

import math
import random

import numpy as np
import pytest

from sitl.faults import FaultParams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.offline_links import Links, WireLinks
from tuav_sitl.scenario import load_scenario
from tuavdefs import component_link as cl


def _values(rng: random.Random) -> list[float]:
    """Values across float32's range and its edges (signed zeros, beyond its precision,
    subnormal in float32, large)."""
    special = [0.0, -0.0, 1e-40, -1e-40, 1.0 + 2.0 ** -30, 123456.789012345, -3.3e38]
    return special + [rng.uniform(-1e3, 1e3) for _ in range(30)]


def test_local_position_as_the_winchs_parser_reads_it():
    rng = random.Random(3)
    vals = _values(rng)
    direct, wire = Links(), WireLinks()
    for i in range(len(vals)):
        pos = (vals[i], vals[i - 1], vals[i - 2])
        vel = (vals[i - 3], vals[i - 4], vals[i - 5])
        t = rng.uniform(0.0, 3600.0)
        a, b = direct.local_position(t, pos, vel), wire.local_position(t, pos, vel)
        assert repr(a) == repr(b)      # signed zeros too
    # the float32 resolution is there: a value beyond it does not come back whole
    (p, _), _ = direct.local_position(0.0, (1.0 + 2.0 ** -30, 0.0, 0.0), (0.0,) * 3)
    assert p[0] == 1.0


def _cov(rng: random.Random) -> tuple[tuple[float, ...], ...]:
    a = np.array([[rng.gauss(0.0, 0.5) for _ in range(3)] for _ in range(3)])
    c = a @ a.T + 0.01 * np.eye(3)
    return tuple(tuple(float(v) for v in row) for row in c)


def test_odometry_as_the_autopilot_takes_it():
    rng = random.Random(5)
    direct, wire = Links(), WireLinks()
    taken = 0
    for _ in range(200):
        fix = cl.ExternalPosition(rng.uniform(0.0, 600.0),
                                  tuple(rng.uniform(-50.0, 50.0) for _ in range(3)),
                                  _cov(rng))
        a, b = direct.odometry(fix), wire.odometry(fix)
        assert repr(a) == repr(b)
        taken += a is not None
        assert a is None or a.pos_m != fix.pos_m   # at float32, not the doubles
    assert taken == 200
    # a covariance not positive definite is refused either way
    bad = cl.ExternalPosition(1.0, (1.0, 2.0, 3.0), ((1.0, 2.0, 0.0), (2.0, 1.0, 0.0),
                                                      (0.0, 0.0, 1.0)))
    assert direct.odometry(bad) is None and wire.odometry(bad) is None
    nan = cl.ExternalPosition(1.0, (math.nan, 2.0, 3.0), _cov(rng))
    assert direct.odometry(nan) is None and wire.odometry(nan) is None


def test_tether_reading_as_the_autopilot_takes_it():
    """The raw reading (DEBUG_FLOAT_ARRAY "TETHER"): the same without the bytes as
    through them, at float32 and whole microseconds; not finite, refused."""
    rng = random.Random(7)
    direct, wire = Links(), WireLinks()
    for i in range(200):
        r = cl.TetherReading(rng.uniform(0.0, 600.0), rng.uniform(0.0, 60.0),
                             rng.uniform(0.0, 30.0), rng.uniform(-math.pi, math.pi),
                             rng.uniform(-0.1, 1.5),
                             rng.uniform(0.05, 3.0) if i % 4 else math.nan)
        a, b = direct.tether_reading(r), wire.tether_reading(r)
        assert repr(a) == repr(b)
        assert a is not None and a.t_s == round(r.t_s * 1e6) * 1e-6
        assert abs(a.length_m - r.length_m) < 1e-5 and a.length_m != r.length_m
        if i % 4:
            assert abs(a.weight_n_m - r.weight_n_m) < 1e-6 * r.weight_n_m
        else:
            assert math.isnan(a.weight_n_m)
    bad = cl.TetherReading(1.0, 10.0, math.nan, 0.1, 0.2)
    assert direct.tether_reading(bad) is None and wire.tether_reading(bad) is None


@pytest.mark.parametrize("weight", [math.nan, math.inf, -math.inf, -0.3, 0.0, 5e-4, 25.0,
                                    1e30])
def test_tether_reading_refuses_a_weight_out_of_range(weight):
    """The winder's weight estimate (``data[4]``) not finite or out of
    ``LINE_WEIGHT_RANGE_N_M`` (0: the array's zero of a winch that sends none) is read as
    none, the reading kept: sent as NaN, and a message carrying it anyway (another
    sender's) taken without it, through pymavlink's packing and parsing."""
    r = cl.TetherReading(3.0, 20.0, 2.5, 0.4, 0.6, weight)
    msg = cl.tether_reading_message(r)
    assert math.isnan(msg.data[4])
    msg.data[4] = weight          # as a sender that does not check would put it
    companion = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
    got, = companion.parse_buffer(msg.pack(cl.new_mavlink(cl.WINCH_COMPONENT_ID)))
    a = cl.tether_reading(got)
    assert a is not None and math.isnan(a.weight_n_m)
    assert (a.length_m, a.elevation_rad) == pytest.approx((20.0, 0.6))
    lo, hi = cl.LINE_WEIGHT_RANGE_N_M
    for w in (lo, 0.33, hi):
        msg.data[4] = w
        got, = companion.parse_buffer(msg.pack(cl.new_mavlink(cl.WINCH_COMPONENT_ID)))
        assert cl.tether_reading(got).weight_n_m == pytest.approx(w, rel=1e-6)


def _short(name: str, seconds: float, **changes) -> object:
    sc = load_scenario(name)
    return sc.replace(duration_s=min(sc.duration_s, seconds),
                      metrics_after_s=min(sc.metrics_after_s, 0.5 * seconds), **changes)


#: The paths: the EKF on GNSS with the tether fix; a mission without GNSS (the tether fix
#: its position source) from the ground through its DO_WINCH; a GNSS loss with a CAN
#: outage and a slow, lossy bus; a vehicle on the truth (no sensor batch).
RUNS = {
    "circle-rtk": lambda: _short("circle-rtk", 6.0),
    "mission-gnss-denied": lambda: _short("mission-gnss-denied", 12.0),
    "hover-gnss-loss, can faults": lambda: _short(
        "hover-gnss-loss", 10.0,
        faults=(FaultParams(kind="gnss_loss", start_s=3.0, end_s=8.0),
                FaultParams(kind="can_loss", start_s=4.0, end_s=4.4),
                FaultParams(kind="can", start_s=5.0, end_s=7.0, drop_probability=0.3,
                            delay_ms=15.0))),
    "circle (truth)": lambda: _short("circle", 4.0),
}


@pytest.mark.parametrize("name", sorted(RUNS))
def test_a_run_through_the_bytes_is_the_run_without_them(name):
    sc = RUNS[name]()
    wire_runner = OfflineRunner(sc, wire=True)
    a, b = OfflineRunner(sc).run(), wire_runner.run()
    assert a.series.keys() == b.series.keys()
    for col in a.series:
        assert np.array_equal(a.series[col], b.series[col], equal_nan=True), col
        assert a.series[col].dtype == b.series[col].dtype, col
    assert [tuple(e) for e in a.events] == [tuple(e) for e in b.events]
    if wire_runner.sensors is not None:    # the batches were parsed from their bytes
        assert wire_runner.sensors.wire and wire_runner.sensors.decoder.bad_frames == 0
