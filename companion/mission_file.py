"""Mission files as ground stations save them: QGC WPL 110 (MAVProxy's ``wp save``,
Mission Planner's ``.waypoints``), read into and written from the mission items the mission
protocol stores (:class:`companion.mission_protocol.MissionItem`).

The format: a first line ``QGC WPL 110``, then one item a line, its fields separated by
tabs (or spaces): ``seq current frame command param1 param2 param3 param4 x y z
autocontinue``, with x and y in degrees for global frames (metres for local ones). Item 0 is
home. Blank lines and lines starting with ``#`` are skipped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from companion.mission_protocol import (
    MissionItem,
    MissionItemError,
    check_item,
    from_message,
    to_message,
)
from tuavdefs.paramspec import ParameterError

HEADER = "QGC WPL 110"
_FIELDS = 12


class MissionFileError(ParameterError):
    """A mission file that cannot be read, said with its line number (``field``: the
    file and line)."""

    def __init__(self, message: str) -> None:
        where, _, text = message.partition(": ")
        super().__init__(where, text)


class _Row:
    """A parsed line in the form pymavlink's MISSION_ITEM (float x, y) has, so that the
    mission protocol's own conversion scales it."""

    def __init__(self, values: list[float]) -> None:
        (self.seq, self.current, self.frame, self.command, self.param1, self.param2,
         self.param3, self.param4, self.x, self.y, self.z, self.autocontinue) = values

    @staticmethod
    def get_type() -> str:
        return "MISSION_ITEM"


def parse(text: str, source: str = "mission") -> list[MissionItem]:
    """The items of a QGC WPL 110 text, home (seq 0) first; MissionFileError names the
    line of anything malformed, out of sequence or refused by the mission protocol's own
    checks."""
    lines = [(n, ln.strip()) for n, ln in enumerate(text.splitlines(), start=1)]
    lines = [(n, ln) for n, ln in lines if ln and not ln.startswith("#")]
    if not lines or lines[0][1].split() != HEADER.split():
        raise MissionFileError(f"{source}: line 1: expected {HEADER!r}")
    items: list[MissionItem] = []
    for n, line in lines[1:]:
        where = f"{source}: line {n}"
        fields = line.split()
        if len(fields) != _FIELDS:
            raise MissionFileError(f"{where}: expected {_FIELDS} fields, got {len(fields)}")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise MissionFileError(f"{where}: a field is not a number") from None
        for i in (0, 1, 2, 3, 11):
            if not (math.isfinite(values[i]) and values[i].is_integer()):
                raise MissionFileError(f"{where}: field {i + 1} must be an integer")
        row = _Row(values)
        if int(row.seq) != len(items):
            raise MissionFileError(f"{where}: item {int(row.seq)} out of sequence "
                                   f"(expected {len(items)})")
        for attr in ("frame", "command", "autocontinue", "current"):
            setattr(row, attr, int(getattr(row, attr)))
        try:
            item = from_message(row)
        except MissionItemError as exc:
            raise MissionFileError(f"{where}: {exc}") from None
        bad = check_item(item)
        if bad is not None:
            raise MissionFileError(f"{where}: {bad[1]}")
        items.append(item)
    if not items:
        raise MissionFileError(f"{source}: no items (item 0 is home)")
    return items


def load(path: str | Path) -> list[MissionItem]:
    """The items of the mission file at ``path`` (see :func:`parse`)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise MissionFileError(f"{p}: {exc.strerror}") from None
    return parse(text, str(p))


def format_items(items: Sequence[MissionItem]) -> str:
    """``items`` (home first) as a QGC WPL 110 text, as MAVProxy's ``wp save`` writes it."""
    out = [HEADER]
    for seq, item in enumerate(items):
        msg = to_message(seq, item, False, 0, 0, 1 if seq == 0 else 0)
        out.append("\t".join([
            str(seq), str(msg.current), str(item.frame), str(item.command),
            *(f"{v:.8f}" for v in (item.param1, item.param2, item.param3, item.param4,
                                  msg.x, msg.y, item.z)),
            str(item.autocontinue)]))
    return "\n".join(out) + "\n"
