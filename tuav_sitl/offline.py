"""The offline runner: plant and controllers in one process, as fast as the machine allows.

It runs the same classes the three processes run: the plant (``sitl``), the onboard
backstepping controllers and mission logic (``companion``), the L-bar estimator and the
winder torque law (``groundstation``), each at its own rate and fed what it would receive in
the field: the companion the vehicle's sensors (or its state, flying on the truth) and the
winch's reported length and tension, the ground station the encoder (length, drum rate),
the load cell, the guide arm's exit angles, and the UAV's position and velocity as the
companion reports them (its estimate, ``LOCAL_POSITION_NED``). Each message reaches its
reader as its link carries it, through its bytes or not (:mod:`tuav_sitl.offline_links`).

:meth:`OfflineRunner.run` is the loop of named steps per rate; its rooms:
:mod:`tuav_sitl.offline_ground` (the winch fed its frames), :mod:`tuav_sitl.offline_bus`
(the CAN bus under faults), :mod:`tuav_sitl.offline_links` (the messages' hops),
:mod:`tuav_sitl.offline_log` (the series into preallocated arrays),
:mod:`tuav_sitl.offline_metrics` (the figures of merit).
"""

from __future__ import annotations

import bisect
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from companion.flight_controller import VehicleState
from companion.mission_items import ItemRefused, nav_commands
from companion.navigation import FlightMode, NavCommand, NavEvent, NavKind, Refusal
from companion.onboard import Companion, OnboardInputs, OnboardOutputs
from companion.reference import Hold, RefSample, Sequence, SequenceBuilder
from groundstation.tether_fix import TetherFix, WindSource
from groundstation.winch import Winch
from groundstation.winder_host import WinderHost
from sitl.exit_angle import ExitAngleSensor
from sitl.faults import FaultSchedule
from sitl.load_cell import LoadCell, LoadCellParams
from sitl.lumped import L_MAXN
from sitl.plant import (
    DRUM_ANGLE,
    DRUM_RATE,
    POS,
    QUAT,
    RATES,
    VEL,
    Plant,
    PlantInputs,
    TetherForces,
    initial_state,
)
from sitl.trim import hover_trim
from tuav_sitl.calibration import CALIBRATED_ACCEL_BIAS_SIGMA_M_S2, accel_calibration
from tuav_sitl.offline_bus import WinderBus
from tuav_sitl.offline_ground import GroundStation
from tuav_sitl.offline_links import Links, WireLinks
from tuav_sitl.offline_log import (
    LINE_NODES_RATE_HZ,
    SERIES,
    LineNodesLog,
    SeriesLog,
    TetherFixLog,
    WinderReadout,
)
from tuav_sitl.offline_metrics import GROUND_REGIMES, compute_metrics
from tuav_sitl.scenario import ScenarioParams
from tuav_sitl.sensor_feed import SensorFeed
from tuavdefs import component_link as cl
from tuavdefs.paramspec import ParameterError, to_dict

__all__ = ["GROUND_REGIMES", "LINE_NODES_RATE_HZ", "SERIES", "GroundStation", "MissionError",
           "OfflineRunner", "Reference", "RunResult", "compute_metrics", "run_scenario",
           "write_outputs"]

_ORIGIN = (0.0, 0.0, 0.0)
#: A record built as the tuple it is (tuple.__new__), without its Python-level constructor
_new = tuple.__new__


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
    events: list[tuple[NavEvent, object, float]] = field(default_factory=list)
    """The navigator's events: (kind, value, time [s])."""
    recording: Any = None
    """The job writing the run folder's ``recording.rrd`` in the background
    (:class:`tuav_sitl.view.recording.RecordingJob`; its ``wait()``), if one was asked."""


