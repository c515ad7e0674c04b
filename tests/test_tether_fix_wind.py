"""The wind the tether fix may be given (groundstation.tether_fix.ReportedWind,
docs/estimation.md §10, *The wind*): the vehicle's own estimate, brought to the fix's
reference height by its profile and low-passed, against closed forms; and the fix made
with it against the plant's lumped line settled in that wind (tests/lumped_util.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from chunk_socket import ChunkSocket
from lumped_util import settled_exit

from groundstation.tether_fix import ReportedWind, TetherFixer, TetherFixParams
from tuavdefs.params import TetherParams

G = 9.81
TP = TetherParams()


def test_a_report_is_brought_to_the_reference_height_and_low_passed():
    """A steady report of 4 m/s at 15 m is the profile's 4 (10/15)^(1/7) m/s at 10 m; the
    first reports are weighted equally (their mean, their population covariance beside
    it, against numpy's); once the reports outnumber ``wind_filter_s`` of them, a step to
    another wind is followed as a first-order lag of ``wind_filter_s`` (1 - 1/e of the
    step after one time constant, on 1 Hz reports); below ``wind_min_height_m`` the
    profile's value there is used."""
    p = TetherFixParams()
    rw = ReportedWind(p)
    rw.report(0.0, (4.0, 0.0, 0.0), 15.0)
    ref = 4.0 * (10.0 / 15.0) ** (1.0 / 7.0)
    assert rw.wind_m_s(0.5) == pytest.approx((ref, 0.0))
    samples = [(ref, 0.0)]
    for k in range(1, 10):
        rw.report(float(k), (0.0, 4.0, 0.0), 15.0)
        samples.append((0.0, ref))
    samples = np.array(samples)
    assert rw.wind_m_s(9.0) == pytest.approx(tuple(samples.mean(axis=0)), rel=1e-12)
    scatter = rw.covariance_m2_s2() - np.eye(2) * p.reported_wind_sigma_m_s ** 2
    assert scatter == pytest.approx(np.cov(samples.T, bias=True), abs=1e-12)
    rw = ReportedWind(p)
    for k in range(100):
        rw.report(float(k), (4.0, 0.0, 0.0), 15.0)
    for k in range(100, 100 + round(p.wind_filter_s)):
        rw.report(float(k), (0.0, 4.0, 0.0), 15.0)
    wx, wy = rw.wind_m_s(99.0 + p.wind_filter_s)
    assert wx == pytest.approx(ref * math.exp(-1.0), rel=1e-9)
    assert wy == pytest.approx(ref * (1.0 - math.exp(-1.0)), rel=1e-9)
    low = ReportedWind(p)
    low.report(0.0, (2.0, 0.0, 0.0), 0.2)
    assert low.wind_m_s(0.0)[0] == pytest.approx(
        2.0 * (10.0 / p.wind_min_height_m) ** p.wind_shear_exponent)


def test_no_wind_without_a_fresh_report():
    """None before a report, or once the last is older than ``wind_max_age_s``; a report
    that is not finite is ignored; a time going back starts the filter again; a report
    made while the vehicle moves faster than ``wind_max_speed_m_s`` is not taken."""
    p = TetherFixParams()
    rw = ReportedWind(p)
    assert rw.wind_m_s(0.0) is None
    rw.report(10.0, (3.0, 1.0, 0.0), None)
    assert rw.wind_m_s(10.0 + p.wind_max_age_s) == (3.0, 1.0)
    assert rw.wind_m_s(10.1 + p.wind_max_age_s) is None
    rw.report(11.0, (math.nan, 0.0, 0.0), 10.0)
    assert rw.wind_m_s(11.0) == (3.0, 1.0)
    rw.report(2.0, (-1.0, 0.0, 0.0), None)
    assert rw.wind_m_s(2.0) == (-1.0, 0.0)
    rw.report(3.0, (5.0, 0.0, 0.0), None, speed_m_s=1.5 * p.wind_max_speed_m_s)
    assert rw.wind_m_s(3.0) == (-1.0, 0.0)                 # a manoeuvring vehicle's: not taken
    assert rw.wind_m_s(2.1 + p.wind_max_age_s) is None


def test_the_reported_wind_takes_the_drag_out_of_the_fix():
    """hover-gnss-loss's hover (8, 4, 15) m on the plant's lumped line settled in a
    uniform 3 m/s from the west: the calm fix is 0.3 m or more off, downwind; given the
    wind as the vehicle reports it (the fix's profile set uniform, as the settled line's
    wind is) the fix is within 0.1 m, inside its covariance."""
    top = (8.0, 4.0, 15.0)
    length = math.dist(top, (0.0, 0.0, 0.0)) + 0.34
    t0, az, el, _, _ = settled_exit(top, length, (3.0, 0.0))
    p = TetherFixParams(wind_shear_exponent=0.0)
    fixer = TetherFixer(p, TP.linear_density_kg_m * G, TP.axial_stiffness_n, TP.diameter_m)
    calm, _, _ = fixer.position(length, t0, az, el)
    assert np.subtract(calm, top)[0] > 0.3
    rw = ReportedWind(p)
    rw.report(0.0, (3.0, 0.0, 0.0), top[2])
    pos, cov, _ = fixer.position(length, t0, az, el, wind_m_s=rw.wind_m_s(0.0))
    e = np.subtract(pos, top)
    assert np.linalg.norm(e) < 0.1
    assert e @ np.linalg.solve(np.array(cov), e) < 3.0


def test_the_winch_takes_the_vehicles_wind_at_its_reported_time_and_height():
    """``WinchSensors.set_wind`` with the winch's reported position: ignored before a
    position with its time; then taken at that time and height (the report at 12 m
    brought to 10 m by the profile)."""
    from groundstation.lbar import LBarParams
    from groundstation.winch import Winch
    from groundstation.winder_control import WinderControlParams
    from groundstation.winder_host import WinderHost
    from tuavdefs.params import SystemParams

    sp = SystemParams()
    host = WinderHost(WinderControlParams(), LBarParams(), sp.winder, sp.tether, G)
    winch = Winch(host, sp.winder, sp.tether, G)
    winch.sensors.set_wind((4.0, 0.0, 0.0), winch.uav, winch.uav_time_ms)
    assert winch.sensors.wind.wind_m_s(0.0) is None
    winch.set_uav(((3.0, 4.0, 12.0), (0.0, 0.0, 0.0)), 7000)
    winch.sensors.set_wind((4.0, 0.0, 0.0), winch.uav, winch.uav_time_ms)
    p = winch.fixer.p
    wx, wy = winch.sensors.wind.wind_m_s(7.0)
    assert wx == pytest.approx(4.0 * (10.0 / 12.0) ** p.wind_shear_exponent)
    assert wy == 0.0


def test_the_component_link_carries_the_vehicles_wind():
    """The companion's ``WIND_COV`` (NED, as pymavlink packs it) reaches the winch's link
    as the z-up wind it was made of (to float32), beside a position; a wind that is not
    finite is not taken."""
    from groundstation.winch_link import WinchLinkClient
    from tuavdefs import component_link as cl

    vehicle = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
    wind = (3.25, -1.5, 0.125)                       # east, north, up [m/s]
    frames = [cl.wind_message(7_000_000, wind).pack(vehicle),
              cl.wind_message(8_000_000, (math.nan, 0.0, 0.0)).pack(vehicle)]
    m = cl.wind_message(0, wind)
    assert (m.wind_x, m.wind_y, m.wind_z) == (-1.5, 3.25, -0.125)      # NED
    client = WinchLinkClient("127.0.0.1:9")
    client.sock, client._last_heartbeat = ChunkSocket(list(frames)), 1e18
    assert client.uav_wind() is None
    client.poll()
    assert client.winds_received == 1
    assert client.uav_wind() == pytest.approx(wind, abs=1e-6)
    client.poll()
    assert client.winds_received == 1 and client.uav_wind() == pytest.approx(wind, abs=1e-6)


def test_the_drag_bias_of_the_winders_weight_estimate_is_taken_off():
    """The winder's weight estimate is a calm line's (``groundstation.lbar.line_weight_n_m``
    of the exit's tension and elevation, the length and the height); on the plant's lumped
    line settled in a uniform wind it reads the line's drag as weight. ``weight_drag_bias``
    (the model's line in that wind, read by the same estimate) predicts that error: on
    lines of 18-29 m in 4-8 m/s along and across, what it leaves is at most a third of the
    error (and the drag's error is at least a tenth of the weight somewhere: the check is
    not idle)."""
    from groundstation.lbar import line_weight_n_m

    p = TetherFixParams(wind_shear_exponent=0.0)
    w_true = TP.linear_density_kg_m * G
    fixer = TetherFixer(p, w_true, TP.axial_stiffness_n, TP.diameter_m)
    worst = 0.0
    for top, speed, turn in (((0.0, -14.0, 25.0), 5.0, 0.0), ((8.0, 4.0, 15.0), 6.0, 0.0),
                             ((-10.0, 3.0, 20.0), 4.0, 0.5 * math.pi),
                             ((0.0, 12.0, 18.0), 8.0, 0.25 * math.pi)):
        az = math.atan2(top[1], top[0])
        wind = (speed * math.cos(az + turn), speed * math.sin(az + turn))
        length = math.dist(top, (0.0, 0.0, 0.0)) + 0.3
        t0, psi, eps, lowest, _ = settled_exit(top, length, wind)
        assert lowest > 0.0
        read = line_weight_n_m(t0, eps, length, top[2]) - w_true
        bias = fixer.weight_drag_bias(length, t0, psi, eps, wind)
        worst = max(worst, abs(read))
        assert abs(read - bias) <= abs(read) / 3.0 + 0.01 * w_true
    assert worst >= 0.1 * w_true
