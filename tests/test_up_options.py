"""``tuav-sitl up``'s options turn into the run's parameters and ports as documented."""

import argparse
import math
import os
import subprocess
import sys

import pytest
from netns_util import netns_available, run_session
from pymavlink import mavutil

from tuav_sitl.locations import Home, load_locations, user_locations_path
from tuav_sitl.up import (
    SIM_LINK_DEFAULT,
    _home,
    _speedup,
    _system_params,
    _wind,
    add_arguments,
    plant_params,
    ports_for,
    sim_address,
)
from tuavdefs.params import SystemParams, TetherModel
from tuavdefs.paramspec import ParameterError
from tuavdefs.simlink import format_sim_address, parse_sim_address

M = mavutil.mavlink


def parse(*argv: str) -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    add_arguments(ap)
    return ap.parse_args(list(argv))


def test_defaults_are_real_time_on_the_ground_with_the_paper_vehicle():
    args = parse()
    assert args.speedup == 1.0 and args.position == (2.0, 0.0, 0.0)
    assert _system_params(args) == SystemParams()


def test_speedup_and_home_parse():
    assert _speedup("max") == math.inf and _speedup("7.5") == 7.5
    for bad in ("0", "-2", "fast"):
        with pytest.raises(argparse.ArgumentTypeError):
            _speedup(bad)
    assert _home("47.1,8.5,500") == Home(47.1, 8.5, 500.0, None)
    assert _home("47.1,8.5,500,-10") == Home(47.1, 8.5, 500.0, 350.0)
    for bad in ("95,8,1", "47,8", "47,8,1,2,3", "47,8,x"):
        with pytest.raises(argparse.ArgumentTypeError):
            _home(bad)


