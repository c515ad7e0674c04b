"""The ground station offline: the winch component fed what its CAN bus and component link
would bring it (:class:`GroundStation`)."""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.tether_fix import TetherFix
from groundstation.winch import CommandRequest, Winch, WinchStatusReport
from tuav_sitl.offline_links import Links
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl

#: Revolutions per radian (the encoder's unit)
_REV = 1.0 / (2.0 * math.pi)


class GroundStation:
    """The ground station offline: the winch component the ground-station process runs
    (:class:`groundstation.winch.Winch`: ``DO_WINCH`` modes, brake, L-bar and the torque
    law), fed the CAN frames the plant's winder node would send (the load cell's tension,
    then the axis's encoder estimates) and the vehicle's reported position the component
    link brings (:meth:`uav_report`); its torque and axis-state frames are read as the
    plant's axis reads them. The winch's only entry is the bus's frames, so they are
    framed here in both of the runner's link modes (:mod:`tuav_sitl.offline_links`)."""

    def __init__(self, winch: Winch, links: Links) -> None:
        self.winch = winch
        #: how the component link's messages reach the winch
        self.links = links
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
        #: the vehicle's last WIND not yet taken [m/s], and when the next is due [s]
        self._wind: tuple[float, float, float] | None = None
        self._next_wind_s = 0.0

    def uav_report(self, t_s: float, pos_m: tuple[float, float, float],
                   vel_m_s: tuple[float, float, float]) -> None:
        """The vehicle's ``LOCAL_POSITION_NED`` of ``t_s`` [s]: its estimate of position
        [m] and velocity [m/s] (z up), sent at ``component_link.POSITION_RATE_HZ`` of
        simulated time as the companion process sends it, carried as the link carries it
        (:meth:`tuav_sitl.offline_links.Links.local_position`: float32 fields, the vehicle's
        time in milliseconds); the winch takes it with its next winder period (the process
        reads the component link after the bus)."""
        if t_s < self._next_report_s:
            return
        self._next_report_s = max(self._next_report_s + 1.0 / cl.POSITION_RATE_HZ, t_s)
        self._report = self.links.local_position(t_s, pos_m, vel_m_s)

    def uav_wind(self, t_s: float, estimate: Callable[[], tuple[float, float, float]]
                 ) -> None:
        """The vehicle's ``WIND`` at ``t_s`` [s] when one is due (at
        ``component_link.WIND_RATE_HZ`` of simulated time, as the companion process sends
        it): ``estimate()``, its wind estimate [m/s] (z-up), asked only then; the winch
        takes it with its next winder period, after the position."""
        if t_s < self._next_wind_s:
            return
        self._next_wind_s = max(self._next_wind_s + 1.0 / cl.WIND_RATE_HZ, t_s)
        self._wind = estimate()

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
        if self._wind is not None:
            w.sensors.set_wind(self._wind, w.uav, w.uav_time_ms)
            self._wind = None
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

