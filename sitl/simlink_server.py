"""The plant's end of the simulator link: PX4's simulator MAVLink API, lockstep.

:class:`SimLinkServer` listens on 127.0.0.1 (port 4560 by default) or on a Unix-domain
socket, accepts one companion and runs the loop (conventions in :mod:`tuavdefs.simlink`)::

    k = 0, t = t0
    repeat:
        send HIL_GPS (when due, 10 Hz), HIL_STATE_QUATERNION, HIL_SENSOR, stamped t
        wait for the HIL_ACTUATOR_CONTROLS with time_usec == t
        hold its rotor commands and armed flag (and the caller's winder inputs) for
        N = T / dt physics steps of the plant; t += T

In **lockstep** (the default) the plant waits as long as it takes: the simulation runs as
fast as the two processes allow and is deterministic. In **real-time** mode the batch for
period k goes out at wall time ``w0 + k T`` and the answer must arrive before
``w0 + (k + 1) T``; if it does not, the plant steps with the commands it holds and counts a
missed deadline (a late answer still replaces the held commands when it arrives). If the
plant itself falls more than a period behind the wall clock it re-anchors its schedule and
counts an overrun.

The winder's inputs are not carried by this link (the winder is driven over CAN by another
process): the caller sets :attr:`SimLinkServer.winder_inputs` between steps, from
``on_step``, which is called once for every state a control period reaches, before the
next period's physics steps: in lockstep just after the batch describing that state has
gone out (so that the caller's work, such as the winder's CAN traffic, overlaps the
companion's), in real time once the answer is in (so that what the caller received while
waiting, such as a torque command, applies as early as possible); and from
``before_physics``, called in both modes just before each period's physics steps, once
the answer is in (in lockstep, the last moment to wait for another process's input).

Malformed, truncated and corrupted frames are counted and dropped; a disconnect of the
companion, ``stop_event`` or ``max_sim_time_s`` ends :meth:`SimLinkServer.serve` with a
:class:`ServeSummary`.
"""

from __future__ import annotations

import errno
import ipaddress
import math
import os
import select
import socket
import stat
import threading
import time
from array import array
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from sitl.batch import batch_packer
from sitl.plant import POS, QUAT, RATES, VEL, Plant, PlantInputs
from sitl.sensors import ISA_RHO0_KG_M3, SensorNoise, SensorSuite, airspeed_from, isa_air
from tuavdefs import simlink as sl

#: How often a waiting loop looks at ``stop_event`` [s].
_POLL_S = 0.05
#: Longest a real-time wait spins before a batch's due time [s].
_SPIN_MAX_S = 0.001


