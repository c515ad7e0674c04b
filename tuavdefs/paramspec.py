"""Typed, frozen parameter dataclasses with units, bounds and TOML loading.

Every parameter group in the project derives from :class:`Params`. Each field is declared
with :func:`quantity`, which records its SI unit, its bounds and a one-line description.
Values are checked when the dataclass is built, so an invalid parameter fails at load time
with a :class:`ParameterError` whose message names the offending field (dotted path from
the TOML file's top level, e.g. ``vehicle.mass_kg``).

Supported field types: ``float``, ``int``, ``bool``, ``str`` (optionally with ``choices``),
fixed-length ``tuple[float, ...]`` (declare ``length``), nested :class:`Params`, and
``tuple[SomeParams, ...]`` for TOML arrays of tables.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import sys
import tomllib
import typing
from pathlib import Path
from typing import Any, Self

__all__ = ["ParameterError", "Params", "quantity", "load_toml", "load_option", "to_dict",
           "describe", "toml_line"]


class ParameterError(ValueError):
    """A parameter is missing, unknown, of the wrong type or out of bounds.

    ``field`` holds the dotted name of the offending field and ``reason`` what is wrong with
    it; ``source`` and ``line`` (1-based), where known, the file and the line it was read
    from (the message then starts ``FILE:LINE:``, as compilers say it).
    """

    def __init__(self, field: str, message: str, *, source: str | None = None,
                 line: int | None = None) -> None:
        where = ("" if source is None else f"{source}:{line}: " if line is not None
                 else f"{source}: ")
        super().__init__(f"{where}{field}: {message}")
        self.field = field
        self.reason = message
        self.source = source
        self.line = line

    def located(self, source: str, line: int | None) -> ParameterError:
        """The same error, said as read from ``source`` at ``line`` (None: unknown)."""
        return ParameterError(self.field, self.reason, source=source, line=line)


def quantity(
    default: Any,
    unit: str,
    doc: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    length: int | None = None,
    choices: tuple[str, ...] | None = None,
) -> Any:
    """Declare a parameter field with its default, SI unit, description and bounds.

    Bounds apply to scalars and to every element of a tuple. ``length`` fixes a tuple's
    length; ``choices`` restricts a string.
    """
    meta = {"unit": unit, "doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le,
            "length": length, "choices": choices}
    if isinstance(default, (list, tuple)):
        frozen = tuple(default)
        return dataclasses.field(default_factory=lambda: frozen, metadata=meta)
    if isinstance(default, Params):
        return dataclasses.field(default_factory=lambda: default, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _check_number(name: str, value: Any, meta: dict[str, Any], want: type) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(name, f"expected a number, got {value!r}")
    if want is int:
        if isinstance(value, float) and not value.is_integer():
            raise ParameterError(name, f"expected an integer, got {value!r}")
        value = int(value)
    else:
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(name, f"must be finite, got {value!r}")
    unit = meta.get("unit") or ""
    suffix = f" {unit}" if unit and unit != "1" else ""
    if meta.get("gt") is not None and not value > meta["gt"]:
        raise ParameterError(name, f"must be > {meta['gt']}{suffix}, got {value!r}")
    if meta.get("ge") is not None and not value >= meta["ge"]:
        raise ParameterError(name, f"must be >= {meta['ge']}{suffix}, got {value!r}")
    if meta.get("lt") is not None and not value < meta["lt"]:
        raise ParameterError(name, f"must be < {meta['lt']}{suffix}, got {value!r}")
    if meta.get("le") is not None and not value <= meta["le"]:
        raise ParameterError(name, f"must be <= {meta['le']}{suffix}, got {value!r}")
    return value


def _coerce(name: str, tp: Any, value: Any, meta: dict[str, Any]) -> Any:
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and issubclass(tp, Params):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise ParameterError(name, f"expected a table, got {value!r}")
        return tp.from_dict(value, prefix=name)
    if origin is tuple:
        args = typing.get_args(tp)
        elem = args[0]
        if not isinstance(value, (list, tuple)):
            raise ParameterError(name, f"expected an array, got {value!r}")
        if meta.get("length") is not None and len(value) != meta["length"]:
            raise ParameterError(
                name, f"expected {meta['length']} elements, got {len(value)}")
        return tuple(_coerce(f"{name}[{i}]", elem, v, meta) for i, v in enumerate(value))
    if tp is bool:
        if not isinstance(value, bool):
            raise ParameterError(name, f"expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ParameterError(name, f"expected a string, got {value!r}")
        choices = meta.get("choices")
        if choices and value not in choices:
            raise ParameterError(name, f"must be one of {', '.join(choices)}; got {value!r}")
        return value
    if tp in (int, float):
        return _check_number(name, value, meta, tp)
    raise TypeError(f"{name}: unsupported parameter type {tp!r}")  # a bug, not bad input


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    """A parameter class's field types, resolved once (``typing.get_type_hints`` compiles
    every string annotation anew: most of a PARAM_SET's cost, a flood's load)."""
    return typing.get_type_hints(cls)


@dataclasses.dataclass(frozen=True)
class Params:
    """Base class of every parameter group: validates itself on construction."""

    def __post_init__(self) -> None:
        hints = _type_hints(type(self))
        prefix = getattr(self, "_prefix", None) or type(self).__name__
        for f in dataclasses.fields(self):
            value = _coerce(f"{prefix}.{f.name}", hints[f.name], getattr(self, f.name),
                            dict(f.metadata))
            object.__setattr__(self, f.name, value)
        try:
            self.check()
        except ParameterError:
            raise
        except ValueError as exc:  # cross-field checks raise ValueError("field: reason")
            field_name, _, reason = str(exc).partition(": ")
            raise ParameterError(f"{prefix}.{field_name}", reason) from None

    def check(self) -> None:
        """Cross-field consistency checks; raise ``ValueError("field: reason")``."""

    @classmethod
    def from_dict(cls, data: dict[str, Any], prefix: str | None = None) -> Self:
        """Build from a mapping (a TOML table), rejecting unknown keys by name."""
        prefix = prefix or cls.__name__
        names = {f.name for f in dataclasses.fields(cls)}
        for key in data:
            if key not in names:
                raise ParameterError(f"{prefix}.{key}", f"unknown parameter (known: "
                                     f"{', '.join(sorted(names))})")
        hints = _type_hints(cls)
        kwargs = {}
        for f in dataclasses.fields(cls):
            if f.name in data:
                kwargs[f.name] = _coerce(f"{prefix}.{f.name}", hints[f.name], data[f.name],
                                         dict(f.metadata))
        obj = cls.__new__(cls)
        object.__setattr__(obj, "_prefix", prefix)
        try:
            cls.__init__(obj, **kwargs)
        finally:
            object.__delattr__(obj, "_prefix")
        return obj

    def replace(self, **changes: Any) -> Self:
        """A copy with some fields changed, validated like any other."""
        return dataclasses.replace(self, **changes)


def load_toml(cls: type[Params], path: str | Path, table: str | None = None) -> Params:
    """Load ``cls`` from a TOML file (optionally from one of its tables).

    Raises :class:`ParameterError` naming the field for any bad value, and for a file that
    is not valid TOML.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(str(path), f"cannot read it: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = _TOML_AT.search(str(exc))
        line = (int(where.group(1)) if where else
                max(len(text.splitlines()), 1) if "end of document" in str(exc) else None)
        raise ParameterError("(syntax)", f"not valid TOML: {exc}", source=str(path),
                             line=line) from None
    prefix = table or path.stem
    if table is not None:
        if table not in data:
            raise ParameterError(table, "table missing", source=str(path))
        data = data[table]
    try:
        return cls.from_dict(data, prefix=prefix)
    except ParameterError as exc:
        keys = _field_keys(exc.field, prefix)
        if table is not None:
            keys = (table, *keys)
        raise exc.located(str(path), toml_line(text, keys)) from None


#: Where tomllib says a syntax error is: "(at line 3, column 7)".
_TOML_AT = re.compile(r"at line (\d+)")
#: A TOML table header: ``[a.b]`` or ``[[a.b]]``.
_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
#: The key of a ``key = value`` line (bare, dotted or quoted).
_KEY = re.compile(r"""^\s*((?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*')"""
                  r"""(?:\s*\.\s*(?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*'))*)\s*=""")


def _split_key(key: str) -> list[str]:
    """The parts of a dotted TOML key, quotes removed."""
    parts = re.findall(r"""[A-Za-z0-9_-]+|"[^"]*"|'[^']*'""", key)
    return [p[1:-1] if p[:1] in "\"'" else p for p in parts]


def _field_keys(field: str, prefix: str) -> tuple[str, ...]:
    """A ParameterError's dotted field (``stem.a.b[2].c``) as TOML key parts
    (``("a", "b[2]", "c")``), the loader's prefix removed."""
    rest = field[len(prefix) + 1:] if field.startswith(prefix + ".") else field
    return tuple(p for p in rest.split(".") if p)


def toml_line(text: str, keys: tuple[str, ...]) -> int | None:
    """The 1-based line of ``text`` (a TOML document) that sets the key ``keys`` (parts as
    :class:`ParameterError` names them: an array of tables' entries as ``name[i]``), or of
    the nearest enclosing key or table that appears in the text; None if nothing does.

    A line scanner, not a parser: it follows table headers and ``key =`` lines, which is
    what a file's author reads; a key inside an inline table or a multi-line value is found
    through the line of the key that holds it."""
    lines: dict[tuple[str, ...], int] = {}
    counts: dict[tuple[str, ...], int] = {}
    table: tuple[str, ...] = ()
    for n, raw in enumerate(text.splitlines(), start=1):
        header = _HEADER.match(raw)
        if header:
            parts = _split_key(header.group(2))
            resolved: list[str] = []
            for i, part in enumerate(parts):
                plain = (*[r.split("[")[0] for r in resolved], part)
                if i < len(parts) - 1 and plain in counts:
                    part = f"{part}[{counts[plain] - 1}]"
                resolved.append(part)
            if header.group(1) == "[[":
                plain = tuple(r.split("[")[0] for r in resolved)
                counts[plain] = counts.get(plain, 0) + 1
                resolved[-1] = f"{resolved[-1]}[{counts[plain] - 1}]"
            table = tuple(resolved)
            lines.setdefault(table, n)
            continue
        key = _KEY.match(raw)
        if key:
            lines.setdefault((*table, *_split_key(key.group(1))), n)
    for k in range(len(keys), 0, -1):
        head = keys[:k]
        for candidate in (head, (*head[:-1], head[-1].split("[")[0])):
            if candidate in lines:
                return lines[candidate]
    return None


def load_option(cls: type[Params], path: str | None, prog: str) -> Params:
    """A process's parameter option: ``cls()`` (the defaults) when ``path`` is None, else
    the TOML file. A bad parameter prints ``PROG: bad parameter: FIELD: why`` on stderr and
    exits with code 2, as every process of the stack does."""
    try:
        return cls() if path is None else load_toml(cls, Path(path))
    except ParameterError as exc:
        print(f"{prog}: bad parameter: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


def to_dict(params: Params) -> dict[str, Any]:
    """The parameters as plain TOML-ready values (tuples become lists)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if isinstance(v, Params):
            out[f.name] = to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = [to_dict(e) if isinstance(e, Params) else e for e in v]
        else:
            out[f.name] = v
    return out


def describe(cls: type[Params]) -> list[tuple[str, str, str, Any]]:
    """(name, unit, description, default) for each field: the parameter table in docs."""
    rows = []
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        rows.append((f.name, f.metadata.get("unit", ""), f.metadata.get("doc", ""), default))
    return rows
