"""Tether-aided navigation end to end: the exit-angle frames the plant's winch node sends
(decoded by cantools), the ground station's fix from the frames, ODOMETRY through
pymavlink, the onboard filter's tether fusion (source switching, refusals, the gate), and
the shipped scenarios flown offline against the truth."""

from __future__ import annotations

import math

import cantools
import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.ekf import (
    AidSource,
    EstimatorFlags,
    EstimatorParams,
    FilterHealth,
    HealthReason,
    NavFilter,
)
from groundstation.lbar import LBarParams
from groundstation.winch import Winch
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from sitl.exit_angle import ExitAngleSensor
from sitl.odrive_axis import WinchSensors
from sitl.plant import Plant
from sitl.trim import hover_trim
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl
from tuavdefs.frames import ned_to_enu
from tuavdefs.params import SystemParams

HOVER = (8.0, 4.0, 15.0)


@pytest.fixture(scope="module")
def db():
    return cantools.database.load_file(cp.dbc_path(), strict=True)


@pytest.fixture(scope="module")
def hovering():
    """A plant in hover trim at HOVER on a tether with 0.4 m of slack."""
    params = SystemParams()
    plant = Plant(params, dt_s=1e-3)
    length = math.dist(HOVER, (0, 0, 0)) + 0.4
    plant.x[:], _ = hover_trim(params, HOVER, length, 0.0)
    return params, plant


def test_exit_angle_frames_decode_with_cantools_to_the_truth(db, hovering):
    """The winch node's Winch_Exit_Angle, decoded by cantools with the DBC: the tether's
    true direction at the exit within the arm's bias, noise and a count; 50 Hz."""
    _, plant = hovering
    tf = plant.tether_forces()
    fx, fy, fz = tf.on_exit_n
    true_az, true_el = math.atan2(fy, fx), math.atan2(fz, math.hypot(fx, fy))
    sensors, arm = WinchSensors(), ExitAngleSensor()
    msg = db.get_message_by_name("Winch_Exit_Angle")
    sent = []
    for k in range(50):                       # 1 s at the plant's 250 Hz control rate
        t = k * 0.004
        if sensors.exit_angle_due(t):
            frame = sensors.exit_angle_frame(t, *arm.read(tf.on_exit_n))
            assert frame.arbitration_id == msg.frame_id == 0x604
            sent.append((t, msg.decode(frame.data)))
    assert 9 <= len(sent) <= 11              # every 20 ms of 0.2 s
    bound = 4 * math.hypot(arm.p.noise_rad, arm.p.bias_sigma_rad) + arm.p.resolution_rad
    for t, d in sent:
        assert d["Valid"] == 1
        assert d["Sample_Time"] == round(t * 1000)
        assert abs(d["Azimuth"] - true_az) < bound
        assert abs(d["Elevation"] - true_el) < bound


def _winch_fixes(db, params: SystemParams, length_m: float, tension_n: float,
                 exit_angle) -> list:
    """The fixes of 1 s of the frames a winch of ``params`` reads (built by cantools, as
    on the bus): a line of ``length_m`` standing still, the load cell reading
    ``tension_n``, the guide arm ``exit_angle()`` (azimuth, elevation [rad], valid) each
    frame."""
    g = params.environment.gravity_m_s2
    host = WinderHost(WinderControlParams(), LBarParams(), params.winder, params.tether, g)
    winch = Winch(host, params.winder, params.tether, g)
    rev = length_m / params.winder.drum_radius_m / (2 * math.pi)
    fixes = []
    for k in range(100):                      # 1 s of encoder frames
        t = k * 0.01
        stamp = round(t * 1000) & 0xFFFF
        az, el, valid = exit_angle()
        for name, values in (
                ("Winch_Exit_Angle", {"Azimuth": az, "Elevation": el, "Sample_Time": stamp,
                                      "Valid": int(valid)}),
                ("Winch_Tension", {"Tension": tension_n, "Brake_Engaged": 0,
                                   "Sample_Time": stamp})):
            m = db.get_message_by_name(name)
            winch.handle_frame(t, m.frame_id, m.encode(values))
        m = db.get_message_by_name("Get_Encoder_Estimates")
        out = winch.handle_frame(t, m.frame_id, m.encode({"Pos_Estimate": rev,
                                                           "Vel_Estimate": 0.0}))
        if out is not None and out.fix is not None:
            fixes.append(out.fix)
    return fixes


