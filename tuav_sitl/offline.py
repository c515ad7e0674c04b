"""The offline runner: plant and controllers in one process, as fast as the machine allows.

It runs the same classes the three processes run: the plant (``sitl``), the onboard
backstepping controllers and mission logic (``companion``), the L-bar estimator and the
winder torque law (``groundstation``), each at its own rate and fed what it would receive in
the field: the companion the vehicle's state and the winch's reported length and tension,
the ground station the encoder (length, drum rate), the load cell, and the UAV's position
and velocity from telemetry.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from companion.flight_controller import FlightController, VehicleState
from companion.trajectory import (
    GotoItem,
    Hold,
    RefSample,
    SequenceBuilder,
    WaypointFollower,
)
from groundstation.winder_host import WinderHost
from sitl.catenary import CatenaryRegime
from sitl.plant import Plant, PlantInputs
from sitl.trim import hover_trim
from tuav_sitl.scenario import ScenarioParams
from tuavdefs.frames import quat_to_euler, wrap_pi
from tuavdefs.paramspec import to_dict

#: Tether regimes in which part of the tether lies on the ground.
GROUND_REGIMES = (int(CatenaryRegime.TOUCHDOWN), int(CatenaryRegime.SLACK),
                  int(CatenaryRegime.FLAT))
#: Distance to the goal within which a set-point run counts as settled [m].
SETTLE_BAND_M = 0.05


class ProgressBar:
    """A throttled text progress bar on a stream (only when the run is long enough)."""

    def __init__(self, total_s: float, stream: TextIO | None, width: int = 30) -> None:
        self.total = total_s
        self.stream = stream
        self.width = width
        self._start = time.perf_counter()
        self._last = -1.0
        self._shown = False

    def update(self, t_s: float) -> None:
        """Report simulated time ``t_s``; draws at most 4 times a second after 1 s."""
        if self.stream is None:
            return
        now = time.perf_counter()
        if now - self._start < 1.0 or now - self._last < 0.25:
            return
        self._last = now
        self._shown = True
        frac = min(t_s / self.total, 1.0)
        filled = int(frac * self.width)
        elapsed = now - self._start
        eta = elapsed * (1 - frac) / frac if frac > 0 else math.inf
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {frac:5.1%} "
                          f"t = {t_s:6.1f}/{self.total:.1f} s, {elapsed:5.1f} s elapsed, "
                          f"~{eta:4.0f} s left ")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self.stream is not None and self._shown:
            self.stream.write("\n")
            self.stream.flush()


@dataclass
class RunResult:
    """Everything a run produced."""

    scenario: ScenarioParams
    series: dict[str, np.ndarray]
    metrics: dict[str, Any]
    events: list[tuple[str, int, float]] = field(default_factory=list)


class Reference:
    """The scenario's reference: a trajectory, or the waypoint mission logic."""

    def __init__(self, sc: ScenarioParams) -> None:
        tr = sc.trajectory
        start = tuple(sc.initial.position_m)
        yaw = sc.initial.yaw_rad
        self.follower: WaypointFollower | None = None
        self.goal: tuple[float, ...] | None = None
        b = SequenceBuilder(start, 0.0, tr.max_speed_m_s, tr.max_acc_m_s2, yaw=yaw)
        if tr.start_s > 0:
            b.hold(tr.start_s)
        if tr.kind == "hold":
            self.traj = Hold(start, yaw, 0.0)
            return
        if tr.kind == "step":
            self.traj = Hold(tuple(tr.goal_m), yaw, 0.0)
            self.goal = tuple(tr.goal_m)
            return
        if tr.kind == "setpoint":
            b.goto(tr.goal_m)
            self.goal = tuple(tr.goal_m)
        elif tr.kind == "line":
            b.line_to(tr.goal_m, tr.speed_m_s)
            self.goal = tuple(tr.goal_m)
        elif tr.kind == "circle":
            b.circle(tr.centre_m, tr.radius_m, tr.speed_m_s, tr.turns,
                     altitude_m=tr.altitude_m, lead_in_s=tr.lead_in_s)
        elif tr.kind == "waypoints":
            self.follower = WaypointFollower(tr.max_speed_m_s, tr.max_acc_m_s2,
                                             tr.acceptance_radius_m, tr.hold_s)
            self._items = [GotoItem(tuple(w.position_m)) for w in tr.waypoints]
            self._start_s = tr.start_s
            self._started = False
        self.traj = b.build()

    def sample(self, t: float, pos: tuple[float, float, float],
               vel: tuple[float, float, float]) -> RefSample:
        """The reference at ``t`` [s] for the vehicle at ``pos`` [m]."""
        if self.follower is None:
            return self.traj.sample(t)
        if not self._started:
            if t < self._start_s:
                return self.traj.sample(t)
            self.follower.start(t, self.traj.sample(t).pos_m, (0.0, 0.0, 0.0), self._items)
            self._started = True
        return self.follower.update(t, pos)

    def events(self) -> list[tuple[str, int, float]]:
        """Mission events (kind, item index, time [s]) so far."""
        if self.follower is None:
            return []
        return [(e.kind, e.index, e.t_s) for e in self.follower.pop_events()]


