"""The plant's end of the simulator link: PX4's simulator MAVLink API, lockstep.

:class:`SimLinkServer` listens on 127.0.0.1 (port 4560 by default) or on a Unix-domain
socket and accepts one companion (conventions in :mod:`tuavdefs.simlink`). It is the link
the plant's loop (:class:`sitl.plant_loop.PlantLoop`, which owns the clock and the order of
each control period) works through, one control period at a time::

    send_batch(t)     HIL_GPS (when due, at the GNSS preset's rate, describing the truth
                      of its latency earlier), HIL_STATE_QUATERNION, HIL_SENSOR, stamped t
    wait_answer(t)    until the HIL_ACTUATOR_CONTROLS with time_usec == t (or, in real
                      time, the period's deadline): hold its rotor commands and armed flag
    advance()         N = T / dt physics steps of the plant with them and the winder inputs

It is configured with the link's pacing: **lockstep** (the default: the plant waits for
each answer as long as it takes, and only the answer to the period's own batch counts),
lockstep paced at N x real time (``speedup``), or **real time** (``real_time``: an answer
to an earlier period, arriving late, still replaces the held commands). The winder's
inputs are not carried by this link (the winder is driven over CAN by another process):
the loop sets :attr:`SimLinkServer.winder_inputs` between periods.

Malformed, truncated and corrupted frames are counted and dropped; a disconnect of the
companion raises :class:`DisconnectedError` out of the period's calls, and the stop event
:class:`StoppedError` out of :meth:`SimLinkServer.wait_answer`. :meth:`SimLinkServer.serve`
runs a :class:`sitl.plant_loop.PlantLoop` over the server alone (no CAN node, no truth log)
with the server's ``on_step`` and ``before_physics``, and returns its
:class:`ServeSummary`.
"""

from __future__ import annotations

import errno
import functools
import ipaddress
import math
import os
import select
import socket
import stat
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from dataclasses import fields as dataclass_fields
from typing import Any, NamedTuple, Protocol

from sitl.plant import Plant, PlantInputs
from sitl.sensor_batch import SensorBatches
from sitl.sensors import SensorNoise, SensorSuite
from sitl.spin import SpinWait
from tuavdefs import simlink as sl

#: In lockstep, a wait for the companion's answer longer than this [s, wall] is said ...
LOCKSTEP_NOTICE_S = 5.0
#: ... and again every this [s, wall] while it lasts.
LOCKSTEP_REPEAT_S = 30.0
#: The simulator link's send buffer in real time [bytes]: about a tenth of a second of
#: batches at 250 Hz once the kernel has doubled it.
REAL_TIME_SNDBUF = 4096
#: How often a waiting loop looks at its stop event [s].
STOP_POLL_S = 0.05


class WinderInputs(NamedTuple):
    """The winder's part of :class:`sitl.plant.PlantInputs`: motor torque request [N m]
    (positive pays out) and whether the motor is powered (brake released)."""

    torque_n_m: float = 0.0
    enabled: bool = False


#: The winder's motor off and its brake on.
_WINDER_BRAKED = WinderInputs()


