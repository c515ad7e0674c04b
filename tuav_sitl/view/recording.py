"""What a Rerun recording of the tethered UAV holds, and a run's series logged into one.

The entities (the paper's frame: z up, origin at the winder's tether exit, metres; the
timeline ``sim`` is simulated time):

- ``world``: the frame (right-handed, z up); ``world/ground``: a grid on the ground;
  ``world/winder``: the winder's frame (east, north, up arrows); ``world/winder/drum``: the
  drum, its spoke turning with the paid-out length (``world/winder/drum/spoke``);
- ``world/vehicle``: the vehicle's pose (the truth) with its body (``world/vehicle/arms``,
  the front arms red) and rotor discs (``world/vehicle/rotors``, brighter with their
  command); ``world/tether``: the line as the plant has it (the lumped nodes when the run
  has them, else the plant's catenary for the position and the paid-out length);
  ``world/path``: the path flown (a piece per shape, the blueprint showing the pieces up to
  the time shown); ``world/reference`` (and ``world/reference_path``): the reference;
  ``world/estimate``: the filter's position with its 3-sigma ellipsoid
  (``world/estimate/ellipsoid``); ``world/fixes/gnss``, ``world/fixes/tether``: position
  fixes (with ``.../accuracy``, their 3-sigma ellipsoids) where the run has them;
- ``plots/tension/{top,drum}`` [N], ``plots/length/{paid_out,lbar}`` [m],
  ``plots/error/tracking_{x,y,z}`` (truth minus reference) and
  ``plots/error/estimate_{x,y,z}`` (estimate minus truth) [m], ``plots/rotors/{1..4}``
  (normalised commands); ``log/status``: the run's messages (``STATUSTEXT``, the
  navigator's events).

:class:`SceneLogger` logs chunks of the offline runner's columns
(:data:`tuav_sitl.offline.SERIES`) in time order, once (``tuav-sitl run``) or as they come
(``tuav-sitl up --view``); :func:`write_run_recording` writes a run folder's recording.
"""

from __future__ import annotations

import contextlib
import enum
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tuav_sitl.view import RECORDING_NAME, rerun_module
from tuavdefs.airframe import ROTOR_LAYOUT

#: The application id of every recording (the viewer groups recordings by it).
APP_ID = "tuav-sitl"
#: The timeline of simulated time [s].
TIMELINE = "sim"
#: How often the tether's shape and the path flown are logged [Hz of simulated time] (the
#: lumped tether's nodes come at the rate the run recorded them).
SHAPE_RATE_HZ = 15.0
#: Points along a catenary drawn as the tether.
CATENARY_POINTS = 60


class Entity(enum.StrEnum):
    """The recording's entity paths (module docstring)."""

    WORLD = "world"
    GROUND = "world/ground"
    WINDER = "world/winder"
    DRUM = "world/winder/drum"
    SPOKE = "world/winder/drum/spoke"
    VEHICLE = "world/vehicle"
    ARMS = "world/vehicle/arms"
    ROTORS = "world/vehicle/rotors"
    TETHER = "world/tether"
    PATH = "world/path"
    REFERENCE = "world/reference"
    REFERENCE_PATH = "world/reference_path"
    ESTIMATE = "world/estimate"
    ELLIPSOID = "world/estimate/ellipsoid"
    GNSS_FIX = "world/fixes/gnss"
    TETHER_FIX = "world/fixes/tether"
    TENSION_TOP = "plots/tension/top"
    TENSION_DRUM = "plots/tension/drum"
    LENGTH = "plots/length/paid_out"
    LBAR = "plots/length/lbar"
    STATUS = "log/status"


#: The error plots: entity, series column pair (a minus b), axis.
ERROR_PLOTS = tuple((f"plots/error/{kind}_{axis}", a, b, i)
                    for kind, a, b in (("tracking", "pos", "ref_pos"),
                                       ("estimate", "est_pos", "pos"))
                    for i, axis in enumerate("xyz"))
#: The rotor command plots, rotors 1..4.
ROTOR_PLOTS = tuple(f"plots/rotors/{i + 1}" for i in range(4))