class Reference:
    """The scenario's trajectory, as the ground station's script streams it to the vehicle
    (the paper's experiments). A ``waypoints`` scenario holds here until ``start_s``, then
    flies its waypoints as a mission (:meth:`OfflineRunner`'s script uploads them)."""

    def __init__(self, sc: ScenarioParams) -> None:
        #: the trajectory segment last sampled, with the times [from, to) it covers
        self._segment: tuple[float, float, Any] = (math.inf, -math.inf, None)
        tr = sc.trajectory
        start = tuple(sc.initial.position_m)
        yaw = sc.initial.yaw_rad
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
        self.traj = b.build()

    def sample(self, t: float, pos: tuple[float, float, float]) -> RefSample:
        """The reference at ``t`` [s] for the vehicle at ``pos`` [m]."""
        lo, hi, segment = self._segment
        if not lo <= t < hi:
            self._segment = lo, hi, segment = _active_segment(self.traj, t)
        return segment.sample(t)


def _active_segment(traj: Any, t: float) -> tuple[float, float, Any]:
    """(from [s], to [s], segment): what ``traj.sample`` samples at ``t`` and the times
    for which it samples the same. A :class:`companion.reference.Sequence` samples its
    segment that started last at or before ``t`` (the first before it starts, the last
    after it ends); anything else is one segment for all times."""
    segments = getattr(traj, "segments", None)
    if not isinstance(traj, Sequence) or not segments:
        return -math.inf, math.inf, traj
    starts = [s.start_s for s in segments]
    i = min(max(bisect.bisect_right(starts, t) - 1, 0), len(segments) - 1)
    lo = starts[i] if i > 0 else -math.inf
    hi = starts[i + 1] if i + 1 < len(starts) else math.inf
    return lo, hi, segments[i]


class MissionError(ParameterError):
    """A scenario's mission (or trajectory) the vehicle refuses, as it would refuse the
    upload: ``field`` names the scenario's mission."""


