"""The companion's end of the simulator link (PX4 simulator MAVLink API over TCP or a
Unix-domain socket).

Pure I/O: :class:`SimLinkClient` connects to the plant (127.0.0.1:4560 by default),
returns each step's sensor batch as a :class:`SimState` in the project frames (inertial ENU
z-up, body FLU; conversions by :mod:`tuavdefs.simlink`) and sends the rotor commands that
answer it. A step's batch is HIL_GPS (10 Hz), HIL_STATE_QUATERNION (truth) and HIL_SENSOR,
which closes it; the answer must echo HIL_SENSOR's ``time_usec`` (:attr:`SimState.time_usec`)
for the plant's lockstep to advance.
"""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Sequence
from typing import Any, NamedTuple

from tuavdefs import simlink as sl
from tuavdefs.frames import Quat, Vec3

#: Longest a send may block (the plant not reading) before the link counts as failed [s].
_SEND_TIMEOUT_S = 5.0
_SENSOR = sl.MSG_HIL_SENSOR
_TRUTH = sl.MSG_HIL_STATE_QUATERNION
_new = tuple.__new__


class TruthState(NamedTuple):
    """The plant's truth from HIL_STATE_QUATERNION, in project frames.

    ``position_enu_m`` [m] (resolution ~1 cm horizontally, 1 mm vertically),
    ``velocity_enu_m_s`` [m/s] (1 cm/s), ``quaternion`` (w, x, y, z) body FLU -> ENU,
    ``body_rates_flu_rad_s`` [rad/s], ``specific_force_flu_m_s2`` [m/s^2] (1 mG),
    ``true_airspeed_m_s``/``ind_airspeed_m_s`` [m/s] (1 cm/s).
    """

    time_usec: int
    position_enu_m: Vec3
    velocity_enu_m_s: Vec3
    quaternion: Quat
    body_rates_flu_rad_s: Vec3
    specific_force_flu_m_s2: Vec3
    true_airspeed_m_s: float
    ind_airspeed_m_s: float


class ImuSample(NamedTuple):
    """HIL_SENSOR in project frames: specific force [m/s^2], rates [rad/s], magnetic field
    [gauss] in body FLU; static pressure [hPa]; pressure altitude [m AMSL]; temperature
    [degC]; ``fields_updated`` bits as sent."""

    time_usec: int
    accel_flu_m_s2: Vec3
    gyro_flu_rad_s: Vec3
    mag_flu_gauss: Vec3
    abs_pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float
    fields_updated: int


class GpsFix(NamedTuple):
    """HIL_GPS in project frames: position [m] and velocity [m/s] in the inertial ENU frame
    (from lat/lon/alt and the home), the raw latitude/longitude [deg] and altitude [m
    AMSL], claimed accuracies eph/epv [m], fix type and satellites."""

    time_usec: int
    position_enu_m: Vec3
    velocity_enu_m_s: Vec3
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    eph_m: float
    epv_m: float
    fix_type: int
    satellites_visible: int


class SimState(NamedTuple):
    """One step's batch. ``time_usec`` is the HIL_SENSOR time to echo in the answer;
    ``sim_time_s`` the same in seconds; ``truth`` the latest HIL_STATE_QUATERNION (None if
    none came yet); ``imu`` this step's HIL_SENSOR; ``gps`` the latest HIL_GPS (None if none
    came yet), ``gps_updated`` whether it arrived in this batch."""

    time_usec: int
    sim_time_s: float
    truth: TruthState | None
    imu: ImuSample
    gps: GpsFix | None
    gps_updated: bool


