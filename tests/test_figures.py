"""Tests of tuav_sitl.figures and tuav_sitl.animation on short real runs.

Two short runs of the offline runner (set-point, 4 s; multi-position, 6 s) are written to a
temporary folder; the figures and the animation are made from them and checked as files
(valid PNG/GIF, size, more than one GIF frame, not blank) and as matplotlib objects (titles,
axis labels, units, the data actually plotted). The blank-image checker is shown to fail on
a blank image.
"""

from __future__ import annotations

import os
import stat
import warnings
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from tuav_sitl import animation as anim
from tuav_sitl.figure_scene import (
    TetherDrawer,
    reached_indices,
    reference_geometry,
    snapshot_indices,
    spread_instants,
)
from tuav_sitl.figures import FIGURE_CAPTIONS, FIGURE_NAMES, build_figures, make_figures
from tuav_sitl.figures_series import length_error
from tuav_sitl.offline import run_scenario
from tuav_sitl.run_data import load_run
from tuav_sitl.scenario import load_scenario

EXPECTED = ("states", "errors", "position_tracking", "attitude_tracking", "path_3d",
            "tether_length", "snapshots", "lyapunov", "tension_and_winder")
#: ... and the one only runs flown on the onboard estimate have
ESTIMATE_ONLY = ("estimate",)
#: Minimum standard deviation of the grey levels of a figure (a blank one has 0; ours are
#: above 20).
MIN_PIXEL_STD = 8.0
#: Minimum fraction of strongly coloured pixels: the data are drawn in colour, the axes,
#: ticks and text in black and grey (an empty axes has none; our figures 0.3 % to 10 %).
MIN_COLOURED = 0.001


@pytest.fixture(scope="module")
def setpoint_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "setpoint"
    sc = load_scenario("setpoint")
    # a nearer goal, so that the move ends (at 3.3 s) within the 4 s run
    sc = sc.replace(duration_s=4.0, trajectory=sc.trajectory.replace(goal_m=(3.0, 3.0, 10.0)))
    run_scenario(sc, out, progress=None)
    return out


@pytest.fixture(scope="module")
def multi_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "multi"
    sc = load_scenario("multi-position").replace(duration_s=6.0)
    run_scenario(sc, out, progress=None)
    return out


@pytest.fixture(scope="module")
def setpoint_figures(setpoint_run) -> dict[str, Figure]:
    run = load_run(setpoint_run)
    return build_figures(run.series, run.scenario, metrics=run.metrics)


def pixel_std(path: Path) -> float:
    with Image.open(path) as im:
        return float(np.asarray(im.convert("L"), dtype=float).std())


def coloured_fraction(path: Path) -> float:
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGB"), dtype=float)
    return float(((a.max(axis=2) - a.min(axis=2)) > 60).mean())


def shows_data(path: Path) -> bool:
    return pixel_std(path) > MIN_PIXEL_STD and coloured_fraction(path) > MIN_COLOURED


def test_blank_checker_fails_on_blank_and_empty_figures(tmp_path):
    blank = tmp_path / "blank.png"
    Image.new("RGB", (400, 300), "white").save(blank)
    assert not shows_data(blank)
    empty = tmp_path / "empty.png"
    fig = Figure(figsize=(10, 7), dpi=110)
    ax = fig.add_subplot()
    ax.set_title("nothing here")
    ax.set_xlabel("time [s]")
    ax.grid(True)
    fig.savefig(empty)
    assert not shows_data(empty)
    ax.plot([0, 1], [0, 1], color="C0", lw=1.5)
    fig.savefig(empty)
    assert shows_data(empty)


def test_captions_cover_every_figure():
    assert tuple(FIGURE_CAPTIONS) == FIGURE_NAMES == EXPECTED + ESTIMATE_ONLY
    for name, caption in FIGURE_CAPTIONS.items():
        assert len(caption) > 40 and caption.endswith("."), name


@pytest.mark.parametrize("run_fixture", ["setpoint_run", "multi_run"])
def test_make_figures_writes_valid_pngs(run_fixture, request):
    run_dir = request.getfixturevalue(run_fixture)
    skipped: list[str] = []
    paths = make_figures(run_dir, skipped=skipped)
    assert [p.name for p in paths] == [f"{n}.png" for n in EXPECTED]   # flown on the truth
    assert any("estimate" in s for s in skipped)
    for p in paths:
        assert p.parent == run_dir / "figures" and p.is_file()
        with Image.open(p) as im:
            im.verify()
        with Image.open(p) as im:
            assert im.format == "PNG"
            w, h = im.size
            assert 800 <= w <= 2000 and 600 <= h <= 2000, (p.name, im.size)
        assert shows_data(p), p.name


