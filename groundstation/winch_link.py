"""The winch component's end of the companion's component link (a TCP client).

In: the UAV's ``LOCAL_POSITION_NED`` and wind estimate (``WIND_COV``), and
``COMMAND_LONG``/``COMMAND_INT`` (the companion forwards ground stations' commands as they
were sent, so their sender ids are the ground station's). Out, as system 1 component 169:
``HEARTBEAT`` (1 Hz of wall time, from :meth:`WinchLinkClient.poll`), ``WINCH_STATUS``,
the tether fix as ``ODOMETRY``, ``COMMAND_ACK`` and ``STATUSTEXT``. The client connects,
and reconnects after a drop, on its own; sends while unconnected are lost.
With a signing key (given at start, or by the vehicle's ``SETUP_SIGNING`` from component 1)
everything sent is signed and only correctly signed frames are taken (``tuavdefs.signing``).
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch import TEMPERATURE_UNKNOWN, CommandRequest
from tuavdefs import component_link as cl
from tuavdefs import signing as sg
from tuavdefs.frames import ned_to_enu
from tuavdefs.simlink import frame_codecs, whole_frames

Vec3 = tuple[float, float, float]

_POSITION = mavlink2.MAVLink_local_position_ned_message
_POSITION_CODECS = frame_codecs(_POSITION)


def local_positions(data: bytes) -> list[tuple] | None:
    """The ``LOCAL_POSITION_NED`` fields (time_boot_ms, x, y, z, vx, vy, vz) of each frame
    of ``data`` when it holds nothing but whole, unsigned MAVLink 2 frames of that message
    with good checksums: what pymavlink's parser, holding no partial frame, decodes from
    it. None for anything else (then pymavlink parses it)."""
    frames = whole_frames(data, _POSITION_CODECS)
    return None if frames is None else [values for _, values in frames]


class WinchLinkClient:
    """Receives the UAV's position and velocity and commands; sends WINCH_STATUS,
    COMMAND_ACK, STATUSTEXT and heartbeats."""

    def __init__(self, address: str, connect_timeout_s: float = 30.0,
                 signing_key: bytes | None = None,
                 log: Callable[[str], None] | None = None) -> None:
        host, _, port = address.rpartition(":")
        self.mav = cl.new_mavlink(cl.WINCH_COMPONENT_ID)
        sg.set_key(self.mav.signing, signing_key)
        self.log = log or (lambda text: print(f"groundstation: {text}", flush=True))
        self.sock: socket.socket | None = None
        self._addr = (host, int(port))
        self._deadline = time.monotonic() + connect_timeout_s
        self._state: tuple[Vec3, Vec3] | None = None
        self._state_ms: int | None = None
        self.positions_received = 0
        """LOCAL_POSITION_NED messages received (the state is new when this changes)."""
        self._wind: Vec3 | None = None
        self.winds_received = 0
        """WIND_COV messages received (:meth:`uav_wind` is new when this changes)."""
        self._last_heartbeat = 0.0
        self._commands: list[CommandRequest] = []
        self.bad_frames = 0
        self._refused_said = 0
        self._held = False          # (hold: what is sent waits in _out until flush)
        self._out = bytearray()

    def _connect(self) -> bool:
        if self.sock is not None:
            return True
        try:
            s = socket.create_connection(self._addr, timeout=0.2)
        except OSError:
            return False
        s.setblocking(False)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = s
        return True

    def poll(self) -> None:
        """Read what has arrived (non-blocking); connects (and reconnects) as needed."""
        if not self._connect():
            return
        assert self.sock is not None
        # no poll first: the process calls this about once per position received, so the
        # read mostly finds data, and a poll would be a second system call
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            data = None
        except OSError:
            data = b""
        if data == b"":
            self.close()
            return
        if data:
            self._receive(data)
        now = time.monotonic()
        if now - self._last_heartbeat >= 1.0:
            self._last_heartbeat = now
            signing = self.mav.signing
            sg.refresh_timestamp(signing)
            if signing.reject_count != self._refused_said:
                self.log(f"{signing.reject_count - self._refused_said} unsigned or badly "
                         "signed frames dropped on the component link")
                self._refused_said = signing.reject_count
            self._send(self.mav.heartbeat_encode(
                mavlink2.MAV_TYPE_WINCH, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
                mavlink2.MAV_STATE_ACTIVE))

    def _receive(self, data: bytes) -> None:
        mav = self.mav
        if mav.buf_len() == 0 and mav.signing.secret_key is None:
            # the usual read: LOCAL_POSITION_NED frames only, parsed here
            positions = local_positions(data)
            if positions is not None:
                self._set_state(*positions[-1])
                self.positions_received += len(positions)
                mav.total_bytes_received += len(data)
                mav.total_packets_received += len(positions)
                return
        chunk = data
        while True:     # parse_buffer, one message at a time: SETUP_SIGNING applies at once
            try:
                m = mav.parse_char(chunk)
            except mavlink2.MAVError:
                self.bad_frames += 1
                m = None
            if m is None:
                break
            chunk = b""
            kind = m.get_type()
            if kind == "LOCAL_POSITION_NED":
                self._set_state(m.time_boot_ms, m.x, m.y, m.z, m.vx, m.vy, m.vz)
                self.positions_received += 1
            elif kind == "WIND_COV":
                wind = cl.wind_of(m)
                if all(math.isfinite(v) for v in wind):
                    self._wind = wind
                    self.winds_received += 1
            elif kind in ("COMMAND_LONG", "COMMAND_INT"):
                self._commands.append(CommandRequest(
                    m.command, m.target_system, m.target_component, m.get_srcSystem(),
                    m.get_srcComponent(), m.param1, m.param2, m.param3, m.param4,
                    m.confirmation if kind == "COMMAND_LONG" else 0))
            elif kind == "SETUP_SIGNING":
                self._setup_signing(m)

    def _setup_signing(self, m: mavlink2.MAVLink_setup_signing_message) -> None:
        """The vehicle's new key, from its autopilot (component 1) alone: the frames
        after it are on the new key."""
        if (m.get_srcComponent() != cl.AUTOPILOT_COMPONENT_ID
                or m.target_component not in (0, cl.WINCH_COMPONENT_ID)):
            return
        key = bytes(m.secret_key)
        off = sg.is_disable(key, m.initial_timestamp)
        sg.set_key(self.mav.signing, None if off else key, m.initial_timestamp)
        self.log("MAVLink signing off" if off else "MAVLink signing key set by the vehicle")

    def _set_state(self, time_boot_ms: int, x: float, y: float, z: float, vx: float,
                   vy: float, vz: float) -> None:
        """The UAV's state from LOCAL_POSITION_NED's fields (NED [m], [m/s]; [ms])."""
        self._state = (ned_to_enu((x, y, z)), ned_to_enu((vx, vy, vz)))
        self._state_ms = int(time_boot_ms)

    def uav_state_time_ms(self) -> int | None:
        """The vehicle's time [ms] (time_boot_ms: simulated time) of :meth:`uav_state`."""
        return self._state_ms

    def uav_wind(self) -> Vec3 | None:
        """The vehicle's latest wind estimate [m/s], z-up (its WIND_COV), or None."""
        return self._wind

    def uav_state(self) -> tuple[Vec3, Vec3] | None:
        """The latest (position [m], velocity [m/s]) of the UAV, z-up frame, or None."""
        return self._state

    @property
    def commands_waiting(self) -> bool:
        """Whether :meth:`take_commands` has something to hand out."""
        return bool(self._commands)

    def take_commands(self) -> list[CommandRequest]:
        """The COMMAND_LONG/COMMAND_INT messages received since the last call (any target:
        :meth:`groundstation.winch.Winch.command` decides which are for the winch)."""
        commands, self._commands = self._commands, []
        return commands

    def winch_status(self, length_m: float, speed_m_s: float, tension_kg: float,
                     brake_engaged: bool, *, flags: int | None = None,
                     voltage_v: float = float("nan"), current_a: float = float("nan"),
                     temperature_c: int = TEMPERATURE_UNKNOWN) -> None:
        """Send WINCH_STATUS: length [m], speed [m/s, + paying out], tension [kg, as the
        message defines], bus voltage [V] and current [A] (NaN unknown), temperature [degC]
        (INT16_MAX unknown); ``flags`` the MAV_WINCH_STATUS_FLAG bits (default: healthy,
        moving above 1 cm/s, clutch engaged = brake)."""
        if flags is None:
            flags = cl.winch_status_flags(brake_engaged, abs(speed_m_s) > 0.01)
        self._send(self.mav.winch_status_encode(
            int(time.monotonic() * 1e6), length_m, speed_m_s, tension_kg,
            voltage_v, current_a, temperature_c, flags))

    def tether_fix(self, t_s: float, pos_m: Vec3,
                   cov_m2: tuple[tuple[float, float, float], ...]) -> None:
        """Send the tether fix as ODOMETRY: its time on the vehicle's clock [s], position
        [m] and covariance [m^2] (z-up frame, origin at the winder)."""
        self._send(cl.odometry_message(cl.ExternalPosition(t_s, pos_m, cov_m2)))

    def tether_reading(self, reading: cl.TetherReading) -> None:
        """Send the raw reading a tether fix was made of as ``DEBUG_FLOAT_ARRAY`` "TETHER"
        (:func:`tuavdefs.component_link.tether_reading_message`)."""
        self._send(cl.tether_reading_message(reading))

    def command_ack(self, command: int, result: int, target_system: int,
                    target_component: int) -> None:
        """Send COMMAND_ACK (``result`` a MAV_RESULT) to the command's sender."""
        self._send(self.mav.command_ack_encode(command, result, 0, 0, target_system,
                                               target_component))

    def statustext(self, severity: int, text: str) -> None:
        """Send STATUSTEXT (``severity`` a MAV_SEVERITY; text cut to 50 characters)."""
        self._send(self.mav.statustext_encode(severity, text.encode()[:50]))

    def hold(self) -> None:
        """Keep what is sent from here on until :meth:`flush`: one write for the messages
        of one turn of the process's loop (a winder cycle's ODOMETRY and WINCH_STATUS),
        which wakes the vehicle once instead of once per message. The bytes are the same,
        in the same order."""
        self._held = True

    def flush(self) -> None:
        """Write what :meth:`hold` kept, in one write, and send at once again."""
        self._held = False
        if self._out:
            data = bytes(self._out)
            self._out.clear()
            self._write(data)

    def _send(self, msg: mavlink2.MAVLink_message) -> None:
        if self.sock is None:
            return
        data = msg.pack(self.mav)
        if self._held:
            self._out += data
        else:
            self._write(data)

    def _write(self, data: bytes) -> None:
        if self.sock is None:
            return
        try:
            self.sock.sendall(data)
        except (BlockingIOError, OSError):
            self.close()

    def close(self) -> None:
        """Close the connection (anything held is dropped with it)."""
        self._out.clear()
        if self.sock is not None:
            self.sock.close()
            self.sock = None