class BatchDecoder:
    """The simulator link's batches decoded, without a socket: the plant's bytes in, one
    :class:`SimState` per HIL_SENSOR out (the client decodes its socket's bytes with one;
    the offline runner feeds one the plant's batches). ``home`` as for
    :class:`SimLinkClient`; ``truth`` whether HIL_STATE_QUATERNION, the simulator's own
    state, is decoded: a vehicle flying on its estimate takes none (``SimState.truth``
    None), as a real one has none to take."""

    def __init__(self, home: tuple[float, float, float] = sl.HOME_DEFAULT,
                 truth: bool = True) -> None:
        self._home_map = sl.home_map(tuple(float(v) for v in home))
        self._decode_truth = truth
        self._parser = sl.FrameParser()
        self._truth: TruthState | None = None
        self._gps: GpsFix | None = None
        self._gps_new = False
        #: The simulator's run-time parameters as the plant last said them (PARAM_VALUE:
        #: name -> value; tuavdefs.sim_params). Never an input to control.
        self.sim_params: dict[str, float] = {}

    @property
    def bad_frames(self) -> int:
        """Malformed frames dropped."""
        return self._parser.bad_frames

    def parse(self, data: bytes) -> list[tuple[int, tuple]]:
        """The link messages in ``data``: (message id, values in wire order)."""
        # the usual case, whole well-formed frames, skips the message objects
        items = self._parser.feed_link(data)
        if items is None:
            items = [v for v in map(sl.link_values, self._parser.feed(data)) if v is not None]
        return items

    def absorb(self, item: tuple[int, tuple]) -> SimState | None:
        """Take one message; the step's :class:`SimState` when it is the HIL_SENSOR."""
        mid, v = item
        if mid == _SENSOR:
            return self.sensor_state(v)
        if mid == _TRUTH:
            if self._decode_truth:
                self._truth = _new(TruthState,
                                   (int(v[0]), *sl.truth_from_wire(v, self._home_map)))
        elif mid == sl.MSG_HIL_GPS:
            pos, vel, eph, epv = sl.gps_from_wire(v, self._home_map)
            self._gps = GpsFix(int(v[0]), pos, vel, v[1] * 1e-7, v[2] * 1e-7, v[3] * 1e-3,
                               eph, epv, int(v[11]), int(v[12]))
            self._gps_new = True
        elif mid == sl.MSG_PARAM_VALUE:
            name, value = v
            self.sim_params[name] = value
        return None

    def sensor_state(self, v: Sequence[Any]) -> SimState:
        """Take a HIL_SENSOR, its field values ``v`` in wire order: the step's
        :class:`SimState` (with the latest truth and fix)."""
        # the records are built as the tuples they are (tuple.__new__), without their
        # Python-level constructors
        t = int(v[0])
        state = _new(SimState, (t, t * 1e-6, self._truth,
                                _new(ImuSample, (t, *sl.imu_from_wire(v), int(v[14]))),
                                self._gps, self._gps_new))
        self._gps_new = False
        return state

    def feed(self, data: bytes) -> list[SimState]:
        """The steps whose HIL_SENSOR is in ``data`` (with the latest truth and fix)."""
        out = []
        for item in self.parse(data):
            state = self.absorb(item)
            if state is not None:
                out.append(state)
        return out


