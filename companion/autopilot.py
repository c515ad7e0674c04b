"""The companion as ground stations see it: an ArduCopter-compatible MAVLink vehicle.

System 1, component 1, HEARTBEAT autopilot ARDUPILOTMEGA, type QUADROTOR, copter custom
modes; MAVLink 2 out, MAVLink 1 accepted. :class:`Autopilot` is the facade that routes
each ground-station message to the piece that handles it and composes them:

- the mission micro-service (``companion.mission_protocol``), whose items are checked and
  turned into the navigator's commands by ``companion.mission_items``, and the parameter
  micro-service (``companion.param_protocol``);
- commands and guided targets (``companion.commands``): COMMAND_LONG and COMMAND_INT, each
  answered by one COMMAND_ACK to its sender at once, SET_MODE, MISSION_SET_CURRENT,
  SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT in GUIDED, guided MISSION_ITEMs;
- telemetry streams per link (``companion.telemetry``): REQUEST_DATA_STREAM,
  SET_MESSAGE_INTERVAL, REQUEST_MESSAGE;
- here: HEARTBEAT once a second of simulated time (and at least once a second of wall
  time), and right after a mode or arming change, with base_mode's custom-mode flag and
  armed bit and system_status STANDBY on the ground, ACTIVE when armed; STATUSTEXT;
  TIMESYNC; the navigator's events (mission item current and reached, take-off done,
  landed, ...) as MAVLink messages and STATUSTEXT.
- MAVLink 2 signing (``companion.signing``): ``SETUP_SIGNING`` from a ground station sets
  the key of every link (an all-zero key with a zero timestamp turns signing off); the
  winch is given the same key on the component link first, under the key it had. Once a
  key is set, frames without a good signature never reach this class (RADIO_STATUS
  aside); how many were dropped is said in a STATUSTEXT at most every
  :data:`SIGNING_NOTICE_S`.
- The winch (component 169, the ground-station process, on the component link) is routed:
  what ground stations send it goes there, and everything it sends (its HEARTBEAT with
  autopilot INVALID, WINCH_STATUS, COMMAND_ACK, STATUSTEXT) reaches every ground station
  as it was sent, except its tether fix (ODOMETRY), which goes to the navigation filter
  alone. MAV_CMD_DO_WINCH addressed to the autopilot is forwarded to it too, and
  acknowledged from component 1 when the winch has answered.

Frames at this boundary: MAVLink's local NED has its origin at the winder (ArduPilot's EKF
origin), global positions come from ``home`` (the winder's latitude, longitude and ground
altitude AMSL; the ground is flat); relative altitudes are above that ground. Inside,
everything is the inertial z-up frame (``tuavdefs.frames`` converts).
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.commands import CommandHandler
from companion.geofence import (
    FenceAction,
    FenceBreach,
    FenceParams,
    Geofence,
    check_fence_item,
)
from companion.mavlink_io import MavlinkEndpoints, Peer
from companion.mission_items import ItemRefused, mission_home, nav_command, nav_commands
from companion.mission_protocol import MissionItem, MissionProtocol
from companion.navigation import FlightMode, NavEvent, Navigator, Reason, Refusal
from companion.param_protocol import ParamDef, ParamProtocol
from companion.signing import VehicleSigning
from companion.statustext import Notice, StatusTextChunks, TextKind
from companion.telemetry import DUE_TOLERANCE_S, Telemetry, TelemetryStreams
from tuavdefs import component_link as cl
from tuavdefs import signing as sg
from tuavdefs.mav_frames import global_to_local

M = mavlink2

_WINCH_ACK_TIMEOUT_S = 0.4
#: Wall time one :meth:`Autopilot.receive` may spend handling ground-station messages [s]
#: (ArduPilot's GCS receive takes 1 ms a loop): a flood costs the control period at most
#: this, between two periods.
RECEIVE_BUDGET_S = 0.001
#: The share of wall time that reading and handling ground-station messages may take on
#: average (a credit refilled at this rate, up to :data:`RECEIVE_BUDGET_S`): a flood
#: that outruns it waits, its sockets unwatched, instead of the loop spinning on it. A
#: real-time process spinning flat out is throttled by the kernel (sched_rt_runtime_us:
#: 50 ms of every second), which is a dozen control periods unanswered.
RECEIVE_SHARE = 0.25
#: The shortest wait :meth:`Autopilot.receive_wait_s` gives for a spent credit [s].
RECEIVE_WAIT_MIN_S = 1e-4
#: Messages read and waiting beyond which the ground stations' sockets are not read.
INBOX_MAX = 2000
#: Messages parsed at one :meth:`Autopilot.receive` at most (some 15 us each; the bytes
#: beyond wait in their links' parsers).
PARSE_MAX = 32
#: The shortest wall time between two STATUSTEXTs about refused (unsigned, badly signed,
#: replayed) frames [s].
SIGNING_NOTICE_S = 5.0
#: How often the fences are checked [s of simulated time].
FENCE_CHECK_S = 0.1


class Autopilot:
    """The vehicle's MAVLink side: watch :meth:`selectables` in the control loop's
    ``select`` and hand what is readable to :meth:`receive`; call :meth:`service` at every
    control period (and after :meth:`receive` between periods).

    ``home`` is the winder's (latitude deg, longitude deg, ground altitude m AMSL);
    ``params`` the parameters ground stations may read and set; ``component`` the
    component link to the winch (or None); ``signing`` the links' signing (whose states
    ``endpoints`` and ``component`` were built on), or None for none ever; ``clock`` the
    wall clock [s] the receive budget is counted on.
    """

    def __init__(self, endpoints: MavlinkEndpoints, nav: Navigator,
                 home: tuple[float, float, float], params: list[ParamDef],
                 param_file: Any = None, component: Any = None,
                 log: Callable[[str], None] | None = None,
                 signing: VehicleSigning | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.io = endpoints
        self.signing = signing
        self._refused_said = 0
        self._refused_wall = -math.inf
        if signing is not None:
            endpoints.on_setup_signing = self._on_setup_signing
        self.nav = nav
        self.origin = tuple(float(v) for v in home)
        self.component = component
        self.log = log or (lambda text: print(f"companion: {text}", flush=True))
        self.missions = MissionProtocol(self._send_to, self.statustext,
                                        self._validate_item, self._mission_changed,
                                        validate_other=self._validate_other,
                                        on_other_changed=self._other_changed)
        self.fence = Geofence(FenceParams(), self.origin)
        """The geofence (its parameters set by the parameter table)."""
        self.rally: list[MissionItem] = []
        """The rally points uploaded (RTL ends at the nearest, or home)."""
        self._breach: FenceBreach | None = None
        self._fence_next_s = -math.inf
        self._pos_m: tuple[float, float, float] | None = None   # the last telemetry's
        inner_prearm = nav.prearm
        # ArduCopter's fence checks come with the other pre-arm checks, ARMING_CHECK or not
        nav.prearm = lambda: (inner_prearm() if inner_prearm is not None else None
                              ) or self._fence_prearm()
        self.params = ParamProtocol(params, self._send_to, self.statustext,
                                    persist_path=param_file)
        self.streams = TelemetryStreams(endpoints, nav, self.origin, self.missions)
        self.fence_changed()
        self.counters = {"commands": 0, "unsupported": 0, "rejected_targets": 0}
        self.commands = CommandHandler(endpoints, nav, self.origin, self.streams,
                                       self.counters, self.statustext, self.send_heartbeat,
                                       self._home_changed, self._forward_winch_command,
                                       self.log)
        # ground-station message type -> handler(peer, msg), after the protocols' turn
        self._handlers: dict[str, Callable[[Peer, Any], None]] = {
            "TIMESYNC": self._on_timesync, "HEARTBEAT": self._on_heartbeat,
            **self.streams.handlers(), **self.commands.handlers()}
        self._boot_wall = time.monotonic()
        self._last_hb_sim = -math.inf
        self._last_hb_wall = -math.inf
        self._chunks = StatusTextChunks()
        self._winch_pending: list[tuple[float, Peer, int, int, int]] = []
        #: the mission's DO_WINCH items sent to the winch and not yet answered (seq)
        self._mission_winch: list[int] = []
        self._winch_sink: Callable[[Any], None] | None = None
        self._gcs_sink: Callable[[], None] | None = None
        self._external_sink: Callable[[Any], None] | None = None
        self._reading_sink: Callable[[Any], None] | None = None
        self._watch: list[Any] = []
        self._watch_gen = -1
        self._watch_comp: Any = None
        self.logs: Any = None
        """The onboard-log service (``companion.log_protocol.LogProtocol``) or None."""
        self._flight_log: Any = None
        self._logged_mode: Any = None
        #: Ground-station messages read and not yet handled (:meth:`receive`'s budget).
        self._inbox: deque[tuple[Peer, Any]] = deque()
        #: Wall time left for :meth:`receive` [s] (:data:`RECEIVE_SHARE`) and when it was
        #: counted [s, ``clock``].
        self._clock = clock
        self._credit_s = RECEIVE_BUDGET_S
        self._credit_at = clock()
        self._watch_winch: list[Any] = []
        #: Logs that ended (a full disk, a lost file, a cap) and are still to be said.
        self._logs_ended: deque[str] = deque()   # appended from the log writer's thread
        if endpoints.tlog is not None:
            endpoints.tlog.on_end = self.log_ended

    # ----- sending helpers

    def _send_to(self, peer: Peer | None, msg: Any) -> None:
        self.io.send(msg, peer)
        if peer is None and self.flight_log is not None and msg.get_type() == "PARAM_VALUE":
            self.flight_log.param(msg.param_id, msg.param_value)   # an accepted change

    def statustext(self, severity: int, text: str | Refusal | Notice) -> None:
        """STATUSTEXT to every link and the process log; a text of more than 50
        characters in chunks as ArduPilot sends them (``companion.statustext``). A
        :class:`Notice` (a repeating text) is said only if the navigator's rate limit
        allows its kind now (the navigator's own events have passed it already)."""
        if isinstance(text, Notice) and not self.nav.texts.allow(text.kind,
                                                                 self.nav.time_s):
            return
        text = str(text)
        self.log(text)
        if self.flight_log is not None:
            self.flight_log.message(text)
        for data, text_id, seq in self._chunks.split(text):
            self.io.send(M.MAVLink_statustext_message(severity, data, text_id, seq))

    # ----- the loop

    def selectables(self) -> list[Any]:
        """The sockets whose input :meth:`receive` takes (the ground stations', the
        component link's), for the caller's ``select``: the same list object until they
        change (a client connects or goes); do not modify it. While the receive credit is
        spent (:meth:`receive_wait_s`) only the component link's: the ground stations'
        sockets wait, so that a flood does not wake the loop."""
        gen = self.io.generation
        comp = self.component.selectable if self.component is not None else None
        if gen != self._watch_gen or comp is not self._watch_comp:
            self._watch = [*self.io.sockets(), *([comp] if comp is not None else [])]
            self._watch_winch = [comp] if comp is not None else []
            self._watch_gen, self._watch_comp = gen, comp
        return self._watch if self._refill() > 0.0 else self._watch_winch

    def _refill(self) -> float:
        """The receive credit now [s]: what was left, plus :data:`RECEIVE_SHARE` of the
        wall time since, at most :data:`RECEIVE_BUDGET_S`."""
        now = self._clock()
        credit = min(RECEIVE_BUDGET_S,
                     self._credit_s + RECEIVE_SHARE * max(0.0, now - self._credit_at))
        self._credit_s, self._credit_at = credit, now
        return credit

    def receive_wait_s(self) -> float:
        """How long the loop may wait before :meth:`receive` has work it may do [s]: 0
        with messages waiting and credit to handle them, the time until the credit is
        back when it is spent, infinity with nothing waiting."""
        credit = self._refill()
        if credit <= 0.0:   # at least RECEIVE_WAIT_MIN_S: the credit is then positive
            return max(RECEIVE_WAIT_MIN_S, -credit / RECEIVE_SHARE)
        return 0.0 if self.backlogged else math.inf

    @property
    def backlogged(self) -> bool:
        """Whether ground-station messages wait to be handled (a flood outran the budget
        of :meth:`receive`): call it again soon, without waiting for a socket."""
        return bool(self._inbox) or self.io.unparsed

    def receive(self, ready: Iterable[Any]) -> None:
        """Take the input of the sockets in ``ready`` (found readable by a ``select`` on
        :meth:`selectables`; other objects in it are ignored): ground-station messages are
        handled (commands answered) and the winch's routed at once; what they change in
        flight applies from the next control period. Call :meth:`service` after it.

        Bounded, as ArduPilot bounds its receive: reading and handling take at most the
        credit left (:data:`RECEIVE_BUDGET_S` at most, refilled at :data:`RECEIVE_SHARE`
        of wall time); the rest wait, in order, for the next call (:attr:`backlogged`,
        :meth:`receive_wait_s`), and while :data:`INBOX_MAX` of them wait or the credit is
        spent the sockets are not read (TCP then pushes back on the sender; a UDP flood
        overflows the kernel's buffer). The winch's messages are always read."""
        credit = self._refill()
        if credit > 0.0:
            start = self._clock()
            inbox = self._inbox
            if len(inbox) < INBOX_MAX:
                inbox.extend(self.io.receive(ready, PARSE_MAX))
            end = start + credit
            while inbox:
                peer, msg = inbox.popleft()
                try:
                    self.handle(peer, msg)
                except Exception as exc:  # noqa: BLE001 - one bad message must not stop flight
                    self.log(f"error handling {msg.get_type()} from {peer}: {exc!r}")
                if self._clock() >= end:
                    break
            now = self._clock()
            self._credit_s, self._credit_at = credit - (now - start), now
        comp = self.component
        if comp is not None and comp.selectable in ready:
            self._from_winch(comp.poll())

    def service(self, telem: Telemetry | None) -> None:
        """Send what is due: at every control period with its telemetry, and (with None)
        after :meth:`receive` or when no period came for a while. Forgets links that
        closed, runs the protocols' timers and the navigator's events, sends heartbeats
        and streams, and writes out what slow TCP clients could not take before. Cheap
        when nothing is due (most periods)."""
        streams = self.streams
        if telem is not None:
            streams.telem = telem
        io = self.io
        io.expire_udp_peers()
        if io.closed_pending:
            for peer in io.pop_closed():
                self.missions.peer_closed(peer)
                self.params.peer_closed(peer)
                if self.logs is not None:
                    self.logs.peer_closed(peer)
                streams.forget(peer)
        now_wall = time.monotonic()
        self.missions.tick(now_wall)
        self.params.tick(now_wall)
        if self.logs is not None:
            self.logs.tick()
        if self._logs_ended:
            self._say_logs_ended()
        fl = self.flight_log
        if fl is not None and telem is not None:
            nav = self.nav
            if nav.mode != self._logged_mode:
                self._logged_mode = nav.mode
                fl.mode(int(nav.mode))
            fl.record(telem, nav.reference() if nav.flying else None, nav.home_m)
        if telem is not None:
            self._pos_m = telem.pos_m
        if telem is not None and telem.t_s >= self._fence_next_s:
            self._fence_next_s = telem.t_s + FENCE_CHECK_S
            self._check_fence(telem.pos_m)
        if self._winch_pending:
            self._expire_winch(now_wall)
        if self.nav.has_events:
            for kind, value in self.nav.pop_events():
                self._nav_event(kind, value)
        tm = streams.telem
        t = tm.t_s if tm is not None else -math.inf
        if (now_wall - self._last_hb_wall >= 1.0
                or t - self._last_hb_sim >= 1.0 - DUE_TOLERANCE_S):
            if self.signing is not None:
                self._signing_duties(now_wall)
            self.send_heartbeat()
        if tm is not None and (t >= streams.due_s - DUE_TOLERANCE_S
                               or io.generation != streams.generation):
            streams.send_due(t)    # something is due on some link (otherwise nothing to do)
        if io.backlogged:
            io.flush()
        if self.component is not None and self.component.backlogged:
            self.component.flush()

    @property
    def flight_log(self) -> Any:
        """This boot's onboard log (``companion.flight_log.FlightLog``) or None; its end (a
        full disk, a cap) is said as any log's (:meth:`log_ended`)."""
        return self._flight_log

    @flight_log.setter
    def flight_log(self, log: Any) -> None:
        self._flight_log = log
        if log is not None:
            log.writer.file.on_end = self.log_ended
            if log.writer.file.ended is not None:     # it could not even be opened
                self.log_ended(log.writer.file.ended)

    def log_ended(self, why: str) -> None:
        """A log of the vehicle's ended (``why``: which and what happened); said with the
        next :meth:`service` (not here: the failing write may be inside a send)."""
        self._logs_ended.append(why)

    def _say_logs_ended(self) -> None:
        while self._logs_ended:
            why = self._logs_ended.popleft()
            print(f"companion: {why}; flying on", file=sys.stderr, flush=True)
            self.statustext(M.MAV_SEVERITY_ERROR, f"Logging: {why}")

    def send_heartbeat(self) -> None:
        """A HEARTBEAT now (after a mode or arming change)."""
        nav = self.nav
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if nav.mode in (FlightMode.GUIDED, FlightMode.AUTO, FlightMode.RTL,
                        FlightMode.LOITER, FlightMode.LAND):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if nav.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        status = M.MAV_STATE_ACTIVE if nav.armed else M.MAV_STATE_STANDBY
        self.io.send(M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, int(nav.mode), status,
            3))
        self._last_hb_wall = time.monotonic()
        if self.streams.telem is not None:
            self._last_hb_sim = self.streams.telem.t_s

    # ----- routing

    def handle(self, peer: Peer, msg: Any) -> None:
        """One message from a ground station."""
        mtype = msg.get_type()
        tsys = getattr(msg, "target_system", None)
        tcomp = getattr(msg, "target_component", None)
        if tsys is not None and tsys not in (0, cl.SYSTEM_ID):
            return
        if mtype == "SETUP_SIGNING":     # the vehicle's alone: never forwarded to the winch
            return
        if tcomp == cl.WINCH_COMPONENT_ID:
            self._to_winch(msg)
            return
        if self.missions.handle(peer, msg, time.monotonic()):
            return
        if self.params.handle(peer, msg, time.monotonic()):
            return
        if self.logs is not None and self.logs.handle(peer, msg):
            return
        if tcomp is not None and tcomp not in (0, cl.AUTOPILOT_COMPONENT_ID):
            return
        handler = self._handlers.get(mtype)
        if handler is not None:
            handler(peer, msg)

    def _to_winch(self, msg: Any) -> bool:
        if self.component is None or not self.component.connected:
            return False
        self.component.send_bytes(msg.get_msgbuf())
        return True

    def _forward_winch_command(self, peer: Peer, msg: Any) -> bool:
        """Hand a MAV_CMD_DO_WINCH addressed to the autopilot to the winch, to be answered
        from the autopilot when the winch answers (or fails); False if no winch is
        connected."""
        if not self._to_winch(msg):
            return False
        self._winch_pending.append((time.monotonic(), peer, msg.get_srcSystem(),
                                    msg.get_srcComponent(), msg.command))
        return True

    def _from_winch(self, msgs: list[Any]) -> None:
        """Route what the winch sent: to every ground station, WINCH_STATUS also to the
        sink; its answer to a DO_WINCH sent to the autopilot goes back as the
        autopilot's."""
        for msg in msgs:
            if msg.get_srcComponent() != cl.WINCH_COMPONENT_ID:
                continue
            if msg.get_type() == "ODOMETRY":    # the tether fix: for the filter alone
                if self.io.tlog is not None:    # (and the tlog: the live view draws it)
                    self.io.tlog.write(msg.get_msgbuf())
                fix = cl.external_position(msg)
                if fix is not None and self._external_sink is not None:
                    self._external_sink(fix)
                continue
            if msg.get_type() == "DEBUG_FLOAT_ARRAY":   # the fix's raw reading: likewise
                reading = cl.tether_reading(msg)
                if reading is not None and self._reading_sink is not None:
                    self._reading_sink(reading)
                continue
            if msg.get_type() == "COMMAND_ACK" and msg.command == M.MAV_CMD_DO_WINCH:
                if self._mission_winch and msg.target_component == cl.AUTOPILOT_COMPONENT_ID:
                    seq = self._mission_winch.pop(0)
                    if msg.result != M.MAV_RESULT_ACCEPTED:
                        self.statustext(M.MAV_SEVERITY_WARNING,
                                        f"Mission: winch refused item {seq} ({msg.result})")
                    continue   # the autopilot's own command
                if self._winch_acked(msg):
                    continue   # answered from the autopilot, to whom it was sent
            if msg.get_type() == "WINCH_STATUS":
                # on each link's WINCH_STATUS schedule (SET_MESSAGE_INTERVAL, EXTRA3)
                self.streams.forward("WINCH_STATUS", msg.get_msgbuf())
                if self._winch_sink is not None:
                    self._winch_sink(msg)
                continue
            self.io.send_bytes(msg.get_msgbuf())

    def _expire_winch(self, now_wall: float) -> None:
        """Fail the DO_WINCH commands the winch has not answered in time."""
        keep = []
        for entry in self._winch_pending:
            t0, peer, sysid, compid, cmd = entry
            if now_wall - t0 > _WINCH_ACK_TIMEOUT_S:
                self.io.send(M.MAVLink_command_ack_message(cmd, M.MAV_RESULT_FAILED, 0, 0,
                                                           sysid, compid), peer)
                self.statustext(M.MAV_SEVERITY_WARNING,
                                Notice(TextKind.WINCH_NO_ANSWER, "Winch: no answer"))
            else:
                keep.append(entry)
        self._winch_pending = keep

    def on_external_position(self, sink: Callable[[Any], None]) -> None:
        """Call ``sink(fix)`` with every tether fix (``ODOMETRY``) the winch sends, as a
        :class:`tuavdefs.component_link.ExternalPosition`; malformed ones are dropped."""
        self._external_sink = sink

    def on_tether_reading(self, sink: Callable[[Any], None]) -> None:
        """Call ``sink(reading)`` with every raw tether reading (``DEBUG_FLOAT_ARRAY``
        "TETHER") the winch sends, as a :class:`tuavdefs.component_link.TetherReading`."""
        self._reading_sink = sink

    def on_winch_status(self, sink: Callable[[Any], None]) -> None:
        """Call ``sink(msg)`` with every WINCH_STATUS the winch sends."""
        self._winch_sink = sink

    def on_gcs_heartbeat(self, sink: Callable[[], None]) -> None:
        """Call ``sink()`` with every ground station's HEARTBEAT (MAV_TYPE_GCS)."""
        self._gcs_sink = sink

    def _on_heartbeat(self, peer: Peer, msg: Any) -> None:
        if msg.type == M.MAV_TYPE_GCS and self._gcs_sink is not None:
            self._gcs_sink()

    def _winch_acked(self, ack: Any) -> bool:
        """Answer a DO_WINCH that was sent to the autopilot with the winch's result;
        False if ``ack`` answers no such command."""
        for i, (_, peer, sysid, compid, cmd) in enumerate(self._winch_pending):
            if ack.target_system in (0, sysid) and ack.target_component in (0, compid):
                self.io.send(M.MAVLink_command_ack_message(cmd, ack.result, 0, 0, sysid,
                                                           compid), peer)
                del self._winch_pending[i]
                return True
        return False

    # ----- signing

    def _on_setup_signing(self, peer: Peer, msg: Any) -> None:
        """SETUP_SIGNING (correctly signed if signing is on: the endpoints see to that):
        the winch gets the key first, under the old one, then every link takes it."""
        assert self.signing is not None
        if msg.target_system not in (0, cl.SYSTEM_ID):
            return
        key = bytes(msg.secret_key)
        if len(key) != sg.KEY_BYTES:     # pymavlink pads and cuts: never, but bounded
            return
        off = sg.is_disable(key, msg.initial_timestamp)
        if self.component is not None and self.component.connected:
            self.component.send(M.MAVLink_setup_signing_message(
                cl.SYSTEM_ID, cl.WINCH_COMPONENT_ID, list(key), msg.initial_timestamp))
        # said under the key every ground station can check: a station with no key
        # checks nothing, one with a key checks it
        if off:
            self.statustext(M.MAV_SEVERITY_NOTICE, "Signing: off")
        self.signing.set_key(None if off else key, msg.initial_timestamp)
        if not off:
            self.statustext(M.MAV_SEVERITY_NOTICE, "Signing: key set, signed links only")

    def _signing_duties(self, now_wall: float) -> None:
        """About once a second: the timestamps kept at the clock; refused frames and
        failed key writes said."""
        signing = self.signing
        assert signing is not None
        signing.refresh()
        for exc in signing.write_errors():
            self.statustext(M.MAV_SEVERITY_ERROR, f"Signing: key not saved: {exc.strerror}")
        refused = signing.refused
        if refused != self._refused_said and now_wall - self._refused_wall >= SIGNING_NOTICE_S:
            self.statustext(M.MAV_SEVERITY_WARNING,
                            f"Signing: {refused - self._refused_said} unsigned or badly "
                            "signed frames dropped")
            self._refused_said, self._refused_wall = refused, now_wall

    # ----- time

    def _on_timesync(self, peer: Peer, msg: Any) -> None:
        if msg.tc1 == 0:
            self.io.send(M.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), peer)

    # ----- missions

    def _validate_item(self, seq: int, item: MissionItem) -> tuple[int, str] | None:
        try:
            nav_command(seq, item, self.origin, self.nav)
        except ItemRefused as exc:
            return exc.result, f"Mission: item {seq}: {exc}"
        return None

    def _mission_changed(self, items: list[MissionItem]) -> None:
        self.nav.set_mission(nav_commands(items, self.origin, self.nav))
        self.streams.mission_started = self.streams.mission_complete = False
        self.log(f"mission of {len(items) - 1} items accepted")

    def _update_mission_home(self) -> None:
        home = self.nav.home_m
        if home is None:
            return
        self.missions.set_home(mission_home(home, self.origin))

    # ----- fence and rally points

    def _validate_other(self, mission_type: int, seq: int, item: MissionItem
                        ) -> tuple[int, str] | None:
        if mission_type == M.MAV_MISSION_TYPE_FENCE:
            return check_fence_item(seq, item)
        if item.command != M.MAV_CMD_NAV_RALLY_POINT:
            return M.MAV_MISSION_UNSUPPORTED, f"Rally: item {seq}: command {item.command}"
        return None

    def _other_changed(self, mission_type: int, items: list[MissionItem]) -> str | None:
        """A fence or rally list uploaded: in use, or why not (the upload is refused with
        that text and the previous list stays)."""
        if mission_type == M.MAV_MISSION_TYPE_FENCE:
            why = self.fence.set_items(items)
            if why is not None:
                return why
            self.fence_changed()
            self.log(f"fence of {len(items)} items accepted")
        else:
            self.rally = items
            self.nav.rally_m = tuple(global_to_local(i.x * 1e-7, i.y * 1e-7, i.z, i.frame,
                                                     self.origin) for i in items)
            self.log(f"{len(items)} rally points accepted")
        return None

    def fence_changed(self) -> None:
        """The fence's parameters, items or breach changed: SYS_STATUS's geofence bits
        follow (:meth:`Geofence.sys_status`, as ArduCopter sets them)."""
        self.streams.fence_status = self.fence.sys_status(self._breach is not None)

    def _fence_prearm(self) -> Refusal | None:
        """The geofence's pre-arm check (:meth:`Geofence.pre_arm`) as a refusal."""
        why = self.fence.pre_arm(self._pos_m, self.nav.home_m)
        return None if why is None else Refusal(Reason.PREARM, f"PreArm: Fence: {why}")

    def _check_fence(self, pos_m: tuple[float, float, float]) -> None:
        """A breach begun (in flight): said, and acted on as FENCE_ACTION says (the
        tether's reach: RTL, always)."""
        nav = self.nav
        breach = (self.fence.breach(pos_m, nav.home_m, nav.tether_limit_m) if nav.flying
                  else None)
        if breach == self._breach:
            return
        self._breach = breach
        self.fence_changed()
        if breach is None:
            return
        self.statustext(M.MAV_SEVERITY_CRITICAL,
                        Notice(TextKind.FENCE_BREACH, f"Fence breach: {breach.value}"))
        action = (FenceAction.RTL if breach is FenceBreach.TETHER
                  else FenceAction(self.fence.p.action))
        if action is FenceAction.REPORT or nav.mode in (FlightMode.RTL, FlightMode.LAND):
            return
        if action is FenceAction.RTL and nav.set_mode(FlightMode.RTL) is None:
            self.send_heartbeat()
            return
        nav.failsafe_land(f"Fence breach: {breach.value}: landing")
        self.send_heartbeat()

    # ----- navigator events

    def _nav_event(self, kind: NavEvent, value: object) -> None:
        if kind == NavEvent.CURRENT:
            self.streams.mission_started, self.streams.mission_complete = True, False
            self.io.send(self.streams.mission_current())
        elif kind == NavEvent.REACHED:
            self.io.send(M.MAVLink_mission_item_reached_message(int(value)))
            self.statustext(M.MAV_SEVERITY_INFO, f"Reached command #{int(value)}")
        elif kind == NavEvent.MISSION_DONE:
            self.streams.mission_complete = True
            self.io.send(self.streams.mission_current())
            self.statustext(M.MAV_SEVERITY_INFO, "Mission: complete")
        elif kind == NavEvent.TAKEOFF_DONE:
            self.statustext(M.MAV_SEVERITY_INFO, "Takeoff complete")
        elif kind == NavEvent.LANDED:
            self.statustext(M.MAV_SEVERITY_INFO, "Landed")
        elif kind == NavEvent.ERROR:
            self.statustext(M.MAV_SEVERITY_ERROR, f"Nav: {value}"[:150])
        elif kind == NavEvent.DISARMED:
            self.statustext(M.MAV_SEVERITY_INFO, "Disarmed")
            self.send_heartbeat()
        elif kind == NavEvent.WINCH:
            self._mission_winch_command(*value)
        elif kind == NavEvent.FAILSAFE:
            self.statustext(M.MAV_SEVERITY_CRITICAL, str(value))
            self.send_heartbeat()     # the mode it may have changed
        elif kind == NavEvent.WARNING:
            self.statustext(M.MAV_SEVERITY_WARNING, str(value))

    def _mission_winch_command(self, seq: int, params: tuple[float, float, float, float]
                               ) -> None:
        """A mission's DO_WINCH item: the command to the winch, from the autopilot."""
        if self.component is None or not self.component.connected:
            self.statustext(M.MAV_SEVERITY_WARNING, f"Mission: item {seq}: no winch")
            return
        self.component.send(M.MAVLink_command_long_message(
            cl.SYSTEM_ID, cl.WINCH_COMPONENT_ID, M.MAV_CMD_DO_WINCH, 0, *params, 0.0, 0.0,
            0.0))
        self._mission_winch.append(seq)

    def armed_changed(self) -> None:
        """Call after arming on the ground: home is set there, and announced."""
        self._home_changed()
        self.send_heartbeat()

    def _home_changed(self) -> None:
        """The navigator's home moved: the mission's item 0 follows, HOME_POSITION to
        every link (once the estimate is ready: until then home is not reported, and the
        streams announce it when it is)."""
        self._update_mission_home()
        if self.streams.home_set():
            self.io.send(self.streams.home_position())