def test_unknown_figure_name_is_refused(setpoint_run):
    run = load_run(setpoint_run)
    with pytest.raises(ValueError, match="unknown figure"):
        build_figures(run.series, run.scenario, ["states", "nope"])


def _labels(fig: Figure) -> tuple[set[str], set[str]]:
    ys = {ax.get_ylabel() for ax in fig.axes}
    xs = {ax.get_xlabel() for ax in fig.axes}
    return ys, xs


def test_figures_are_titled_with_the_scenario_and_have_grids_and_legends(setpoint_figures):
    for name, fig in setpoint_figures.items():
        title = fig.get_suptitle()
        assert title.startswith("setpoint:"), name
        for ax in fig.axes:
            if ax.name == "3d":
                continue
            assert ax.xaxis.get_gridlines()[0].get_visible(), name
            assert ax.get_legend() is not None, name


def test_time_series_axes_carry_units(setpoint_figures):
    ys, xs = _labels(setpoint_figures["states"])
    assert {"x [m]", "y [m]", "z [m]", "roll [deg]", "pitch [deg]", "yaw [deg]",
            "L [m]"} <= ys
    assert "time [s]" in xs
    ys, _ = _labels(setpoint_figures["errors"])
    assert ys == {"position error [m]", "attitude error [deg]", "length error [m]"}
    ys, _ = _labels(setpoint_figures["attitude_tracking"])
    assert ys == {"roll [deg]", "pitch [deg]", "yaw [deg]"}
    ys, _ = _labels(setpoint_figures["tension_and_winder"])
    assert ys == {"tension [N]", "torque [N m]", "drum rate [rad/s]"}
    assert setpoint_figures["lyapunov"].axes[0].get_yscale() == "log"
    for name in ("path_3d", "snapshots"):
        for ax in setpoint_figures[name].axes:
            assert ax.name == "3d"
            assert ax.get_xlabel().startswith("x") and ax.get_xlabel().endswith("[m]")
            assert ax.get_zlabel().startswith("z") and ax.get_zlabel().endswith("[m]")


def test_plotted_data_are_the_run_in_the_stated_units(setpoint_run, setpoint_figures):
    s = load_run(setpoint_run).series
    att = setpoint_figures["attitude_tracking"].axes
    roll = att[0].get_lines()[0]
    assert np.allclose(roll.get_xdata(), s["t"])
    assert np.allclose(roll.get_ydata(), np.degrees(s["euler"][:, 0]))  # degrees, not rad
    err = setpoint_figures["errors"].axes[0].get_lines()
    assert np.allclose(err[2].get_ydata(), s["pos"][:, 2] - s["ref_pos"][:, 2])
    pos = setpoint_figures["position_tracking"].axes[1].get_lines()
    assert np.allclose(pos[0].get_ydata(), s["pos"][:, 1])
    assert np.allclose(pos[1].get_ydata(), s["ref_pos"][:, 1])
    tl = {ln.get_label(): ln for ln in setpoint_figures["tether_length"].axes[0].get_lines()}
    assert np.allclose(tl["desired length L-bar"].get_ydata(), s["lbar"])
    assert np.allclose(tl["altitude z"].get_ydata(), s["pos"][:, 2])


def test_path_3d_draws_the_tether_from_the_winder_to_the_uav(setpoint_run, setpoint_figures):
    s = load_run(setpoint_run).series
    ax = setpoint_figures["path_3d"].axes[0]
    tethers = [ln for ln in ax.get_lines() if ln.get_color() == "#8c564b"]
    assert len(tethers) >= 3
    for ln in tethers:
        x, y, z = (np.asarray(v) for v in ln.get_data_3d())
        assert np.allclose((x[0], y[0], z[0]), 0.0, atol=1e-6)
        end = np.array([x[-1], y[-1], z[-1]])
        assert np.min(np.linalg.norm(s["pos"] - end, axis=1)) < 1e-3
        assert np.all(z >= -1e-9)
    # equal scale: the box aspect follows the axis ranges
    box = np.asarray(ax.get_box_aspect())
    spans = np.array([np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())])
    assert np.allclose(box / box[0], spans / spans[0], rtol=1e-6)


