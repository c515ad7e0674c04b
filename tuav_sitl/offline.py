"""The offline runner: plant and controllers in one process, as fast as the machine allows.

It runs the same classes the three processes run: the plant (``sitl``), the onboard
backstepping controllers and mission logic (``companion``), the L-bar estimator and the
winder torque law (``groundstation``), each at its own rate and fed what it would receive in
the field: the companion the vehicle's state and the winch's reported length and tension,
the ground station the encoder (length, drum rate), the load cell, the guide arm's exit
angles, and the UAV's position and velocity as the companion reports them (its estimate,
``LOCAL_POSITION_NED``).
"""

from __future__ import annotations

import bisect
import json
import math
import struct
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
from companion.onboard import Companion, OnboardInputs
from companion.reference import Hold, RefSample, Sequence, SequenceBuilder
from groundstation.tether_fix import TetherFix, TetherFixParams
from groundstation.winch import CommandRequest, Winch, WinchStatusReport
from groundstation.winder_host import WinderHost
from sitl.catenary import CatenaryRegime
from sitl.exit_angle import ExitAngleSensor
from sitl.faults import CanChannel, FaultSchedule
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
    initial_state,
)
from sitl.trim import hover_trim
from tuav_sitl.calibration import CALIBRATED_ACCEL_BIAS_SIGMA_M_S2, accel_calibration
from tuav_sitl.scenario import ScenarioParams
from tuav_sitl.sensor_feed import SensorFeed
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl
from tuavdefs.frames import quat_to_euler, wrap_pi
from tuavdefs.paramspec import ParameterError, to_dict

#: How often a run with the lumped tether records its nodes (``line_t``, ``line_nodes``):
#: the animation's default frame rate [Hz].
LINE_NODES_RATE_HZ = 15.0
#: Tether regimes in which part of the tether lies on the ground.
GROUND_REGIMES = (int(CatenaryRegime.TOUCHDOWN), int(CatenaryRegime.SLACK),
                  int(CatenaryRegime.FLAT))
#: Distance to the goal within which a set-point run counts as settled [m].
SETTLE_BAND_M = 0.05
#: Height above the gear's below which the vehicle counts as on the ground (the metrics'
#: saturation counts in the air only) [m].
GEAR_MARGIN_M = 0.02
#: The time series logged at every control step, in the order of a row: (name, width),
#: width 0 for a scalar.
SERIES: tuple[tuple[str, int], ...] = (
    ("t", 0), ("pos", 3), ("vel", 3), ("ref_pos", 3), ("ref_vel", 3), ("euler", 3),
    ("att_cmd", 3), ("att_des", 3), ("rates", 3), ("thrust", 0), ("torque", 3),
    ("rotor_cmd", 4), ("mixer_sat", 0), ("pos_sat", 0), ("d_hat", 3), ("v_pos", 0),
    ("v_att", 0), ("v_win", 0), ("v_pos_raw", 0), ("v_att_raw", 0), ("length", 0),
    ("lbar", 0), ("lbar_rate", 0), ("lbar_fresh", 0), ("drum_rate", 0),
    ("winder_torque", 0), ("drum_tension", 0), ("top_tension", 0), ("regime", 0),
    ("lowest", 0), ("wind", 3), ("tether_force", 3), ("tether_force_est", 3),
    ("est_pos", 3), ("est_vel", 3), ("est_euler", 3), ("est_pos_sigma", 3))


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


#: The flight controller's diagnostics logged for a control period without flight (on the
#: ground): att_cmd and att_des; thrust and torque; mixer_sat, pos_sat, d_hat, v_pos, v_att.
_GROUND_ATTITUDE = (math.nan,) * 6
_GROUND_WRENCH = (math.nan,) * 4
_GROUND_REST = (0.0, 0.0, math.nan, math.nan, math.nan, math.nan, math.nan)
_NAN3 = (math.nan,) * 3
#: The estimate's columns (est_pos, est_vel, est_euler, est_pos_sigma) without one.
_NO_ESTIMATE = (math.nan,) * 12
_ORIGIN = (0.0, 0.0, 0.0)
_new = tuple.__new__
#: LOCAL_POSITION_NED's six position and velocity fields (float32)
_F32 = struct.Struct("<6f")
#: Revolutions per radian (the encoder's unit)
_REV = 1.0 / (2.0 * math.pi)