_TETHER_COLOR = (140, 86, 75)
_PATH_COLOR = (31, 119, 180)
_REF_COLOR = (128, 128, 128)
_EST_COLOR = (44, 160, 44)
_AXIS_COLORS = ((214, 39, 40), (44, 160, 44), (31, 119, 180))


class LogLevel(enum.StrEnum):
    """Rerun's text-log levels the recordings use."""

    ERROR = "ERROR"
    WARN = "WARN"
    INFO = "INFO"
    DEBUG = "DEBUG"


def blueprint() -> Any:
    """The first view: the 3-D scene beside the tension, length and error plots (the
    rotor commands and the text log in tabs), the time panel on simulated time."""
    import rerun as rr
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin=Entity.WORLD, name="scene", overrides={
                # the path's pieces from the start to the time shown: the path flown
                Entity.PATH: rrb.VisibleTimeRanges(
                    timeline=TIMELINE, start=rr.TimeRangeBoundary.infinite(),
                    end=rr.TimeRangeBoundary.cursor_relative(seconds=0.0))}),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="plots/tension", name="tension [N]"),
                rrb.TimeSeriesView(origin="plots/length", name="paid-out length, L-bar [m]"),
                rrb.TimeSeriesView(origin="plots/error", name="position errors [m]"),
                rrb.Tabs(rrb.TextLogView(origin="log", name="messages"),
                         rrb.TimeSeriesView(origin="plots/rotors", name="rotor commands")),
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        collapse_panels=True,
    )


def _finite_rows(*arrays: np.ndarray) -> np.ndarray:
    """Rows at which every array is finite."""
    ok = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        a = np.asarray(a, dtype=float)
        ok &= np.isfinite(a).all(axis=1) if a.ndim == 2 else np.isfinite(a)
    return ok


def _next_on_grid(t_s: float, step_s: float) -> float:
    """The first multiple of ``step_s`` after ``t_s`` [s] (a sample within a microsecond
    of a multiple counts as on it)."""
    return (math.floor(t_s / step_s + 1e-6) + 1) * step_s


def euler_to_quat_xyzw(euler: np.ndarray) -> np.ndarray:
    """Quaternions (x, y, z, w) of rows of Z-Y-X Euler angles (roll, pitch, yaw) [rad]:
    R = Rz(yaw) Ry(pitch) Rx(roll), as :func:`tuavdefs.frames.euler_to_quat`."""
    h = 0.5 * np.asarray(euler, dtype=float)
    cr, sr = np.cos(h[:, 0]), np.sin(h[:, 0])
    cp, sp = np.cos(h[:, 1]), np.sin(h[:, 1])
    cy, sy = np.cos(h[:, 2]), np.sin(h[:, 2])
    return np.column_stack((sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy))


