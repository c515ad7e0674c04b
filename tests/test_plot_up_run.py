"""``tuav-sitl plot`` on a ``tuav-sitl up`` run folder (tuav_sitl/run_import.py, with
tuav_sitl/tlog_read.py, clock_pairing.py and up_series.py).

A small but real up-style run folder is made by flying the plant and companion processes
(``python -m sitl`` on the ground with a long slack tether and the winder braked, no CAN, and
``python -m companion``) from a pymavlink client: GUIDED, arm, take off to 4 m, one target
refused (below the ground), one flown to, then a two-waypoint mission in AUTO. Its
``truth.csv`` and ``flight.tlog`` are the processes' own; ``params.toml`` is written as
``tuav-sitl up`` writes it. ``tuav-sitl plot`` then runs on it as a subprocess.

What is checked against independent truth: the imported series equal the CSV's columns
(read here with the csv module); L-bar lies between the straight-line distance (plus the
estimator's least slack) and the horizontal plus vertical distance (a rising catenary is
shorter than that); the tether-model tensions differ by the weight of the height climbed
(T_top - T_drum = w z for a catenary on frictionless ground); the metrics equal their
definitions recomputed from the CSV; the waypoints reached are those the client saw, at the
simulated time it saw them, with the UAV at the waypoint; the goals are the waypoints sent.
The CAN path is checked on a can.log written with the project's real frame encoders and
candump formatter at wall-clock instants of the real tlog.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from gcs_util import Vehicle, arm, command, upload_mission, wait_msg
from PIL import Image
from pymavlink import mavutil

from groundstation.lbar import LBarParams
from tuav_sitl.candump_format import format_log
from tuav_sitl.cli import main as cli_main
from tuav_sitl.figure_scene import reached_indices, reference_geometry
from tuav_sitl.offline import _to_toml
from tuav_sitl.run_data import load_run
from tuav_sitl.run_import import import_up_run, needs_import, read_truth
from tuav_sitl.scenario import WaypointParams
from tuav_sitl.tlog_read import read_tlog
from tuavdefs.can_protocol import (
    Cmd,
    SensorCmd,
    encode_encoder_estimates,
    encode_set_input_torque,
    encode_winch_tension,
    frame_id,
)
from tuavdefs.frames import local_enu_to_global
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import to_dict
from tuavdefs.simlink import HOME_DEFAULT

ROOT = Path(__file__).resolve().parents[1]
M = mavutil.mavlink
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
#: Positions flown [m], z-up frame.
TAKEOFF_ALT = 4.0
GUIDED_TARGET = (4.0, 2.0, 5.0)
WAYPOINTS = ((2.0, 3.0, 6.0), (5.0, -1.0, 5.0))
#: Figures an up run supports, and those it cannot (no reference, command, Lyapunov).
DRAWN = ("states", "path_3d", "tether_length", "snapshots", "tension_and_winder")
SKIPPED = ("errors", "position_tracking", "attitude_tracking", "lyapunov")
GEAR_M = SystemParams().vehicle.gear_height_m


def ll(x: float, y: float) -> tuple[float, float]:
    lat, lon, _ = local_enu_to_global((x, y, 0.0), HOME_DEFAULT)
    return lat, lon


def near(m, target: tuple[float, float, float], tol: float = 0.2):
    """Wait until LOCAL_POSITION_NED (NED) is within ``tol`` of ``target`` (z-up)."""
    x, y, z = target
    return wait_msg(m, "LOCAL_POSITION_NED",
                    lambda p: math.dist((p.y, p.x, -p.z), (x, y, z)) < tol, 60)


def start_vehicle(run: Path, attempts: int = 3) -> tuple[Vehicle, mavutil.mavfile]:
    """Start plant + companion writing into ``run`` and connect; a start that fails on a
    port (free_port's choice taken by another process in between) is tried again."""
    for attempt in range(attempts):
        veh = None
        try:
            veh = Vehicle(run)
            return veh, veh.connect()
        except (OSError, RuntimeError, TimeoutError, AssertionError):
            if veh is not None:
                veh.stop()
            if attempt == attempts - 1:
                raise
            for name in ("truth.csv", "flight.tlog", "plant.log", "companion.log"):
                (run / name).unlink(missing_ok=True)
    raise AssertionError("unreachable")


@pytest.fixture(scope="module")
def up_run(tmp_path_factory) -> dict:
    """Fly the short flight; the run folder and what the client saw."""
    run = tmp_path_factory.mktemp("runs") / "up-20250101-000000-0"
    run.mkdir()
    (run / "params.toml").write_text(_to_toml(to_dict(SystemParams())))
    veh, m = start_vehicle(run)
    seen: dict = {"dir": run, "reached": []}
    try:
        m.set_mode("GUIDED")
        assert wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_SET_MODE)
        assert arm(m).result == M.MAV_RESULT_ACCEPTED
        ack = command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, TAKEOFF_ALT)
        assert ack.result == M.MAV_RESULT_ACCEPTED
        assert near(m, (2.0, 0.0, TAKEOFF_ALT))
        mask = 0b0000111111111000   # position only
        # refused: below the ground (NED z = +3 m)
        m.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask,
                                                 1.0, 1.0, 3.0, 0, 0, 0, 0, 0, 0, 0, 0)
        assert wait_msg(m, "STATUSTEXT", lambda s: "below the ground" in s.text)
        x, y, z = GUIDED_TARGET
        m.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask,
                                                 y, x, -z, 0, 0, 0, 0, 0, 0, 0, 0)
        assert near(m, GUIDED_TARGET)
        items = [(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 0, 0, 0, *ll(wx, wy), wz)
                 for wx, wy, wz in WAYPOINTS]
        assert upload_mission(m, items).type == M.MAV_MISSION_ACCEPTED
        m.set_mode("AUTO")
        end = time.monotonic() + 60
        while time.monotonic() < end and len(seen["reached"]) < len(WAYPOINTS):
            msg = wait_msg(m, "MISSION_ITEM_REACHED", timeout=5)
            if msg is not None:   # the simulated time of the latest telemetry
                seen["reached"].append((msg.seq, m.messages["ATTITUDE"].time_boot_ms * 1e-3))
        assert [s for s, _ in seen["reached"]] == [1, 2]
    finally:
        plant_log, comp_log = veh.stop()
    assert "Traceback" not in plant_log + comp_log
    return seen


