"""Named home locations for ``tuav-sitl up --home``, in ArduPilot's ``locations.txt`` form
(``NAME=LAT,LON,ALT,HEADING``; ``#`` starts a comment): the shipped file
(``tuav_sitl/data/locations.txt``) and the user's own in the configuration directory
(``$XDG_CONFIG_HOME/tuav-sitl/locations.txt``, default ``~/.config/...``), whose names
override the shipped ones. A ``--home`` is either such a name or ``LAT,LON,ALT[,HEADING]``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["SHIPPED", "Home", "load_locations", "parse_home", "user_locations_path"]

#: The locations shipped with the package.
SHIPPED = Path(__file__).resolve().parent / "data" / "locations.txt"


@dataclass(frozen=True)
class Home:
    """Where the winder stands and how the vehicle faces at start."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    """Ground altitude AMSL [m]."""
    heading_deg: float | None = None
    """The vehicle's heading at start, clockwise from north [deg] (None: the default)."""


def user_locations_path() -> Path:
    """The user's own locations file (it need not exist)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "tuav-sitl" / "locations.txt"


def _parse_numbers(text: str) -> Home:
    """``LAT,LON,ALT[,HEADING]`` (ValueError naming what is wrong)."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (3, 4) or any(p == "" for p in parts):
        raise ValueError("expected LAT,LON,ALT[,HEADING]")
    lat, lon, alt = (float(p) for p in parts[:3])
    heading = float(parts[3]) if len(parts) == 4 else None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ValueError("latitude in -90..90 and longitude in -180..180 degrees")
    if not all(map(_finite, (alt, heading if heading is not None else 0.0))):
        raise ValueError("altitude and heading must be finite")
    return Home(lat, lon, alt, None if heading is None else heading % 360.0)


def _finite(x: float) -> bool:
    return x == x and abs(x) != float("inf")


def load_locations(paths: list[Path] | None = None) -> dict[str, Home]:
    """The named locations of ``paths`` (default: the shipped file, then the user's), the
    later overriding the earlier; a malformed line raises ValueError naming file and line."""
    found: dict[str, Home] = {}
    for path in paths if paths is not None else [SHIPPED, user_locations_path()]:
        if not path.is_file():
            continue
        for lineno, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            name, sep, value = line.partition("=")
            try:
                if not sep or not name.strip():
                    raise ValueError("expected NAME=LAT,LON,ALT,HEADING")
                found[name.strip()] = _parse_numbers(value)
            except ValueError as exc:
                raise ValueError(f"{path}:{lineno}: {exc}") from None
    return found


def parse_home(text: str, locations: dict[str, Home] | None = None) -> Home:
    """A ``--home``: a location's name or ``LAT,LON,ALT[,HEADING]``; ValueError saying what
    to write otherwise."""
    if "," in text:
        try:
            return _parse_numbers(text)
        except ValueError as exc:
            raise ValueError(f"{exc} (degrees, degrees, m AMSL, degrees from north)") \
                from None
    known = load_locations() if locations is None else locations
    if text in known:
        return known[text]
    names = ", ".join(sorted(known)) or "none"
    raise ValueError(f"no location named {text!r} (known: {names}; add your own to "
                     f"{user_locations_path()} as NAME=LAT,LON,ALT,HEADING), or give "
                     "LAT,LON,ALT[,HEADING]")
