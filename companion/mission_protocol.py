"""The MAVLink mission micro-service of the companion, behaving as ArduCopter does.

:class:`MissionProtocol` answers ground control stations (QGroundControl, MAVProxy, MAVSDK,
pymavlink scripts) for system 1 / component 1. It is transport-free: messages come in through
:meth:`MissionProtocol.handle` with an opaque *peer* naming the link, replies leave through the
``send(peer, msg)`` callback as unpacked pymavlink messages, and :meth:`MissionProtocol.tick`
drives the re-requests and timeouts of an upload (wall-clock seconds).

Storage
    The mission is a list of :class:`MissionItem` in MISSION_ITEM_INT representation. Item 0 is
    always the home position, as in ArduPilot: a NAV_WAYPOINT in ``MAV_FRAME_GLOBAL``
    (latitude/longitude in degrees x 1e7, altitude in metres AMSL) set by
    :meth:`MissionProtocol.set_home`; before that it is all zeros, so a download then gives
    ``count`` 1. ArduPilot answers every read of item 0 with the live home and never executes
    an uploaded item 0, so an uploaded seq 0 is accepted and discarded here as well (it is not
    validated and does not move home).

Upload (GCS -> vehicle)
    MISSION_COUNT starts it; the vehicle requests every item in order with MISSION_REQUEST_INT
    (ArduPilot itself still sends the deprecated MISSION_REQUEST, but MAVSDK answers that with
    MISSION_ACK UNSUPPORTED when it does not recognise the autopilot, and QGC, MAVProxy and
    Mission Planner all handle MISSION_REQUEST_INT); once a peer has sent a float MISSION_ITEM
    it is requested in kind. Items may come as MISSION_ITEM_INT or MISSION_ITEM. A request
    unanswered for ``timeout_s`` is repeated, at most ``max_retries`` times; then, or when no
    expected item has arrived for ``timeout_s * (max_retries + 1)``, the upload ends with
    MISSION_ACK ``MAV_MISSION_OPERATION_CANCELLED`` and the STATUSTEXT "Mission upload timeout"
    (ArduPilot's answer after 8 s of silence). Choices that differ from ArduPilot, following the
    MAVLink mission-protocol specification instead:

    - uploads are atomic: the stored mission changes only when the last item has arrived and
      every item passed the checks; any failure leaves it exactly as it was (ArduPilot writes
      items as they arrive);
    - an out-of-sequence item is dropped and the expected one re-requested (ArduPilot answers
      MISSION_ACK ``MAV_MISSION_INVALID_SEQUENCE``, on which MAVSDK ends its upload as
      failed); a duplicate only triggers a re-request if the last request is older than
      :attr:`MissionProtocol.REREQUEST_HOLDOFF_S`, so a re-request that crossed a late item does
      not double every later exchange;
    - a MISSION_ACK from the uploader cancels its upload (the specification's cancellation;
      MAVSDK sends ``MAV_MISSION_OPERATION_CANCELLED``);
    - the last item re-sent after the final MISSION_ACK was lost gets that ACK again instead
      of ``MAV_MISSION_ERROR``;
    - an uploader is a (peer, system id, component id), not only the ids ArduPilot compares
      (QGC and MAVProxy both default to system 255): the same uploader may restart with a new
      MISSION_COUNT (as ArduPilot allows); while an upload is in progress any other
      MISSION_COUNT or item, and any download request, gets ``MAV_MISSION_DENIED`` and
      MISSION_CLEAR_ALL gets ``MAV_MISSION_ERROR`` (as ArduPilot).

    ``count`` 0 clears the mission; ``count`` above ``max_items`` gets ``MAV_MISSION_NO_SPACE``.
    Every item from seq 1 is converted (:func:`from_message`), checked (:func:`check_item`) and
    passed to the ``validate`` callback; the first failure ends the upload with MISSION_ACK
    carrying its result and a STATUSTEXT (``MAV_SEVERITY_WARNING``) with its reason. A complete
    upload replaces the mission, is acknowledged ``MAV_MISSION_ACCEPTED`` with the STATUSTEXT
    "Flight plan received" (``MAV_SEVERITY_INFO``, as ArduPilot) and calls ``on_changed``.

Download (vehicle -> GCS)
    MISSION_REQUEST_LIST -> MISSION_COUNT; MISSION_REQUEST_INT -> MISSION_ITEM_INT and the
    deprecated MISSION_REQUEST -> MISSION_ITEM (as ArduPilot); a seq beyond the mission ->
    MISSION_ACK ``MAV_MISSION_INVALID_SEQUENCE`` (ArduPilot sends MISSION_COUNT and
    ``MAV_MISSION_ERROR``). The GCS's closing MISSION_ACK is consumed. Downloads keep no state.

Mission types
    ``MAV_MISSION_TYPE_MISSION`` (home at seq 0), ``_FENCE`` and ``_RALLY`` (their items from
    seq 0) are each a store uploaded, downloaded and cleared with the same exchanges, one
    upload at a time; a fence or rally upload's items are checked by ``validate_other(type,
    seq, item)`` and the new list handed to ``on_other_changed(type, items)``, which may
    refuse the list as a whole (a polygon cut short): the upload is then answered
    ``MAV_MISSION_ERROR`` with its reason and the stored list stays what it was, so that
    the count a download gets is the list in use (ArduPilot refuses a fence it cannot
    write).
    ``MAV_MISSION_TYPE_ALL`` is accepted by MISSION_CLEAR_ALL only (it clears the mission;
    ArduPilot answers it ``MAV_MISSION_UNSUPPORTED``); other values get
    ``MAV_MISSION_UNSUPPORTED``.

Not handled here (``handle`` returns False): MISSION_ITEM(_INT) with ``current`` 2 (guided
"fly to") or 3 (altitude change), which ArduPilot treats as commands, not mission items, and
MISSION_SET_CURRENT. MISSION_WRITE_PARTIAL_LIST and MISSION_REQUEST_PARTIAL_LIST get
``MAV_MISSION_UNSUPPORTED``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.mav_frames import GLOBAL_FRAMES, LOCAL_FRAMES

__all__ = [
    "MissionItem", "MissionItemError", "MissionProtocol", "from_message", "to_message",
    "check_item", "home_item", "degrees_to_e7", "e7_to_degrees", "GLOBAL_FRAMES",
    "LOCAL_FRAMES",
]

SendFn = Callable[[Hashable, Any], None]
StatusTextFn = Callable[[int, str], None]
ValidateFn = Callable[[int, "MissionItem"], "tuple[int, str] | None"]
ChangedFn = Callable[[list["MissionItem"]], None]

OWN_SYSTEM_ID = 1
OWN_COMPONENT_ID = 1
INT32_MAX = 2**31 - 1
INT32_MIN = -(2**31)

_DEG_SCALE = 1e7
_LOCAL_SCALE = 1e4

_MISSION = mavlink2.MAV_MISSION_TYPE_MISSION
_FENCE = mavlink2.MAV_MISSION_TYPE_FENCE
_RALLY = mavlink2.MAV_MISSION_TYPE_RALLY
_ALL = mavlink2.MAV_MISSION_TYPE_ALL

#: Which of param1..param4 may be NaN ("use the default") per command, as ArduPilot's
#: AP_Mission accepts them; every other command must have all four finite.
_NAN_ALLOWED: dict[int, frozenset[int]] = {
    mavlink2.MAV_CMD_NAV_WAYPOINT: frozenset({4}),
    mavlink2.MAV_CMD_NAV_LAND: frozenset({4}),
    mavlink2.MAV_CMD_NAV_TAKEOFF: frozenset({4}),
    mavlink2.MAV_CMD_NAV_VTOL_TAKEOFF: frozenset({4}),
    mavlink2.MAV_CMD_NAV_VTOL_LAND: frozenset({3, 4}),
}


class MissionItemError(ValueError):
    """A mission item that cannot be stored; ``result`` is the MAV_MISSION_RESULT to send."""

    def __init__(self, result: int, reason: str) -> None:
        super().__init__(reason)
        self.result = result
        self.reason = reason


@dataclass(frozen=True)
class MissionItem:
    """One mission item as MISSION_ITEM_INT carries it, without its sequence number.

    ``command`` is a MAV_CMD and ``frame`` a MAV_FRAME. ``param1``..``param4`` and ``z`` are
    the command's float parameters (for positional frames ``z`` is the altitude or z position
    in metres). ``x``, ``y`` are integers: degrees x 1e7 in global frames, metres x 1e4 in
    local frames, the raw parameter in ``MAV_FRAME_MISSION``; ``INT32_MAX`` means "default"
    (NaN in the float message). ``autocontinue`` is 0 or 1.
    """

    command: int
    frame: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    autocontinue: int = 1


def degrees_to_e7(degrees: float) -> int:
    """Latitude or longitude in degrees -> the MAVLink integer (degrees x 1e7, rounded)."""
    return round(degrees * _DEG_SCALE)


def e7_to_degrees(value: int) -> float:
    """The MAVLink integer latitude or longitude (degrees x 1e7) -> degrees."""
    return value / _DEG_SCALE


def home_item(lat_deg: float, lon_deg: float, alt_amsl_m: float) -> MissionItem:
    """The home item ArduPilot stores at seq 0: NAV_WAYPOINT in ``MAV_FRAME_GLOBAL`` at the
    given latitude and longitude [deg] and altitude above mean sea level [m]."""
    return MissionItem(command=mavlink2.MAV_CMD_NAV_WAYPOINT, frame=mavlink2.MAV_FRAME_GLOBAL,
                       x=degrees_to_e7(lat_deg), y=degrees_to_e7(lon_deg), z=float(alt_amsl_m))


def _frame_scale(frame: int) -> float | None:
    if frame in GLOBAL_FRAMES:
        return _DEG_SCALE
    if frame in LOCAL_FRAMES:
        return _LOCAL_SCALE
    if frame == mavlink2.MAV_FRAME_MISSION:
        return 1.0
    return None


def _float_to_int(value: float, scale: float, result: int, name: str) -> int:
    if math.isnan(value):
        return INT32_MAX
    if math.isinf(value):
        raise MissionItemError(result, f"{name} is infinite")
    scaled = round(value * scale)
    if not INT32_MIN <= scaled < INT32_MAX:
        raise MissionItemError(result, f"{name} out of range")
    return scaled


def _int_to_float(value: int, scale: float) -> float:
    return math.nan if value == INT32_MAX else value / scale


def from_message(msg: Any) -> MissionItem:
    """The :class:`MissionItem` of a MISSION_ITEM_INT or MISSION_ITEM message.

    A float MISSION_ITEM is converted as the MAVLink specification says: in global frames
    latitude/longitude [deg] x 1e7, in local frames x/y [m] x 1e4, in ``MAV_FRAME_MISSION``
    unscaled, all rounded to the nearest integer; NaN becomes ``INT32_MAX``. The float
    message carries float32, so a latitude keeps only ~7 significant digits
    (47.3977419 deg arrives as 47.3977432 deg). Raises :class:`MissionItemError` if x or y
    cannot be represented (infinite, beyond int32) or the frame is unknown.
    """
    fields = dict(command=int(msg.command), frame=int(msg.frame),
                  param1=float(msg.param1), param2=float(msg.param2),
                  param3=float(msg.param3), param4=float(msg.param4),
                  z=float(msg.z), autocontinue=int(msg.autocontinue))
    if msg.get_type() == "MISSION_ITEM_INT":
        return MissionItem(x=int(msg.x), y=int(msg.y), **fields)
    scale = _frame_scale(fields["frame"])
    if scale is None:
        raise MissionItemError(mavlink2.MAV_MISSION_UNSUPPORTED_FRAME,
                               f"unknown frame {fields['frame']}")
    x = _float_to_int(float(msg.x), scale, mavlink2.MAV_MISSION_INVALID_PARAM5_X, "x")
    y = _float_to_int(float(msg.y), scale, mavlink2.MAV_MISSION_INVALID_PARAM6_Y, "y")
    return MissionItem(x=x, y=y, **fields)


def to_message(seq: int, item: MissionItem, int_variant: bool, target_system: int,
               target_component: int, current: int,
               mission_type: int = _MISSION) -> Any:
    """``item`` at ``seq`` as MISSION_ITEM_INT (``int_variant``) or MISSION_ITEM.

    The float variant undoes :func:`from_message`'s scaling (``INT32_MAX`` -> NaN).
    """
    common = dict(target_system=target_system, target_component=target_component, seq=seq,
                  frame=item.frame, command=item.command, current=current,
                  autocontinue=item.autocontinue, param1=item.param1, param2=item.param2,
                  param3=item.param3, param4=item.param4, z=item.z, mission_type=mission_type)
    if int_variant:
        return mavlink2.MAVLink_mission_item_int_message(x=item.x, y=item.y, **common)
    scale = _frame_scale(item.frame) or 1.0
    return mavlink2.MAVLink_mission_item_message(x=_int_to_float(item.x, scale),
                                                 y=_int_to_float(item.y, scale), **common)


def check_item(item: MissionItem) -> tuple[int, str] | None:
    """The checks every stored item passes, whatever its command; None if it passes.

    As ArduPilot's AP_Mission: param1..param4 finite, except the NaN ("default") it allows
    for NAV_WAYPOINT, NAV_LAND, NAV_TAKEOFF, NAV_VTOL_TAKEOFF (param4) and NAV_VTOL_LAND
    (param3, param4); command 0 is invalid; latitude within +-90 deg and longitude within
    +-180 deg in global frames (``INT32_MAX``, "default", allowed). Also: the frame is a known
    MAV_FRAME, ``z`` is finite (NaN allowed only in ``MAV_FRAME_MISSION``) and
    ``autocontinue`` is 0 or 1. Command-specific checks are the ``validate`` callback's.
    """
    if item.command == 0:
        return mavlink2.MAV_MISSION_INVALID, "command 0 is invalid"
    nan_ok = _NAN_ALLOWED.get(item.command, frozenset())
    params = (item.param1, item.param2, item.param3, item.param4)
    for n, value in enumerate(params, start=1):
        if math.isinf(value) or (math.isnan(value) and n not in nan_ok):
            return mavlink2.MAV_MISSION_INVALID_PARAM1 + n - 1, f"param{n} is {value}"
    scale = _frame_scale(item.frame)
    if scale is None:
        return mavlink2.MAV_MISSION_UNSUPPORTED_FRAME, f"unknown frame {item.frame}"
    if math.isinf(item.z) or (math.isnan(item.z) and item.frame != mavlink2.MAV_FRAME_MISSION):
        return mavlink2.MAV_MISSION_INVALID_PARAM7, f"z is {item.z}"
    if item.frame in GLOBAL_FRAMES:
        if item.x != INT32_MAX and not -90 * _DEG_SCALE <= item.x <= 90 * _DEG_SCALE:
            return mavlink2.MAV_MISSION_INVALID_PARAM5_X, "latitude out of range"
        if item.y != INT32_MAX and not -180 * _DEG_SCALE <= item.y <= 180 * _DEG_SCALE:
            return mavlink2.MAV_MISSION_INVALID_PARAM6_Y, "longitude out of range"
    if item.autocontinue not in (0, 1):
        return mavlink2.MAV_MISSION_INVALID, "autocontinue must be 0 or 1"
    return None


@dataclass
class _Upload:
    """An upload in progress: who sends it and what has arrived (seq 1.. in ``received``)."""

    peer: Hashable
    sysid: int
    compid: int
    count: int
    expected: int = 0
    received: list[MissionItem] = dataclasses.field(default_factory=list)
    float_peer: bool = False
    last_request_s: float = 0.0
    last_progress_s: float = 0.0
    retries: int = 0
    mission_type: int = _MISSION


@dataclass(frozen=True)
class _Finished:
    """The last completed upload, to answer its last item again if the final ACK was lost."""

    peer: Hashable
    sysid: int
    compid: int
    last_seq: int
    time_s: float
    mission_type: int = _MISSION


class MissionProtocol:
    """The vehicle side of the MAVLink mission protocol (see the module docstring).

    ``send(peer, msg)`` delivers a reply; ``statustext(severity, text)`` raises a STATUSTEXT;
    ``validate(seq, item)`` returns None or ``(MAV_MISSION_RESULT, reason)`` for each uploaded
    item from seq 1; ``on_changed(items)`` receives the new mission (home first) after a
    complete upload or a clear. ``timeout_s`` [s] is the wait before an upload request is
    repeated, at most ``max_retries`` times; ``max_items`` bounds MISSION_COUNT.
    """

    #: A request repeated because of an out-of-sequence item waits at least this long after
    #: the previous request [s].
    REREQUEST_HOLDOFF_S = 0.1

    def __init__(self, send: SendFn, statustext: StatusTextFn, validate: ValidateFn,
                 on_changed: ChangedFn, *, timeout_s: float = 1.5, max_retries: int = 5,
                 max_items: int = 700,
                 validate_other: Callable[[int, int, MissionItem], tuple[int, str] | None]
                 | None = None,
                 on_other_changed: Callable[[int, list[MissionItem]], str | None] | None
                 = None
                 ) -> None:
        if timeout_s <= 0 or max_retries < 0 or max_items < 1:
            raise ValueError("timeout_s must be > 0, max_retries >= 0, max_items >= 1")
        self._send = send
        self._statustext = statustext
        self._validate = validate
        self._on_changed = on_changed
        self.timeout_s = float(timeout_s)
        self.max_retries = int(max_retries)
        self.max_items = int(max_items)
        self._home = MissionItem(command=mavlink2.MAV_CMD_NAV_WAYPOINT,
                                 frame=mavlink2.MAV_FRAME_GLOBAL)
        self._body: list[MissionItem] = []
        self._other: dict[int, list[MissionItem]] = {_FENCE: [], _RALLY: []}
        self._validate_other = validate_other
        self._on_other_changed = on_other_changed or (lambda _t, _items: None)
        self._upload: _Upload | None = None
        self._finished: _Finished | None = None
        #: Seq reported with ``current`` = 1 in downloads (None: no item is current).
        self.current_seq: int | None = None

    # --- state -------------------------------------------------------------------------

    @property
    def items(self) -> list[MissionItem]:
        """The mission, home at index 0 (a copy)."""
        return [self._home, *self._body]

    def stored(self, mission_type: int) -> list[MissionItem]:
        """The fence's or the rally points' items (a copy)."""
        return list(self._other[mission_type])

    @property
    def home(self) -> MissionItem:
        """Item 0, the home position."""
        return self._home

    def set_home(self, item: MissionItem) -> None:
        """Replace item 0 (see :func:`home_item`); does not call ``on_changed``."""
        self._home = item

    @property
    def upload_in_progress(self) -> bool:
        """True while a GCS is uploading a mission."""
        return self._upload is not None

    # --- entry points ------------------------------------------------------------------

    def handle(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        """Process one message from ``peer`` at wall-clock time ``now_s`` [s].

        Returns True when the message belonged to this service (and was consumed).
        """
        handler = self._HANDLERS.get(msg.get_type())
        if handler is None:
            return False
        if (getattr(msg, "target_system", None) not in (0, OWN_SYSTEM_ID)
                or getattr(msg, "target_component", None) not in (0, OWN_COMPONENT_ID)):
            return False
        return handler(self, peer, msg, float(now_s))

    def tick(self, now_s: float) -> None:
        """Repeat an unanswered upload request or give the upload up; call often (>= 10 Hz)."""
        up = self._upload
        if up is None:
            return
        if now_s - up.last_progress_s > self.timeout_s * (self.max_retries + 1):
            self._give_up(up)
        elif now_s - up.last_request_s >= self.timeout_s:
            if up.retries >= self.max_retries:
                self._give_up(up)
            else:
                up.retries += 1
                self._request(up, now_s)

    def peer_closed(self, peer: Hashable) -> None:
        """Forget an upload from a link that has gone (the GCS cannot be answered)."""
        if self._upload is not None and self._upload.peer == peer:
            self._upload = None

    # --- handlers ----------------------------------------------------------------------

    def _on_request_list(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        mtype = msg.mission_type
        if mtype in (_FENCE, _RALLY):
            self._reply_count(peer, msg, len(self._other[mtype]), mtype)
        elif mtype != _MISSION:
            self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, mtype)
        elif self._upload is not None:
            self._ack(peer, msg, mavlink2.MAV_MISSION_DENIED, mtype)
        else:
            self._reply_count(peer, msg, 1 + len(self._body), mtype)
        return True

    def _on_request(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        mtype = msg.mission_type
        if mtype in (_FENCE, _RALLY):
            store = self._other[mtype]
            if not 0 <= msg.seq < len(store):
                self._ack(peer, msg, mavlink2.MAV_MISSION_INVALID_SEQUENCE, mtype)
            else:
                sysid, compid = _source(msg)
                self._send(peer, to_message(msg.seq, store[msg.seq],
                                            msg.get_type() == "MISSION_REQUEST_INT", sysid,
                                            compid, 0, mtype))
        elif mtype != _MISSION:
            self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, mtype)
        elif self._upload is not None:
            self._ack(peer, msg, mavlink2.MAV_MISSION_DENIED, mtype)
        elif not 0 <= msg.seq <= len(self._body):
            self._ack(peer, msg, mavlink2.MAV_MISSION_INVALID_SEQUENCE, mtype)
        else:
            item = self._home if msg.seq == 0 else self._body[msg.seq - 1]
            sysid, compid = _source(msg)
            current = int(self.current_seq is not None and msg.seq == self.current_seq)
            self._send(peer, to_message(msg.seq, item, msg.get_type() == "MISSION_REQUEST_INT",
                                        sysid, compid, current, mtype))
        return True

    def _on_count(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        mtype = msg.mission_type
        if mtype not in (_MISSION, _FENCE, _RALLY):
            self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, mtype)
            return True
        sysid, compid = _source(msg)
        up = self._upload
        if up is not None:
            if (up.peer, up.sysid, up.compid) != (peer, sysid, compid):
                self._ack(peer, msg, mavlink2.MAV_MISSION_DENIED, mtype)
                return True
            self._upload = None  # the uploader restarts
        if msg.count > self.max_items:
            self._statustext(mavlink2.MAV_SEVERITY_WARNING,
                             f"Only {self.max_items} items are supported")
            self._ack(peer, msg, mavlink2.MAV_MISSION_NO_SPACE, mtype)
            return True
        self._finished = None
        if msg.count == 0:
            self._ack(peer, msg, mavlink2.MAV_MISSION_ACCEPTED, mtype)
            self._store(mtype, [])
            return True
        up = _Upload(peer=peer, sysid=sysid, compid=compid, count=msg.count,
                     last_progress_s=now_s, mission_type=mtype)
        self._upload = up
        self._request(up, now_s)
        return True

    def _on_item(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        mtype = msg.mission_type
        if mtype == _MISSION and msg.current in (2, 3):
            return False  # a guided-mode target or altitude change, not a mission item
        if mtype not in (_MISSION, _FENCE, _RALLY):
            self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, mtype)
            return True
        sysid, compid = _source(msg)
        up = self._upload
        if up is None:
            fin = self._finished
            if (fin is not None and (fin.peer, fin.sysid, fin.compid) == (peer, sysid, compid)
                    and msg.seq == fin.last_seq and mtype == fin.mission_type
                    and now_s - fin.time_s <= self.timeout_s * (self.max_retries + 1)):
                self._ack(peer, msg, mavlink2.MAV_MISSION_ACCEPTED, mtype)
            else:
                self._ack(peer, msg, mavlink2.MAV_MISSION_ERROR, mtype)
            return True
        if (up.peer, up.sysid, up.compid) != (peer, sysid, compid) or mtype != up.mission_type:
            self._ack(peer, msg, mavlink2.MAV_MISSION_DENIED, mtype)
            return True
        if msg.get_type() == "MISSION_ITEM":
            up.float_peer = True
        if msg.seq != up.expected:
            if now_s - up.last_request_s >= self.REREQUEST_HOLDOFF_S:
                self._request(up, now_s)
            return True
        if msg.seq > 0 or mtype != _MISSION:
            try:
                item = from_message(msg)
            except MissionItemError as exc:
                self._abort(up, exc.result, f"Mission item {msg.seq}: {exc.reason}")
                return True
            problem = check_item(item)
            if problem is not None:
                self._abort(up, problem[0], f"Mission item {msg.seq}: {problem[1]}")
                return True
            try:
                problem = (self._validate(msg.seq, item) if mtype == _MISSION
                           else self._validate_other(mtype, msg.seq, item)
                           if self._validate_other is not None else None)
            except Exception as exc:  # a validator tripping on odd content rejects the item
                problem = (mavlink2.MAV_MISSION_ERROR, f"Mission item {msg.seq}: {exc}")
            if problem is not None:
                self._abort(up, int(problem[0]), str(problem[1]))
                return True
            up.received.append(item)
        up.expected += 1
        up.retries = 0
        up.last_progress_s = now_s
        if up.expected < up.count:
            self._request(up, now_s)
            return True
        if mtype != _MISSION:
            why = self._on_other_changed(mtype, list(up.received))
            if why is not None:      # the list as a whole cannot be used: the old one stays
                self._abort(up, mavlink2.MAV_MISSION_ERROR, why)
                return True
        self._upload = None
        self._finished = _Finished(peer, sysid, compid, up.count - 1, now_s, mtype)
        self._ack(peer, msg, mavlink2.MAV_MISSION_ACCEPTED, mtype)
        if mtype == _MISSION:
            self._statustext(mavlink2.MAV_SEVERITY_INFO, "Flight plan received")
            self._store(mtype, up.received)
        else:
            self._other[mtype] = up.received
        return True

    def _store(self, mtype: int, items: list[MissionItem]) -> None:
        """Keep a complete upload (or a clear) of ``mtype`` and say it changed."""
        if mtype == _MISSION:
            self._body = items
            self._on_changed(self.items)
        elif self._on_other_changed(mtype, list(items)) is None:
            self._other[mtype] = items

    def _on_ack(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        up = self._upload
        if (up is not None and msg.mission_type == up.mission_type
                and (up.peer, up.sysid, up.compid) == (peer, *_source(msg))):
            self._upload = None  # the uploader cancelled
        return True

    def _on_clear_all(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        mtype = msg.mission_type
        if mtype in (_FENCE, _RALLY) and self._upload is None:
            self._ack(peer, msg, mavlink2.MAV_MISSION_ACCEPTED, mtype)
            self._store(mtype, [])
        elif mtype not in (_MISSION, _FENCE, _RALLY, _ALL):
            self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, mtype)
        elif self._upload is not None:
            self._ack(peer, msg, mavlink2.MAV_MISSION_ERROR, mtype)
        else:
            self._body = []
            self._finished = None
            self._ack(peer, msg, mavlink2.MAV_MISSION_ACCEPTED, mtype)
            self._on_changed(self.items)
        return True

    def _on_partial(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        self._ack(peer, msg, mavlink2.MAV_MISSION_UNSUPPORTED, msg.mission_type)
        return True

    _HANDLERS: dict[str, Callable[[MissionProtocol, Hashable, Any, float], bool]] = {
        "MISSION_REQUEST_LIST": _on_request_list,
        "MISSION_REQUEST_INT": _on_request,
        "MISSION_REQUEST": _on_request,
        "MISSION_COUNT": _on_count,
        "MISSION_ITEM_INT": _on_item,
        "MISSION_ITEM": _on_item,
        "MISSION_ACK": _on_ack,
        "MISSION_CLEAR_ALL": _on_clear_all,
        "MISSION_WRITE_PARTIAL_LIST": _on_partial,
        "MISSION_REQUEST_PARTIAL_LIST": _on_partial,
    }

    # --- replies -----------------------------------------------------------------------

    def _ack(self, peer: Hashable, msg: Any, result: int, mission_type: int) -> None:
        sysid, compid = _source(msg)
        self._send(peer, mavlink2.MAVLink_mission_ack_message(sysid, compid, result,
                                                              mission_type))

    def _reply_count(self, peer: Hashable, msg: Any, count: int, mission_type: int) -> None:
        sysid, compid = _source(msg)
        self._send(peer, mavlink2.MAVLink_mission_count_message(sysid, compid, count,
                                                                mission_type))

    def _request(self, up: _Upload, now_s: float) -> None:
        cls = (mavlink2.MAVLink_mission_request_message if up.float_peer
               else mavlink2.MAVLink_mission_request_int_message)
        self._send(up.peer, cls(up.sysid, up.compid, up.expected, up.mission_type))
        up.last_request_s = now_s

    def _abort(self, up: _Upload, result: int, reason: str) -> None:
        self._upload = None
        self._send(up.peer, mavlink2.MAVLink_mission_ack_message(up.sysid, up.compid, result,
                                                                 up.mission_type))
        self._statustext(mavlink2.MAV_SEVERITY_WARNING, reason)

    def _give_up(self, up: _Upload) -> None:
        self._abort(up, mavlink2.MAV_MISSION_OPERATION_CANCELLED, "Mission upload timeout")


def _source(msg: Any) -> tuple[int, int]:
    """(system id, component id) of a message's sender, for replies' targets."""
    return int(msg.get_srcSystem() or 0), int(msg.get_srcComponent() or 0)