def truth_csv(path: Path) -> dict[str, np.ndarray]:
    """The truth CSV read independently of the import."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], np.array(rows[1:], dtype=float)
    return {name: body[:, i] for i, name in enumerate(header)}


def plot(run: Path, *extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-m", "tuav_sitl", "plot", str(run), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, env=env)


def shows_data(path: Path) -> bool:
    """Not blank: grey levels vary and some pixels are strongly coloured."""
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGB"), dtype=float)
    return a.mean(axis=2).std() > 8.0 and ((a.max(axis=2) - a.min(axis=2)) > 60).mean() > 1e-3


@pytest.fixture(scope="module")
def plotted(up_run) -> dict:
    """``tuav-sitl plot RUN_DIR --no-animation`` on the fresh folder."""
    run = up_run["dir"]
    assert needs_import(run)
    res = plot(run, "--no-animation")
    assert res.returncode == 0, res.stderr
    return {"dir": run, "stdout": res.stdout, "csv": truth_csv(run / "truth.csv"),
            "npz": dict(np.load(run / "timeseries.npz")),
            "metrics": json.loads((run / "metrics.json").read_text()),
            "scenario": tomllib.loads((run / "scenario.toml").read_text())}


def test_plot_imports_the_run_and_draws_what_it_supports(plotted):
    run, out = plotted["dir"], plotted["stdout"]
    assert "imported the 'tuav-sitl up' run from truth.csv, params.toml, flight.tlog" in out
    assert "note: no can.log: no winder torque" in out
    assert f"wrote {len(DRAWN)} figures" in out
    for name in DRAWN:
        png = run / "figures" / f"{name}.png"
        assert png.is_file() and shows_data(png), name
    for name in SKIPPED:
        assert not (run / "figures" / f"{name}.png").exists()
        assert f"skipped {name}: the run has no " in out
    assert not (run / "animation.gif").exists()
    assert not needs_import(run)


def test_series_are_the_truth(plotted):
    s, c = plotted["npz"], plotted["csv"]
    assert np.array_equal(s["t"], c["t_s"])
    assert np.array_equal(s["pos"], np.column_stack((c["x_m"], c["y_m"], c["z_m"])))
    assert np.array_equal(s["vel"], np.column_stack((c["vx_m_s"], c["vy_m_s"], c["vz_m_s"])))
    assert np.array_equal(s["euler"],
                          np.column_stack((c["roll_rad"], c["pitch_rad"], c["yaw_rad"])))
    assert np.array_equal(s["length"], c["tether_length_m"])
    assert np.array_equal(s["drum_rate"], c["drum_rate_rad_s"])
    assert np.array_equal(s["rotor_cmd"], np.column_stack([c[f"rotor{i}"] for i in (1, 2, 3, 4)]))
    assert np.array_equal(s["armed"], c["armed"])
    # the flight happened: up to the highest point flown, and back to the second waypoint
    assert s["pos"][:, 2].max() == pytest.approx(6.0, abs=0.3)
    assert math.dist(s["pos"][-1], WAYPOINTS[-1]) < 0.6
    # no reference, no CAN in this run
    for name in ("ref_pos", "att_cmd", "v_pos", "winder_torque"):
        assert np.isnan(s[name]).all(), name


def test_lbar_lies_between_the_chord_and_the_two_legs(plotted):
    s = plotted["npz"]
    pos = s["pos"]
    h, v = np.hypot(pos[:, 0], pos[:, 1]), pos[:, 2]
    chord = np.linalg.norm(pos, axis=1)
    lbar = s["lbar"]
    assert np.isfinite(lbar).all() and (s["lbar_fresh"] == 1).all()
    assert (lbar >= chord + LBarParams().min_slack_m - 1e-9).all()
    # a catenary rising from the winder (the exit angle is kept above 8 deg) is a monotone
    # curve: no longer than the horizontal plus the vertical leg (+ the smoothing's 1 cm,
    # and the least slack where the chord is flatter than the exit angle)
    assert (lbar <= h + v + LBarParams().min_slack_m + 0.011).all()


def test_tether_tensions_differ_by_the_weight_of_the_height(plotted):
    s = plotted["npz"]
    w = SystemParams().tether.weight_per_length_n_m(SystemParams().environment.gravity_m_s2)
    ok = np.isfinite(s["regime"])
    assert ok.mean() > 0.99
    z = s["pos"][ok, 2]
    diff = s["top_tension"][ok] - s["drum_tension"][ok]
    # dT = w dz / (1 + T/EA): equal to w z to well under 0.1 % at these tensions
    assert np.allclose(diff, w * z, rtol=2e-3, atol=1e-6)
    # 40 m paid out and braked: much of it lies on the ground all along
    assert plotted["metrics"]["tether_ground_contact_fraction"] == 1.0


def test_metrics_are_their_definitions_on_the_csv(plotted, up_run):
    m, c, s = plotted["metrics"], plotted["csv"], plotted["npz"]
    t = c["t_s"]
    dist = np.linalg.norm(np.column_stack((c["x_m"], c["y_m"], c["z_m"])), axis=1)
    flying = (c["armed"] > 0.5) & (c["z_m"] > GEAR_M + 0.1)
    assert m["source"] == "tuav-sitl up" and m["samples"] == len(t)
    assert m["sim_time_s"] == pytest.approx(t[-1], abs=1e-12)
    dt = np.diff(t)
    assert m["flight_time_s"] == pytest.approx(dt[flying[:-1]].sum(), abs=1e-9)
    assert m["armed_time_s"] == pytest.approx(dt[(c["armed"] > 0.5)[:-1]].sum(), abs=1e-9)
    assert 5.0 < m["flight_time_s"] < m["armed_time_s"] <= t[-1]
    assert m["max_tether_slack_violation_m"] == pytest.approx(
        np.max(dist - c["tether_length_m"]), abs=1e-12)
    assert m["max_tether_slack_violation_m"] < -30.0     # 40 m out, braked: never taut
    err = (c["tether_length_m"] - s["lbar"])[flying]
    assert m["tether_length_rmse_m"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
    assert m["max_winder_torque_n_m"] is None and m["position_rmse_m"] is None
    # the waypoints reached: the ones the client saw, when it saw them, with the UAV there
    reached = m["waypoints_reached"]
    assert [r["index"] for r in reached] == [seq for seq, _ in up_run["reached"]]
    radius = 0.5   # the companion's default WPNAV_RADIUS (50 cm)
    for r, (_, t_seen), wp in zip(reached, up_run["reached"], WAYPOINTS, strict=True):
        assert abs(r["t_s"] - t_seen) < 0.25
        at = [np.interp(r["t_s"], t, c[k]) for k in ("x_m", "y_m", "z_m")]
        assert math.dist(at, wp) < radius + 0.1


def test_scenario_holds_the_run_start_and_the_mission_flown(plotted):
    sc, c = plotted["scenario"], plotted["csv"]
    assert sc["name"] == plotted["dir"].name
    assert sc["initial"]["position_m"] == pytest.approx([c["x_m"][0], c["y_m"][0], c["z_m"][0]])
    tr = sc["trajectory"]
    assert tr["kind"] == "waypoints" and tr["acceptance_radius_m"] == 0.5
    got = [w["position_m"] for w in tr["waypoints"]]
    assert len(got) == len(WAYPOINTS)
    for g, wp in zip(got, WAYPOINTS, strict=True):   # 1e-7 deg of latitude is 1.1 cm
        assert math.dist(g, wp) < 0.02
    assert sc["vehicle"] == to_dict(SystemParams())["vehicle"]


def test_tlog_guided_targets_are_those_accepted(plotted):
    run, c = plotted["dir"], plotted["csv"]
    pos = np.column_stack((c["x_m"], c["y_m"], c["z_m"]))
    tl = read_tlog(run / "flight.tlog", c["t_s"], pos)
    assert tl.origin_source == "HOME_POSITION"
    assert math.dist(tl.origin[:2], HOME_DEFAULT[:2]) < 1e-8
    assert tl.origin[2] == pytest.approx(HOME_DEFAULT[2], abs=1e-6)
    # the clock: a telemetry message's wall stamp maps to its own simulated time
    assert np.allclose(tl.clock.sim(tl.clock.wall_s), tl.clock.sim_s)
    assert len(tl.guided_goals) == 2            # take-off and the target: not the refused one
    takeoff, target = tl.guided_goals
    assert takeoff.source == "NAV_TAKEOFF"
    assert takeoff.pos_m == pytest.approx((2.0, 0.0, TAKEOFF_ALT), abs=0.01)
    assert target.source == "SET_POSITION_TARGET_LOCAL_NED"
    assert target.pos_m == pytest.approx(GUIDED_TARGET, abs=1e-6)
    assert 0 < takeoff.t_s < target.t_s < c["t_s"][-1]
    # when the target was sent the UAV was at the take-off altitude, not yet moving to it
    # (3 m away); the tlog's wall stamp maps to simulated time through the telemetry's
    # pairing, a few tens of ms of wall time off at --speedup max, which is up to about a
    # metre of the 1.5 m/s climb: near the take-off point, far from the target
    at = [np.interp(target.t_s, c["t_s"], pos[:, i]) for i in range(3)]
    assert math.dist(at, (2.0, 0.0, TAKEOFF_ALT)) < 1.0
    assert math.dist(at, GUIDED_TARGET) > 2.0


def test_guided_goals_count_as_reached_by_proximity_without_a_reference(plotted):
    """A run with guided targets only (no mission): its goals are drawn as waypoints and,
    with no reference logged, count as reached when the UAV came within the acceptance
    radius of each in turn."""
    c = plotted["csv"]
    pos = np.column_stack((c["x_m"], c["y_m"], c["z_m"]))
    tl = read_tlog(plotted["dir"] / "flight.tlog", c["t_s"], pos)
    run = load_run(plotted["dir"])
    sc = run.scenario.replace(trajectory=run.scenario.trajectory.replace(
        waypoints=tuple(WaypointParams(position_m=g.pos_m) for g in tl.guided_goals)))
    geo = reference_geometry(sc)
    got = reached_indices(run.series, geo, {"waypoints_reached": None})
    want, start = [], 0
    for p in geo.points:
        hit = np.nonzero(np.linalg.norm(pos[start:] - p, axis=1) <= geo.acceptance_m)[0]
        start += int(hit[0])
        want.append(start)
    assert got == want and len(got) == 2 and want[0] < want[1]


def test_can_torque_is_decoded_onto_the_time_series(plotted, tmp_path):
    run = tmp_path / "with-can"
    shutil.copytree(plotted["dir"], run)
    for name in ("timeseries.npz", "metrics.json", "scenario.toml"):
        (run / name).unlink()
    c = plotted["csv"]
    tl = read_tlog(run / "flight.tlog", c["t_s"],
                   np.column_stack((c["x_m"], c["y_m"], c["z_m"])))
    w0, w1 = tl.clock.wall_s[0], tl.clock.wall_s[-1]
    walls = w0 + (w1 - w0) * np.array([0.2, 0.4, 0.6, 0.8])
    torques = [-1.5, 0.25, 2.0, -0.75]          # exact in float32
    lines = [format_log(w0 - 5.0, "vcan0", frame_id(0, Cmd.SET_INPUT_TORQUE),
                        encode_set_input_torque(3.5))]   # before the telemetry: untimed
    for w, tq in zip(walls, torques, strict=True):
        lines.append(format_log(w - 1e-4, "vcan0", frame_id(0, Cmd.GET_ENCODER_ESTIMATES),
                                encode_encoder_estimates(12.0, 0.5)))
        lines.append(format_log(w, "vcan0", frame_id(0, Cmd.SET_INPUT_TORQUE),
                                encode_set_input_torque(tq)))
        lines.append(format_log(w + 1e-4, "vcan0", frame_id(0x30, SensorCmd.WINCH_TENSION),
                                encode_winch_tension(9.0, False)))
    (run / "can.log").write_text("\n".join(lines) + "\n")
    res = import_up_run(run)
    t = res.series["t"]
    t_cmd = tl.clock.sim(walls)
    expected = np.full(len(t), np.nan)
    for tc, tq in zip(t_cmd, torques, strict=True):
        expected[t >= tc] = tq
    got = res.series["winder_torque"]
    # samples within a microsecond of a command instant may fall either side
    clear = np.min(np.abs(t[:, None] - t_cmd[None, :]), axis=1) > 1e-6
    assert np.array_equal(np.isnan(got[clear]), np.isnan(expected[clear]))
    ok = clear & ~np.isnan(expected)
    assert np.array_equal(got[ok], expected[ok])
    assert res.metrics["max_winder_torque_n_m"] == 2.0
    assert any("1 Set_Input_Torque frames outside" in n for n in res.notes)


def test_partial_last_line_and_reimport(plotted, tmp_path):
    run = tmp_path / "partial"
    shutil.copytree(plotted["dir"], run)
    assert not needs_import(run)
    n = len(read_truth(run / "truth.csv")["t_s"])
    with open(run / "truth.csv", "a") as f:
        f.write("99.0,1.0,2.")          # the plant stopped while writing
    assert len(read_truth(run / "truth.csv")["t_s"]) == n
    assert needs_import(run)             # the truth changed after the import
    import_up_run(run)
    assert not needs_import(run)


def test_plot_refuses_a_folder_with_neither_run_kind(tmp_path, capsys):
    assert cli_main(["plot", str(tmp_path), "--no-animation"]) == 2
    err = capsys.readouterr().err
    assert "no timeseries.npz" in err and "truth.csv" in err


def test_animation_of_the_up_run(plotted):
    run = plotted["dir"]
    res = plot(run)
    assert res.returncode == 0, res.stderr
    assert "imported" not in res.stdout            # already imported, nothing newer
    assert f"wrote {run / 'animation.gif'}" in res.stdout
    with Image.open(run / "animation.gif") as gif:
        assert gif.n_frames > 10
        # the last frame: the trail is the whole flight's by then (how much of it the
        # middle frame shows depends on how long the script took between its steps)
        gif.seek(gif.n_frames - 1)
        frame = gif.convert("RGB")
    a = np.asarray(frame, dtype=float)
    assert a.mean(axis=2).std() > 8.0
    # the tether (brown) and the trail (blue) are drawn
    brown = np.all(np.abs(a - (0x8C, 0x56, 0x4B)) < 30, axis=2).sum()
    blue = np.all(np.abs(a - (0x1F, 0x77, 0xB4)) < 30, axis=2).sum()
    assert brown > 50 and blue > 50, (brown, blue)