class OfflineRunner:
    """Plant, companion and ground-station logic stepped together."""

    def __init__(self, scenario: ScenarioParams) -> None:
        sc = self.sc = scenario
        params = self.params = sc.system()
        veh = params.vehicle
        g = params.environment.gravity_m_s2
        self.dt = 1.0 / sc.physics_rate_hz
        self.n_ctrl = round(sc.physics_rate_hz / sc.control.rate_hz)
        self.n_wind = round(sc.physics_rate_hz / sc.winder_control.rate_hz)
        self.winder_host = WinderHost(sc.winder_control, sc.lbar, params.winder,
                                      params.tether, g)
        start = tuple(sc.initial.position_m)
        length0, _ = self.winder_host.lbar.length(start)
        x0, _ = hover_trim(params, start, length0, sc.initial.yaw_rad)
        self.plant = Plant(params, dt_s=self.dt, state=x0)
        self.flight = FlightController(sc.control, veh, params.tether, g)
        self.flight.reset(self._vehicle_state(), tuple(self.plant.rotor_speeds_rad_s))
        self.reference = Reference(sc)

    def _vehicle_state(self) -> VehicleState:
        """What the companion receives: the truth state (docs/architecture.md)."""
        p = self.plant
        return VehicleState(tuple(p.position_m), tuple(p.velocity_m_s), p.quaternion,
                            tuple(p.body_rates_rad_s))

    def run(self, progress: TextIO | None = None,
            on_sample: Callable[[float], None] | None = None) -> RunResult:
        """Run the scenario; returns the time series and metrics."""
        sc, plant = self.sc, self.plant
        r_w = self.params.winder.drum_radius_m
        n_steps = round(sc.duration_s / self.dt)
        n_log = n_steps // self.n_ctrl + 1
        log = _Log(n_log)
        bar = ProgressBar(sc.duration_s, progress)
        inputs = PlantInputs()
        winder_torque, winder_lyap, lbar = 0.0, 0.0, (0.0, 0.0)
        self.flight.winch_report(0.0, plant.tether_length_m, 0.0,
                                 plant.tether_forces().drum_tension_n)
        events: list[tuple[str, int, float]] = []
        wall0 = time.perf_counter()
        for k in range(n_steps + 1):
            t = k * self.dt
            fresh = k % self.n_wind == 0
            if fresh:
                # ground station: encoder, load cell and the UAV's telemetry
                drum_tension = plant.tether_forces().drum_tension_n
                ws = self.winder_host.update(plant.tether_length_m, plant.drum_rate_rad_s,
                                             drum_tension, tuple(plant.position_m),
                                             tuple(plant.velocity_m_s))
                winder_torque, winder_lyap = ws.torque_n_m, ws.command.lyapunov
                lbar = (ws.lbar_m, ws.lbar_rate_m_s)
                # ... and the winch's report reaches the companion
                self.flight.winch_report(t, plant.tether_length_m,
                                         plant.drum_rate_rad_s * r_w, drum_tension)
            if k % self.n_ctrl == 0:
                state = self._vehicle_state()
                ref = self.reference.sample(t, state.pos_m, state.vel_m_s)
                events.extend(self.reference.events())
                fs = self.flight.update(t, state, ref)
                po, ao = fs.position, fs.attitude
                inputs = PlantInputs(fs.rotor_commands, True, winder_torque, True)
                truth_tether = plant.tether_forces()
                log.add(t=t, pos=state.pos_m, vel=state.vel_m_s, ref_pos=ref.pos_m,
                        ref_vel=ref.vel_m_s, euler=quat_to_euler(state.quat),
                        att_cmd=ao.attitude_cmd_rad, att_des=po.attitude_rad,
                        rates=state.rates_rad_s, thrust=po.thrust_n, torque=ao.torque_n_m,
                        rotor_cmd=fs.rotor_commands, mixer_sat=fs.mixer_saturated,
                        pos_sat=po.saturated, d_hat=po.disturbance_m_s2,
                        v_pos=po.lyapunov, v_att=ao.lyapunov, v_win=winder_lyap,
                        v_pos_raw=po.lyapunov_raw, v_att_raw=ao.lyapunov_raw,
                        length=plant.tether_length_m, lbar=lbar[0], lbar_rate=lbar[1],
                        lbar_fresh=fresh,
                        drum_rate=plant.drum_rate_rad_s, winder_torque=winder_torque,
                        drum_tension=truth_tether.drum_tension_n,
                        top_tension=truth_tether.top_tension_n,
                        regime=int(truth_tether.info.regime),
                        lowest=truth_tether.info.lowest_point_height_m,
                        wind=plant.wind_m_s, tether_force=truth_tether.on_uav_n,
                        tether_force_est=fs.tether_force_est_n)
                bar.update(t)
                if on_sample is not None:
                    on_sample(t)
            elif fresh:
                inputs = inputs._replace(winder_torque_n_m=winder_torque)
            if k < n_steps:
                plant.step(inputs)
        wall = time.perf_counter() - wall0
        bar.close()
        series = log.arrays()
        metrics = compute_metrics(sc, series, self.reference, wall)
        metrics["waypoints_reached"] = [
            {"index": i, "t_s": round(ts, 3)} for kind, i, ts in events if kind == "reached"]
        return RunResult(sc, series, metrics, events)


