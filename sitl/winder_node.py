"""The plant's end of the winder's CAN bus: the simulated ODrive axis and winch sensors.

Every control period the plant process hands the node the frames the bus delivered
(:meth:`WinderCanNode.service`), lets the axis and the sensors emit what is due for the
current simulated time, and reads back the motor's state for the drum: powered or braked,
and the torque it is asked for. A host's answer to an encoder frame applies from the next
control period on, in lockstep as in real time (:meth:`WinderCanNode.inputs`). The plant
applies the torque limits' cut-back near the velocity limit itself
(``sitl.kernel.motor_torque``).

CAN faults (:attr:`WinderCanNode.can`, from :mod:`sitl.faults`): each frame, either way, is
lost with the drop probability (all of them when the bus is down) and, kept, reaches the
other end the delay later in simulated time (frames from the host are handed to the axis
then; frames to the host go out then). In lockstep a host's answer that is lost or delayed
still ends the wait for it (the wait only paces the wall clock).
"""

from __future__ import annotations

import math
import time

from sitl.exit_angle import ExitAngleSensor
from sitl.faults import CanChannel, CanFaults
from sitl.load_cell import LoadCell
from sitl.odrive_axis import OdriveAxis, WinchSensors
from sitl.plant import Plant
from sitl.spin import SpinWait
from tuavdefs.can_protocol import (
    AXIS_NODE_ID_DEFAULT,
    WINCH_SENSOR_NODE_ID_DEFAULT,
    Cmd,
    frame_id,
    split_id,
)
from tuavdefs.canbus import CanLink, RxFrame

#: Commands only a host sends: an answer to the encoder frame is one of these.
_HOST_COMMANDS = frozenset({Cmd.SET_INPUT_TORQUE, Cmd.SET_AXIS_STATE, Cmd.SET_CONTROLLER_MODE,
                            Cmd.SET_LIMITS, Cmd.CLEAR_ERRORS, Cmd.ESTOP})

#: DC bus voltage of the winder's drive [V] (a 48 V tether power supply's low side).
BUS_VOLTAGE_V = 48.0
_TWO_PI = 2.0 * math.pi