def test_the_winch_fixes_the_uav_from_its_frames(db, hovering):
    """The ground station's Winch fed the frames of the bus (built by cantools) finds the
    UAV where the plant has it, and sends the fix at its rate."""
    params, plant = hovering
    tf = plant.tether_forces()
    arm = ExitAngleSensor()
    fixes = _winch_fixes(db, params, plant.tether_length_m, tf.drum_tension_n,
                         lambda: arm.read(tf.on_exit_n))
    assert len(fixes) == 10                   # 10 Hz
    for f in fixes:
        cov = np.array(f.cov_m2)
        e = np.subtract(f.pos_m, HOVER)
        assert float(e @ np.linalg.solve(cov, e)) < 11.34      # chi-square(3), 0.99
        assert np.linalg.norm(e) < 0.15
        assert not f.on_ground
    assert [f.sample_time_ms for f in fixes] == [90 + 100 * i for i in range(10)]


def _fixes_from(db, length_m: float, tension_n: float, elevation_rad: float) -> list:
    """The fixes of 1 s of the winch's frames: a line of ``length_m`` leaving the exit at
    ``elevation_rad`` (azimuth 0) with the load cell reading ``tension_n``."""
    return _winch_fixes(db, SystemParams(), length_m, tension_n,
                        lambda: (0.0, elevation_rad, True))


def test_a_line_off_the_ground_pulling_nothing_gives_no_fix(db):
    """A line leaving the exit upward with a load cell reading nothing (within its noise:
    a dynamic line's slack lying on the ground past the exit, the guide arm still
    reading): the model would place the vehicle straight above the winder, L up, so no fix
    is sent; with a pull the load cell can tell, or a line flat on the ground, there is."""
    el = math.radians(35.0)
    assert _fixes_from(db, 2.4, 0.0, el) == []
    assert _fixes_from(db, 2.4, 0.04, el) == []
    assert len(_fixes_from(db, 2.4, 0.06, el)) == 10
    assert len(_fixes_from(db, 2.4, 0.0, 0.0)) == 10      # flat: the ground model's


def test_odometry_through_pymavlink_keeps_position_covariance_and_time():
    """ODOMETRY packed on the winch's link and parsed by pymavlink on the vehicle's: local
    NED as MAVLink defines it, the covariance's position block, the stamp."""
    cov = ((0.04, 0.01, -0.02), (0.01, 0.09, 0.03), (-0.02, 0.03, 0.16))
    fix = cl.ExternalPosition(123.456, (8.0, 4.0, 15.0), cov)
    data = cl.odometry_message(fix).pack(cl.new_mavlink(cl.WINCH_COMPONENT_ID))
    (m,) = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID).parse_buffer(data)
    assert m.get_type() == "ODOMETRY" and m.get_srcComponent() == cl.WINCH_COMPONENT_ID
    assert m.frame_id == mavlink2.MAV_FRAME_LOCAL_NED
    assert ned_to_enu((m.x, m.y, m.z)) == pytest.approx(fix.pos_m)
    assert m.time_usec == 123456000
    # pose_covariance: upper triangle of (x, y, z, ...) NED: x north, y east, z down
    assert m.pose_covariance[0] == pytest.approx(0.09)        # north-north = ENU y-y
    assert m.pose_covariance[1] == pytest.approx(0.01)        # north-east
    assert m.pose_covariance[2] == pytest.approx(-0.03)       # north-down = -(y-z)
    assert math.isnan(m.pose_covariance[3]) and math.isnan(m.q[0])
    back = cl.external_position(m)
    assert back.t_s == pytest.approx(fix.t_s)
    assert np.array(back.cov_m2) == pytest.approx(np.array(cov), rel=1e-6)
    # what the vehicle refuses: not local NED, not positive definite, not finite
    m.frame_id = mavlink2.MAV_FRAME_BODY_FRD
    assert cl.external_position(m) is None
    bad = cl.odometry_message(cl.ExternalPosition(1.0, (1.0, 2.0, 3.0),
                                                  ((1.0, 2.0, 0.0), (2.0, 1.0, 0.0),
                                                   (0.0, 0.0, 1.0))))
    assert cl.external_position(bad) is None
    bad.x = math.nan
    assert cl.external_position(bad) is None