class _Log:
    """Preallocated columns of the time series."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.i = 0
        self.cols: dict[str, np.ndarray] = {}

    def add(self, **values: Any) -> None:
        if self.i >= self.n:
            return
        for name, v in values.items():
            col = self.cols.get(name)
            if col is None:
                width = len(v) if isinstance(v, (tuple, list)) else 0
                shape = (self.n, width) if width else (self.n,)
                col = self.cols[name] = np.full(shape, np.nan)
            col[self.i] = v
        self.i += 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: v[: self.i] for k, v in self.cols.items()}


def compute_metrics(sc: ScenarioParams, s: dict[str, np.ndarray], reference: Reference,
                    wall_s: float) -> dict[str, Any]:
    """The run's figures of merit (see docs/results.md for their definitions)."""
    t = s["t"]
    win = t >= sc.metrics_after_s
    pos_err = np.linalg.norm(s["pos"] - s["ref_pos"], axis=1)
    e_att = s["euler"] - s["att_cmd"]
    e_att[:, 2] = (e_att[:, 2] + np.pi) % (2 * np.pi) - np.pi
    att_err = np.linalg.norm(e_att, axis=1)
    # L-bar is computed at the winder's rate and held between updates: compare the length
    # with it only at the instants it was computed
    fresh = s["lbar_fresh"].astype(bool)
    len_err = (s["length"] - s["lbar"])[fresh]
    len_win = win[fresh]
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    rotor = s["rotor_cmd"]
    rotor_sat = (rotor <= 1e-9).any(axis=1) | (rotor >= 1 - 1e-9).any(axis=1)
    motor_sat = rotor_sat | s["mixer_sat"].astype(bool)
    m: dict[str, Any] = {
        "scenario": sc.name,
        "position_rmse_m": _rms(pos_err[win]),
        "position_max_error_m": float(pos_err[win].max()),
        "attitude_rmse_rad": _rms(att_err[win]),
        "tether_length_rmse_m": _rms(len_err[len_win]),
        "tether_length_max_error_m": float(np.abs(len_err[len_win]).max()),
        "min_tether_slack_m": float(slack.min()),
        "max_tension_n": float(s["top_tension"].max()),
        "max_drum_tension_n": float(s["drum_tension"].max()),
        "tether_ground_contact_fraction": float(np.isin(s["regime"], GROUND_REGIMES).mean()),
        "motor_saturation_fraction": float(motor_sat.mean()),
        "position_loop_saturation_fraction": float(s["pos_sat"].astype(bool).mean()),
        "settling_time_s": None,
        "overshoot_percent": None,
        "metrics_after_s": sc.metrics_after_s,
        "sim_time_s": float(t[-1]),
        "wall_time_s": round(wall_s, 3),
        "realtime_factor": round(float(t[-1]) / wall_s, 2) if wall_s > 0 else None,
    }
    if sc.trajectory.kind in ("setpoint", "step") and reference.goal is not None:
        goal = np.array(reference.goal)
        start = np.array(sc.initial.position_m)
        dist_goal = np.linalg.norm(s["pos"] - goal, axis=1)
        outside = np.nonzero(dist_goal > SETTLE_BAND_M)[0]
        if len(outside) == 0:
            m["settling_time_s"] = 0.0
        elif outside[-1] + 1 < len(t):
            m["settling_time_s"] = float(t[outside[-1] + 1] - sc.trajectory.start_s)
        still = reference.traj.end_s if sc.trajectory.kind == "setpoint" else 0.0
        m["lyapunov"] = lyapunov_report(s, still)
        span = np.linalg.norm(goal - start)
        if span > 0:
            along = (s["pos"] - goal) @ ((goal - start) / span)
            m["overshoot_percent"] = float(max(along.max(), 0.0) / span * 100.0)
    return m


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def write_outputs(result: RunResult, out_dir: Path) -> list[Path]:
    """Write the time series, metrics and the scenario used into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    npz = out_dir / "timeseries.npz"
    np.savez_compressed(npz, **result.series)
    written.append(npz)
    mj = out_dir / "metrics.json"
    mj.write_text(json.dumps(result.metrics, indent=2) + "\n")
    written.append(mj)
    sc_file = out_dir / "scenario.toml"
    sc_file.write_text(_to_toml(to_dict(result.scenario)))
    written.append(sc_file)
    return written


def _to_toml(d: dict[str, Any], prefix: str = "") -> str:
    """A minimal TOML writer for parameter dictionaries (scalars, arrays, tables, arrays of
    tables)."""
    scalars, tables, arrays = [], [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            arrays.append((k, v))
        else:
            scalars.append(f"{k} = {_toml_value(v)}")
    out = "\n".join(scalars) + ("\n" if scalars else "")
    for k, v in tables:
        name = f"{prefix}{k}"
        out += f"\n[{name}]\n" + _to_toml(v, name + ".")
    for k, items in arrays:
        name = f"{prefix}{k}"
        for item in items:
            out += f"\n[[{name}]]\n" + _to_toml(item, name + ".")
    return out


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(e) for e in v) + "]"
    if isinstance(v, float) and not math.isfinite(v):
        return "inf" if v > 0 else ("-inf" if v < 0 else "nan")
    return repr(v)


def run_scenario(scenario: ScenarioParams, out_dir: Path | None = None,
                 progress: TextIO | None = sys.stderr) -> RunResult:
    """Run ``scenario`` and, if ``out_dir`` is given, write its outputs there."""
    result = OfflineRunner(scenario).run(progress=progress)
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


#: A subsystem's reference counts as constant once its rate stays below these.
ATTITUDE_REF_STILL_RAD_S = 1e-3
LENGTH_REF_STILL_M_S = 1e-3
#: Below these values a Lyapunov function is under what a 250 Hz sampled loop on a 1 kHz
#: plant resolves (position errors ~0.3 mm, attitude ~1e-4 rad, length ~30 um).
LYAPUNOV_FLOORS = {"v_pos": 1e-7, "v_att": 1e-8, "v_win": 1e-8}


def still_from(t: np.ndarray, x: np.ndarray, tol: float) -> float | None:
    """First time after which ``x``'s rate stays at or below ``tol`` (None if never)."""
    rate = np.abs(np.gradient(x, t, axis=0))
    if rate.ndim > 1:
        rate = rate.max(axis=1)
    moving = np.nonzero(rate > tol)[0]
    if len(moving) == 0:
        return float(t[0])
    if moving[-1] + 1 >= len(t):
        return None
    return float(t[moving[-1] + 1])