class GroundStation:
    """The ground station offline: the winch component the ground-station process runs
    (:class:`groundstation.winch.Winch`: ``DO_WINCH`` modes, brake, L-bar and the torque
    law), fed the CAN frames the plant's winder node would send (the load cell's tension,
    then the axis's encoder estimates) and the vehicle's reported position the component
link brings (:meth:`uav_report`);
    its torque and axis-state frames are read as the plant's axis reads them."""

    def __init__(self, winch: Winch) -> None:
        self.winch = winch
        self._encoder_id = cp.frame_id(winch.node, cp.Cmd.GET_ENCODER_ESTIMATES)
        self._tension_id = cp.frame_id(winch.sensor_node, cp.SensorCmd.WINCH_TENSION)
        self._torque_id = cp.frame_id(winch.node, cp.Cmd.SET_INPUT_TORQUE)
        self._state_id = cp.frame_id(winch.node, cp.Cmd.SET_AXIS_STATE)
        self.torque_n_m = 0.0
        """The last torque asked of the axis [N m]."""
        self.axis_enabled = True
        """Whether the axis is in closed-loop control (False: IDLE, the drum braked)."""
        self.notices: list[tuple[float, str]] = []
        """What the winch said (time [s], text)."""
        self._exit_id = cp.frame_id(winch.sensor_node, cp.SensorCmd.WINCH_EXIT_ANGLE)
        self.fix: TetherFix | None = None
        """The winch's last tether fix not yet taken (ODOMETRY to the vehicle)."""
        #: the vehicle's last LOCAL_POSITION_NED not yet taken: ((position [m], velocity
        #: [m/s]), time_boot_ms), and when the next is due [s]
        self._report: tuple[tuple[tuple[float, ...], tuple[float, ...]], int] | None = None
        self._next_report_s = 0.0

    def uav_report(self, t_s: float, pos_m: tuple[float, float, float],
                   vel_m_s: tuple[float, float, float]) -> None:
        """The vehicle's ``LOCAL_POSITION_NED`` of ``t_s`` [s]: its estimate of position
        [m] and velocity [m/s] (z up), sent at ``component_link.POSITION_RATE_HZ`` of
        simulated time as the companion process sends it; the winch takes it with its next
        winder period (the process reads the component link after the bus), as float32
        fields with the vehicle's time in milliseconds."""
        if t_s < self._next_report_s:
            return
        self._next_report_s = max(self._next_report_s + 1.0 / cl.POSITION_RATE_HZ, t_s)
        f32 = _F32.unpack(_F32.pack(*pos_m, *vel_m_s))
        self._report = ((f32[0:3], f32[3:6]), int(t_s * 1000))

    def period(self, t_s: float, drum_angle_rad: float, drum_rate_rad_s: float,
               drum_tension_n: float,
               exit_angle: tuple[float, float, bool] | None = None
               ) -> WinchStatusReport | None:
        """One winder period at ``t_s`` [s] with the encoder's drum angle [rad] and rate
        [rad/s] (the winch turns them into length with its own drum radius); ``exit_angle``
        the guide arm's reading (azimuth, elevation [rad], valid) when one is due; the
        vehicle's position as it last reported it (:meth:`uav_report`; none before its
        filter has an estimate). Returns the WINCH_STATUS it sends, if any; a tether fix it
        computed waits in :attr:`fix`."""
        w = self.winch
        if self._report is not None:
            w.set_uav(*self._report)
            self._report = None
        stamp = round(t_s * 1000.0) & 0xFFFF
        if exit_angle is not None:
            w.handle_frame(t_s, self._exit_id, cp.encode_winch_exit_angle(
                exit_angle[0], exit_angle[1], stamp, exit_angle[2]))
        w.handle_frame(t_s, self._tension_id,
                       cp.encode_winch_tension(drum_tension_n, not self.axis_enabled, stamp))
        out = w.handle_frame(t_s, self._encoder_id, cp.encode_encoder_estimates(
            drum_angle_rad * _REV, drum_rate_rad_s * _REV))
        if out is None:
            return None
        if out.fix is not None:
            self.fix = out.fix
        for frame in out.frames:
            if frame.arbitration_id == self._torque_id:
                self.torque_n_m = cp.decode_set_input_torque(frame.data)
            elif frame.arbitration_id == self._state_id:
                self.axis_enabled = (cp.decode_set_axis_state(frame.data)
                                     == cp.AxisState.CLOSED_LOOP_CONTROL)
                if not self.axis_enabled:
                    self.torque_n_m = 0.0
        if out.notices:
            self.notices.extend((t_s, n.text) for n in out.notices)
        return out.status

    def command(self, t_s: float, params: tuple[float, float, float, float]) -> int:
        """MAV_CMD_DO_WINCH (instance, action, length [m], rate [m/s]) from the vehicle, as
        the component link brings it; returns the COMMAND_ACK's result."""
        reply = self.winch.command(CommandRequest(
            mavlink2.MAV_CMD_DO_WINCH, cl.SYSTEM_ID, cl.WINCH_COMPONENT_ID, cl.SYSTEM_ID,
            cl.AUTOPILOT_COMPONENT_ID, *params), t_s)
        self.notices.extend((t_s, n.text) for n in reply.notices)
        return reply.result


