"""The Rerun recordings and views (tuav_sitl/view): a run's recording.rrd read back with
rerun's own reader (its entities, their rows against the run's duration and rates, the
lumped tether's wave after the gust-lumped gust), ``tuav-sitl run`` writing it,
``tuav-sitl view --web`` served and drawn by headless Chromium (compared with a blank
page), rerun's analytics off, ``up --view`` without rerun refused with the way to get it.
(``up --view web`` live: tests/test_view_live.py.)"""

from __future__ import annotations

import datetime as dt
import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from tuav_sitl.offline import OfflineRunner, write_outputs  # noqa: E402
from tuav_sitl.scenario import load_scenario  # noqa: E402
from tuav_sitl.view import RECORDING_NAME, analytics_config_path, analytics_off  # noqa: E402
from tuav_sitl.view.recording import (  # noqa: E402
    ERROR_PLOTS,
    ROTOR_PLOTS,
    SHAPE_RATE_HZ,
    Entity,
    nav_event_texts,
    write_recording,
)
from tuavdefs.component_link import TETHER_FIX_RATE_HZ  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONTROL_HZ = 250.0


def _seconds(v: object) -> float:
    if isinstance(v, dt.timedelta):
        return v.total_seconds()
    return float(v) * 1e-9   # nanoseconds


def read_back(path: Path) -> tuple[Counter, set[str], dict[str, list]]:
    """Rows per entity on the timeline, the static entities, and the tether's strips as
    (t [s], points) — all through rerun's own RRD reader."""
    rows: Counter = Counter()
    static: set[str] = set()
    tether: list[tuple[float, np.ndarray]] = []
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
            continue
        rows[chunk.entity_path] += chunk.num_rows
        if chunk.entity_path == "/" + Entity.TETHER:
            batch = chunk.to_record_batch()
            names = batch.schema.names
            t = batch.column(names.index("sim")).to_pylist()
            strips = batch.column(names.index("LineStrips3D:strips")).to_pylist()
            tether += [(_seconds(a), np.array(b[0])) for a, b in zip(t, strips, strict=True)]
    tether.sort(key=lambda x: x[0])
    return rows, static, {"tether": tether}


def entity_column(path: Path, entity: str, column: str) -> tuple[np.ndarray, list]:
    """(times [s], values) of one column of one entity, in time order, read back with
    rerun's own reader."""
    out: list[tuple[float, object]] = []
    for chunk in RrdReader(path).stream():
        if chunk.is_static or chunk.entity_path != "/" + entity:
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        t = batch.column(names.index("sim")).to_pylist()
        v = batch.column(names.index(column)).to_pylist()
        out += [(_seconds(a), b) for a, b in zip(t, v, strict=True)]
    out.sort(key=lambda x: x[0])
    return np.array([x[0] for x in out]), [x[1] for x in out]


@pytest.fixture(scope="module")
def denied(tmp_path_factory) -> dict:
    """hover-gnss-loss (on the filter, fusing the winch's tether fixes) for 6 s,
    recorded."""
    sc = load_scenario("hover-gnss-loss").replace(duration_s=6.0)
    result = OfflineRunner(sc).run()
    out = tmp_path_factory.mktemp("denied")
    rrd = write_recording(out / RECORDING_NAME, sc.name, sc, result.series)
    return {"series": result.series, "rrd": rrd}


def test_the_tether_fixes_are_drawn_at_their_rate(denied):
    """world/fixes/tether: a point per fix the vehicle received (the winch's 10 Hz), at
    the fix's sample time, where the runner handed it over, and its 3-sigma ellipsoid."""
    s, rrd = denied["series"], denied["rrd"]
    t, pts = entity_column(rrd, Entity.TETHER_FIX, "Points3D:positions")
    assert len(t) == len(s["tether_fix_t"])
    assert abs(len(t) - 6.0 * TETHER_FIX_RATE_HZ) <= 2
    np.testing.assert_allclose(np.diff(t), 1.0 / TETHER_FIX_RATE_HZ, atol=1e-3)
    np.testing.assert_allclose(t, s["tether_fix_t"], atol=1e-6)
    np.testing.assert_allclose(np.array([p[0] for p in pts]), s["tether_fix_pos"],
                               atol=1e-5)
    # each fix near the truth at its sample time (within its own 3 sigma and 5 cm)
    truth = np.column_stack([np.interp(t, s["t"], s["pos"][:, i]) for i in range(3)])
    err = np.abs(np.array([p[0] for p in pts]) - truth)
    assert (err <= 3.0 * s["tether_fix_sigma"] + 0.05).all()
    ta, half = entity_column(rrd, Entity.TETHER_FIX + "/accuracy", "Ellipsoids3D:half_sizes")
    assert len(ta) == len(t)
    np.testing.assert_allclose(np.array([h[0] for h in half]), 3.0 * s["tether_fix_sigma"],
                               rtol=1e-6)