def test_home_by_name_from_the_shipped_file_and_the_users_own(tmp_path, monkeypatch):
    """ArduPilot's locations.txt form; the user's file (XDG config dir) overrides."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    assert user_locations_path() == tmp_path / "tuav-sitl" / "locations.txt"
    cmac = _home("CMAC")        # ArduPilot SITL's own default location
    assert (cmac.lat_deg, cmac.lon_deg, cmac.alt_m, cmac.heading_deg) == pytest.approx(
        (-35.363261, 149.165230, 584.0, 353.0))
    user = tmp_path / "tuav-sitl" / "locations.txt"
    user.parent.mkdir(parents=True)
    user.write_text("# mine\nFIELD = 51.5, -0.12, 20, 45  # a comment\nCMAC=1,2,3,4\n")
    assert _home("FIELD") == Home(51.5, -0.12, 20.0, 45.0)
    assert _home("CMAC") == Home(1.0, 2.0, 3.0, 4.0)
    with pytest.raises(argparse.ArgumentTypeError, match="FIELD.*NAME=LAT,LON,ALT,HEADING"):
        _home("NOWHERE")
    user.write_text("BROKEN=1,2\n")
    with pytest.raises(ValueError, match="locations.txt:1"):
        load_locations([user])


def test_out_is_repeatable_and_instance_has_sim_vehicles_short_option():
    args = parse("--out", "udp:127.0.0.1:14551", "--out", "udpout:10.0.0.5:14552", "-I", "3")
    assert args.out == [("127.0.0.1", 14551), ("10.0.0.5", 14552)]
    assert args.instance == 3
    for bad in ("127.0.0.1:14551", "tcp:127.0.0.1:5760", "udp:127.0.0.1:", "udp:h:70000"):
        with pytest.raises(SystemExit):
            parse("--out", bad)


def test_wind_without_a_direction_says_what_to_write(capsys):
    with pytest.raises(SystemExit):
        parse("--wind", "5")
    err = capsys.readouterr().err
    assert "direction" in err and "--wind 5,270" in err


def test_wind_from_the_west_blows_east():
    args = parse("--wind", "5,270,light")
    wind = _system_params(args).wind
    assert wind.steady_m_s == pytest.approx((5.0, 0.0, 0.0), abs=1e-12)
    assert wind.turbulence == "light"
    assert _wind("3,0")[:2] == (3.0, 0.0)          # from the north: towards -y
    assert _system_params(parse("--wind", "3,0")).wind.steady_m_s == pytest.approx(
        (0.0, -3.0, 0.0), abs=1e-12)
    with pytest.raises(argparse.ArgumentTypeError):
        _wind("3,0,hurricane")


def test_vehicle_tether_winder_files_replace_their_groups(tmp_path):
    veh = tmp_path / "veh.toml"
    veh.write_text("mass_kg = 3.2\n")
    teth = tmp_path / "teth.toml"
    teth.write_text("total_length_m = 80.0\n")
    p = _system_params(parse("--vehicle", str(veh), "--tether", str(teth)))
    assert p.vehicle.mass_kg == 3.2 and p.tether.total_length_m == 80.0
    assert p.winder == SystemParams().winder
    bad = tmp_path / "bad.toml"
    bad.write_text("drum_radius_m = -1.0\n")
    with pytest.raises(ParameterError) as exc:
        _system_params(parse("--winder", str(bad)))
    assert exc.value.field == "winder.drum_radius_m"


def test_plant_params_set_the_truth_apart_field_by_field(tmp_path):
    veh = tmp_path / "veh.toml"
    veh.write_text("mass_kg = 3.2\n")
    truth_file = tmp_path / "truth.toml"
    truth_file.write_text("[vehicle]\nrotor_thrust_coeff = 1.8e-5\n[tether]\n"
                          "linear_density_kg_m = 0.068\n")
    args = parse("--vehicle", str(veh), "--plant-params", str(truth_file))
    model = _system_params(args)
    truth = plant_params(args, model)
    assert model.vehicle.mass_kg == 3.2 and model.vehicle.rotor_thrust_coeff == 2.0e-5
    # the truth: the model's fields, with the file's replacing theirs
    assert truth.vehicle.mass_kg == 3.2 and truth.vehicle.rotor_thrust_coeff == 1.8e-5
    assert truth.tether.linear_density_kg_m == 0.068 and truth.winder == model.winder
    # without a file the truth is the model on the default truth line, the lumped one
    assert plant_params(parse(), model) == model.replace(
        tether=model.tether.replace(model=TetherModel.LUMPED.value))
    catenary = parse("--tether-model", "catenary")
    assert plant_params(catenary, model) is model
    truth_file.write_text("[vehicle]\nmass_kg = 0.0\n")
    with pytest.raises(ParameterError) as exc:
        plant_params(args, model)
    assert exc.value.field == "truth.vehicle.mass_kg"


def test_every_port_moves_per_instance():
    assert tuple(ports_for(0)) == (4560, 5762, 5760, 14550, 14540)
    assert tuple(ports_for(3)) == (4590, 5792, 5790, 14580, 14543)
    # no instance's API port is another's ground-station port
    gcs = {ports_for(i).udp_gcs for i in range(10)}
    assert not gcs & {ports_for(i).udp_api for i in range(10)}


def test_the_simulator_link_per_instance():
    """On Linux an abstract Unix-domain name per instance (no file to clean up), else TCP
    on the instance's port; either way what the companion's --sim reads."""
    assert ("unix" if sys.platform.startswith("linux") else "tcp") == SIM_LINK_DEFAULT
    assert parse().sim_link == SIM_LINK_DEFAULT
    assert sim_address("unix", 3) == "@tuav-sitl-sim-3"
    assert sim_address("tcp", 3) == ("127.0.0.1", 4590)
    for kind in ("unix", "tcp"):
        address = sim_address(kind, 3)
        assert parse_sim_address(format_sim_address(address)) == address
    with pytest.raises(SystemExit):
        parse("--sim-link", "udp")


def test_lockstep_puts_the_plant_and_the_companion_on_one_cpu():
    from tuav_sitl.realtime import cpu_split

    assert cpu_split({3}) is None
    split = cpu_split({5, 2, 7})
    assert split == {"plant": {2}, "companion": {2}, "groundstation": {5, 7},
                     "candump": {5, 7}}


def test_the_recorder_runs_at_idle_priority_in_lockstep():
    from tuav_sitl.realtime import BACKGROUND, set_background

    assert {"candump"} == BACKGROUND
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert os.sched_getscheduler(proc.pid) == os.SCHED_OTHER
        assert set_background(proc.pid) is None
        assert os.sched_getscheduler(proc.pid) == os.SCHED_IDLE
    finally:
        proc.kill()
        proc.wait()


def test_the_ground_station_yields_to_the_companion_in_lockstep():
    from tuav_sitl.realtime import NICENESS, set_nice

    assert NICENESS == {"groundstation": 5}
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert os.getpriority(os.PRIO_PROCESS, proc.pid) == 0
        assert set_nice(proc.pid, 5) is None
        assert os.getpriority(os.PRIO_PROCESS, proc.pid) == 5
    finally:
        proc.kill()
        proc.wait()


def test_the_stack_waits_for_the_plants_own_end(tmp_path):
    """When the companion ends first (the plant closing the link at the end of its run),
    ``up`` waits for the plant's own exit to decide: a process that ends in time gives its
    code, one that does not gives None."""
    from tuav_sitl.up import Stack

    stack = Stack(tmp_path, echo=False)
    sleep = [sys.executable, "-c", "import sys, time; time.sleep(float(sys.argv[1]))"]
    stack.procs["plant"] = subprocess.Popen([*sleep, "0.3"])
    stack.procs["companion"] = subprocess.Popen([*sleep, "30"])
    try:
        assert stack.wait_exit("plant", 10.0) == ("plant", 0)
        assert stack.wait_exit("companion", 0.2) is None
    finally:
        stack.procs["companion"].kill()
        stack.procs["companion"].wait()


def test_up_names_the_gnss_presets_and_estimator_kinds_as_their_packages_do():
    from companion.ekf import ESTIMATOR_KINDS
    from sitl.sensors import GnssPreset
    from tuav_sitl import up

    assert tuple(p.value for p in GnssPreset) == up.GNSS_PRESETS
    assert up.ESTIMATOR_KINDS == ESTIMATOR_KINDS


@pytest.mark.skipif(not netns_available(),
                    reason="needs root (unshare) for a private network namespace")
def test_up_with_a_named_home_an_out_port_and_dash_i(tmp_path):
    """A ground station on the --out port sees the vehicle at CMAC facing 353 degrees (as
    ArduPilot SITL starts there); -I 1 moves the TCP port to 5770."""
    out = run_session("tests.netns.up_options_session", str(tmp_path), timeout_s=300)
    assert out["out"]["heartbeat"] == [1, M.MAV_AUTOPILOT_ARDUPILOTMEGA]
    lat, lon = out["out"]["lat_lon"]
    assert lat == pytest.approx(-35.363261, abs=1e-4)    # 2 m east of the winder
    assert lon == pytest.approx(149.165230, abs=1e-4)
    assert abs((out["out"]["yaw_deg"] - 353.0 + 180.0) % 360.0 - 180.0) < 3.0
    assert out["tcp_5770"]
    assert out["up_rc"] == 0 and out["left"] == []