class MissionError(ParameterError):
    """A scenario's mission (or trajectory) the vehicle refuses, as it would refuse the
    upload: ``field`` names the scenario's mission."""


class OfflineRunner:
    """Plant, onboard software and ground-station logic stepped together.

    The onboard software is :class:`companion.onboard.Companion`, the object the companion
    process steps; a scenario's ground station either uploads its mission and flies it in
    AUTO from the ground, or streams the scenario's trajectory as full set-points in GUIDED
    (:meth:`companion.navigation.Navigator.follow`).
    """

    def __init__(self, scenario: ScenarioParams) -> None:
        sc = self.sc = scenario
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
        fix = TetherFixParams(enabled=sc.estimator.kind != "truth")
        self.ground = GroundStation(Winch(self.winder_host, model.winder, model.tether, g,
                                          sc.winch, fix_params=fix))
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
        self.companion = Companion(model, sc.control, nav_params, estimator,
                                   on_event=self._on_nav_event)
        self.companion.on_start = self._on_start
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
                                   1.0 / sc.control.rate_hz)
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
        # a lossy or slow CAN bus (a "can" fault): a winder period's exchange lost, or the
        # torque it brings applied the round trip (twice the delay) later
        self._can_lost = CanChannel(seed=1)
        self._can_late = CanChannel(seed=2)

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

    def _on_nav_event(self, kind: NavEvent, value: object) -> None:
        self.nav_events.append((kind, value, self._t))
        if kind is NavEvent.WINCH:   # the autopilot sends it to the winch
            seq, params = value
            result = self.ground.command(self._t, params)
            if result != mavlink2.MAV_RESULT_ACCEPTED:
                self.ground.notices.append((self._t, f"Mission: winch refused item {seq} "
                                                     f"({result})"))

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

    def _vehicle_state(self) -> VehicleState:
        """What the companion receives: the truth state (docs/architecture.md)."""
        x = self.plant.x.tolist()
        return VehicleState(tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]), tuple(x[RATES]))

    def run(self, progress: TextIO | None = None,
            on_sample: Callable[[float], None] | None = None) -> RunResult:
        """Run the scenario; returns the time series and metrics. A mission ends when the
        vehicle has landed and disarmed (or at ``duration_s``)."""
        sc, plant = self.sc, self.plant
        companion, ground = self.companion, self.ground
        winch = ground.winch
        nav = companion.nav
        r_w = self.params.winder.drum_radius_m
        dt, n_wind, n_ctrl = self.dt, self.n_wind, self.n_ctrl
        n_steps = round(sc.duration_s / dt)
        n_log = n_steps // n_ctrl + 1
        log = _Log(n_log, SERIES)
        bar = ProgressBar(sc.duration_s, progress)
        # the plant's inputs (PlantInputs' fields), held between control and winder steps
        rotor_commands, armed = PlantInputs().rotor_commands, PlantInputs().armed
        winder_torque, winder_lyap, lbar_m, lbar_rate = 0.0, 0.0, 0.0, 0.0
        winder_enabled = True
        plant_torque, plant_enabled = 0.0, True   # what the axis holds (a late bus)
        g = self.model.environment.gravity_m_s2   # the companion's: WINCH_STATUS is in kg
        mission = sc.flies_mission
        sensors = self.sensors
        faults = bool(sc.faults)
        filt = companion.filter
        was_armed = False
        advance, tether_forces = plant.advance_held, plant.tether_forces
        step = companion.step
        # the log's rows packed here, without a method call per row (_Log.add's work: the
        # loop makes at most n_log rows)
        pack_row, log_buffer, row_bytes = log.pack_into, log.buffer, log.row_bytes
        row_at = 0
        # the lumped tether's nodes (exit to attachment point) at LINE_NODES_RATE_HZ, float32,
        # padded with NaN to the most points the line can have
        lumped = plant.model.lumped
        line_t: list[float] = []
        line_nodes: list[np.ndarray] = []
        line_points = int(plant.model.lp[L_MAXN]) + 2
        next_nodes_t = 0.0
        wall0 = time.perf_counter()
        k = 0
        while True:
            t = k * dt
            fresh = k % n_wind == 0
            if faults and k % n_ctrl == 0:
                self.fault_log += self.faults.apply(t)
            if fresh:
                # ground station: encoder, load cell and the UAV's telemetry
                tf = tether_forces()
                drum_tension = tf.drum_tension_n
                x = plant.x.tolist()
                if faults and self.faults.can_down:
                    # no frame either way: the axis's watchdog disarms it (the drum
                    # brakes), the winch hears nothing and says nothing
                    status = None
                    winder_torque, winder_enabled = 0.0, False
                elif faults and not self._can_lost.keep(self.faults.can):
                    status = None       # this period's frames lost: the axis holds its torque
                else:
                    exit_angle = (self.exit_sensor.read(tf.on_exit_n)
                                  if (k // n_wind) % self._exit_every == 0 else None)
                    status = ground.period(t, x[DRUM_ANGLE], x[DRUM_RATE],
                                           self.load_cell.read(t, drum_tension), exit_angle)
                    fix = ground.fix
                    if fix is not None:     # ODOMETRY reaches the companion
                        ground.fix = None
                        ext = cl.external_position(cl.odometry_message(cl.ExternalPosition(
                            fix.sample_time_ms * 1e-3, fix.pos_m, fix.cov_m2)))
                        if ext is not None:
                            companion.external_position(ext)
                    winder_torque, winder_enabled = ground.torque_n_m, ground.axis_enabled
                    if faults and (self.faults.can.delay_s > 0.0 or self._can_late.pending):
                        self._can_late.hold(t, (winder_torque, winder_enabled))
                        due = self._can_late.due(t, 2.0 * self.faults.can.delay_s)
                        winder_torque, winder_enabled = (due[-1] if due else
                                                         (plant_torque, plant_enabled))
                plant_torque, plant_enabled = winder_torque, winder_enabled
                if faults and self.faults.winder_motor_failed:
                    winder_torque = 0.0
                cmd = winch.last_command
                winder_lyap = cmd.lyapunov if cmd is not None else math.nan
                lbar_m, lbar_rate = winch.reference()
                if status is not None:   # WINCH_STATUS reaches the companion
                    companion.winch_report(
                        t, status.line_length_m, status.speed_m_s, status.tension_kg * g,
                        bool(status.flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED),
                        bool(status.flags & mavlink2.MAV_WINCH_STATUS_HEALTHY))
            if k % n_ctrl == 0:
                x = plant.x.tolist()
                self._t = t
                if t >= self._mission_at_s:   # the script starts the mission in the air
                    self._mission_at_s = math.inf
                    why = nav.start_mission()
                    if why is not None:
                        raise MissionError(f"{sc.name}.mission", f"refused: {why}")
                if self._arm_pending:
                    self._try_arm()
                pos, vel, quat, rates = (tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]),
                                         tuple(x[RATES]))
                # (the records built as the tuples they are, without their Python-level
                # constructors: tuple.__new__)
                if sensors is not None:     # on its estimate: no truth onboard
                    sim = sensors.read(t)
                    out = step(_new(OnboardInputs, (t, None, sim.imu, sim.gps
                                                    if sim.gps_updated else None)),
                               diagnostics=True)
                else:
                    truth = _new(VehicleState, (pos, vel, quat, rates))
                    out = step(_new(OnboardInputs, (t, truth, None, None)), diagnostics=True)
                state, fs, ref = out.state, out.flight, out.reference
                if state is not None:   # LOCAL_POSITION_NED on the component link
                    ground.uav_report(t, state.pos_m, state.vel_m_s)
                rotor_commands, armed = out.rotor_commands, out.armed
                forces = tether_forces()
                info = forces.info
                if fs is not None:
                    po, ao = fs.position, fs.attitude
                    control = (*ao.attitude_cmd_rad, *po.attitude_rad, *rates,
                               po.thrust_n, *ao.torque_n_m, *fs.rotor_commands,
                               fs.mixer_saturated, po.saturated, *po.disturbance_m_s2,
                               po.lyapunov, ao.lyapunov)
                    lyap_raw = (po.lyapunov_raw, ao.lyapunov_raw)
                    est = fs.tether_force_est_n
                else:
                    control = (*_GROUND_ATTITUDE, *rates, *_GROUND_WRENCH,
                               *out.rotor_commands, *_GROUND_REST)
                    lyap_raw, est = (math.nan, math.nan), _NAN3
                ref_pos, ref_vel = ((ref.pos_m, ref.vel_m_s) if ref is not None
                                    else (_NAN3, _NAN3))
                if filt is None or state is None:
                    estimate = _NO_ESTIMATE
                else:
                    estimate = (*state.pos_m, *state.vel_m_s, *quat_to_euler(state.quat),
                                *filt.position_sigma_m())
                pack_row(log_buffer, row_at, t, *pos, *vel, *ref_pos, *ref_vel,
                         *quat_to_euler(quat), *control, winder_lyap, *lyap_raw,
                         r_w * x[DRUM_ANGLE], lbar_m, lbar_rate, fresh, x[DRUM_RATE],
                         winder_torque, forces.drum_tension_n, forces.top_tension_n,
                         int(info.regime), info.lowest_point_height_m, *plant.wind_m_s,
                         *forces.on_uav_n, *est, *estimate)
                row_at += row_bytes
                if lumped and t >= next_nodes_t - 1e-9:
                    next_nodes_t += 1.0 / LINE_NODES_RATE_HZ
                    nodes = plant.line_nodes_m()
                    row = np.full((line_points, 3), np.nan, dtype=np.float32)
                    row[:nodes.shape[0]] = nodes
                    line_t.append(t)
                    line_nodes.append(row)
                if progress is not None:
                    bar.update(t)
                if on_sample is not None:
                    on_sample(t)
                if nav.armed:
                    was_armed = True
                elif mission and was_armed and nav.landed:
                    break   # landed and disarmed: the mission is over
            if k >= n_steps:
                break
            # the plant runs with the inputs held up to the next control or winder step, in
            # one compiled call
            nxt = min(k - k % n_ctrl + n_ctrl, k - k % n_wind + n_wind, n_steps)
            advance(rotor_commands, armed, winder_torque, winder_enabled, nxt - k)
            k = nxt
        wall = time.perf_counter() - wall0
        bar.close()
        log.i = row_at // row_bytes
        series = log.arrays()
        metrics = compute_metrics(sc, series, self.reference, wall)
        if sc.faults:
            metrics["faults"] = self.fault_log
        if line_t:
            series["line_t"] = np.array(line_t)
            series["line_nodes"] = np.stack(line_nodes)
        reached = [(int(v), ts) for kind, v, ts in self.nav_events if kind is NavEvent.REACHED]
        if self._waypoints:
            metrics["waypoints_reached"] = [{"index": seq - 1, "t_s": round(ts, 3)}
                                            for seq, ts in reached]
        if mission:
            metrics["items_reached"] = [seq for seq, _ in reached]
            metrics["items_reached_t_s"] = [round(ts, 3) for _, ts in reached]
            metrics["landed_disarmed"] = bool(was_armed and nav.landed and not nav.armed)
            metrics["arming_refused"] = (str(self.arm_refusal) if self._arm_pending
                                         else None)
        return RunResult(sc, series, metrics, self.nav_events)