def _quantile(sorted_values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (nearest rank) of ascending values; NaN for none."""
    if not sorted_values:
        return math.nan
    k = min(len(sorted_values) - 1, max(0, math.ceil(q * len(sorted_values)) - 1))
    return float(sorted_values[k])


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


class _DisconnectedError(Exception):
    pass


class _StoppedError(Exception):
    pass


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


class SimLinkServer:
    """The plant's simulator-link server (PX4 simulator MAVLink API, one companion).

    ``plant`` is stepped in place; ``control_rate_hz`` [Hz] is the lockstep rate (its period
    must be a whole number of the plant's steps); ``home`` (lat deg, lon deg, alt m AMSL)
    places the inertial origin. The link is TCP on ``host``:``port`` (``port=0`` picks a
    free port, see :attr:`port`), or with ``unix_path`` a Unix-domain socket at that path
    (``@NAME``: a name in Linux's abstract namespace), which costs the two ends less per
    period than TCP on the loopback interface. :attr:`address` says which; the socket is
    bound and listening when the constructor returns. ``sensor_noise`` configures the
    sensor errors (None: :class:`sitl.sensors.SensorNoise` defaults; ``SensorNoise.off()``
    for exact readings). ``gps_rate_hz`` [Hz] is the rate of HIL_GPS.
    """

    def __init__(self, plant: Plant, control_rate_hz: float = sl.CONTROL_RATE_HZ_DEFAULT,
                 home: tuple[float, float, float] = sl.HOME_DEFAULT,
                 host: str = sl.SIM_HOST_DEFAULT, port: int = sl.SIM_PORT_DEFAULT,
                 real_time: bool = False, sensor_noise: SensorNoise | None = None,
                 gps_rate_hz: float = sl.GPS_RATE_HZ_DEFAULT,
                 winder_inputs: WinderInputs = _WINDER_BRAKED,
                 earth_field_ned_gauss: tuple[float, float, float] | None = None,
                 on_step: Callable[[SimLinkServer], None] | None = None,
                 speedup: float | None = None,
                 before_physics: Callable[[SimLinkServer], None] | None = None,
                 unix_path: str | None = None) -> None:
        if unix_path is None:
            _check_loopback(host)
        self.plant = plant
        self.control_rate_hz = float(control_rate_hz)
        self.period_us = sl.control_period_us(control_rate_hz)
        self.physics_steps = sl.physics_steps_per_period(control_rate_hz, plant.dt_s)
        self.gps_period_us = sl.control_period_us(gps_rate_hz)
        self.home = tuple(float(v) for v in home)
        self.real_time = bool(real_time)
        #: In real time, the wait for a batch's due time ends awake, spinning for this long
        #: [s]: an eighth of the period, at most 1 ms.
        self.spin_s = min(_SPIN_MAX_S, self.period_us * 1e-6 / 8.0)
        #: Lockstep paced at this many times real time (None: as fast as possible).
        self.speedup = None if real_time or speedup is None or math.isinf(speedup) \
            else float(speedup)
        if self.speedup is not None and not self.speedup > 0:
            raise ValueError(f"speedup must be > 0, got {speedup!r}")
        self.winder_inputs = winder_inputs
        self.on_step = on_step
        self.before_physics = before_physics
        suite_kw = {} if earth_field_ned_gauss is None else {
            "earth_field_ned_gauss": tuple(earth_field_ned_gauss)}
        self.sensors = SensorSuite(noise=sensor_noise or SensorNoise(), home=self.home,
                                   **suite_kw)
        #: The commands held from the last answer: rotor commands in [0, 1] and armed.
        self.rotor_commands: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
        self.armed = False
        #: Whether the last answer announced lockstep (HIL_ACTUATOR_CONTROLS flags bit 0).
        self.companion_lockstep = False
        # what the last period's physics steps held: PlantInputs' fields (last_inputs)
        self._held: tuple = tuple(PlantInputs())
        #: Control periods advanced by the running (or last) serve().
        self.steps = 0
        self._encoder = sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID)
        #: The batches in one compiled call (None without numba: :meth:`_batch_bytes`).
        self._packer = batch_packer(plant, self.sensors, self.home, self._encoder,
                                    self.period_us)
        self._parser = sl.FrameParser()
        self._sock: socket.socket | None = None
        self._poller: select.poll | None = None
        self._home_map = sl.home_map(self.home)
        self._last_gps_us: int | None = None
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
        self._close_client()
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

    def _close_client(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            finally:
                self._sock = None
                self._poller = None

    # ----- the loop
    def serve(self, max_sim_time_s: float | None = None,
              stop_event: threading.Event | None = None,
              accept_timeout_s: float | None = None) -> ServeSummary:
        """Accept one companion and run the loop until it disconnects, ``stop_event`` is
        set, or ``max_sim_time_s`` [s] of simulated time have passed in this call. Without a
        connection within ``accept_timeout_s`` [s] (None: wait) returns at once."""
        stop = stop_event or threading.Event()
        self.steps = 0
        self._parser = sl.FrameParser()
        self._last_gps_us = None
        ignored = late = missed = overruns = 0
        if not self._accept(stop, accept_timeout_s):
            return self._summary(0.0, 0, 0, 0, 0, "stopped" if stop.is_set() else "no_client")
        wall0 = time.monotonic()
        t0_us = sl.time_usec(self.plant.t_s)
        max_steps = (None if max_sim_time_s is None
                     else math.ceil(max_sim_time_s * 1e6 / self.period_us - 1e-9))
        reason = "disconnected"
        sched0 = wall0       # wall time of period 0's batch (real time)
        pending = False      # on_step is due for the state the last period reached
        # real time: the wall time between batches, and each batch's time after its due time
        intervals: array[float] = array("d")
        lateness: array[float] = array("d")
        last_sent: float | None = None
        in_service = False
        service_steps = service_missed = 0
        try:
            while True:
                if stop.is_set():
                    reason = "stopped"
                    break
                if max_steps is not None and self.steps >= max_steps:
                    reason = "max_sim_time"
                    break
                t_us = t0_us + self.steps * self.period_us
                if self.real_time:
                    due = sched0 + self.steps * self.period_us * 1e-6
                    now = time.monotonic()
                    if now > due + self.period_us * 1e-6:
                        overruns += 1
                        sched0 = now - self.steps * self.period_us * 1e-6
                        due = now
                    elif now < due:
                        self._sleep_until(due, stop)
                    deadline: float | None = due + self.period_us * 1e-6
                else:
                    deadline = None
                    if self.speedup is not None:
                        due = sched0 + self.steps * self.period_us * 1e-6 / self.speedup
                        now = time.monotonic()
                        if now < due:
                            self._sleep_until(due, stop)
                        elif now > due + 0.1:
                            # fell behind (a slow step): resume the pace, don't sprint
                            sched0 = now - self.steps * self.period_us * 1e-6 / self.speedup
                self._send_batch(t_us)
                if self.real_time and in_service:
                    sent = time.monotonic()
                    if last_sent is not None:
                        intervals.append(sent - last_sent)
                    lateness.append(sent - due)
                    last_sent = sent
                if pending and not self.real_time:
                    # lockstep: the caller's work for the state just reached (the winder's
                    # CAN traffic, the truth log) runs while the companion computes its
                    # answer, off the critical path
                    pending = False
                    self.on_step(self)  # type: ignore[misc]
                answered, n_late, n_ignored = self._wait_answer(t_us, deadline, stop)
                if pending:
                    # real time: just before the physics steps, so that whatever the
                    # caller received meanwhile (a torque command) applies from them on
                    pending = False
                    self.on_step(self)  # type: ignore[misc]
                late += n_late
                ignored += n_ignored
                if not answered:
                    missed += 1
                if in_service:
                    service_steps += 1
                    service_missed += not answered
                # the pacing's statistics start once the companion has answered (before
                # that it is still starting up)
                in_service = in_service or answered or n_late > 0
                if self.before_physics is not None:
                    self.before_physics(self)
                self._advance()
                self.steps += 1
                pending = self.on_step is not None
        except _DisconnectedError:
            reason = "disconnected"
        except _StoppedError:
            reason = "stopped"
        finally:
            try:
                if pending:
                    self.on_step(self)  # type: ignore[misc]
            finally:
                self._close_client()
        return self._summary(time.monotonic() - wall0, missed, overruns, late, ignored, reason,
                             intervals, lateness, service_steps, service_missed)

    def _summary(self, wall: float, missed: int, overruns: int, late: int, ignored: int,
                 reason: str, intervals: Sequence[float] = (),
                 lateness: Sequence[float] = (), service_steps: int = 0,
                 service_missed: int = 0) -> ServeSummary:
        period = self.period_us * 1e-6
        jitter = sorted(abs(d - period) for d in intervals)
        behind = sorted(lateness)
        return ServeSummary(
            steps=self.steps, sim_time_s=self.steps * period, wall_time_s=wall,
            missed_deadlines=missed, overruns=overruns, bad_frames=self._parser.bad_frames,
            bad_bytes=self._parser.bad_bytes, late_answers=late, ignored_messages=ignored,
            pacing=self.pacing, end_reason=reason,
            jitter_p50_s=_quantile(jitter, 0.5), jitter_p99_s=_quantile(jitter, 0.99),
            jitter_max_s=jitter[-1] if jitter else math.nan,
            lateness_p99_s=_quantile(behind, 0.99),
            lateness_max_s=behind[-1] if behind else math.nan,
            periods_in_service=service_steps, missed_in_service=service_missed)

    def _accept(self, stop: threading.Event, timeout_s: float | None) -> bool:
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while not stop.is_set():
            wait = _POLL_S if end is None else min(_POLL_S, end - time.monotonic())
            if wait <= 0:
                return False
            ready, _, _ = select.select([self._listener], [], [], wait)
            if ready:
                sock, _ = self._listener.accept()
                if sock.family != socket.AF_UNIX:
                    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.setblocking(True)
                # lockstep: recv itself waits for the answer, _POLL_S at a time
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, sl.timeval(_POLL_S))
                self._sock = sock
                self._poller = select.poll()
                self._poller.register(sock, select.POLLIN)
                return True
        return False

    def _sleep_until(self, t: float, stop: threading.Event) -> None:
        """Wait until wall time ``t`` [s]: sleep to :attr:`spin_s` before it, then spin.

        A sleeping process is woken by the scheduler, which on a busy machine first lets the
        task on the CPU finish its slice (up to a few milliseconds): the last stretch is
        spent awake, so the batch goes out on time whenever the process holds a CPU then.
        """
        spin = self.spin_s
        while True:
            now = time.monotonic()
            left = t - now
            if left <= 0 or stop.is_set():
                return
            if left <= spin:
                while time.monotonic() < t:
                    pass
                return
            time.sleep(min(left - spin, _POLL_S))

    def _send_batch(self, t_us: int) -> None:
        """HIL_GPS (when due), HIL_STATE_QUATERNION and HIL_SENSOR for the current state."""
        gps_dt: float | None = None
        last = self._last_gps_us
        if last is None or t_us - last >= self.gps_period_us:
            gps_dt = (self.gps_period_us if last is None else t_us - last) * 1e-6
            self._last_gps_us = t_us
        data = None if self._packer is None else self._packer.pack(t_us, gps_dt)
        if data is None:
            data = self._batch_bytes(t_us, gps_dt)
        try:
            self._sock.sendall(data)  # type: ignore[union-attr]
        except OSError as e:
            raise _DisconnectedError from e

    def _batch_bytes(self, t_us: int, gps_dt: float | None) -> bytes:
        """The batch for the current state at ``t_us`` [us] (with HIL_GPS, its channels read
        ``gps_dt`` [s] after the last fix, unless None), interpreted: the reference of
        :class:`sitl.batch.BatchPacker`, and the path for what it leaves alone."""
        p = self.plant
        dt = self.period_us * 1e-6
        x = p.x.tolist()
        pos, vel, quat, rates = (tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]),
                                 tuple(x[RATES]))
        f_flu = p.specific_force_flu()
        pressure_hpa, temperature_k, density = isa_air(self.home[2] + pos[2])
        tas = airspeed_from(vel, p.wind_m_s)
        ias = tas * math.sqrt(density / ISA_RHO0_KG_M3)
        s, enc, home = self.sensors, self._encoder, self._home_map
        chunks = []
        if gps_dt is not None:
            fix = s.gps(pos, vel, gps_dt)
            chunks.append(enc.pack_values(sl.MSG_HIL_GPS, sl.hil_gps_values(
                t_us, fix.position_enu_m, fix.velocity_enu_m_s, home, fix.eph_m, fix.epv_m)))
        chunks.append(enc.pack_values(sl.MSG_HIL_STATE_QUATERNION,
                                      sl.hil_state_quaternion_values(
                                          t_us, pos, vel, quat, rates, f_flu, home, tas, ias)))
        chunks.append(enc.pack_values(sl.MSG_HIL_SENSOR, sl.hil_sensor_values(
            t_us, *s.imu(f_flu, rates, quat, dt),
            *s.baro_of_air(pressure_hpa, temperature_k, dt))))
        return b"".join(chunks)

    def _wait_answer(self, t_us: int, deadline: float | None, stop: threading.Event
                     ) -> tuple[bool, int, int]:
        """Read until the answer to ``t_us`` arrives (True) or, in real time, the wall
        ``deadline`` passes (False). Returns (answered, late answers, ignored messages)."""
        sock = self._sock
        poller = self._poller
        assert sock is not None and poller is not None
        parser = self._parser
        late = ignored = 0
        while True:
            if stop.is_set():
                raise _StoppedError
            if deadline is not None:
                wait = deadline - time.monotonic()
                if wait <= 0:
                    return False, late, ignored
                if not poller.poll(min(wait, _POLL_S) * 1e3):
                    continue
            try:
                data = sock.recv(65536)   # (lockstep: waits up to _POLL_S)
            except BlockingIOError:   # the socket's receive timeout
                continue
            except OSError as e:
                raise _DisconnectedError from e
            if not data:
                raise _DisconnectedError
            answered = False
            # the usual case, one well-formed answer, skips the message objects
            items = parser.feed_link(data)
            if items is None:
                items = [sl.link_values(m) for m in parser.feed(data)]
            for item in items:
                if item is None or item[0] != sl.MSG_HIL_ACTUATOR_CONTROLS:
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
                return True, late, ignored

    def _hold(self, answer: tuple[int, tuple[float, float, float, float], bool, bool]
              ) -> None:
        """Hold an answer's (:func:`tuavdefs.simlink.answer_from_wire`) commands."""
        _, self.rotor_commands, self.armed, self.companion_lockstep = answer

    @property
    def last_inputs(self) -> PlantInputs:
        """The inputs the last control period's physics steps held."""
        return PlantInputs(*self._held)

    def _advance(self) -> None:
        """N physics steps with the held commands and the caller's winder inputs."""
        torque, enabled = self.winder_inputs
        held = self._held = (self.rotor_commands, self.armed, float(torque), bool(enabled))
        self.plant.advance_held(*held, self.physics_steps)