def test_snapshots_show_the_waypoints(multi_run):
    run = load_run(multi_run)
    figs = build_figures(run.series, run.scenario, ["snapshots"], run.metrics)
    axes = figs["snapshots"].axes
    assert len(axes) == 4 and all(ax.name == "3d" for ax in axes)
    for ax in axes:
        assert ax.get_title().startswith("t = ")
        stars = [c for c in ax.collections if len(c.get_offsets()) > 0
                 and c.get_label().startswith("waypoints")]
        assert sum(len(c.get_offsets()) for c in stars) == 4
    times = [float(ax.get_title().split()[2]) for ax in axes]
    assert times == sorted(times) and times[-1] > times[0]


def test_reached_waypoints_follow_the_mission_rule():
    sc = load_scenario("multi-position")
    geo = reference_geometry(sc)
    wp = geo.points
    # the reference rests on WP1 from sample 10, the UAV arrives within the radius at 12;
    # it passes within the radius of WP2 at 20 while the reference is still moving
    n = 40
    ref = np.tile(wp[0], (n, 1))
    ref[:10] = wp[0] + [0.0, 0.0, -1.0]
    pos = ref.copy()
    pos[:12] = wp[0] + [0.0, 0.0, -0.5]
    ref[25:], pos[25:] = wp[1], wp[1]
    ref[20], pos[20] = wp[1] + [0.0, 0.0, -0.2], wp[1] + [0.0, 0.0, -0.1]
    series = {"t": np.arange(n) * 0.1, "pos": pos, "ref_pos": ref}
    assert reached_indices(series, geo) == [12, 25]
    assert reached_indices(series, geo, {"waypoints_reached": [{"index": 0, "t_s": 0.5}]}) \
        == [5]


def test_snapshot_instants_spread_over_the_path():
    sc = load_scenario("setpoint")
    t = np.linspace(0.0, 10.0, 1001)
    x = np.clip(t - 2.0, 0.0, 4.0)  # still until 2 s, moves until 6 s, then still
    series = {"t": t, "pos": np.column_stack((x, 0 * t, 5 + 0 * t)), "ref_pos": None}
    idx = snapshot_indices(series, sc, 4)
    assert idx[0] == 0
    assert [round(t[i], 1) for i in idx[1:]] == pytest.approx([3.3, 4.7, 6.0], abs=0.05)
    spread = spread_instants(np.column_stack((np.cos(t), np.sin(t), 0 * t)), 3)
    assert spread == sorted(spread) and len(spread) == 3


def test_length_error_uses_only_the_samples_where_lbar_was_just_computed():
    sc = load_scenario("setpoint")  # control 250 Hz, winder 100 Hz: every 5th sample
    t = np.arange(50) / 250.0
    lbar_true = 10.0 + 2.0 * t
    held = np.floor(t * 100 + 1e-9) / 100.0
    series = {"t": t, "length": lbar_true, "lbar": 10.0 + 2.0 * held}
    tt, e = length_error(series, sc)
    assert np.allclose(tt, t[::5])
    assert np.allclose(e, 0.0, atol=1e-9)  # the hold itself is not a tracking error


def test_frame_plan():
    t = np.arange(0, 75.0 + 1e-9, 0.004)
    idx, speed = anim.frame_plan(t, 15, 300, None)
    assert len(idx) == 300 and idx[0] == 0 and idx[-1] == len(t) - 1
    assert np.all(np.diff(idx) > 0)
    assert speed == pytest.approx(75 * 15 / 299)
    idx, speed = anim.frame_plan(t[:2501], 15, 300, None)  # 10 s fits at real time
    assert len(idx) == 151 and speed == pytest.approx(1.0)
    idx, speed = anim.frame_plan(t, 10, 300, 5.0)
    assert len(idx) == 151 and speed == pytest.approx(5.0)
    for bad in ({"fps": 0}, {"max_frames": 1}, {"speed": -1.0}):
        kw = {"fps": 15, "max_frames": 300, "speed": None} | bad
        with pytest.raises(ValueError):
            anim.frame_plan(t, **kw)