class _Log:
    """The time series: rows of :data:`SERIES` packed as doubles as they come into a buffer
    of ``n`` rows allocated up front (later rows are dropped), split into columns at the
    end."""

    def __init__(self, n: int, columns: tuple[tuple[str, int], ...]) -> None:
        self.n = n
        self.i = 0
        self.columns = columns
        self.width = sum(max(w, 1) for _, w in columns)
        packer = struct.Struct(f"{self.width}d")
        #: ``pack_into(buffer, offset, *row)``: a row into :attr:`buffer` at ``offset``
        #: [bytes] (rows :attr:`row_bytes` apart); set :attr:`i` to the rows written
        self.pack_into = packer.pack_into
        self.row_bytes = packer.size
        self._data = np.empty((n, self.width))
        self.buffer = memoryview(self._data).cast("B")

    def add(self, *row: Any) -> None:
        """One row: the columns' values in order, vectors flattened (bools count 0/1)."""
        i = self.i
        if i >= self.n:
            return
        self.pack_into(self.buffer, i * self.row_bytes, *row)
        self.i = i + 1

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns: 1-D arrays for scalars, (rows, width) arrays for vectors."""
        if not self.i:
            return {}
        # one pass over the rows; the columns are views of the result (a vector's
        # (rows, width) view is column-major)
        cols = np.ascontiguousarray(self._data[:self.i].T)
        out: dict[str, np.ndarray] = {}
        j = 0
        for name, w in self.columns:
            out[name] = cols[j] if w == 0 else cols[j:j + w].T
            j += max(w, 1)
        return out


def compute_metrics(sc: ScenarioParams, s: dict[str, np.ndarray],
                    reference: Reference | None, wall_s: float) -> dict[str, Any]:
    """The run's figures of merit (see docs/results.md for their definitions)."""
    t = s["t"]
    # tracking counts while flying a reference (a mission's time on the ground has none)
    flying = np.isfinite(s["ref_pos"]).all(axis=1)
    win = (t >= sc.metrics_after_s) & flying
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
    # saturation counts in the air: a vehicle down on its gear with the rotors at their
    # minimum (landed, the land detector not yet done) is not short of control
    airborne = flying & (s["pos"][:, 2] > sc.plant.vehicle.gear_height_m + GEAR_MARGIN_M)
    m: dict[str, Any] = {
        "scenario": sc.name,
        "position_rmse_m": _rms(pos_err[win]),
        "position_max_error_m": _max(pos_err[win]),
        "attitude_rmse_rad": _rms(att_err[win]),
        "tether_length_rmse_m": _rms(len_err[len_win]),
        "tether_length_max_error_m": _max(np.abs(len_err[len_win])),
        "min_tether_slack_m": float(slack.min()),
        "max_tension_n": float(s["top_tension"].max()),
        "max_drum_tension_n": float(s["drum_tension"].max()),
        "tether_ground_contact_fraction": float(np.isin(s["regime"], GROUND_REGIMES).mean()),
        "motor_saturation_fraction": (float(motor_sat[airborne].mean()) if airborne.any()
                                      else 0.0),
        "position_loop_saturation_fraction": (
            float(s["pos_sat"].astype(bool)[airborne].mean()) if airborne.any() else 0.0),
        "settling_time_s": None,
        "overshoot_percent": None,
        "metrics_after_s": sc.metrics_after_s,
        "sim_time_s": float(t[-1]),
        "wall_time_s": round(wall_s, 3),
        "realtime_factor": round(float(t[-1]) / wall_s, 2) if wall_s > 0 else None,
    }
    m["estimator"] = sc.estimator.kind
    est = np.isfinite(s["est_pos"]).all(axis=1) & (t >= sc.metrics_after_s)
    if est.any():
        denied = any(f.kind == "gnss_loss" and f.start_s <= 0.0 and f.end_s >= sc.duration_s
                     for f in sc.faults)
        m["gnss"] = "none" if denied else sc.sensors.gnss
        e_att_est = s["est_euler"][est] - s["euler"][est]
        e_att_est[:, 2] = (e_att_est[:, 2] + np.pi) % (2 * np.pi) - np.pi
        m["estimate_position_rmse_m"] = _rms(np.linalg.norm(
            s["est_pos"][est] - s["pos"][est], axis=1))
        m["estimate_velocity_rmse_m_s"] = _rms(np.linalg.norm(
            s["est_vel"][est] - s["vel"][est], axis=1))
        m["estimate_attitude_rmse_rad"] = _rms(np.linalg.norm(e_att_est, axis=1))
    loss = np.zeros(len(t), dtype=bool)
    for f in sc.faults:
        if f.kind == "gnss_loss":
            loss |= (t >= f.start_s) & (t < f.end_s)
    if (loss & flying).any():
        # while the GNSS is lost (in flight): the truth off its reference and the estimate
        # off the truth, horizontally
        lf = loss & flying
        m["gnss_loss_horizontal_error_max_m"] = float(np.hypot(
            *(s["pos"][lf, :2] - s["ref_pos"][lf, :2]).T).max())
        lfe = lf & np.isfinite(s["est_pos"]).all(axis=1)
        if lfe.any():
            m["gnss_loss_estimate_horizontal_error_max_m"] = float(np.hypot(
                *(s["est_pos"][lfe, :2] - s["pos"][lfe, :2]).T).max())
    if (reference is not None and sc.trajectory.kind in ("setpoint", "step")
            and reference.goal is not None):
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