def test_the_gnss_fixes_are_drawn_at_the_receivers_rate(denied):
    """world/fixes/gnss: a point per GNSS fix the vehicle received (before the scenario's
    GNSS loss: the receiver's rate over the whole 6 s), at the fix's time, near the truth
    there (within its own 3 sigma and 5 cm), and its 3-sigma ellipsoid."""
    s, rrd = denied["series"], denied["rrd"]
    rate_hz = load_scenario("hover-gnss-loss").sensors.noise_model().gps_rate_hz
    t, pts = entity_column(rrd, Entity.GNSS_FIX, "Points3D:positions")
    assert len(t) == len(s["gnss_fix_t"])
    assert abs(len(t) - 6.0 * rate_hz) <= 2
    np.testing.assert_allclose(np.diff(t), 1.0 / rate_hz, atol=1e-3)
    np.testing.assert_allclose(t, s["gnss_fix_t"], atol=1e-6)
    pos = np.array([p[0] for p in pts])
    np.testing.assert_allclose(pos, s["gnss_fix_pos"], atol=1e-5)
    truth = np.column_stack([np.interp(t, s["t"], s["pos"][:, i]) for i in range(3)])
    assert (np.abs(pos - truth) <= 3.0 * s["gnss_fix_sigma"] + 0.05).all()
    ta, half = entity_column(rrd, Entity.GNSS_FIX + "/accuracy", "Ellipsoids3D:half_sizes")
    assert len(ta) == len(t)
    np.testing.assert_allclose(np.array([h[0] for h in half]), 3.0 * s["gnss_fix_sigma"],
                               rtol=1e-6)


def test_the_estimates_ellipsoid_is_three_sigma(denied):
    """world/estimate/ellipsoid: at every control period with an estimate, centred on
    it, its half-sizes three standard deviations."""
    s, rrd = denied["series"], denied["rrd"]
    ok = np.isfinite(s["est_pos_sigma"]).all(axis=1) & np.isfinite(s["est_pos"]).all(axis=1)
    t, half = entity_column(rrd, Entity.ELLIPSOID, "Ellipsoids3D:half_sizes")
    _, centres = entity_column(rrd, Entity.ELLIPSOID, "Ellipsoids3D:centers")
    assert len(t) == ok.sum() > 0.9 * len(s["t"])
    np.testing.assert_allclose(t, s["t"][ok], atol=1e-6)
    np.testing.assert_allclose(np.array([h[0] for h in half]), 3.0 * s["est_pos_sigma"][ok],
                               rtol=1e-6)
    np.testing.assert_allclose(np.array([c[0] for c in centres]), s["est_pos"][ok],
                               atol=1e-5)


