"""The six-position accelerometer calibration run on the simulated vehicle
(tuav_sitl/calibration.py) against the plant part's own offsets, and what it gives the
filter: the attitude on the consumer-GNSS circle."""

import math

import numpy as np
import pytest

from sitl.sensors import SensorNoise, SensorSuite
from tuav_sitl.calibration import accel_calibration
from tuav_sitl.offline import run_scenario
from tuav_sitl.scenario import load_scenario

HOME = (47.0, 8.0, 400.0)
G = 9.80665


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_offsets_found_are_the_parts_within_its_drift(seed):
    noise = SensorNoise.preset("gnss", seed)
    part = SensorSuite(noise, HOME).accel
    found = np.array(accel_calibration(noise, HOME, G, seed=seed))
    # the turn-on offset (20 mg class) plus the in-run wander at the start
    truth = np.asarray(part.bias) + np.asarray(part.gauss_markov_error)
    assert np.abs(np.asarray(part.bias)).max() > 0.05           # a real offset to find
    np.testing.assert_allclose(found, truth, atol=0.01)


def test_the_faces_tilts_do_not_enter():
    """Exact readings, faces held 2 degrees (1 sigma) off: the fit finds no offset (the
    mid-points of opposite faces alone would be off by g (1 - cos tilt), 5 mm/s^2 here)."""
    noise = SensorNoise.off()
    for seed in range(3):
        np.testing.assert_allclose(accel_calibration(noise, HOME, G, seed=seed), (0, 0, 0),
                                   atol=1e-6)


def _tilt_error_rad(series: dict, after_s: float) -> float:
    """RMS of the roll and pitch estimates' error [rad] from ``after_s`` [s] on."""
    t, est = series["t"], series["est_euler"]
    w = (t >= after_s) & np.isfinite(est[:, 0])
    e = est[w, :2] - series["euler"][w, :2]
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def test_a_calibrated_vehicle_knows_its_attitude_to_half_a_degree():
    """The shipped circle-gnss within the 0.5 degree target; and what the calibration is
    for, the tilt (the heading is the magnetometer's): over four sensor seeds, from 5 s on
    (after the in-air alignment), its error without the calibration is several times what
    it is with it (measured 0.09-0.14 against 0.21-1.16 degrees; the whole attitude's RMSE,
    the heading's error in it, differs by 0.8-1.4 times only).

    On the catenary truth, the line the fused tether fix's model assumes: on the lumped line
    (circle-gnss's default) that fix is biased (issue 33) and the filter takes it out of the
    heading, 1-2 degrees from 3 s on, decaying over a minute: the attitude's RMSE 1.29
    degrees over 40 s, roll 0.04 and pitch 0.14 of it (0.24 here, and 0.24 on the lumped
    line without the tether fix)."""
    sc = load_scenario("circle-gnss").with_tether_model("catenary")
    cal = run_scenario(sc.replace(duration_s=40.0), None, progress=None).metrics
    assert cal["estimate_attitude_rmse_rad"] <= math.radians(0.5)
    tilt: dict[bool, list[float]] = {True: [], False: []}
    for seed in range(4):
        for on in (True, False):
            s = sc.replace(duration_s=20.0,
                           sensors=sc.sensors.replace(seed=seed, accel_calibration=on))
            tilt[on].append(_tilt_error_rad(run_scenario(s, None, progress=None).series, 5.0))
    assert max(tilt[True]) <= math.radians(0.25)
    assert np.mean(tilt[False]) > 2.0 * np.mean(tilt[True])