class SceneLogger:
    """Logs a run into the recording stream ``rec``: the fixed scene at once, then chunks
    of series in time order (:meth:`log_series`, :meth:`log_line_nodes`,
    :meth:`log_fixes`, :meth:`log_text`).

    ``system`` holds the run's parameters (``vehicle``, ``tether``, ``winder``,
    ``environment``: a scenario or :class:`tuavdefs.params.SystemParams`); ``lumped`` says
    the tether's nodes will come (:meth:`log_line_nodes`) instead of being solved for;
    ``ground_half_m`` is the ground grid's half-width [m].
    """

    def __init__(self, rec: Any, system: Any, lumped: bool = False,
                 ground_half_m: float = 30.0) -> None:
        from sitl.tether import Tether

        self.rr = rerun_module()
        self.rec = rec
        self.system = system
        self.lumped = lumped
        self.drum_radius_m = float(system.winder.drum_radius_m)
        self.tether = Tether(system.tether, system.environment.gravity_m_s2)
        self._next_shape_t = 0.0
        self._path_last: np.ndarray | None = None
        self._log_static(ground_half_m)

    # --- the fixed scene ------------------------------------------------------------

    def _log_static(self, half_m: float) -> None:
        rr, rec = self.rr, self.rec
        rec.log(Entity.WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        step = max(1.0, round(half_m / 10.0))
        ticks = np.arange(-half_m, half_m + 1e-9, step)
        lines = ([[(x, -half_m, 0.0), (x, half_m, 0.0)] for x in ticks]
                 + [[(-half_m, y, 0.0), (half_m, y, 0.0)] for y in ticks])
        rec.log(Entity.GROUND, rr.LineStrips3D(lines, colors=(170, 170, 170),
                                               radii=rr.Radius.ui_points(0.5)), static=True)
        rec.log(Entity.WINDER, rr.Arrows3D(vectors=np.eye(3) * step, colors=_AXIS_COLORS,
                                           labels=["east", "north", "up"],
                                           radii=rr.Radius.ui_points(1.5)), static=True)
        r = self.drum_radius_m
        width = 2.0 * r
        # the drum below the exit, its axle along y (north)
        rec.log(Entity.DRUM, rr.Transform3D(translation=(0.0, 0.0, -r)), static=True)
        rec.log(Entity.DRUM, rr.Cylinders3D(lengths=[width], radii=[r], centers=[(0, 0, 0)],
                                            rotation_axis_angles=[rr.RotationAxisAngle(
                                                axis=(1, 0, 0), degrees=90.0)],
                                            colors=[(90, 90, 110)], fill_mode="solid"),
                static=True)
        rec.log(Entity.SPOKE, rr.LineStrips3D([[(0.0, -0.51 * width, 0.0),
                                                (r, -0.51 * width, 0.0)]],
                                              colors=(250, 200, 0),
                                              radii=rr.Radius.ui_points(2.0)), static=True)
        arm = float(self.system.vehicle.arm_length_m)
        d = arm / math.sqrt(2.0)
        centres = [(sx * d, sy * d, 0.0) for sx, sy, _ in ROTOR_LAYOUT]
        front = [c for c in centres if c[0] > 0]
        rear = [c for c in centres if c[0] < 0]
        rec.log(Entity.ARMS, rr.LineStrips3D(
            [[front[0], (0, 0, 0), front[1]], [rear[0], (0, 0, 0), rear[1]],
             [(0, 0, 0), (0, 0, 0.6 * arm)]],
            colors=[(214, 39, 40), (30, 30, 30), (30, 30, 30)],
            radii=rr.Radius.ui_points(2.5)), static=True)
        rec.log(Entity.ROTORS, rr.Cylinders3D(
            lengths=[0.02 * arm] * 4, radii=[0.45 * arm] * 4, centers=centres,
            colors=[(120, 120, 120)] * 4),
            static=True)
        names = {Entity.TENSION_TOP: ("at the vehicle", (214, 39, 40)),
                 Entity.TENSION_DRUM: ("at the drum", (31, 119, 180)),
                 Entity.LENGTH: ("paid out", (31, 119, 180)),
                 Entity.LBAR: ("L-bar", (255, 127, 14))}
        for i, path in enumerate(ROTOR_PLOTS):
            names[path] = (f"rotor {i + 1}", (31, 119, 180) if i < 2 else (214, 39, 40))
        for path, _a, _b, axis in ERROR_PLOTS:
            kind = "truth - reference" if "tracking" in path else "estimate - truth"
            names[path] = (f"{kind} {'xyz'[axis]}", _AXIS_COLORS[axis])
        for path, (name, color) in names.items():
            rec.log(path, rr.SeriesLines(names=name, colors=color), static=True)

    # --- series ---------------------------------------------------------------------

    def _time(self, t: np.ndarray) -> list[Any]:
        return [self.rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float))]

    def _scalars(self, path: str, t: np.ndarray, v: np.ndarray) -> None:
        ok = np.isfinite(v)
        if ok.any():
            self.rec.send_columns(path, indexes=self._time(t[ok]),
                                  columns=self.rr.Scalars.columns(scalars=v[ok]))

    def reference_path(self, ref_pos: np.ndarray) -> None:
        """The whole reference path (static): rows of (x, y, z) [m], NaN where none."""
        ok = _finite_rows(ref_pos)
        if ok.sum() >= 2:
            self.rec.log(Entity.REFERENCE_PATH, self.rr.LineStrips3D(
                [np.asarray(ref_pos)[ok][::max(1, int(ok.sum()) // 2000)]],
                colors=_REF_COLOR, radii=self.rr.Radius.ui_points(1.0)), static=True)

    def log_series(self, s: Mapping[str, np.ndarray], only: Sequence[str] = ()) -> None:
        """A chunk of the offline runner's columns (any of them; ``t`` [s] required, later
        than the previous chunk's), NaN where a column has no value. ``only=("errors",)``
        logs the error plots alone (columns that also fill other entities)."""
        rr, rec = self.rr, self.rec
        t = np.asarray(s["t"], dtype=float)
        if not len(t):
            return
        if "errors" in only:
            self._error_plots(t, s)
            return
        if "pos" in s and "euler" in s:
            pos, euler = np.asarray(s["pos"], float), np.asarray(s["euler"], float)
            ok = _finite_rows(pos, euler)
            if ok.any():
                rec.send_columns(Entity.VEHICLE, indexes=self._time(t[ok]),
                                 columns=rr.Transform3D.columns(
                                     translation=pos[ok],
                                     quaternion=euler_to_quat_xyzw(euler[ok])))
        if "rotor_cmd" in s:
            cmd = np.asarray(s["rotor_cmd"], float)
            ok = _finite_rows(cmd)
            if ok.any():
                level = np.clip(cmd[ok], 0.0, 1.0)
                rgb = np.empty((level.size, 4), dtype=np.uint8)
                flat = level.reshape(-1)
                rgb[:, 0] = (60 + 195 * flat).astype(np.uint8)
                rgb[:, 1] = (60 + 120 * flat).astype(np.uint8)
                rgb[:, 2] = 60
                rgb[:, 3] = 255
                rec.send_columns(Entity.ROTORS, indexes=self._time(t[ok]),
                                 columns=rr.Cylinders3D.columns(colors=rgb).partition(
                                     np.full(int(ok.sum()), 4)))
                for i, path in enumerate(ROTOR_PLOTS):
                    self._scalars(path, t, cmd[:, i])
        if "length" in s:
            length = np.asarray(s["length"], float)
            self._scalars(Entity.LENGTH, t, length)
            ok = np.isfinite(length)
            if ok.any():
                angle = length[ok] / self.drum_radius_m
                q = np.column_stack((np.zeros_like(angle), np.sin(-0.5 * angle),
                                     np.zeros_like(angle), np.cos(-0.5 * angle)))
                rec.send_columns(Entity.SPOKE, indexes=self._time(t[ok]),
                                 columns=rr.Transform3D.columns(quaternion=q))
        for name, path in (("lbar", Entity.LBAR), ("top_tension", Entity.TENSION_TOP),
                           ("drum_tension", Entity.TENSION_DRUM)):
            if name in s:
                self._scalars(path, t, np.asarray(s[name], float))
        self._error_plots(t, s)
        if "ref_pos" in s:
            ref = np.asarray(s["ref_pos"], float)
            ok = _finite_rows(ref)
            if ok.any():
                rec.send_columns(Entity.REFERENCE, indexes=self._time(t[ok]),
                                 columns=rr.Points3D.columns(positions=ref[ok]))
        if "est_pos" in s:
            est = np.asarray(s["est_pos"], float)
            ok = _finite_rows(est)
            if ok.any():
                rec.send_columns(Entity.ESTIMATE, indexes=self._time(t[ok]),
                                 columns=rr.Points3D.columns(positions=est[ok]))
            if "est_pos_sigma" in s:
                self.log_estimate_ellipsoids(t, est, np.asarray(s["est_pos_sigma"], float))
        if "pos" in s:
            self._shapes_and_path(t, np.asarray(s["pos"], float),
                                  np.asarray(s["length"], float) if "length" in s else None)

    def log_estimate_ellipsoids(self, t: np.ndarray, est: np.ndarray,
                                sigma: np.ndarray) -> None:
        """The estimate's 3-sigma ellipsoids: times [s], centres (the estimate) [m] and
        its position's standard deviations along x, y, z [m] (rows with a NaN skipped)."""
        t, est, sigma = (np.asarray(a, float) for a in (t, est, sigma))
        ok = _finite_rows(est, sigma)
        if ok.any():
            self.rec.send_columns(Entity.ELLIPSOID, indexes=self._time(t[ok]),
                                  columns=self.rr.Ellipsoids3D.columns(
                                      centers=est[ok], half_sizes=3.0 * sigma[ok]))

    def _error_plots(self, t: np.ndarray, s: Mapping[str, np.ndarray]) -> None:
        for path, a, b, axis in ERROR_PLOTS:
            if a in s and b in s:
                self._scalars(path, t, np.asarray(s[a], float)[:, axis]
                              - np.asarray(s[b], float)[:, axis])

    def _shapes_and_path(self, t: np.ndarray, pos: np.ndarray,
                         length: np.ndarray | None) -> None:
        """The catenary (unless the nodes come) and the path flown (a piece at a time),
        at :data:`SHAPE_RATE_HZ`."""
        ticks: list[float] = []
        pieces: list[np.ndarray] = []
        shape_t: list[float] = []
        shapes: list[np.ndarray] = []
        for i in range(len(t)):
            ti = float(t[i])
            p = pos[i]
            if not np.isfinite(p).all() or ti < self._next_shape_t - 1e-9:
                continue
            self._next_shape_t = _next_on_grid(ti, 1.0 / SHAPE_RATE_HZ)
            # the piece flown since the last one (the blueprint shows them all up to the
            # time shown): the recording grows with the run, not with its square
            last = self._path_last if self._path_last is not None else p
            ticks.append(ti)
            pieces.append(np.vstack((last, p)))
            self._path_last = p
            if not self.lumped and length is not None and np.isfinite(length[i]) \
                    and length[i] > 0:
                shape_t.append(ti)
                shapes.append(self.catenary(p, float(length[i])))
        self._strips(Entity.PATH, ticks, pieces, _PATH_COLOR, 1.2)
        self._strips(Entity.TETHER, shape_t, shapes, _TETHER_COLOR, 2.0)

    def _strips(self, path: str, t: Sequence[float], strips: Sequence[np.ndarray],
                color: tuple[int, int, int], width_pt: float,
                points_pt: float | None = None) -> None:
        """A line strip per instant (and, with ``points_pt``, its points), in one call."""
        if not strips:
            return
        rr, n = self.rr, len(strips)
        cols = rr.LineStrips3D.columns(strips=list(strips), colors=np.tile(color, (n, 1)),
                                       radii=np.full(n, -width_pt))
        if points_pt is not None:
            sizes = [len(s) for s in strips]
            total = int(sum(sizes))
            cols = [*cols, *rr.Points3D.columns(
                positions=np.vstack(strips), colors=np.tile(color, (total, 1)),
                radii=np.full(total, -points_pt)).partition(sizes)]
        self.rec.send_columns(path, indexes=self._time(np.asarray(t, float)), columns=cols)

    def catenary(self, pos: np.ndarray, length_m: float) -> np.ndarray:
        """(n, 3) points [m] of the plant's catenary from the exit to the vehicle at
        ``pos`` with ``length_m`` paid out (a straight line where it cannot be solved)."""
        x, y, z = float(pos[0]), float(pos[1]), max(float(pos[2]), 0.0)
        try:
            self.tether.forces(x, y, z, length_m)
            return self.tether.shape(x, y, z, length_m, CATENARY_POINTS)
        except (ValueError, RuntimeError):
            self.tether.reset_warm_start()
            return np.linspace(0.0, 1.0, CATENARY_POINTS)[:, None] * np.array([[x, y, z]])

    def log_line_nodes(self, t: np.ndarray, nodes: np.ndarray) -> None:
        """The lumped tether's nodes: times [s] and (samples, points, 3) [m], NaN-padded
        (the offline runner's ``line_t``, ``line_nodes``), as a strip and its points."""
        rows = np.asarray(nodes, float)
        self._strips(Entity.TETHER, np.asarray(t, float),
                     [row[np.isfinite(row[:, 0])] for row in rows], _TETHER_COLOR, 2.0,
                     points_pt=3.0)

    def log_fixes(self, path: str, t: np.ndarray, pos: np.ndarray,
                  accuracy_m: np.ndarray | None = None) -> None:
        """Position fixes (``Entity.GNSS_FIX`` or ``Entity.TETHER_FIX``): times [s] and
        positions [m]; with ``accuracy_m`` (their 1-sigma along x, y, z [m]) also their
        3-sigma ellipsoids (``PATH/accuracy``)."""
        pos = np.asarray(pos, float).reshape(-1, 3)
        t = np.asarray(t, float)
        ok = _finite_rows(pos)
        if not ok.any():
            return
        color = (255, 127, 14) if path == Entity.GNSS_FIX else (148, 103, 189)
        n = int(ok.sum())
        self.rec.send_columns(path, indexes=self._time(t[ok]),
                              columns=self.rr.Points3D.columns(
                                  positions=pos[ok], colors=np.tile(color, (n, 1))))
        if accuracy_m is not None:
            acc = np.asarray(accuracy_m, float).reshape(-1, 3)
            ok &= _finite_rows(acc) & (acc > 0).all(axis=1)
            if ok.any():
                self.rec.send_columns(f"{path}/accuracy", indexes=self._time(t[ok]),
                                      columns=self.rr.Ellipsoids3D.columns(
                                          centers=pos[ok], half_sizes=3.0 * acc[ok]))

    def log_text(self, t_s: float, text: str, level: LogLevel = LogLevel.INFO) -> None:
        """A message at simulated time ``t_s`` [s]."""
        self.rec.set_time(TIMELINE, duration=float(t_s))
        self.rec.log(Entity.STATUS, self.rr.TextLog(text, level=level.value))


def new_stream(name: str) -> Any:
    """A recording stream of :data:`APP_ID` (not the global one) named ``name``, with
    the recording's properties set."""
    rr = rerun_module()
    rec = rr.RecordingStream(APP_ID)
    rec.send_recording_name(name)
    return rec


def log_run(logger: SceneLogger, series: Mapping[str, np.ndarray],
            events: Sequence[tuple[float, str, LogLevel]] = ()) -> None:
    """A whole run: its series (and the lumped nodes when it has them) and its events
    ((t [s], text, level), in time order)."""
    if "ref_pos" in series:
        logger.reference_path(series["ref_pos"])
    logger.log_series(series)
    if "line_nodes" in series and len(series["line_t"]):
        logger.log_line_nodes(series["line_t"], series["line_nodes"])
    for name, path in (("gnss_fix", Entity.GNSS_FIX), ("tether_fix", Entity.TETHER_FIX)):
        if f"{name}_t" in series:
            logger.log_fixes(path, series[f"{name}_t"], series[f"{name}_pos"],
                             accuracy_m=series.get(f"{name}_sigma"))
    for t, text, level in events:
        logger.log_text(t, text, level)


def ground_half_width_m(series: Mapping[str, np.ndarray]) -> float:
    """Half the ground grid's width [m]: the run's farthest horizontal point and a margin,
    at least 5 m."""
    pos = np.asarray(series.get("pos", np.zeros((1, 3))), float)
    ok = _finite_rows(pos)
    reach = float(np.abs(pos[ok, :2]).max()) if ok.any() else 0.0
    return max(5.0, math.ceil(1.2 * reach + 2.0))


def write_recording(path: Path, name: str, system: Any, series: Mapping[str, np.ndarray],
                    events: Sequence[tuple[float, str, LogLevel]] = ()) -> Path:
    """Write the recording of a run (``series``: the offline runner's columns; ``system``:
    its parameters) to ``path`` with the default blueprint; returns ``path``."""
    rec = new_stream(name)
    rec.save(str(path), default_blueprint=blueprint())
    lumped = "line_nodes" in series and len(series["line_t"]) > 0
    logger = SceneLogger(rec, system, lumped=lumped,
                         ground_half_m=ground_half_width_m(series))
    log_run(logger, series, events)
    rec.flush()
    rec.disconnect()
    return path


def write_run_recording(run_dir: Path) -> Path:
    """The recording of a ``tuav-sitl run`` folder (``timeseries.npz``, ``scenario.toml``)
    as ``RUN/recording.rrd``; returns its path."""
    from tuav_sitl.run_data import load_run

    run = load_run(run_dir)
    return write_recording(Path(run_dir) / RECORDING_NAME, run.scenario.name, run.scenario,
                           run.series)


def nav_event_texts(events: Sequence[tuple[Any, object, float]]
                    ) -> list[tuple[float, str, LogLevel]]:
    """The navigator's events ((kind, value, t [s]), a run's ``RunResult.events``) as the
    text log's entries."""
    out = []
    for kind, value, t in events:
        name = getattr(kind, "value", str(kind))
        level = (LogLevel.ERROR if name in ("error", "failsafe") else
                 LogLevel.WARN if name == "warning" else LogLevel.INFO)
        text = name.replace("_", " ") if value is None else f"{name.replace('_', ' ')}: {value}"
        out.append((float(t), text, level))
    return out


class RecordingJob:
    """A run's ``recording.rrd`` written by a forked process that is started before the
    run, so that it imports rerun while the run goes on; :meth:`write` hands it the run
    (through a pipe) when it is over, :meth:`wait` waits for the file, :meth:`cancel`
    ends it without one."""

    def __init__(self) -> None:
        import multiprocessing

        ctx = multiprocessing.get_context("fork")
        self._conn, child = ctx.Pipe()
        self.path: Path | None = None
        self.process = ctx.Process(target=_recording_child, args=(child,),
                                   name="tuav-sitl recording", daemon=True)
        self.process.start()
        child.close()

    def write(self, path: Path, name: str, system: Any, series: Mapping[str, np.ndarray],
              events: Sequence[tuple[float, str, LogLevel]] = ()) -> None:
        """Have the run written to ``path`` (see :func:`write_recording`)."""
        self.path = Path(path)
        self._conn.send((self.path, name, system, dict(series), list(events)))
        self._conn.close()

    def cancel(self) -> None:
        """End the process without a recording."""
        with contextlib.suppress(OSError):
            self._conn.send(None)
            self._conn.close()
        self.process.join(10.0)

    def wait(self, timeout_s: float | None = None) -> bool:
        """Wait for the file (at most ``timeout_s`` [s]); whether it was written."""
        self.process.join(timeout_s)
        return (self.process.exitcode == 0 and self.path is not None
                and self.path.is_file())


def _recording_child(conn: Any) -> None:
    """The job's process: rerun imported (pyarrow's conversions too) while the run goes
    on, then the run it is handed written."""
    with contextlib.suppress(OSError):
        os.nice(5)       # below the figures the parent draws meanwhile
    rerun_module()
    import pyarrow

    pyarrow.array(["warm"])   # (its first text conversion loads pandas: not in the wait)
    try:
        job = conn.recv()
    except EOFError:
        return
    if job is not None:
        write_recording(*job)


def start_recording_job() -> RecordingJob | None:
    """A :class:`RecordingJob` started now, or None without rerun-sdk
    (:data:`tuav_sitl.view.INSTALL_HINT`)."""
    from tuav_sitl.view import available

    return RecordingJob() if available() else None


def run_recording_args(result: Any, out_dir: Path) -> tuple:
    """:meth:`RecordingJob.write`'s arguments for an offline run (a
    :class:`tuav_sitl.offline.RunResult`) in ``out_dir``."""
    return (Path(out_dir) / RECORDING_NAME, result.scenario.name, result.scenario,
            result.series, nav_event_texts(result.events))
