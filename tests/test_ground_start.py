"""A start on the ground as a real vehicle has it: the plant's gear levels a tipped vehicle
at body rates its gyroscope sees (an invariant: the rates integrate to the rotation), and
the companion on a consumer receiver, whose first fix is a metre off, neither takes itself
for airborne nor arms before its filter has settled on the gear's height and the tether's
fix (the shipped mission on that receiver, through the offline runner)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from companion.navigation import Reason
from sitl.plant import QUAT, RATES, Plant, PlantInputs, initial_state
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario
from tuavdefs.frames import quat_multiply, quat_normalize, quat_to_euler
from tuavdefs.params import SystemParams


def test_the_gear_levels_a_tipped_vehicle_at_rates_the_gyro_sees() -> None:
    plant = Plant(SystemParams())
    roll0, pitch0, yaw0 = math.radians(7.5), math.radians(-5.0), 0.4
    plant.x[:] = initial_state(plant.model, euler_rad=(roll0, pitch0, yaw0))
    u = PlantInputs()
    # the body's rotation from its rates alone (the gyroscope's view), integrated as a
    # quaternion at the plant's step
    q = tuple(plant.x[QUAT].tolist())
    for _ in range(round(1.0 / plant.dt_s)):
        w0 = np.array(plant.x[RATES])
        plant.step(u)
        w = 0.5 * (w0 + np.array(plant.x[RATES]))
        angle = float(np.linalg.norm(w)) * plant.dt_s
        if angle > 0.0:
            ax = w / np.linalg.norm(w)
            dq = (math.cos(angle / 2), *(math.sin(angle / 2) * ax).tolist())
            q = quat_multiply(q, dq)
    roll, pitch, yaw = quat_to_euler(tuple(plant.x[QUAT]))
    assert abs(roll) < math.radians(0.01) and abs(pitch) < math.radians(0.01)
    # no yaw rate: the heading moves only as much as a rotation about a horizontal axis
    # moves a tilted body's Z-Y-X yaw
    assert yaw == pytest.approx(yaw0, abs=0.01)
    # what the rates integrate to is where the body is: no rotation the gyro missed
    gyro_roll, gyro_pitch, _ = quat_to_euler(quat_normalize(q))
    assert gyro_roll == pytest.approx(roll, abs=math.radians(0.05))
    assert gyro_pitch == pytest.approx(pitch, abs=math.radians(0.05))


@pytest.mark.parametrize("seed", [5, 6, 8])
def test_a_consumer_receiver_start_on_the_ground(seed: int) -> None:
    """Seeds whose first fixes are 1-1.8 m high or 1.3 m off: before, 6 and 8 took
    themselves for airborne and 5 and 6 pulled the line taut at the take-off."""
    sc = load_scenario("mission")
    sc = sc.replace(sensors=replace(sc.sensors, gnss="gnss", seed=seed),
                    wind=replace(sc.wind, seed=seed), duration_s=20.0)
    r = OfflineRunner(sc)
    refusals = []
    arm = r.companion.nav.arm

    def arm_heard() -> object:
        why = arm()
        refusals.append(why)
        return why

    r.companion.nav.arm = arm_heard
    res = r.run()
    assert r.companion._airborne_at_boot is False
    texts = [str(w) for w in refusals if w is not None]
    assert "PreArm: EKF settling" in texts
    assert all(w.reason is Reason.PREARM for w in refusals if w is not None)
    assert refusals[-1] is None                      # armed in the end
    s = res.series
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    assert slack.min() > 0.0
    # the estimate on the gear before the take-off: the gear's height, not the fix's
    on_gear = np.isfinite(s["est_pos"]).all(axis=1) & np.isnan(s["ref_pos"]).any(axis=1)
    assert on_gear.any()
    assert np.abs(s["est_pos"][on_gear][-1, 2] - sc.plant.vehicle.gear_height_m) < 0.15


def test_a_start_in_the_air_too_low_for_its_receiver_is_refused(tmp_path) -> None:
    """Below the height its first fix needs to be taken for the air (6.57 m with the
    consumer receiver, 0.63 m with RTK), a start in the air on the estimate would drop
    the vehicle: the scenario and ``up`` refuse it, naming the field."""
    from companion.navigation import air_start_too_low_m
    from tuavdefs.paramspec import ParameterError

    sc = load_scenario("circle-gnss")
    gear = sc.plant.vehicle.gear_height_m
    need = air_start_too_low_m(1.0, gear, sc.sensors.noise_model().gps_epv_m)
    assert need == pytest.approx(6.57, abs=0.01)
    with pytest.raises(ParameterError, match="initial.position_m: a start in the air"):
        sc.replace(initial=replace(sc.initial, position_m=(5.0, 0.0, need - 0.1)))
    sc.replace(initial=replace(sc.initial, position_m=(5.0, 0.0, need + 0.1)))
    sc.replace(initial=replace(sc.initial, position_m=(5.0, 0.0, 0.0)))      # the ground
    rtk = sc.replace(sensors=replace(sc.sensors, gnss="rtk"))
    rtk.replace(initial=replace(rtk.initial, position_m=(5.0, 0.0, 1.0)))
    import subprocess
    import sys
    run = subprocess.run([sys.executable, "-m", "tuav_sitl", "up", "--gnss", "gnss",
                          "--position", "0", "5", "3", "--logdir", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "--position: a start in the air with --gnss gnss needs Z >= 6.57 m" in run.stderr
