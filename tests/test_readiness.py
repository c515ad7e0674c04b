"""What the vehicle reports as ready comes from the check arming runs: every control period
of a start on the ground (the offline runner's onboard step, the telemetry's own messages
built from it), no report says "ready" (SYS_STATUS's pre-arm, GPS and AHRS health,
EKF_STATUS_REPORT's PRED_POS_HORIZ_ABS, home set) while the navigator's pre-arm check would
refuse an arm, and all of them say it in the period it passes. The calibration bits are
healthy from the first report, as ArduPilot sets them for calibrated sensors."""

from __future__ import annotations

from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.telemetry import Telemetry, TelemetryStreams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario

M = apm
READY_BITS = {"pre-arm": M.MAV_SYS_STATUS_PREARM_CHECK, "GPS": M.MAV_SYS_STATUS_SENSOR_GPS,
              "AHRS": M.MAV_SYS_STATUS_AHRS}
CALIBRATION = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
               | M.MAV_SYS_STATUS_SENSOR_3D_MAG)


def _reports(gnss: str, seed: int) -> list[tuple[float, bool, dict[str, bool], int]]:
    """Every period of the shipped mission's first seconds on receiver ``gnss``: the time
    [s], whether an arm would be accepted (the pre-arm check arming runs), what each
    readiness report says, SYS_STATUS's calibration health."""
    sc = load_scenario("mission")
    sc = sc.replace(sensors=replace(sc.sensors, gnss=gnss, seed=seed),
                    wind=replace(sc.wind, seed=seed), duration_s=6.0)
    r = OfflineRunner(sc)
    c = r.companion
    streams = TelemetryStreams(None, c.nav, (47.0, 8.0, 500.0), None)
    streams.estimator_ready = c.estimator_ready
    begin, finish = c.begin, c.finish
    seen = []
    period = {}

    def begin_and_keep(inputs):          # a period: the runner calls begin, then finish
        period["inputs"] = inputs
        return begin(inputs)

    def step_and_report(diagnostics=False):
        inputs = period["inputs"]
        out = finish(diagnostics)
        s = out.state
        if s is not None and not c.nav.armed:
            tm = streams.telem = Telemetry(inputs.t_s, s.pos_m, s.vel_m_s, s.quat,
                                           s.rates_rad_s, 0.0, c.imu, c.gps,
                                           c.last_status, out.rotor_commands)
            health = streams.build("SYS_STATUS", tm).onboard_control_sensors_health
            said = {name: bool(health & bit) for name, bit in READY_BITS.items()}
            said["EKF 512"] = bool(streams.build("EKF_STATUS_REPORT", tm).flags
                                   & M.EKF_PRED_POS_HORIZ_ABS)
            said["home"] = streams.home_set()
            seen.append((inputs.t_s, c.nav.prearm() is None, said, health & CALIBRATION))
        return out

    c.begin, c.finish = begin_and_keep, step_and_report
    r.run()
    return seen


@pytest.mark.parametrize(("gnss", "seed"), [("rtk", 0), ("gnss", 6)])
def test_no_report_says_ready_before_an_arm_would_be_accepted(gnss: str, seed: int) -> None:
    seen = _reports(gnss, seed)
    assert seen and not seen[0][1]                  # it starts refusing (settling)
    for t, accepted, said, _ in seen:
        if not accepted:
            assert not any(said.values()), (t, said)
    first = next(i for i, (_, accepted, _, _) in enumerate(seen) if accepted)
    assert all(seen[first][2].values()), seen[first]      # all of them, at once
    assert all(calibration == CALIBRATION for *_, calibration in seen)