class OfflineRunner:
    """Plant, onboard software and ground-station logic stepped together.

    The onboard software is :class:`companion.onboard.Companion`, the object the companion
    process steps; a scenario's ground station either uploads its mission and flies it in
    AUTO from the ground, or streams the scenario's trajectory as full set-points in GUIDED
    (:meth:`companion.navigation.Navigator.follow`). ``wire``: every link's message packed
    into its bytes and parsed as the processes do (:mod:`tuav_sitl.offline_links`; the same
    run, slower).
    """

    def __init__(self, scenario: ScenarioParams, wire: bool = False) -> None:
        sc = self.sc = scenario
        #: how the links' messages reach their readers (:mod:`tuav_sitl.offline_links`)
        self.links = WireLinks() if wire else Links()
        # the plant integrates the truth; the controllers are built from their own model
        # (the scenario's [vehicle], [tether], [winder], [environment]), which [plant] may
        # set the truth apart from
        params = self.params = sc.system()
        model = self.model = sc.model()
        g = model.environment.gravity_m_s2
        self.dt = 1.0 / sc.physics_rate_hz
        self.n_ctrl = round(sc.physics_rate_hz / sc.control.rate_hz)
        self.n_wind = round(sc.physics_rate_hz / sc.winder_control.rate_hz)
        self.winder_host = WinderHost(sc.winder_control, sc.lbar, model.winder,
                                      model.tether, g)
        # the winch's tether fix only for a vehicle that fuses it: one flying on the
        # truth drops every fix (Companion.external_position), so it is not computed (it
        # changes nothing else the winch does)
        fix = sc.tether_fix.replace(enabled=sc.tether_fix.enabled
                                    and sc.estimator.kind != "truth")
        self.ground = GroundStation(Winch(self.winder_host, model.winder, model.tether, g,
                                          sc.winch, fix_params=fix), self.links)
        #: whether the winch's fix takes the vehicle's wind (its WIND on the component link)
        self._wind_to_winch = (fix.enabled
                               and WindSource(fix.wind_source) is WindSource.VEHICLE)
        start = tuple(sc.initial.position_m)
        gear = params.vehicle.gear_height_m
        self.plant = Plant(params, dt_s=self.dt)
        if start[2] <= gear:
            # resting on its gear, rotors stopped, the tether lying out to it with a little
            # slack (as the plant process starts on the ground)
            start = (start[0], start[1], gear)
            self.plant.x[:] = initial_state(self.plant.model, start,
                                            tether_length_m=math.dist(start, _ORIGIN) + 0.1)
        else:
            length0, _ = self.winder_host.lbar.length(start)
            x0, _ = hover_trim(params, start, length0, sc.initial.yaw_rad)
            self.plant.x[:] = x0
        self.plant.lay_line()       # a lumped tether laid out to the state just set
        #: the navigator's events: (kind, value, time [s])
        self.nav_events: list[tuple[NavEvent, object, float]] = []
        nav_params = sc.navigation
        tr = sc.trajectory
        if not sc.flies_mission and tr.kind == "waypoints":
            # the paper's multi-position runs: its waypoints, at its speed limits
            nav_params = nav_params.replace(speed_m_s=tr.max_speed_m_s,
                                            acc_m_s2=tr.max_acc_m_s2,
                                            acceptance_radius_m=tr.acceptance_radius_m)
        estimator = sc.estimator
        if estimator.kind == "ekf" and sc.sensors.noise and sc.sensors.accel_calibration:
            # the user calibrated the accelerometer before the flight (on these sensors)
            estimator = estimator.replace(
                accel_offsets_m_s2=accel_calibration(sc.sensors.noise_model(), tuple(sc.home),
                                                     model.environment.gravity_m_s2),
                accel_bias_sigma_m_s2=CALIBRATED_ACCEL_BIAS_SIGMA_M_S2)
        self.companion = Companion(model, sc.control, nav_params, estimator)
        #: the last control period's time [s] (the navigator's events are stamped with it)
        self._t = 0.0
        self.reference: Reference | None = None
        self.home: tuple[float, float, float] = tuple(sc.home)  # type: ignore[assignment]
        #: the mission the script uploads (checked now, as an upload is), and when a
        #: waypoints run starts its mission [s]
        self._mission: list[NavCommand] = []
        self._waypoints = False
        self._mission_at_s = math.inf
        #: the script's arming request, retried every period until the vehicle accepts it
        #: (as a ground station waits for "EKF OK"); the last refusal
        self._arm_pending = False
        self.arm_refusal: Refusal | None = None
        if sc.flies_mission:
            self.home, items = sc.mission_items()
            try:
                self._mission = nav_commands(items, self.home, self.companion.nav)
            except ItemRefused as exc:
                raise MissionError(f"{sc.name}.mission", str(exc)) from None
        elif tr.kind == "waypoints":
            self._mission = self._waypoint_commands()
            self._waypoints = True
        else:
            self.reference = Reference(sc)
        #: the plant's sensors, as the simulator link would deliver them (not needed when
        #: the companion flies on the truth)
        self.sensors = (SensorFeed(self.plant, sc.sensors.noise_model(), self.home,
                                   1.0 / sc.control.rate_hz, wire=wire)
                        if self.companion.filter is not None else None)
        #: the winch's guide-arm encoders (Winch_Exit_Angle every 20 ms, as the plant's
        #: winch node sends it)
        self.exit_sensor = ExitAngleSensor()
        #: the winch's load cell (Winch_Tension, as the plant's winch node reads it; without
        #: its noise for a companion flying on the truth, as the paper's experiments feed
        #: exact measurements: the tension reaches its tether model through WINCH_STATUS)
        self.load_cell = LoadCell(LoadCellParams(noise_n=0.0)
                                  if self.companion.filter is None else None)
        self._exit_every = max(1, round(0.02 * sc.winder_control.rate_hz))
        #: the plant's faults (scenario [[faults]])
        self.faults = FaultSchedule(sc.faults, self.plant,
                                    self.sensors.batches if self.sensors else None)
        #: what began or ended, with its time (metrics.json's "faults")
        self.fault_log: list[str] = []
        #: the winder's CAN bus under the faults: what the axis applies
        self.bus = WinderBus(self.faults if sc.faults else None)
        #: the plant's rotor inputs, held between control periods (rotor commands, armed)
        self._rotors: tuple[tuple[float, ...], bool] = (PlantInputs().rotor_commands,
                                                        PlantInputs().armed)
        #: what the log takes from the last winder period
        self._winder = WinderReadout(0.0, 0.0, 0.0, 0.0)
        self._g = g     # the companion's gravity: WINCH_STATUS is in kg
        #: the tether's forces the winder period solved at the current state (None once
        #: the state moved on): the log's row takes them
        self._tether: TetherForces | None = None
        self._was_armed = False

    def _on_start(self) -> None:
        """The ground station's script, once the vehicle has a state: upload the mission,
        AUTO and arm (a vehicle in the air starts it), or start streaming the trajectory
        (a waypoints run starts its mission at ``trajectory.start_s``)."""
        sc, nav = self.sc, self.companion.nav
        if self._mission:
            nav.set_mission(self._mission)
            if self._waypoints:
                self._mission_at_s = sc.trajectory.start_s
            elif nav.landed:
                why = nav.set_mode(FlightMode.AUTO)
                if why is not None:
                    raise MissionError(f"{sc.name}.mission", f"refused: {why}")
                self._arm_pending = True
                self._try_arm()
            else:
                self._mission_at_s = 0.0
            return
        why = nav.follow(self.reference.sample)
        if why is not None:
            raise MissionError(f"{sc.name}.trajectory",
                               f"the trajectory cannot be flown: {why} (does [initial] "
                               "start on the ground?)")

    def _try_arm(self) -> None:
        """The script's arming request (MAV_CMD_COMPONENT_ARM_DISARM), again."""
        why = self.companion.nav.arm()
        self.arm_refusal = why
        if why is None:
            self._arm_pending = False

    def _waypoint_commands(self) -> list[NavCommand]:
        """A waypoints run's waypoints as mission items (seq from 1), checked as an upload
        checks them."""
        tr, nav = self.sc.trajectory, self.companion.nav
        commands = []
        for seq, w in enumerate(tr.waypoints, start=1):
            why = nav.check_target(w.position_m)
            if why is not None:
                raise MissionError(f"{self.sc.name}.trajectory.waypoints[{seq - 1}]", str(why))
            x, y, z = w.position_m
            commands.append(NavCommand(seq, NavKind.WAYPOINT, (x, y), z, hold_s=tr.hold_s,
                                       accept_m=tr.acceptance_radius_m))
        return commands

    def run(self, progress: TextIO | None = None,
            on_sample: Callable[[float], None] | None = None) -> RunResult:
        """Run the scenario; returns the time series and metrics. A mission ends when the
        vehicle has landed and disarmed (or at ``duration_s``). ``on_sample(t)`` is called
        after each control period."""
        sc, dt, n_ctrl, n_wind = self.sc, self.dt, self.n_ctrl, self.n_wind
        n_steps = round(sc.duration_s / dt)
        self.log = SeriesLog(n_steps // n_ctrl + 1, self.params.winder.drum_radius_m,
                             self.companion.filter)
        self.line_log = (LineNodesLog(sc.duration_s, int(self.plant.model.lp[L_MAXN]) + 2)
                         if self.plant.model.lumped else None)
        self.fix_log = TetherFixLog(sc.duration_s, cl.TETHER_FIX_RATE_HZ)
        self.gnss_log = TetherFixLog(sc.duration_s, sc.sensors.noise_model().gps_rate_hz,
                                     "gnss_fix")
        bar = ProgressBar(sc.duration_s, progress)
        faults, mission = bool(sc.faults), sc.flies_mission
        wall0 = time.perf_counter()
        k = 0
        while True:
            t = k * dt
            control = k % n_ctrl == 0
            if faults and control:
                self.fault_log += self.faults.apply(t)       # faults begin and end
            if k % n_wind == 0:
                self._winder_period(t, k // n_wind)          # winch <-> bus <-> axis
            if control:
                out = self._control_period(t)                # sensors -> onboard step
                self._record(t, out, k % n_wind == 0)        # the log's row
                if progress is not None:
                    bar.update(t)
                if on_sample is not None:
                    on_sample(t)
                if mission and self._mission_over():
                    break
            if k >= n_steps:
                break
            k = self._advance(k, n_steps)                    # physics to the next step due
        wall = time.perf_counter() - wall0
        bar.close()
        return self._result(wall)

    def _winder_period(self, t: float, n: int) -> None:
        """The ground station's winder period ``n`` at ``t`` [s]: over the bus (when it
        carries this exchange) the encoder, the load cell and every 20 ms the guide arm to
        the winch, its torque to the axis; its tether fix (ODOMETRY) and WINCH_STATUS to
        the vehicle."""
        plant, ground, bus, winch = self.plant, self.ground, self.bus, self.ground.winch
        status = None
        # (the tether solved every winder period, the exchange lost or not: its solver
        # starts from its last solution)
        tf = self._tether = plant.tether_forces()
        if bus.exchange():
            x = plant.x.tolist()
            exit_angle = (self.exit_sensor.read(tf.on_exit_n) if n % self._exit_every == 0
                          else None)
            status = ground.period(t, x[DRUM_ANGLE], x[DRUM_RATE],
                                   self.load_cell.read(t, tf.drum_tension_n), exit_angle)
            fix = ground.fix
            if fix is not None:
                ground.fix = None
                self._tether_fix_to_vehicle(fix)
            bus.deliver(t, ground.torque_n_m, ground.axis_enabled)
        bus.settle()
        cmd = winch.last_command
        self._winder = _new(WinderReadout, (cmd.lyapunov if cmd is not None else math.nan,
                                            *winch.reference(), bus.torque_n_m))
        if status is not None:     # WINCH_STATUS reaches the companion
            self.companion.winch_report(
                t, status.line_length_m, status.speed_m_s, status.tension_kg * self._g,
                bool(status.flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED),
                bool(status.flags & mavlink2.MAV_WINCH_STATUS_HEALTHY))
            self._take_events(self._t)

    def _tether_fix_to_vehicle(self, fix: TetherFix) -> None:
        """The winch's tether fix as ODOMETRY to the companion (if it takes it)."""
        ext = self.links.odometry(cl.ExternalPosition(fix.sample_time_ms * 1e-3, fix.pos_m,
                                                      fix.cov_m2))
        winch = self.ground.winch
        reading = winch.sensors.tether_reading(fix, winch.length_m, winch.host.lbar)
        if reading is not None:
            reading = self.links.tether_reading(reading)
        if reading is not None:
            self.companion.tether_reading(reading)
        if ext is not None:
            self.companion.external_position(ext)
            self.fix_log.record(ext.t_s, ext.pos_m, ext.cov_m2)

    def _control_period(self, t: float) -> OnboardOutputs:
        """The control period at ``t`` [s]: the script's requests, the onboard step on what
        the simulator link delivers, LOCAL_POSITION_NED to the winch; the rotor inputs held
        until the next."""
        self._t = t
        if t >= self._mission_at_s or self._arm_pending:
            self._script(t)
        x = self._x = self.plant.x.tolist()
        sensors = self.sensors
        # (the records built as the tuples they are: tuple.__new__)
        if sensors is not None:     # on its estimate: no truth onboard
            sim = sensors.read(t)
            gps = sim.gps if sim.gps_updated else None
            inputs = _new(OnboardInputs, (t, None, sim.imu, gps))
            if gps is not None and gps.fix_type >= 3:    # (the view draws them)
                self.gnss_log.record_sigma(gps.time_usec * 1e-6, gps.position_enu_m,
                                           (gps.eph_m, gps.eph_m, gps.epv_m))
        else:
            inputs = _new(OnboardInputs, (t, _new(VehicleState, (
                tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]), tuple(x[RATES]))), None, None))
        if self.companion.begin(inputs):   # the first state: the script begins
            self._on_start()
        out = self.companion.finish(diagnostics=True)
        self._take_events(t)
        state = out.state
        if state is not None:   # LOCAL_POSITION_NED on the component link, and WIND
            self.ground.uav_report(t, state.pos_m, state.vel_m_s)
            if self._wind_to_winch:
                self.ground.uav_wind(t, self.companion.wind_estimate)
        self._rotors = (out.rotor_commands, out.armed)
        return out

    def _record(self, t: float, out: OnboardOutputs, fresh: bool) -> None:
        """The period's row of the series (and the lumped line's nodes when due)."""
        plant = self.plant
        # (in a winder period the tether was solved at this very state: taken as it is)
        tf = self._tether
        self.log.record(t, self._x, out, fresh, self._winder,
                        tf if tf is not None else plant.tether_forces(), plant.wind_m_s)
        if self.line_log is not None:
            self.line_log.record(t, plant)

    def _advance(self, k: int, n_steps: int) -> int:
        """The plant from physics step ``k`` to the next control or winder step (or the
        end) with its inputs held, in one compiled call; returns that step."""
        n_ctrl, n_wind = self.n_ctrl, self.n_wind
        nxt = min(k - k % n_ctrl + n_ctrl, k - k % n_wind + n_wind, n_steps)
        bus = self.bus
        self._tether = None
        self.plant.advance_held(*self._rotors, bus.torque_n_m, bus.enabled, nxt - k)
        return nxt

    def _mission_over(self) -> bool:
        """Whether the mission has ended: the vehicle landed and disarmed after flying."""
        nav = self.companion.nav
        if nav.armed:
            self._was_armed = True
            return False
        return self._was_armed and nav.landed

    def _take_events(self, t: float) -> None:
        """The navigator's events since the last call, stamped ``t`` [s]; a DO_WINCH item
        goes to the winch as the autopilot forwards it."""
        nav = self.companion.nav
        if not nav.has_events:
            return
        for kind, value in nav.pop_events():
            self.nav_events.append((kind, value, t))
            if kind is NavEvent.WINCH:
                seq, params = value
                result = self.ground.command(t, params)
                if result != mavlink2.MAV_RESULT_ACCEPTED:
                    self.ground.notices.append((t, f"Mission: winch refused item {seq} "
                                                   f"({result})"))

    def _script(self, t: float) -> None:
        """The ground station's script in the control period at ``t`` [s]: a waypoints run
        (or one starting in the air) starts its mission when due; an arming request
        refused is asked again."""
        nav = self.companion.nav
        if t >= self._mission_at_s:
            self._mission_at_s = math.inf
            why = nav.start_mission()
            if why is not None:
                raise MissionError(f"{self.sc.name}.mission", f"refused: {why}")
        if self._arm_pending:
            self._try_arm()

    def _result(self, wall_s: float) -> RunResult:
        """The run's series, metrics and events after ``wall_s`` [s] of wall time."""
        sc, nav = self.sc, self.companion.nav
        series = self.log.arrays()
        metrics = compute_metrics(sc, series, self.reference, wall_s)
        if sc.faults:
            metrics["faults"] = self.fault_log
        if self.line_log is not None:
            series |= self.line_log.arrays()
        series |= self.fix_log.arrays()
        series |= self.gnss_log.arrays()
        reached = [(int(v), ts) for kind, v, ts in self.nav_events if kind is NavEvent.REACHED]
        if self._waypoints:
            metrics["waypoints_reached"] = [{"index": seq - 1, "t_s": round(ts, 3)}
                                            for seq, ts in reached]
        if sc.flies_mission:
            metrics["items_reached"] = [seq for seq, _ in reached]
            metrics["items_reached_t_s"] = [round(ts, 3) for _, ts in reached]
            metrics["landed_disarmed"] = bool(self._was_armed and nav.landed
                                              and not nav.armed)
            metrics["arming_refused"] = (str(self.arm_refusal) if self._arm_pending
                                         else None)
        return RunResult(sc, series, metrics, self.nav_events)


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
                 progress: TextIO | None = sys.stderr, recording: bool = False) -> RunResult:
    """Run ``scenario`` and, if ``out_dir`` is given, write its outputs there; with
    ``recording`` (and rerun-sdk installed) also its ``recording.rrd``, written by a
    background process (``result.recording``)."""
    job = None
    if recording and out_dir is not None:
        from tuav_sitl.view.recording import run_recording_args, start_recording_job

        job = start_recording_job()   # it imports rerun while the run goes on
    try:
        result = OfflineRunner(scenario).run(progress=progress)
        if out_dir is not None:
            write_outputs(result, out_dir)
    except BaseException:
        if job is not None:
            job.cancel()
        raise
    if job is not None:
        job.write(*run_recording_args(result, out_dir))
        result.recording = job
    return result