def _gif_frames(path: Path) -> list[np.ndarray]:
    out = []
    with Image.open(path) as im:
        for i in range(im.n_frames):
            im.seek(i)
            out.append(np.asarray(im.convert("RGB"), dtype=float))
    return out


def test_animation_gif(setpoint_run, monkeypatch):
    monkeypatch.setattr(anim.shutil, "which", lambda name: None)
    paths = anim.make_animation(setpoint_run, fps=10, max_frames=12)
    assert paths == [setpoint_run / "animation.gif"]
    with Image.open(paths[0]) as im:
        assert im.format == "GIF"
        assert im.size == anim.ANIMATION_SIZE_PX
        assert im.n_frames == 12
    frames = _gif_frames(paths[0])
    for f in frames:
        assert f.mean(axis=2).std() > MIN_PIXEL_STD
        assert ((f.max(axis=2) - f.min(axis=2)) > 60).mean() > MIN_COLOURED
    # the UAV moves: first and last frames differ, beyond the title
    assert np.abs(frames[0][80:] - frames[-1][80:]).mean() > 0.1


def _fake_ffmpeg(tmp_path: Path, ok: bool) -> str:
    exe = tmp_path / ("ffmpeg_ok" if ok else "ffmpeg_bad")
    body = ('cat > /dev/null; for a in "$@"; do last="$a"; done; echo fake > "$last"'
            if ok else 'cat > /dev/null; echo "Unknown encoder" >&2; exit 1')
    exe.write_text(f'#!/bin/sh\ncase "$1" in -hide_banner) exit 0;; esac\n{body}\n')
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    return str(exe)


@pytest.mark.skipif(os.name != "posix", reason="uses a shell script as a stand-in ffmpeg")
def test_animation_mp4_written_or_dropped_with_a_warning(setpoint_run, tmp_path,
                                                        monkeypatch):
    good = _fake_ffmpeg(tmp_path, ok=True)
    monkeypatch.setattr(anim.shutil, "which", lambda name: good)
    paths = anim.make_animation(setpoint_run, fps=10, max_frames=4)
    assert [p.name for p in paths] == ["animation.gif", "animation.mp4"]
    bad = _fake_ffmpeg(tmp_path, ok=False)
    monkeypatch.setattr(anim.shutil, "which", lambda name: bad)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        paths = anim.make_animation(setpoint_run, fps=10, max_frames=4)
    assert [p.name for p in paths] == ["animation.gif"]
    assert not (setpoint_run / "animation.mp4").exists()
    assert any("ffmpeg failed" in str(w.message) for w in caught)


def test_ground_contact_is_shaded(setpoint_run):
    run = load_run(setpoint_run)
    s = dict(run.series)
    regime = np.ones_like(s["regime"])
    regime[100:200] = 2  # CatenaryRegime.TOUCHDOWN
    regime[300:320] = 3  # CatenaryRegime.SLACK
    s["regime"] = regime
    fig = build_figures(s, run.scenario, ["tension_and_winder"])["tension_and_winder"]
    ax = fig.axes[0]
    spans = ax.patches
    assert len(spans) == 2
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "tether on the ground" in labels
    plain = build_figures(run.series, run.scenario, ["tension_and_winder"])
    assert len(plain["tension_and_winder"].axes[0].patches) == 0


@pytest.fixture(scope="module")
def lumped_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "gust-lumped"
    sc = load_scenario("gust-lumped").replace(duration_s=6.5)   # through the gust's peak
    run_scenario(sc, out, progress=None)
    return out


