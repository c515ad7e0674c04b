"""The simulator's fault parameters (SIM_*, tuavdefs/sim_params.py) as a ground station
meets them: a pymavlink client on a real ``tuav-sitl up`` sets them on the vehicle, which
relays them to the plant; the plant's truth log shows the wind it was given, GPS_RAW_INT
loses its fix and gets it back, and values out of range or unknown names are refused as
any parameter is (the value unchanged, a STATUSTEXT)."""

from __future__ import annotations

import math

import pytest
from netns_util import netns_available, run_session
from pymavlink import mavutil

M = mavutil.mavlink


@pytest.mark.skipif(not netns_available(),
                    reason="needs root (unshare) for a private network namespace")
def test_a_ground_station_sets_the_wind_and_the_gnss_of_the_plant(tmp_path):
    s = run_session("tests.netns.sim_params_session", str(tmp_path), timeout_s=600)
    assert s["rc"] == 0, s["stderr"]
    # the run's own wind (calm) announced by the plant; fixes to begin with
    assert s["wind_spd_0"] == 0.0 and s["fix_0"] >= M.GPS_FIX_TYPE_3D_FIX
    assert s["wind_dir"] == 90.0 and s["wind_spd"] == 5.0
    assert "simulator parameter SIM_WIND_SPD = 5" in s["plant_log"]
    # the truth: calm at the start; from the set on, 5 m/s from the east at the reference
    # height (10 m), the log profile's share of it at the UAV's height (roughness 0.03 m),
    # wherever the vehicle is (a loaded machine's run may have flown home and landed)
    wind = s["wind"]
    assert wind[0][1] == 0.0 and wind[0][2] == 0.0
    first = next(i for i, w in enumerate(wind) if w[1] != 0.0)
    flown = [w for w in wind[first + 1:] if w[3] > 1.0]
    assert len(flown) > 50
    for _, wx, wy, z in flown:
        assert wx == pytest.approx(-5.0 * math.log(z / 0.03) / math.log(10.0 / 0.03),
                                   rel=0.01)
        assert abs(wy) < 1e-9
    # refused: out of range, not an integer's range, unknown; the value kept
    assert s["wind_too_strong"] == 5.0
    assert "SIM_WIND_SPD: 100 outside 0..40" in s["texts"]
    assert s["gps_disable_2"] == 0.0
    assert "SIM_GPS_DISABLE: 2 outside 0..1" in s["texts"]
    assert s["unknown"] is None and "Unknown parameter SIM_NO_SUCH" in s["texts"]
    # the receiver disabled: GPS_RAW_INT says no GPS; enabled: a fix again
    assert s["gps_disable"] == 1.0
    assert s["fix_lost"] == M.GPS_FIX_TYPE_NO_GPS
    assert s["gps_enable"] == 0.0 and s["fix_back"] >= M.GPS_FIX_TYPE_3D_FIX