def lyapunov_increases(t: np.ndarray, v: np.ndarray, from_s: float, floor: float = 0.0
                       ) -> int:
    """How many times ``v`` rises after ``from_s`` while above ``floor``: zero for a
    Lyapunov function once its reference is constant."""
    sel = t >= from_s
    vv = v[sel]
    d = np.diff(vv)
    return int(np.sum((d > 0.0) & (vv[:-1] > floor)))


def lyapunov_report(s: dict[str, np.ndarray], position_ref_still_s: float
                    ) -> dict[str, dict[str, float | int | None]]:
    """For each subsystem: from when its reference is constant, its Lyapunov function's
    value then, and how often it rose (above its floor) after that (docs/control.md §5).

    Position: the position reference is constant. Attitude: the filtered attitude command
    is still. Winder: L-bar is still.
    """
    t = s["t"]
    starts = {
        "v_pos": position_ref_still_s,
        "v_att": still_from(t, s["att_cmd"], ATTITUDE_REF_STILL_RAD_S),
        "v_win": still_from(t, s["lbar"], LENGTH_REF_STILL_M_S),
    }
    out: dict[str, dict[str, float | int | None]] = {}
    for name, t0 in starts.items():
        if t0 is not None and t0 >= t[-1]:
            t0 = None   # the run ended before the reference settled
        if t0 is None:
            out[name] = {"from_s": None, "value_then": None, "increases": None}
            continue
        i0 = int(np.searchsorted(t, t0))
        out[name] = {"from_s": round(t0, 3), "value_then": float(s[name][i0]),
                     "increases": lyapunov_increases(t, s[name], t0, LYAPUNOV_FLOORS[name])}
    return out


def yaw_error(a: float, b: float) -> float:
    """Wrapped difference of two headings [rad]."""
    return wrap_pi(a - b)