def test_a_lumped_run_draws_the_recorded_nodes(lumped_run):
    # the run records the truth's nodes at the animation's frame rate; the 3-D path, the
    # snapshots and the animation draw them (from the exit to the attachment point), not
    # the catenary
    run = load_run(lumped_run)
    s = run.series
    from tuav_sitl.offline import LINE_NODES_RATE_HZ
    assert np.diff(s["line_t"]) == pytest.approx(1.0 / LINE_NODES_RATE_HZ, abs=0.005)
    assert s["line_nodes"].dtype == np.float32
    drawer = TetherDrawer(run.scenario, series=s)
    assert drawer.lumped
    k = int(np.searchsorted(s["t"], 6.0))
    pts = drawer.points(s["pos"][k], float(s["length"][k]), float(s["t"][k]))
    assert len(pts) > 10
    np.testing.assert_allclose(pts[0], 0.0, atol=1e-6)
    assert np.linalg.norm(pts[-1] - s["pos"][k]) < 0.05       # attached at the UAV
    # the gust (north, 5 to 7 s) blows the line sideways: the nodes leave the vertical
    # plane through the winder and the UAV, which the catenary never does
    assert np.max(np.abs(pts[:, 1])) > 0.05
    figs = build_figures(s, run.scenario, names=("path_3d", "snapshots"))
    for fig in figs.values():
        lines = [ln for ax in fig.axes for ln in ax.get_lines()
                 if ln.get_color() == "#8c564b"]
        assert lines and all(ln.get_marker() == "o" for ln in lines)
    paths = anim.make_animation(lumped_run, fps=10, max_frames=6)
    assert any(p.suffix == ".gif" and p.stat().st_size > 0 for p in paths)


def test_envelope_keeps_every_bins_extremes_and_every_gap():
    from tuav_sitl.figure_style import envelope

    rng = np.random.default_rng(5)
    n, bins = 50_001, 1000
    x = np.arange(n) * 0.004
    y = np.cumsum(rng.normal(size=n))
    y[12_345] += 500.0                                   # a one-sample spike
    y[30_000:30_010] = np.nan                            # a gap
    ex, ey = envelope(x, y, bins)
    assert len(ex) <= 3 * bins + 2 and np.all(np.diff(ex) > 0)
    assert ex[0] == x[0] and ex[-1] == x[-1]
    assert np.nanmax(ey) == np.nanmax(y) and np.nanmin(ey) == np.nanmin(y)
    assert 12_345 * 0.004 in ex
    assert np.isnan(ey).any() and np.all(np.isnan(ey[(ex >= x[30_000]) & (ex <= x[30_009])]))
    # every kept sample is a real one, at its own time
    idx = np.rint(ex / 0.004).astype(int)
    assert np.array_equal(ey, y[idx], equal_nan=True)
    # each run of samples keeps its extremes (runs of ceil(n / bins) samples)
    m = -(-n // bins)
    for s in range(0, n, m):
        seg = y[s:s + m]
        if np.isnan(seg).all():
            continue
        kept = ey[(idx >= s) & (idx < s + m)]
        assert np.nanmax(kept) == np.nanmax(seg) and np.nanmin(kept) == np.nanmin(seg)
    short = np.arange(10.0)
    assert envelope(short, short, bins)[1] is short


def test_draw_run_writes_the_same_figures_in_parallel_with_progress(setpoint_run, tmp_path,
                                                                   monkeypatch):
    """draw_run with a forked worker drawing the figures while this process draws the
    animation: the same PNG bytes as make_figures alone, the same GIF frames, and a
    progress line that counts every figure and frame."""
    import io
    import shutil as sh

    from tuav_sitl.render import draw_run

    monkeypatch.setattr(anim.shutil, "which", lambda name: None)
    alone = tmp_path / "alone"
    sh.copytree(setpoint_run, alone)
    for sub in ("figures",):
        sh.rmtree(alone / sub, ignore_errors=True)
    expected = make_figures(alone)
    ref_gif = anim.make_animation(alone)[0].read_bytes()
    both = tmp_path / "both"
    sh.copytree(alone, both)
    sh.rmtree(both / "figures")
    (both / "animation.gif").unlink()
    stream = io.StringIO()
    drawn = draw_run(both, progress=stream, workers=1)
    assert [p.name for p in drawn.figures] == [p.name for p in expected]
    for a, b in zip(expected, drawn.figures, strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name
    assert drawn.animation == [both / "animation.gif"]
    assert drawn.animation[0].read_bytes() == ref_gif
    assert drawn.skipped == ["estimate: the run has no est_pos, est_pos_sigma"]
    text = stream.getvalue()
    frames = len(anim.frame_plan(load_run(both).series["t"], anim.FPS, anim.MAX_FRAMES,
                                 None)[0])
    assert f"figures {len(expected)}/{len(expected)}" in text
    assert f"animation frames {frames}/{frames}" in text and text.endswith("\n")
    quiet = draw_run(both, animation=False, progress=None, workers=0)
    assert [p.name for p in quiet.figures] == [p.name for p in expected]