class SimLinkClient:
    """Client of the plant's simulator link: TCP to ``host``:``port``, or with ``unix_path``
    the plant's Unix-domain socket (``@NAME``: Linux's abstract namespace).

    ``home`` (lat deg, lon deg, alt m AMSL) is the inertial origin the plant uses, needed to
    turn latitude/longitude back into positions; ``truth`` False leaves the simulator's
    own state undecoded (:class:`BatchDecoder`). Connection problems raise
    :class:`ConnectionError`; waiting too long raises :class:`TimeoutError`.
    """

    def __init__(self, host: str = sl.SIM_HOST_DEFAULT, port: int = sl.SIM_PORT_DEFAULT,
                 home: tuple[float, float, float] = sl.HOME_DEFAULT, *,
                 unix_path: str | None = None, truth: bool = True) -> None:
        self.host = host
        self.port = port
        self.unix_path = unix_path
        #: The plant's address, as :func:`tuavdefs.simlink.parse_sim_address` reads it.
        self.address = sl.format_sim_address(unix_path if unix_path is not None
                                              else (host, port))
        self.home = tuple(float(v) for v in home)
        self._sock: socket.socket | None = None
        self._decoder = BatchDecoder(self.home, truth)
        self._encoder = sl.Encoder(sl.COMPANION_SYSID, sl.COMPANION_COMPID)
        #: The link's messages read and not yet absorbed: (message id, values in wire order)
        self._pending: deque[tuple[int, tuple]] = deque()
        #: The receive timeout set on the socket [ms] (it blocks in recv for at most that)
        self._recv_timeout_ms: int | None = None

    # ----- connection
    def connect(self, timeout_s: float = 10.0) -> None:
        """Connect, retrying until the plant listens or ``timeout_s`` [s] pass."""
        end = time.monotonic() + timeout_s
        while True:
            try:
                sock = self._open(max(end - time.monotonic(), 0.01))
                break
            except OSError as e:
                if time.monotonic() >= end:
                    raise TimeoutError(f"no simulator at {self.address}") from e
                time.sleep(0.02)
        # a blocking socket whose timeouts the kernel keeps (one system call a recv)
        sock.settimeout(None)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, sl.timeval(_SEND_TIMEOUT_S))
        self._recv_timeout_ms = None
        self._sock = sock

    def _open(self, timeout_s: float) -> socket.socket:
        """One attempt to connect, within ``timeout_s`` [s]."""
        if self.unix_path is None:
            sock = socket.create_connection((self.host, self.port), timeout=timeout_s)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return sock
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(timeout_s)
            sock.connect(sl.unix_sockaddr(self.unix_path))
        except OSError:
            sock.close()
            raise
        return sock

    @property
    def connected(self) -> bool:
        """Whether a connection is open."""
        return self._sock is not None

    def fileno(self) -> int:
        """The link's socket descriptor (for a caller's ``select``); -1 when not connected."""
        return self._sock.fileno() if self._sock is not None else -1

    def has_buffered_state(self) -> bool:
        """Whether messages already read from the socket are waiting to be absorbed (a
        caller's ``select`` on :meth:`fileno` would not show them)."""
        return bool(self._pending)

    @property
    def bad_frames(self) -> int:
        """Malformed frames dropped from the plant's stream."""
        return self._decoder.bad_frames

    def close(self) -> None:
        """Close the connection (the plant's serve() then ends)."""
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None

    def __enter__(self) -> SimLinkClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- receiving
    def receive_state(self, timeout_s: float = 5.0) -> SimState:
        """The next step's batch, waiting up to ``timeout_s`` [s] for its HIL_SENSOR."""
        end = time.monotonic() + timeout_s
        absorb = self._decoder.absorb
        while True:
            while self._pending:
                state = absorb(self._pending.popleft())
                if state is not None:
                    return state
            self._read(end)

    def _read(self, end: float) -> None:
        sock = self._require()
        left = end - time.monotonic()
        if left <= 0:
            raise TimeoutError("no sensor message from the simulator")
        # the socket's receive timeout: what is left, in whole milliseconds below it (set
        # again only when that changes), or the microseconds left in the last one
        ms = int(left * 1e3)
        if ms != self._recv_timeout_ms:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO,
                            sl.timeval(ms * 1e-3 if ms else left))
            self._recv_timeout_ms = ms if ms else None
        try:
            data = sock.recv(65536)
        except BlockingIOError:     # the receive timeout
            raise TimeoutError("no sensor message from the simulator") from None
        except OSError as e:
            raise ConnectionError(f"simulator link failed: {e}") from e
        if not data:
            raise ConnectionError("the simulator closed the link")
        self._pending.extend(self._decoder.parse(data))

    # ----- sending
    def send_actuators(self, time_usec: int, rotor_commands: Sequence[float], armed: bool,
                       lockstep: bool = True) -> None:
        """Answer the batch stamped ``time_usec`` [us] with four rotor commands in [0, 1]
        (rotor order of :mod:`tuavdefs.airframe`) and the armed flag."""
        self.send_raw(self._encoder.actuator_controls(time_usec, rotor_commands, armed,
                                                      lockstep))

    @property
    def sim_params(self) -> dict[str, float]:
        """The simulator's run-time parameters as the plant last said them (name -> value;
        empty until it has)."""
        return self._decoder.sim_params

    def set_sim_param(self, name: str, value: float) -> None:
        """Ask the plant to set a simulator parameter (PARAM_SET; it answers PARAM_VALUE
        with the value it holds, which :attr:`sim_params` then shows)."""
        self.send_raw(sl.param_set_frame(self._encoder, (sl.PLANT_SYSID, sl.PLANT_COMPID),
                                         name, value))

    def send_raw(self, data: bytes) -> None:
        """Write bytes on the link as they are (diagnostics and tests)."""
        sock = self._require()
        try:
            sock.sendall(data)
        except OSError as e:
            raise ConnectionError(f"simulator link failed: {e}") from e

    def _require(self) -> socket.socket:
        if self._sock is None:
            raise ConnectionError("not connected to the simulator")
        return self._sock
