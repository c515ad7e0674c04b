"""The onboard log's pieces without processes: its GPS time against pymavlink's (the
clock DFReader and mavlogdump take from it), and its failsafe and event records from the
onboard objects flown offline, hooked as the companion process hooks them (after each
onboard step), with a winder lost on the CAN bus for a while."""

from __future__ import annotations

import math

import pytest
from pymavlink import DFReader

from companion.flight_log import ErrorCode, ErrorSubsystem, FlightLog, LogClock, gps_week_ms
from sitl.faults import FaultParams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario


@pytest.mark.parametrize("utc_s", [315964800.0, 1796601600.0, 1796601599.999,
                                   2000000000.123, 1167609600.5])
def test_gps_week_and_ms_are_what_log_tools_read_back(utc_s):
    week, ms = gps_week_ms(utc_s)
    assert 0 <= ms < 604800 * 1000
    assert DFReader.DFReaderClock()._gpsTimeToTime(week, ms) == pytest.approx(utc_s,
                                                                              abs=1e-3)


def test_the_clock_is_anchored_once_and_shared():
    clock = LogClock()
    first = clock.utc_s(12.5)
    assert clock.utc_s(13.5) == pytest.approx(first + 1.0)
    assert LogClock(clock.utc_at_zero_s).utc_s(12.5) == first


def test_a_lost_winder_is_an_error_record_and_its_end_another(tmp_path):
    sc = load_scenario("hover-gnss-loss")
    sc = sc.replace(duration_s=14.0, faults=(FaultParams(kind="can_loss", start_s=5.0,
                                                         end_s=9.0),))
    runner = OfflineRunner(sc)
    comp = runner.companion
    log = FlightLog(tmp_path, tuple(sc.home))
    begin, finish, report = comp.begin, comp.finish, comp.winch_report
    period = {}
    healthy_at: list[float] = []      # the winch's healthy reports [s]

    def heard(t_s, length_m, speed_m_s, tension_n, braked=False, healthy=True):
        if healthy:
            healthy_at.append(t_s)
        report(t_s, length_m, speed_m_s, tension_n, braked, healthy)

    def logged_begin(inputs):           # a period: the runner calls begin, then finish
        period["inputs"] = inputs
        return begin(inputs)

    def logged_finish(diagnostics=False):
        out = finish(diagnostics)
        log.period(period["inputs"], out, comp)
        return out

    comp.begin, comp.finish, comp.winch_report = logged_begin, logged_finish, heard
    runner.run()
    log.close()
    reader = DFReader.DFReader_binary(str(log.path))
    rec: dict[str, list] = {}
    while (msg := reader.recv_msg()) is not None:
        rec.setdefault(msg.get_type(), []).append(msg)
    errs = [(e.Subsys, e.ECode, e.TimeUS * 1e-6) for e in rec["ERR"]]
    assert [e[:2] for e in errs] == [(ErrorSubsystem.FAILSAFE_WINCH, ErrorCode.OCCURRED),
                                     (ErrorSubsystem.FAILSAFE_WINCH, ErrorCode.RESOLVED)]
    timeout_s = comp.failsafes.params.winch_timeout_s
    # the failsafe its timeout after the last healthy report, its end at the next one
    last = max(t for t in healthy_at if t < 5.0)
    back = min(t for t in healthy_at if t > 5.0)
    assert errs[0][2] == pytest.approx(last + timeout_s, abs=0.0041)
    assert errs[1][2] == pytest.approx(back, abs=0.0041) and back >= 9.0
    # in the air from the start: armed and airborne at the first state, home set there
    assert [e.Id for e in rec["EV"]] == [10, 28, 25]
    assert {"GPS", "IMU", "BARO", "MAG", "XKF1", "XKF4", "XKFT"} <= set(rec)
    assert any(k.U for k in rec["XKFT"])                        # the tether fix fused
    assert all(math.isfinite(x.PN) for x in rec["XKF1"])