class WinderCanNode:
    """Axis + sensors on a bus, stepped with the plant's simulated time. In lockstep
    (``lockstep``) a host's answer is awaited for at most ``answer_timeout_s`` [s] of wall
    time, spinning for the first ``spin_s`` [s] of it (:mod:`sitl.spin`; 0: sleeping)."""

    def __init__(self, link: CanLink, plant: Plant, axis_node_id: int = AXIS_NODE_ID_DEFAULT,
                 sensor_node_id: int = WINCH_SENSOR_NODE_ID_DEFAULT,
                 watchdog_timeout_s: float = 0.1, lockstep: bool = False,
                 answer_timeout_s: float = 0.25, spin_s: float = 0.0) -> None:
        self.link = link
        self.lockstep = lockstep
        self.answer_timeout_s = answer_timeout_s
        #: How long a wait for the host's answer spins before it sleeps [s] (0: never).
        self.spin = SpinWait(spin_s if link.pollable else 0.0)
        self.host_seen = False
        self.late_answers = 0
        self._awaiting = False
        self._encoder_t = -math.inf      # when the last encoder frame was sent [s]
        self.plant = plant
        w = plant.params.winder
        self.axis = OdriveAxis(axis_node_id, watchdog_timeout_s=watchdog_timeout_s,
                               torque_limit_nm=w.motor_torque_limit_n_m,
                               vel_limit_rev_s=w.motor_speed_limit_rad_s / _TWO_PI)
        self.sensors = WinchSensors(sensor_node_id)
        #: the guide arm's encoders at the fairlead (Winch_Exit_Angle)
        self.exit_sensor = ExitAngleSensor()
        #: the load cell at the fairlead (Winch_Tension)
        self.load_cell = LoadCell()
        self.frames_received = 0
        self.frames_sent = 0
        #: The bus's faults now (sitl.faults: lost frames, delayed frames).
        self.can = CanFaults()
        #: Frames lost to them, both ways.
        self.frames_lost = 0
        self._rx = CanChannel(seed=1)      # host -> node
        self._tx = CanChannel(seed=2)      # node -> host
        self._encoder_id = frame_id(axis_node_id, Cmd.GET_ENCODER_ESTIMATES)
        self._drum_radius = w.drum_radius_m
        wm = plant.model.winder
        self._motor_torque = wm.motor_torque_n_m
        self._theta_min = wm.theta_min + 1e-9   # at the full stop at or below [rad]
        self._theta_max = wm.theta_max - 1e-9   # at the empty stop at or above [rad]

    @property
    def bus_down(self) -> bool:
        """Whether the bus carries nothing now (a CAN-loss fault)."""
        return self.can.down

    def service(self, t_s: float) -> None:
        """Feed every frame the bus holds (and the delayed ones now due) to the axis, and
        send its replies; under :attr:`can` frames are lost or held."""
        while True:
            rx = self.link.recv(timeout_s=0.0)
            if rx is None:
                break
            self._arrive(t_s, rx)
        if self._rx.pending:
            for rx in self._rx.due(t_s, self.can.delay_s):
                self._receive(t_s, rx)
        if self._tx.pending:
            for frames in self._tx.due(t_s, self.can.delay_s):
                self._transmit(t_s, frames)

    def _arrive(self, t_s: float, rx: RxFrame) -> None:
        """A frame off the bus at ``t_s`` [s]: lost, held (delayed) or handled now."""
        faults = self.can
        if faults.drop_probability > 0.0 and not self._rx.keep(faults):
            self.frames_lost += 1
            if self._is_host_command(rx):
                self._awaiting = False   # (lost: no answer is coming to wait for)
            return
        if faults.delay_s > 0.0 or self._rx.pending:
            if self._is_host_command(rx):
                self.host_seen = True
                self._awaiting = False
            self._rx.hold(t_s, rx)
            return
        self._receive(t_s, rx)

    def _is_host_command(self, rx: RxFrame) -> bool:
        fid = rx.arbitration_id
        if rx.is_extended or not 0 <= fid <= 0x7FF or rx.is_remote:
            return False
        node, cmd = split_id(fid)
        return node == self.axis.node_id and cmd in _HOST_COMMANDS

    def _receive(self, t_s: float, rx: RxFrame) -> None:
        self.frames_received += 1
        fid = rx.arbitration_id
        if rx.is_extended or not 0 <= fid <= 0x7FF:
            # a 29-bit frame of another protocol on the same bus: not CAN Simple, and not
            # for this node (the axis counts nothing either)
            return
        if self._is_host_command(rx):
            self.host_seen = True
            self._awaiting = False
        self._send(t_s, self.axis.handle(t_s, rx.arbitration_id, rx.data, rx.is_remote,
                                         rx.is_extended))

    def await_host(self, t_s: float) -> None:
        """In lockstep, once a host has shown itself, wait (at most ``answer_timeout_s`` of
        wall time) for its answer to the last encoder frame sent, if it has not come yet;
        ``t_s`` [s] is the simulated time it is received at."""
        if self.bus_down:
            self._awaiting = False
        if not (self.lockstep and self.host_seen and self._awaiting):
            return
        end = time.monotonic() + self.answer_timeout_s
        while self._awaiting:
            if self.spin.budget_s > 0.0:
                # usually tens of microseconds away: awake, the ground station's send
                # need not wake this process (sitl/spin.py)
                self.spin.until(self.link.readable)
            rx = self.link.recv(timeout_s=max(end - time.monotonic(), 0.0))
            if rx is None:
                self.late_answers += 1
                self._awaiting = False
                return
            self._arrive(t_s, rx)

    def tick(self, t_s: float) -> None:
        """Emit the cyclic frames due at ``t_s`` [s]; the plant takes its inputs for the
        physics from :meth:`inputs`.

        It waits for a host only to keep one encoder frame unanswered at a time (at
        control rates above the encoder's 100 Hz, never: :meth:`inputs` has waited
        already)."""
        p = self.plant
        axis = self.axis
        length = p.tether_length_m
        theta = length / self._drum_radius
        omega = p.drum_rate_rad_s
        enabled = axis.enabled
        applied = self._motor_torque(axis.torque_command_nm, omega, enabled)
        frames = axis.tick(t_s, theta / _TWO_PI, omega / _TWO_PI, applied, BUS_VOLTAGE_V)
        # solved every period, not only when the sensors send: each solve starts from the
        # last one's solution, and the tensions sent must not depend on when it last ran
        tf = p.tether_forces()
        sensor_frames: list = []
        if self.sensors.due(t_s):
            # the winch's sensor frames of this instant go first: a host answering the
            # encoder frame at once then knows the tension and the sample time that go
            # with it
            enabled = axis.enabled      # after the tick, which may have disarmed the axis
            sensor_frames = self.sensors.tick(
                t_s, length, omega * self._drum_radius,
                self.load_cell.read(t_s, tf.drum_tension_n), not enabled,
                theta <= self._theta_min, theta >= self._theta_max)
        if self.sensors.exit_angle_due(t_s):
            az, el, valid = self.exit_sensor.read(tf.on_exit_n)
            sensor_frames.append(self.sensors.exit_angle_frame(t_s, az, el, valid))
        if sensor_frames:
            frames = sensor_frames + frames if frames else sensor_frames
        if frames:
            # every frame of the instant built first, then sent back to back: a host
            # tends to find them together, and wakes once
            self._send(t_s, frames)

    def inputs(self, t_s: float) -> tuple[float, bool]:
        """(torque request [N m], motor powered) for the plant's physics from ``t_s`` [s] on.

        In lockstep it first waits for the host's answer to an encoder frame sent at an
        earlier period (:meth:`await_host`; one sent at ``t_s`` itself is answered for the
        next period): the torque a host computes from the drum's state at one control
        period applies from the next, whatever the host's speed. That is the timing of real
        time, where the answer arrives during the period and the plant reads it just
        before the next one's physics; lockstep keeps it exactly, and the ground station
        computes while the plant and the companion go on."""
        if self._awaiting and self._encoder_t < t_s:
            self.await_host(t_s)
        return self.axis.torque_command_nm, self.axis.enabled

    def _send(self, t_s: float, frames: list) -> None:
        """Frames for the bus at ``t_s`` [s], under :attr:`can`."""
        if not frames:
            return
        faults = self.can
        if faults.drop_probability > 0.0:
            kept = [f for f in frames if self._tx.keep(faults)]
            self.frames_lost += len(frames) - len(kept)
            frames = kept
            if not frames:
                return
        if faults.delay_s > 0.0 or self._tx.pending:
            self._tx.hold(t_s, frames)
            return
        self._transmit(t_s, frames)

    def _transmit(self, t_s: float, frames: list) -> None:
        """Frames onto the bus now; an encoder frame among them awaits its answer."""
        for f in frames:
            if f.arbitration_id == self._encoder_id and not f.is_remote:
                self.await_host(t_s)     # (the one before, if still unanswered)
                self._awaiting = True
                self._encoder_t = t_s
        self.frames_sent += self.link.send_frames(frames)