def _still_filter(params: EstimatorParams) -> tuple[NavFilter, callable]:
    """A filter aligned on a still vehicle at HOVER from tether fixes alone, and a step
    function feeding it 250 Hz IMU samples (level, still) and a baro."""
    f = NavFilter(params, 9.81, ned_to_enu((0.2, 0.0, 0.45)))
    mag = (0.2, 0.0, -0.45)                   # body FLU, level, heading east... any field
    cov = ((0.01, 0.0, 0.0), (0.0, 0.01, 0.0), (0.0, 0.0, 0.01))

    def step(t: float, fix: tuple[float, float, float] | None = None) -> None:
        f.predict(t, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
        f.fuse_baro(t, 100.0 + HOVER[2])
        f.fuse_mag(t, mag)
        if fix is not None:
            f.fuse_tether(t, t - 0.02, fix, cov)

    return f, step


def test_filter_aligns_and_holds_on_tether_fixes_alone():
    """No GNSS ever: aligned from the tether fix, healthy, position from it; a 20 m outlier
    is rejected by the gate; stale, non-finite or indefinite fixes are refused."""
    f, step = _still_filter(EstimatorParams())
    t = 0.0
    for k in range(250 * 5):
        t = k / 250
        step(t, HOVER if k % 25 == 0 else None)
    st = f.status(t)
    # (converged once the tilt's variance is down: a still vehicle cannot tell it from the
    # accelerometer's bias; it fails nothing)
    assert f.aligned and st.reasons == HealthReason.NONE
    assert st.health in (FilterHealth.ALIGNED, FilterHealth.HEALTHY)
    assert st.flags & EstimatorFlags.POS_HORIZ_REL
    assert st.sources == AidSource.TETHER | AidSource.BARO | AidSource.MAG
    assert f.state().pos_m == pytest.approx(HOVER, abs=0.05)
    assert not f.fuse_tether(t, t, (HOVER[0] + 20.0, HOVER[1], HOVER[2]),
                             ((0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)))
    assert f.status(t).tether_variance > 1.0
    refused = f.tether_refused
    assert not f.fuse_tether(t, t - 1.0, HOVER, ((0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01)))
    assert not f.fuse_tether(t, t, (math.nan, 0.0, 0.0), ((1, 0, 0), (0, 1, 0), (0, 0, 1)))
    assert not f.fuse_tether(t, t, HOVER, ((1, 2, 0), (2, 1, 0), (0, 0, 1)))
    assert f.tether_refused == refused + 3
    # without tether aid nothing of it is taken: never aligned (no GNSS)
    g, step_g = _still_filter(EstimatorParams(tether_aid=False))
    for k in range(250 * 3):
        step_g(k / 250, HOVER if k % 25 == 0 else None)
    assert not g.aligned


def test_a_fix_rejected_for_long_without_gnss_is_reset_to_with_its_covariance():
    """No GNSS: fixes 20 m off the estimate, each rejected by the gate, for longer than
    tether_reset_s: the position is reset to the fix and its covariance is the fix's
    (with the floor on the diagonal), not one of its entries spread over the block."""
    params = EstimatorParams()
    f, step = _still_filter(params)
    t = 0.0
    for k in range(250 * 3):
        t = k / 250
        step(t, HOVER if k % 25 == 0 else None)
    assert f.aligned
    off = (HOVER[0] + 20.0, HOVER[1], HOVER[2])
    cov = ((0.04, 0.01, 0.005), (0.01, 0.09, 0.0), (0.005, 0.0, 0.01))
    k0 = k
    while f.tether_resets == 0 and k < k0 + 250 * (params.tether_reset_s + 2.0):
        k += 1
        t = k / 250
        step(t)
        if k % 25 == 0:
            f.fuse_tether(t, t, off, cov)
    assert f.tether_resets == 1
    assert f.state().pos_m == pytest.approx(off, abs=0.05)
    floor = params.tether_noise_min_m ** 2
    want = np.array(cov) + floor * np.eye(3)
    assert f.covariance[0:3, 0:3] == pytest.approx(want, rel=0.05, abs=1e-4)


def test_a_line_lighter_than_believed_does_not_pull_the_rtk_estimate():
    """circle-rtk on a line 0.52x the controllers' (the robustness sweep's lightest): the
    winder's weight estimate finds it, the fix takes the belief moved to within the band
    of it (a weight 20 % heavy, the fix about a metre off) and says so in its covariance,
    so the filter keeps to the RTK: the estimate within 12 cm RMS of the plant's truth and
    the circle flown within 12 cm (25 and 24 cm when the covariance allowed 3 % of the
    weight alone)."""
    sc = load_scenario("circle-rtk")
    line = sc.plant.tether
    sc = sc.replace(duration_s=40.0, plant=sc.plant.replace(
        tether=line.replace(linear_density_kg_m=0.52 * line.linear_density_kg_m)))
    m = OfflineRunner(sc).run().metrics
    assert m["estimate_position_rmse_m"] < 0.12
    assert m["position_rmse_m"] < 0.12
    assert m["min_tether_slack_m"] > 0.0


def _hover(aid: bool):
    sc = load_scenario("hover-gnss-loss")
    sc = sc.replace(duration_s=50.0, faults=(sc.faults[0].replace(start_s=15.0, end_s=40.0),),
                    estimator=sc.estimator.replace(tether_aid=aid))
    return OfflineRunner(sc).run()


def test_hover_holds_through_a_gnss_loss_on_the_tether_fix():
    """GNSS lost for 25 s in wind: the truth stays within 0.5 m of the hold horizontally,
    the tether never taut, and the STATUSTEXTs say the sources; without tether aid the EKF
    failsafe lands it (no position)."""
    res = _hover(True)
    s = res.series
    t = s["t"]
    loss = (t >= 15.0) & (t < 40.0)
    horiz = np.hypot(*(s["pos"][loss, :2] - np.array(HOVER[:2])).T)
    assert horiz.max() <= 0.5
    est = np.hypot(*(s["est_pos"][loss, :2] - s["pos"][loss, :2]).T)
    assert est.max() <= 0.5
    assert res.metrics["min_tether_slack_m"] > 0.0
    texts = [v for k, v, _ in res.events if k.value == "warning"]
    assert "EKF: GNSS lost, tether fix in use" in texts
    i = texts.index("EKF: GNSS lost, tether fix in use")
    assert any(x.startswith("EKF: GNSS in use") for x in texts[i + 1:])
    assert not [k for k, _, _ in res.events if k.value == "failsafe"]
    off = _hover(False)
    assert [k for k, _, _ in off.events if k.value == "failsafe"]
    texts = [v for k, v, _ in off.events if k.value == "warning"]
    assert "EKF: GNSS lost" in texts


def test_mission_without_any_gnss():
    """The shipped mission-gnss-denied (on the lumped line): every item reached within 1 m
    (truth), landed and disarmed, the tether never taut in flight. Before the take-off
    the winch's ground pre-tension pulls the line straight once, the only way to a fix on
    the ground without GNSS: 2 m of line is one lumped segment, which pulls nothing until
    it is straight, and then is strained (0.3 mm at 16.5 N for a moment)."""
    sc = load_scenario("mission-gnss-denied")
    runner = OfflineRunner(sc)
    res = runner.run()
    m = res.metrics
    assert m["items_reached"] == [1, 2, 3, 4, 5, 6]
    assert m["landed_disarmed"] is True
    s = res.series
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    assert slack[np.isfinite(s["ref_pos"]).all(axis=1)].min() > 0.0
    assert m["min_tether_slack_m"] > -1e-3
    t, pos = res.series["t"], res.series["pos"]
    targets = {3: (10.0, 0.0, 12.0), 4: (6.0, 8.0, 10.0), 5: (-2.0, 6.0, 8.0)}
    for seq, ts in zip(m["items_reached"], m["items_reached_t_s"], strict=True):
        if seq in targets:
            i = int(np.searchsorted(t, ts))
            assert math.dist(pos[i], targets[seq]) <= 1.0
    # the tether fix aided the estimate down to the touchdown: fused until the line lay
    # slack on the ground under the landed vehicle (no suspended line, no fix: on this
    # mission the last 1.2 s; the source's own timeout is 1 s)
    tether = runner.companion.filter.aid_sources.tether
    assert m["items_reached_t_s"][-1] - tether.time_last_fused <= 2.0


def test_the_stationary_constraint_keeps_a_parked_estimate_from_drifting():
    """Aligned on tether fixes at rest on the ground, then no fix for 40 s (a line the arm
    cannot read) while the accelerometer's bias shifts by 0.02 m/s^2: with the zero
    velocity fused (landed and disarmed) the estimate stays within 2 cm, without it it
    drifts by tens of centimetres."""
    parked = (2.0, 0.0, 0.2)
    drift = {}
    for stationary in (True, False):
        rng = np.random.default_rng(3)
        f = NavFilter(EstimatorParams(), 9.81, ned_to_enu((0.2, 0.0, 0.45)))
        cov = ((0.04, 0.0, 0.0), (0.0, 0.04, 0.0), (0.0, 0.0, 0.04))
        for k in range(250 * 43):
            t = k / 250
            bias = 0.02 if t > 3.0 else 0.0
            n = rng.normal(0.0, 0.06, 3)
            f.predict(t, tuple(rng.normal(0.0, 5e-3, 3)), (bias + n[0], n[1], 9.81 + n[2]))
            f.fuse_baro(t, 100.0 + parked[2])
            f.fuse_mag(t, (0.2, 0.0, -0.45))
            if t < 3.0 and k % 25 == 0:
                f.fuse_tether(t, t - 0.02, parked, cov)
            if stationary:
                f.fuse_stationary(t)
        assert f.aligned
        p = f.state().pos_m
        drift[stationary] = math.hypot(p[0] - parked[0], p[1] - parked[1])
    assert drift[True] <= 0.02
    assert drift[False] >= 0.2