def test_the_live_view_draws_the_tlogs_tether_fixes_and_ellipsoid(tmp_path):
    """The live view's reading of flight.tlog: the winch's ODOMETRY (as the winch encodes
    it) becomes world/fixes/tether with its 3-sigma ellipsoid, the companion's
    LOCAL_POSITION_NED_COV (as its telemetry builds it) the estimate's ellipsoid, both in
    the z-up frame; other messages are skipped, a copy per link is drawn once."""
    import struct
    from types import SimpleNamespace

    from companion.telemetry import Telemetry, TelemetryStreams
    from tuav_sitl.view.live import LiveView
    from tuav_sitl.view.recording import new_stream
    from tuavdefs import component_link as cl
    from tuavdefs.params import SystemParams

    winch, autopilot = cl.new_mavlink(cl.WINCH_COMPONENT_ID), cl.new_mavlink(1)
    frames = []
    fixes = [(0.1 * k, (3.0 + 0.1 * k, -2.0, 9.0), (0.04, 0.09, 0.01)) for k in range(1, 6)]
    for t, pos, var in fixes:
        cov = tuple(tuple(var[i] if i == j else 0.0 for j in range(3)) for i in range(3))
        frames.append(cl.odometry_message(cl.ExternalPosition(t, pos, cov)).pack(winch))
    est = [(0.5 * k, (1.0 * k, 2.0, 10.0), (0.3, 0.2, 0.1)) for k in range(1, 4)]
    for t, pos, sig in est:
        tm = Telemetry(t, pos, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5,
                       ekf=SimpleNamespace(pos_sigma_m=sig, vel_sigma_m_s=(0.1, 0.1, 0.1)))
        msg = TelemetryStreams._local_position_cov(tm)
        frames += [msg.pack(autopilot)] * 2          # sent on two links
        frames.append(autopilot.attitude_encode(int(t * 1e3), 0, 0, 0, 0, 0, 0)
                      .pack(autopilot))                # not drawn: skipped
    (tmp_path / "flight.tlog").write_bytes(b"".join(struct.pack(">Q", 1) + bytes(f)
                                                    for f in frames))
    rrd = tmp_path / RECORDING_NAME
    rec = new_stream("live")
    rec.save(str(rrd))
    view = LiveView(rec, tmp_path, SystemParams(), (47.0, 8.0, 400.0))
    view.poll()
    view.close()
    rec.flush()
    rec.disconnect()
    t, pts = entity_column(rrd, Entity.TETHER_FIX, "Points3D:positions")
    np.testing.assert_allclose(t, [f[0] for f in fixes], atol=1e-6)
    np.testing.assert_allclose([p[0] for p in pts], [f[1] for f in fixes], atol=1e-5)
    _, half = entity_column(rrd, Entity.TETHER_FIX + "/accuracy", "Ellipsoids3D:half_sizes")
    np.testing.assert_allclose([h[0] for h in half],
                               [3.0 * np.sqrt(f[2]) for f in fixes], rtol=1e-5)
    t, half = entity_column(rrd, Entity.ELLIPSOID, "Ellipsoids3D:half_sizes")
    _, centres = entity_column(rrd, Entity.ELLIPSOID, "Ellipsoids3D:centers")
    np.testing.assert_allclose(t, [e[0] for e in est], atol=1e-6)
    np.testing.assert_allclose([c[0] for c in centres], [e[1] for e in est], atol=1e-5)
    np.testing.assert_allclose([h[0] for h in half], [3.0 * np.array(e[2]) for e in est],
                               rtol=1e-5)


@pytest.fixture(scope="module")
def gust(tmp_path_factory) -> dict:
    """gust-lumped for 10 s (the gust blows from 5 to 7 s), recorded."""
    sc = load_scenario("gust-lumped").replace(duration_s=10.0)
    result = OfflineRunner(sc).run()
    out = tmp_path_factory.mktemp("gust")
    write_outputs(result, out)
    rrd = write_recording(out / RECORDING_NAME, sc.name, sc, result.series,
                          nav_event_texts(result.events))
    rows, static, data = read_back(rrd)
    return {"series": result.series, "rows": rows, "static": static, **data, "sc": sc}


def test_every_entity_is_there_with_the_runs_rows(gust):
    s, rows, static = gust["series"], gust["rows"], gust["static"]
    n = len(s["t"])
    assert n == round(10.0 * CONTROL_HZ) + 1
    # the control-rate series: one row per control period
    for path in (Entity.VEHICLE, Entity.ROTORS, Entity.SPOKE, Entity.TENSION_TOP,
                 Entity.TENSION_DRUM, Entity.LENGTH, Entity.LBAR, Entity.REFERENCE,
                 *ROTOR_PLOTS, *(p for p, a, _, _ in ERROR_PLOTS if a == "pos")):
        assert rows["/" + path] == n, (path, rows["/" + path])
    # the lumped tether's nodes at the rate the run recorded them, the path at the shapes'
    assert rows["/" + Entity.TETHER] == len(s["line_t"]) == round(10.0 * 15.0) + 1
    assert rows["/" + Entity.PATH] == round(10.0 * SHAPE_RATE_HZ) + 1
    # on the truth: no estimate; the fixed scene is static
    assert rows["/" + Entity.ESTIMATE] == 0
    for path in (Entity.WORLD, Entity.GROUND, Entity.WINDER, Entity.DRUM, Entity.ARMS,
                 Entity.ROTORS, Entity.REFERENCE_PATH):
        assert "/" + path in static, path


def test_the_tether_in_the_recording_is_the_plants(gust):
    """Each strip is the run's own node row (exit at the origin, the last node at the
    vehicle's attachment)."""
    s = gust["series"]
    for (t, pts), t_run, nodes in zip(gust["tether"], s["line_t"], s["line_nodes"],
                                      strict=True):
        assert t == pytest.approx(t_run, abs=1e-6)
        want = nodes[np.isfinite(nodes[:, 0])]
        np.testing.assert_allclose(pts, want, atol=1e-5)
        assert np.linalg.norm(pts[0]) < 1e-6


