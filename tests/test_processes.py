"""The plant and companion as separate OS processes over the real simulator link."""

import csv
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from gcs_util import free_port

ROOT = Path(__file__).resolve().parents[1]
GOAL = (5.0, 1.0, 11.0)



def _fly(tmp: Path, duration: float = 12.0, unix: bool = False, spin_us: float = 0.0
         ) -> tuple[np.ndarray, str, str]:
    """The flight with the simulator link on TCP, or (``unix``) on a Unix-domain socket
    file in ``tmp``, which the plant removes when it ends; the plant's lockstep waits spin
    for ``spin_us`` [us] before sleeping."""
    port = free_port()
    sock = tmp / "sim.sock"
    listen, sim, banner = ((["--socket", str(sock)], f"unix:{sock}", f"listening on unix:{sock}")
                           if unix else (["--port", str(port)], f"127.0.0.1:{port}",
                                         "listening on tcp:127.0.0.1:"))
    log = tmp / "truth.csv"
    plant = subprocess.Popen(
        [sys.executable, "-m", "sitl", *listen, "--duration", str(duration),
         "--truth-log", str(log), "--no-noise", "--position", "4", "0", "10",
         "--accept-timeout", "60", "--lockstep-spin-us", repr(spin_us)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ready = plant.stdout.readline()
        assert banner in ready, ready
        comp = subprocess.run(
            # on the simulator's state: this test holds the flight to millimetres
            [sys.executable, "-m", "companion", "--sim", sim, "--state", "truth",
             "--component-port", "0", "--gcs-tcp", "0", "--gcs-udp", "none",
             "--goto", *map(str, GOAL)],
            cwd=ROOT, capture_output=True, text=True, timeout=180)
        out, _ = plant.communicate(timeout=60)
    finally:
        if plant.poll() is None:
            plant.kill()
    assert plant.returncode == 0, out
    assert comp.returncode == 0, comp.stderr
    assert not sock.exists()
    with open(log) as f:
        rows = list(csv.DictReader(f))
    data = np.array([[float(r[k]) for k in ("t_s", "x_m", "y_m", "z_m", "tether_length_m",
                                            "armed")] for r in rows])
    return data, log.read_text(), out + comp.stdout


def test_companion_flies_the_plant_in_lockstep(tmp_path):
    data, text, out = _fly(tmp_path)
    t, pos = data[:, 0], data[:, 1:4]
    assert t[-1] >= 11.9                             # the whole simulated time went by
    assert np.all(np.diff(t) > 0)
    assert np.all(data[:, 5] == 1.0)                 # armed throughout
    assert np.linalg.norm(pos[-1] - np.array(GOAL)) < 0.05
    assert np.all(pos[:, 2] > 9.5)                   # no sagging on the way
    assert np.ptp(data[:, 4]) == 0.0                 # the winder stays braked (no ground station)
    assert "max_sim_time: 3000 periods" in out and "0 bad frames" in out
    assert "spun" not in out                         # (it sleeps at once by default)
    # lockstep: a second flight is identical to the bit, and so is one over a Unix-domain
    # socket (the transport carries the same bytes) with the plant waiting awake for its
    # answers (only when it notices them changes)
    (tmp_path / "again").mkdir()
    _, text2, _ = _fly(tmp_path / "again")
    assert text2 == text
    (tmp_path / "unix").mkdir()
    _, text3, out3 = _fly(tmp_path / "unix", unix=True, spin_us=200.0)
    assert text3 == text
    assert "connected to the plant at unix:" in out3
    assert re.search(r"spun [1-9]\d* waits, \d+ answered awake", out3), out3


def test_plant_without_a_companion_gives_up_cleanly():
    port = free_port()
    res = subprocess.run([sys.executable, "-m", "sitl", "--port", str(port),
                          "--accept-timeout", "0.5"], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 1
    assert "no_client" in res.stdout


def test_bad_simulator_link_addresses_are_refused_by_name(tmp_path):
    """A file where the plant would put its socket is left alone (exit 1, saying where);
    a --sim the companion cannot read is a usage error (exit 2)."""
    taken = tmp_path / "taken"
    taken.write_text("not a socket")
    res = subprocess.run([sys.executable, "-m", "sitl", "--socket", str(taken)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 1
    assert f"cannot listen on unix:{taken}: a file is already there" in res.stderr
    assert taken.read_text() == "not a socket"
    res = subprocess.run([sys.executable, "-m", "companion", "--sim", "unix:"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "argument --sim: 'unix:': no path" in res.stderr


def test_processes_reject_bad_parameters_by_name(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[vehicle]\nmass_kg = -1.0\n")
    for module in ("sitl", "companion"):
        res = subprocess.run([sys.executable, "-m", module, "--params", str(bad)], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
        assert res.returncode == 2, module
        assert "vehicle.mass_kg" in res.stderr, module


def test_speedup_paces_lockstep(tmp_path):
    port = free_port()
    plant = subprocess.Popen(
        [sys.executable, "-m", "sitl", "--port", str(port), "--duration", "1.0",
         "--speedup", "20", "--no-noise", "--position", "4", "0", "10"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ready = plant.stdout.readline()
        assert "(lockstep at 20x" in ready, ready
        comp = subprocess.run(
            [sys.executable, "-m", "companion", "--sim", f"127.0.0.1:{port}", "--state",
             "truth", "--component-port", "0", "--gcs-tcp", "-1", "--gcs-udp", "none"],
            cwd=ROOT, capture_output=True, text=True, timeout=120)
        out, _ = plant.communicate(timeout=60)
    finally:
        if plant.poll() is None:
            plant.kill()
    assert comp.returncode == 0, comp.stdout + comp.stderr
    assert "max_sim_time: 250 periods" in out and "0 missed deadlines" in out