def _max(x: np.ndarray) -> float:
    """The largest of ``x``; NaN for none (a run that never flew a reference)."""
    return float(x.max()) if len(x) else float("nan")


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


def above_floor_s(t: np.ndarray, v: np.ndarray, from_s: float, floor: float) -> float:
    """How long after ``from_s`` [s] ``v`` stays above ``floor`` before it first reaches
    it: the span a count of rises above the floor covers (0 if it starts at the floor)."""
    sel = t >= from_s
    tt, vv = t[sel], v[sel]
    if not len(vv) or not vv[0] > floor:
        return 0.0
    below = np.nonzero(~(vv > floor))[0]
    end = tt[below[0]] if len(below) else tt[-1]
    return float(end - tt[0])


#: The Lyapunov functions of the raw (uncompensated) errors, beside the compensated ones.
RAW_LYAPUNOV = {"v_pos": "v_pos_raw", "v_att": "v_att_raw"}


def lyapunov_report(s: dict[str, np.ndarray], position_ref_still_s: float
                    ) -> dict[str, dict[str, Any]]:
    """For each subsystem, from when its reference is constant (docs/control.md §5): its
    Lyapunov function's value then and its floor (:data:`LYAPUNOV_FLOORS`), how long it
    stays above the floor (``above_floor_s``: what the count covers; 0 means the count is
    no evidence), how often it rose above the floor and at all; for the position and
    attitude loops the same of the raw errors' function (``raw_*``).

    Position: the position reference is constant. Attitude: the filtered attitude command
    is still. Winder: L-bar is still.
    """
    t = s["t"]
    starts = {
        "v_pos": position_ref_still_s,
        "v_att": still_from(t, s["att_cmd"], ATTITUDE_REF_STILL_RAD_S),
        "v_win": still_from(t, s["lbar"], LENGTH_REF_STILL_M_S),
    }
    out: dict[str, dict[str, Any]] = {}
    for name, t0 in starts.items():
        floor = LYAPUNOV_FLOORS[name]
        if t0 is not None and t0 >= t[-1]:
            t0 = None   # the run ended before the reference settled
        if t0 is None:
            out[name] = {"from_s": None, "value_then": None, "floor": floor,
                         "above_floor_s": None, "increases": None, "increases_any": None}
            continue
        i0 = int(np.searchsorted(t, t0))
        v = s[name]
        r: dict[str, Any] = {
            "from_s": round(t0, 3), "value_then": float(v[i0]), "floor": floor,
            "above_floor_s": round(above_floor_s(t, v, t0, floor), 3),
            "increases": lyapunov_increases(t, v, t0, floor),
            "increases_any": lyapunov_increases(t, v, t0, 0.0)}
        raw = RAW_LYAPUNOV.get(name)
        if raw is not None:
            vr = s[raw]
            r |= {"raw_value_then": float(vr[i0]),
                  "raw_above_floor_s": round(above_floor_s(t, vr, t0, floor), 3),
                  "raw_increases": lyapunov_increases(t, vr, t0, floor)}
        out[name] = r
    return out


def yaw_error(a: float, b: float) -> float:
    """Wrapped difference of two headings [rad]."""
    return wrap_pi(a - b)
