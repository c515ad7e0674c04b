"""The companion's onboard log, as ArduCopter keeps one: a DataFlash ``.bin`` per boot in
a log directory (``00000001.BIN``, ``00000002.BIN``, ... and ``LASTLOG.TXT``, as ArduPilot
names them), with ArduPilot's message names where ArduPilot has the message.

Records (simulated time in ``TimeUS``; angles in degrees, NED/FRD as ArduPilot's):

- ``PARM`` every parameter at the start of the log and at each change (name, value);
- ``MSG`` every STATUSTEXT; ``MODE`` each mode change (name as ``M``, number, reason 0);
- at :data:`RATE_HZ` of simulated time: ``ATT`` (desired and flown roll, pitch, yaw),
  ``RATE`` (body rates [deg/s]), ``POS`` (lat, lng, altitude AMSL, above home, above
  origin [m]), ``CTUN`` (throttle out, desired and flown altitude [m], desired and flown
  climb rate [m/s]), ``RCOU`` (the four rotor outputs as PWM [us]);
- ``TETH`` (the project's own): each winch report — paid-out length [m], line speed
  [m/s], tension [N].
"""

from __future__ import annotations

import math
from pathlib import Path

from companion.dataflash import DataFlashWriter, LogFormat
from tuavdefs.frames import (
    enu_to_ned,
    flu_to_frd,
    local_enu_to_global,
    quat_enu_flu_to_ned_frd,
    quat_to_euler,
)

__all__ = ["FORMATS", "RATE_HZ", "FlightLog", "log_path", "next_log_number"]

#: Rate of the periodic records [Hz of simulated time].
RATE_HZ = 10.0
FORMATS = [
    LogFormat(64, "PARM", "QNf", "TimeUS,Name,Value"),
    LogFormat(65, "MSG", "QZ", "TimeUS,Message"),
    LogFormat(66, "MODE", "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    LogFormat(67, "ATT", "Qffffff", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw"),
    LogFormat(68, "RATE", "Qfff", "TimeUS,R,P,Y"),
    LogFormat(69, "POS", "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt"),
    LogFormat(70, "CTUN", "Qfffff", "TimeUS,ThO,DAlt,Alt,DCRt,CRt"),
    LogFormat(71, "RCOU", "QHHHH", "TimeUS,C1,C2,C3,C4"),
    LogFormat(72, "TETH", "Qfff", "TimeUS,Len,Spd,Ten"),
]


def log_path(log_dir: Path, number: int) -> Path:
    """Log ``number``'s file in ``log_dir``."""
    return Path(log_dir) / f"{number:08d}.BIN"


def next_log_number(log_dir: Path) -> int:
    """One more than the highest log number in ``log_dir`` (1 in an empty one)."""
    numbers = [int(p.stem) for p in Path(log_dir).glob("*.BIN") if p.stem.isdigit()]
    return max(numbers, default=0) + 1


class FlightLog:
    """One boot's log in ``log_dir``, global positions from ``origin`` (the winder's
    latitude deg, longitude deg, ground altitude m AMSL)."""

    def __init__(self, log_dir: Path, origin: tuple[float, float, float]) -> None:
        self.dir = Path(log_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.number = next_log_number(self.dir)
        (self.dir / "LASTLOG.TXT").write_text(f"{self.number}\n")
        self.writer = DataFlashWriter(log_path(self.dir, self.number), FORMATS)
        self.origin = origin
        self._next_s = -math.inf
        self._t_us = 0

    @property
    def path(self) -> Path:
        return self.writer.path

    def param(self, name: str, value: float) -> None:
        self.writer.write("PARM", self._t_us, name, float(value))

    def message(self, text: str) -> None:
        self.writer.write("MSG", self._t_us, text[:64])

    def mode(self, number: int) -> None:
        self.writer.write("MODE", self._t_us, number, number, 0)

    def tether(self, t_s: float, length_m: float, speed_m_s: float, tension_n: float
               ) -> None:
        self.writer.write("TETH", int(t_s * 1e6), length_m, speed_m_s, tension_n)

    def record(self, tm, ref, home_m) -> None:
        """The periodic records of telemetry ``tm`` (companion.telemetry.Telemetry) when
        due; ``ref`` the navigator's reference (None when not flying), ``home_m`` its home
        (None: unknown)."""
        self._t_us = t_us = int(tm.t_s * 1e6)
        if tm.t_s < self._next_s - 1e-6:
            return
        step = 1.0 / RATE_HZ
        due = self._next_s
        self._next_s = due + step if tm.t_s - due < step else tm.t_s + step
        w = self.writer
        roll, pitch, yaw = (math.degrees(a) for a in
                            quat_to_euler(quat_enu_flu_to_ned_frd(tm.quat)))
        des_yaw = yaw if ref is None else math.degrees(math.pi / 2 - ref.yaw_rad)
        w.write("ATT", t_us, roll, roll, pitch, pitch, des_yaw % 360.0, yaw % 360.0)
        p, q, r = (math.degrees(v) for v in flu_to_frd(tm.rates_rad_s))
        w.write("RATE", t_us, p, q, r)
        lat, lon, alt = local_enu_to_global(tm.pos_m, self.origin)
        home_z = home_m[2] if home_m is not None else 0.0
        w.write("POS", t_us, round(lat * 1e7), round(lon * 1e7), alt,
                tm.pos_m[2] - home_z, tm.pos_m[2])
        climb = -enu_to_ned(tm.vel_m_s)[2]
        d_alt, d_climb = ((tm.pos_m[2], climb) if ref is None
                          else (ref.pos_m[2], ref.vel_m_s[2]))
        w.write("CTUN", t_us, tm.throttle, d_alt, tm.pos_m[2], d_climb, climb)
        motors = tm.motors or (0.0, 0.0, 0.0, 0.0)
        w.write("RCOU", t_us, *(1000 + round(1000 * min(max(c, 0.0), 1.0)) for c in motors))

    def close(self) -> None:
        self.writer.close()