@dataclass(frozen=True)
class ServeSummary:
    """What one :meth:`SimLinkServer.serve` did.

    ``steps``: control periods advanced; ``sim_time_s``: simulated time advanced [s];
    ``wall_time_s``: wall time from the companion's connection to the end [s];
    ``missed_deadlines``: real-time periods stepped without their answer; ``overruns``:
    times the plant fell a period behind the wall clock; ``bad_frames``/``bad_bytes``:
    dropped malformed input; ``late_answers``: answers to an earlier period (real time);
    ``ignored_messages``: other messages and answers that were not expected (lockstep);
    ``pacing``: "lockstep" or "real-time"; ``end_reason``: "disconnected", "stopped",
    "max_sim_time" or "no_client". In real time, the pacing's statistics [s]: the period
    jitter |interval between two batches - T| (``jitter_p50_s``, ``jitter_p99_s``,
    ``jitter_max_s``) and how late a batch went out after its due time
    (``lateness_p99_s``, ``lateness_max_s``), and the deadlines missed
    (``missed_in_service``) of the ``periods_in_service``: all counted from the companion's
    first answer on (before it the companion is still starting); NaN/0 in lockstep.
    """

    steps: int
    sim_time_s: float
    wall_time_s: float
    missed_deadlines: int
    overruns: int
    bad_frames: int
    bad_bytes: int
    late_answers: int
    ignored_messages: int
    pacing: str
    end_reason: str
    jitter_p50_s: float = math.nan
    jitter_p99_s: float = math.nan
    jitter_max_s: float = math.nan
    lateness_p99_s: float = math.nan
    lateness_max_s: float = math.nan
    periods_in_service: int = 0
    missed_in_service: int = 0

    @property
    def missed_fraction(self) -> float:
        """Missed deadlines per control period once the companion had answered (real
        time)."""
        return (self.missed_in_service / self.periods_in_service if self.periods_in_service
                else 0.0)

    @property
    def steps_per_s(self) -> float:
        """Control periods per wall-clock second."""
        return self.steps / self.wall_time_s if self.wall_time_s > 0 else math.inf

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf


class DisconnectedError(Exception):
    """The companion closed the link (or it failed)."""


class StoppedError(Exception):
    """The stop event was set while waiting for an answer."""


class SimParamStore(Protocol):
    """What holds the simulator's run-time parameters (:class:`sitl.faults.FaultSchedule`)."""

    def sim_values(self) -> dict[str, float]:
        """Every parameter's value now, by name."""
        ...

    def set_sim(self, name: str, value: float) -> str | None:
        """Set one: None, or why it was refused (the value unchanged)."""
        ...


def _check_loopback(host: str) -> None:
    if host == "localhost":
        return
    try:
        ok = ipaddress.ip_address(host).is_loopback
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"the simulator link stays on the loopback interface, not {host!r}")


def _listen_unix(path: str) -> socket.socket:
    """A Unix-domain socket listening at ``path`` (``@NAME``: Linux's abstract namespace).

    A file already at the path is left alone and the bind fails with EADDRINUSE, as a TCP
    port in use does: it may be another plant's socket, and probing it would connect to that
    plant as its companion. The plant removes its own socket file when it closes.
    """
    if not path.startswith("@") and os.path.lexists(path):
        why = ("a socket is already there (another plant's, or one left by a plant that "
               "was killed: then remove it)" if stat.S_ISSOCK(os.lstat(path).st_mode)
               else "a file is already there, and it is not a socket")
        raise OSError(errno.EADDRINUSE, why, path)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.bind(sl.unix_sockaddr(path))
        sock.listen(1)
    except OSError:
        sock.close()
        raise
    return sock


@dataclass(frozen=True)
class SimLinkConfig:
    """How the plant's simulator link is set up (:class:`SimLinkServer`).

    ``control_rate_hz`` [Hz] is the lockstep rate (its period must be a whole number of the
    plant's steps); ``home`` (lat deg, lon deg, alt m AMSL) places the inertial origin. The
    link is TCP on ``host``:``port`` (``port=0`` picks a free port), or with ``unix_path`` a
    Unix-domain socket at that path (``@NAME``: a name in Linux's abstract namespace), which
    costs the two ends less per period than TCP on the loopback interface.
    ``sensor_noise`` configures the sensor errors (None: :class:`sitl.sensors.SensorNoise`
    defaults, the RTK receiver; ``SensorNoise.preset(...)`` for another;
    ``SensorNoise.off()`` for exact readings); ``earth_field_ned_gauss`` the Earth's field
    the magnetometer reads (None: the suite's). ``gps_rate_hz`` [Hz] is the rate of HIL_GPS
    (None: the noise's ``gps_rate_hz``, the preset's); its latency is the noise's
    ``gps_latency_s``. The link's pacing: lockstep, or with ``real_time`` real time, or
    lockstep paced at ``speedup`` x real time (None or inf: as fast as possible).
    ``lockstep_spin_s`` [s]: in lockstep, how long each wait for an answer spins before it
    sleeps (:mod:`sitl.spin`; 0: it sleeps at once).
    """

    control_rate_hz: float = sl.CONTROL_RATE_HZ_DEFAULT
    home: tuple[float, float, float] = sl.HOME_DEFAULT
    host: str = sl.SIM_HOST_DEFAULT
    port: int = sl.SIM_PORT_DEFAULT
    unix_path: str | None = None
    real_time: bool = False
    speedup: float | None = None
    lockstep_spin_s: float = 0.0
    sensor_noise: SensorNoise | None = None
    gps_rate_hz: float | None = None
    earth_field_ned_gauss: tuple[float, float, float] | None = None