def test_the_gust_runs_along_the_line_as_a_wave(gust):
    """After the crosswind gust (5-7 s) each node's sideways swing peaks later the nearer
    it is to the winder: a wave travelling down the line from the vehicle."""
    t = np.array([x[0] for x in gust["tether"]])
    pts = [x[1] for x in gust["tether"]]
    n = min(p.shape[0] for p in pts)
    y = np.array([p[-n:, 1] for p in pts])         # nodes counted from the vehicle's end
    swing = np.abs(y - y[t < 5.0].mean(axis=0))
    after = t >= 5.0
    inner = range(1, n - 1)                         # the exit and the vehicle's node aside
    assert min(swing[after, k].max() for k in inner) > 0.1   # every node moved [m]
    peak = np.array([t[after][np.argmax(swing[after, k])] for k in inner])
    # node k+1 is nearer the vehicle: its peak comes earlier
    r = np.corrcoef(np.arange(len(peak)), peak)[0, 1]
    assert r < -0.9, peak
    assert peak[0] - peak[-1] > 0.5, peak


def test_tuav_sitl_run_writes_the_recording(tmp_path):
    out = tmp_path / "gust"
    res = subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "gust-lumped", "--duration",
                          "2", "--out", str(out), "--no-figures", "--quiet"],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-2000:]
    assert f"wrote {out / RECORDING_NAME}" in res.stdout
    rows, static, _ = read_back(out / RECORDING_NAME)
    n = round(2.0 * CONTROL_HZ) + 1
    assert rows["/" + Entity.VEHICLE] == n
    assert rows["/" + Entity.TETHER] == round(2.0 * 15.0) + 1   # the lumped nodes
    assert "/" + Entity.GROUND in static


def test_analytics_are_turned_off(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    path = analytics_config_path()
    assert not path.exists()
    assert analytics_off()
    assert json.loads(path.read_text())["analytics_enabled"] is False


def test_up_view_without_rerun_says_how_to_get_it(monkeypatch, capsys):
    import tuav_sitl.view as view
    from tuav_sitl.cli import main

    monkeypatch.setattr(view, "available", lambda: False)
    rc = main(["up", "--view", "--logdir", "/nonexistent-logdir-never-made"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "pip install" in err and "[view]" in err
    assert not Path("/nonexistent-logdir-never-made").exists()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: The tether's colour in the web viewer (RGB), and how near a pixel must be to count.
TETHER_RGB, TETHER_TOLERANCE = (140, 86, 75), 30


def _tether_pixels(png: bytes) -> int:
    """How many pixels of a screenshot have the tether's colour."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    return int((np.abs(img - np.array(TETHER_RGB)).max(axis=2) < TETHER_TOLERANCE).sum())


def _draws_the_scene(png: bytes) -> bool:
    """Not a blank page, and the tether drawn (an error page has none of its colour)."""
    from chromium_util import image_spread

    return image_spread(png) > 10.0 and _tether_pixels(png) > 50


def test_the_web_viewer_draws_the_scene(gust, tmp_path):
    """``tuav-sitl view RUN --web`` serves the recording; headless Chromium draws it: not
    a blank page, and the tether's colour where the scene is (an error page has none).
    Each screenshot is taken as soon as it shows what is checked (the view: the scene; the
    blank page: its first picture), not after the page has stood still for seconds."""
    from chromium_util import chromium, image_spread, screenshot

    if chromium() is None:
        pytest.skip("chromium is not installed (Debian: apt-get install chromium)")
    run = tmp_path / "run"
    run.mkdir()
    sc = gust["sc"]
    write_recording(run / RECORDING_NAME, sc.name, sc, gust["series"])
    web, grpc = _free_port(), _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "view", str(run), "--web",
                             "--web-port", str(web), "--grpc-port", str(grpc)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert f"http://127.0.0.1:{web}/?url=" in line, line + proc.stderr.read()
        url = line.split("viewer: ", 1)[1].split()[0]
        deadline = time.monotonic() + 120
        while True:
            try:
                socket.create_connection(("127.0.0.1", web), timeout=2).close()
                break
            except OSError:
                assert time.monotonic() < deadline and proc.poll() is None
                time.sleep(0.5)
        shot = screenshot(url, tmp_path / "view.png", size=(1280, 720),
                          until=_draws_the_scene)
        blank = screenshot("about:blank", tmp_path / "blank.png", size=(1280, 720),
                           settle_s=30.0, until=lambda png: True)
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=30)
    png, empty = shot.read_bytes(), blank.read_bytes()
    assert image_spread(empty) < 1.0            # the blank page is blank
    assert image_spread(png) > 10.0             # the view is not
    tether = _tether_pixels(png)
    assert tether > 50, tether                  # the line is drawn