def _fields_of(config: SimLinkConfig) -> tuple:
    """``config``'s fields in their order, as they are (``dataclasses.astuple`` would copy
    the noise record deeply)."""
    return tuple(getattr(config, f.name) for f in dataclass_fields(config))


class SimLinkServer:
    """The plant's simulator-link server (PX4 simulator MAVLink API, one companion).

    ``plant`` is stepped in place; ``config`` says the link's address, rate, pacing and
    sensors (:class:`SimLinkConfig`; its fields may also be given by name here, over
    ``config``'s). :attr:`address` says where it listens; the socket is bound and
    listening when the constructor returns. The loop that runs it is
    :class:`sitl.plant_loop.PlantLoop`. ``winder_inputs`` are the winder's inputs until the
    loop sets others; ``on_step`` and ``before_physics`` are the hooks :meth:`serve` runs
    its loop with; ``log`` takes its messages (None: printed).
    """

    def __init__(self, plant: Plant, config: SimLinkConfig | None = None, *,
                 winder_inputs: WinderInputs = _WINDER_BRAKED,
                 on_step: Callable[[SimLinkServer], None] | None = None,
                 before_physics: Callable[[SimLinkServer], None] | None = None,
                 log: Callable[[str], None] | None = None, **fields: Any) -> None:
        config = replace(config or SimLinkConfig(), **fields)
        #: The link's set-up.
        self.config = config
        (control_rate_hz, home, host, port, unix_path, real_time, speedup, lockstep_spin_s,
         sensor_noise, gps_rate_hz, earth_field_ned_gauss) = _fields_of(config)
        if unix_path is None:
            _check_loopback(host)
        self.plant = plant
        self.log = log or (lambda text: print(f"plant: {text}", flush=True))
        # real time: what the companion's link could not take yet (the rest of a batch)
        self._unsent = bytearray()
        #: Batches not sent in real time because the companion had not read the last.
        self.dropped_batches = 0
        self._stalled_since: int | None = None    # dropped_batches when the stall began
        self.control_rate_hz = float(control_rate_hz)
        self.period_us = sl.control_period_us(control_rate_hz)
        self.physics_steps = sl.physics_steps_per_period(control_rate_hz, plant.dt_s)
        self.home = tuple(float(v) for v in home)
        self.real_time = bool(real_time)
        #: Lockstep paced at this many times real time (None: as fast as possible).
        self.speedup = None if real_time or speedup is None or math.isinf(speedup) \
            else float(speedup)
        if self.speedup is not None and not self.speedup > 0:
            raise ValueError(f"speedup must be > 0, got {speedup!r}")
        self.winder_inputs = winder_inputs
        #: The caller's hooks of :meth:`serve` (see :class:`sitl.plant_loop.PlantLoop`).
        self.on_step = on_step
        self.before_physics = before_physics
        suite_kw = {} if earth_field_ned_gauss is None else {
            "earth_field_ned_gauss": tuple(earth_field_ned_gauss)}
        self.sensors = SensorSuite(noise=sensor_noise or SensorNoise(), home=self.home,
                                   **suite_kw)
        #: HIL_GPS's rate [Hz] and period [us].
        self.gps_rate_hz = float(self.sensors.gps_rate_hz if gps_rate_hz is None
                                 else gps_rate_hz)
        self.gps_period_us = sl.control_period_us(self.gps_rate_hz)
        #: The commands held from the last answer: rotor commands in [0, 1] and armed.
        self.rotor_commands: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self.armed = False
        #: Whether the last answer announced lockstep (HIL_ACTUATOR_CONTROLS flags bit 0).
        self.companion_lockstep = False
        # what the last period's physics steps held: PlantInputs' fields (last_inputs)
        self._held: tuple = tuple(PlantInputs())
        #: Control periods advanced in the running (or last) session (the loop counts).
        self.steps = 0
        self._encoder = sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID)
        #: Each period's batch (compiled where it can be).
        self.batches = SensorBatches(plant, self.sensors, self.home, self.period_us,
                                     self.gps_period_us, self._encoder)
        self._parser = sl.FrameParser()
        #: In lockstep, how long the wait for an answer spins before it sleeps
        #: (:class:`sitl.spin.SpinWait`; ``lockstep_spin_s`` [s], 0: never).
        self.spin = SpinWait(lockstep_spin_s)
        self._sock: socket.socket | None = None
        self._poller: select.poll | None = None
        #: Whether the answer's bytes are there (a poll(0) on the connection).
        self._ready: Callable[[], object] = lambda: False
        #: The simulator's run-time parameters (tuavdefs.sim_params) the companion may set
        #: over the link (None: it sets none; its PARAM_SETs are ignored).
        self.sim_params: SimParamStore | None = None
        self._params_out = bytearray()    # PARAM_VALUEs to go out before the next batch
        # (an encoder of their own: the batches' sequence numbers stay the batches')
        self._param_encoder = sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID)
        #: The Unix-domain path listened on (None: TCP).
        self.unix_path = unix_path
        address: tuple[str, int] | str
        if unix_path is not None:
            self._listener = _listen_unix(unix_path)
            self.host, self.port = "", 0
            # (close removes the file only if it is still this socket's)
            self._unix_file = None if unix_path.startswith("@") else os.stat(unix_path)
            address = unix_path
        else:
            self._unix_file = None
            self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                self._listener.bind((host, port))
                self._listener.listen(1)
            except OSError:
                self._listener.close()
                raise
            self.host, self.port = self._listener.getsockname()[:2]
            address = (self.host, self.port)
        #: Where the link listens, as :func:`tuavdefs.simlink.parse_sim_address` reads it.
        self.address = sl.format_sim_address(address)

    # ----- lifecycle
    @property
    def pacing(self) -> str:
        """"real-time" or "lockstep"."""
        if self.real_time:
            return "real-time"
        return "lockstep" if self.speedup is None else f"lockstep at {self.speedup:g}x"

    def close(self) -> None:
        """Close the listening socket (and a connection, if any); remove its socket file."""
        self.close_client()
        self._listener.close()
        made, self._unix_file = self._unix_file, None
        if made is not None and self.unix_path is not None:
            try:
                now = os.stat(self.unix_path)
            except OSError:
                return
            if (now.st_dev, now.st_ino) == (made.st_dev, made.st_ino):
                os.unlink(self.unix_path)

    def __enter__(self) -> SimLinkServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close_client(self) -> None:
        """Close the companion's connection, if any (the listening socket stays)."""
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None
                self._poller = None

    @property
    def bad_frames(self) -> int:
        """Malformed frames dropped in this session."""
        return self._parser.bad_frames

    @property
    def bad_bytes(self) -> int:
        """Bytes dropped as malformed in this session."""
        return self._parser.bad_bytes

    # ----- the loop
    def serve(self, max_sim_time_s: float | None = None,
              stop_event: threading.Event | None = None,
              accept_timeout_s: float | None = None) -> ServeSummary:
        """Accept one companion and run the loop (:class:`sitl.plant_loop.PlantLoop` over
        this server alone, with :attr:`on_step` and :attr:`before_physics`) until it
        disconnects, ``stop_event`` is set, or ``max_sim_time_s`` [s] of simulated time have
        passed in this call. Without a connection within ``accept_timeout_s`` [s] (None:
        wait) returns at once."""
        from sitl.plant_loop import PlantLoop  # (which imports this module)

        loop = PlantLoop(self, on_step=self.on_step, before_physics=self.before_physics,
                         stop_event=stop_event)
        return loop.run(max_sim_time_s=max_sim_time_s, accept_timeout_s=accept_timeout_s)

    # ----- the link's part of a session and of each control period (the loop's calls)
    def accept(self, stop: threading.Event, timeout_s: float | None) -> bool:
        """Start a session: forget the last one's periods, parser, GPS schedule and the
        sensors' recorded truth (:meth:`sitl.sensors.SensorSuite.reset_truth`), and
        wait for a companion to connect (True), at most ``timeout_s`` [s] (None: until
        ``stop`` is set; then, or on the timeout, False)."""
        self.steps = 0
        self._parser = sl.FrameParser()
        self.batches.reset()
        self._unsent.clear()
        self._stalled_since = None
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while not stop.is_set():
            wait = STOP_POLL_S if end is None else min(STOP_POLL_S, end - time.monotonic())
            if wait <= 0:
                return False
            ready, _, _ = select.select([self._listener], [], [], wait)
            if ready:
                sock, _ = self._listener.accept()
                if sock.family != socket.AF_UNIX:
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                if self.real_time:
                    # a companion that stops reading holds a fraction of a second of
                    # batches, not seconds of stale ones (the kernel doubles the value)
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, REAL_TIME_SNDBUF)
                sock.setblocking(True)
                # lockstep: recv itself waits for the answer, STOP_POLL_S at a time
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, sl.timeval(STOP_POLL_S))
                self._sock = sock
                self._poller = select.poll()
                self._poller.register(sock, select.POLLIN)
                self._ready = functools.partial(self._poller.poll, 0)
                self._params_out.clear()
                if self.sim_params is not None:   # what they are, before the first batch
                    for name in self.sim_params.sim_values():
                        self._queue_param(name)
                return True
        return False

    def send_batch(self, t_us: int) -> None:
        """Send HIL_GPS (when due), HIL_STATE_QUATERNION and HIL_SENSOR for the current
        state, stamped ``t_us`` [us].

        In real time this never waits: what the link cannot take now is kept and written
        before the next batch, and a batch finding the last one still unsent is dropped
        (the plant flies on the commands it holds; said when it begins and ends). In
        lockstep the plant waits for the companion anyway."""
        sock = self._sock
        assert sock is not None
        if self._params_out:
            # (a few frames now and then, ahead of the batch: in real time they go the way
            # of the batch's bytes)
            self._unsent[:0] = self._params_out
            self._params_out.clear()
        if not self.real_time:
            try:
                if self._unsent:
                    sock.sendall(self._unsent)
                    self._unsent.clear()
                sock.sendall(self.batches.batch(t_us))
            except OSError as e:
                raise DisconnectedError from e
            return
        if self._unsent:
            del self._unsent[:self._send_nowait(sock, self._unsent)]
            if self._unsent:
                self.dropped_batches += 1
                if self._stalled_since is None:
                    self._stalled_since = self.dropped_batches - 1
                    self.log(f"the companion does not read the simulator link (t = "
                             f"{t_us * 1e-6:.3f} s): flying on its last commands")
                return
        data = self.batches.batch(t_us)
        n = self._send_nowait(sock, data)
        if n < len(data):
            self._unsent += data[n:]
        if self._stalled_since is not None:
            self.log(f"the companion reads again (t = {t_us * 1e-6:.3f} s) after "
                     f"{self.dropped_batches - self._stalled_since} batches dropped")
            self._stalled_since = None

    @staticmethod
    def _send_nowait(sock: socket.socket, data: bytes | bytearray) -> int:
        """How many bytes of ``data`` the link took at once."""
        try:
            return sock.send(data, socket.MSG_DONTWAIT)
        except BlockingIOError:
            return 0
        except OSError as e:
            raise DisconnectedError from e

    def wait_answer(self, t_us: int, deadline: float | None, stop: threading.Event
                    ) -> tuple[bool, int, int]:
        """Read until the answer to ``t_us`` arrives (True) or, in real time, the wall
        ``deadline`` [s, time.monotonic] passes (False; None: no deadline, lockstep).
        Returns (answered, late answers, ignored messages)."""
        sock = self._sock
        poller = self._poller
        assert sock is not None and poller is not None
        parser = self._parser
        spin = self.spin if self.spin.budget_s > 0.0 and deadline is None else None
        ready = self._ready
        late = ignored = 0
        # lockstep: a wait this long is said (and again every LOCKSTEP_REPEAT_S)
        notice_at = None if deadline is not None else time.monotonic() + LOCKSTEP_NOTICE_S
        waited_from = time.monotonic() if notice_at is not None else 0.0
        said = False
        while True:
            if stop.is_set():
                raise StoppedError
            if notice_at is not None and time.monotonic() >= notice_at:
                notice_at += LOCKSTEP_REPEAT_S
                said = True
                self.log(f"lockstep: waiting for the companion's answer to t = "
                         f"{t_us * 1e-6:.3f} s ({time.monotonic() - waited_from:.0f} s so "
                         "far); the simulation stands still until it answers")
            if deadline is not None:
                wait = deadline - time.monotonic()
                if wait <= 0:
                    return False, late, ignored
                if not poller.poll(min(wait, STOP_POLL_S) * 1e3):
                    continue
            elif spin is not None:
                # lockstep: the answer is usually tens of microseconds away; waiting awake
                # spares the companion waking this process (sitl/spin.py)
                spin.until(ready)
            try:
                data = sock.recv(65536)   # (lockstep: waits up to STOP_POLL_S)
            except BlockingIOError:   # the socket's receive timeout
                continue
            except OSError as e:
                raise DisconnectedError from e
            if not data:
                raise DisconnectedError
            answered = False
            # the usual case, one well-formed answer, skips the message objects
            items = parser.feed_link(data)
            if items is None:
                items = [sl.link_values(m) for m in parser.feed(data)]
            for item in items:
                if item is None or item[0] != sl.MSG_HIL_ACTUATOR_CONTROLS:
                    if item is not None and item[0] == sl.MSG_PARAM_SET:
                        self._param_set(*item[1])
                    else:
                        ignored += 1
                    continue
                answer = sl.answer_from_wire(item[1])
                ts = answer[0]
                if ts == t_us or (self.real_time and ts < t_us):
                    self._hold(answer)
                    if ts == t_us:
                        answered = True
                    else:
                        late += 1
                else:
                    ignored += 1
            if answered:
                if said:
                    self.log(f"lockstep: the companion answered after "
                             f"{time.monotonic() - waited_from:.1f} s")
                return True, late, ignored

    def _param_set(self, name: str, value: float) -> None:
        """A PARAM_SET of a simulator parameter from the companion: applied, or refused
        (logged); the value held echoed as PARAM_VALUE either way (nothing for a name
        that is not one)."""
        store = self.sim_params
        if store is None or name not in store.sim_values():
            return
        why = store.set_sim(name, value)
        self.log(f"simulator parameter {name} = {value:g}" if why is None
                 else f"simulator parameter {name}: {why}; kept "
                      f"{store.sim_values()[name]:g}")
        self._queue_param(name)

    def _queue_param(self, name: str) -> None:
        store = self.sim_params
        assert store is not None
        values = store.sim_values()
        names = list(values)
        self._params_out += sl.param_value_frame(self._param_encoder, name, values[name],
                                                 names.index(name), len(names))

    def _hold(self, answer: tuple[int, tuple[float, float, float, float], bool, bool]
              ) -> None:
        """Hold an answer's (:func:`tuavdefs.simlink.answer_from_wire`) commands."""
        _, self.rotor_commands, self.armed, self.companion_lockstep = answer

    @property
    def last_inputs(self) -> PlantInputs:
        """The inputs the last control period's physics steps held."""
        return PlantInputs(*self._held)

    def advance(self) -> None:
        """One control period of the plant: its N physics steps with the held commands and
        :attr:`winder_inputs`."""
        torque, enabled = self.winder_inputs
        held = self._held = (self.rotor_commands, self.armed, float(torque), bool(enabled))
        self.plant.advance_held(*held, self.physics_steps)
