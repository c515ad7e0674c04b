"""Faults the plant injects: the truth side of a failure, over windows of simulated time
(a scenario's ``[[faults]]``) or set at run time through the ``SIM_*`` parameters any
ground station can set (:mod:`tuavdefs.sim_params`), as ArduPilot's SITL injects them.

A :class:`FaultParams` is one fault over a window of simulated time (``start_s`` to
``end_s``); :class:`FaultSchedule` applies a list of them, and the run-time parameters
(:meth:`FaultSchedule.set_sim`), to a plant every control period
(:meth:`FaultSchedule.apply`), in the offline runner and in the plant process alike
(scenario ``[[faults]]``, ``python -m sitl --faults FILE``, ``tuav-sitl up --faults FILE``).
A scheduled fault and a parameter act together (the worse of the two):

- ``gnss_loss``: the receiver delivers no fix (``SIM_GPS_DISABLE``): no HIL_GPS on the
  simulator link;
- ``wind``: the mean wind becomes ``wind_speed_m_s`` from ``wind_from_deg`` (the compass
  direction it blows from, at the profile's reference height) with the Dryden intensity
  ``turbulence``; the scenario's wind returns at the end (``SIM_WIND_SPD``,
  ``SIM_WIND_DIR``, ``SIM_WIND_TURB`` set the mean wind and the turbulence's W20 from the
  moment one of them is set; a scheduled wind fault overrides them while it lasts);
- ``motor``: rotor ``motor`` (0-3, tuavdefs.airframe's order) gives ``thrust_multiplier``
  of its commanded output (``SIM_ENGINE_FAIL``, a bitmask, with ``SIM_ENGINE_MUL``);
- ``winder_motor``: the winder's motor produces no torque (its drive failed; the brake stays
  as the drive last set it; ``SIM_TUAV_WDRFAIL``);
- ``can_loss``: the winder's CAN bus carries nothing, either way (the axis's watchdog then
  disarms it: the drum brakes; the ground station hears no encoder and its winch reports
  unhealthy);
- ``can``: each frame of the winder's bus, either way, is lost with ``drop_probability``
  (seeded, reproducible) and arrives ``delay_ms`` of simulated time late
  (``SIM_TUAV_CANDROP``, ``SIM_TUAV_CANDLY``; a drop probability of 1 is ``can_loss``);
- ``tether_snag``: the tether catches at the winder's exit (the fairlead's guide jams it):
  the line there can move neither way, so the length paid out to the UAV is pinned at its
  value when the snag begins. The drum, coupled to the line, stops dead at that angle (its
  hard stops close on it: winding in stalls the motor against the jammed line, paying out
  pushes no line out); the UAV flies on a fixed length of line anchored at the exit, the
  load cell still reads the line's tension. At the end the drum's stops open again
  (``SIM_TUAV_SNAG``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, replace
from enum import Enum
from typing import NamedTuple, Protocol

from sitl.plant import Plant
from sitl.wind import W20_DEFAULT_M_S
from tuavdefs.params import WindParams
from tuavdefs.paramspec import Params, quantity
from tuavdefs.sim_params import SIM_PARAMS, check_sim_param

#: ``end_s`` of a fault that never ends [s] (TOML has no infinity the loader takes).
NEVER_S = 1.0e9


class FaultKind(Enum):
    """What fails (module docstring)."""

    GNSS_LOSS = "gnss_loss"
    WIND = "wind"
    MOTOR = "motor"
    WINDER_MOTOR = "winder_motor"
    CAN_LOSS = "can_loss"
    CAN = "can"
    TETHER_SNAG = "tether_snag"


@dataclass(frozen=True)
class FaultParams(Params):
    """One fault from ``start_s`` to ``end_s`` [s] of simulated time."""

    kind: str = quantity("gnss_loss", "", "what fails: " + ", ".join(k.value for k in FaultKind),
                         choices=tuple(k.value for k in FaultKind))
    start_s: float = quantity(0.0, "s", "when it begins", ge=0)
    end_s: float = quantity(NEVER_S, "s", "when it ends (the default: never)", ge=0)
    motor: int = quantity(0, "", "motor: the failing rotor (0-3, tuavdefs.airframe order)",
                          ge=0, le=3)
    thrust_multiplier: float = quantity(
        0.0, "1", "motor: the share of its commanded output the rotor gives", ge=0, le=1)
    wind_speed_m_s: float = quantity(0.0, "m/s", "wind: mean speed at the reference height",
                                     ge=0, le=60)
    wind_from_deg: float = quantity(0.0, "deg", "wind: the direction it blows from (0 north, "
                                    "90 east)", ge=0, lt=360)
    turbulence: str = quantity("none", "1", "wind: Dryden intensity",
                               choices=("none", "light", "moderate", "severe"))
    drop_probability: float = quantity(0.0, "1", "can: the probability each frame is lost",
                                       ge=0, le=1)
    delay_ms: float = quantity(0.0, "ms", "can: how late each frame arrives (simulated "
                               "time)", ge=0, le=1000)

    def check(self) -> None:
        if self.end_s <= self.start_s:
            raise ValueError("end_s: must be after start_s")

    @property
    def fault_kind(self) -> FaultKind:
        """:attr:`kind` as its enum."""
        return FaultKind(self.kind)

    def active(self, t_s: float) -> bool:
        """Whether the fault acts at ``t_s`` [s]."""
        return self.start_s <= t_s < self.end_s


@dataclass(frozen=True)
class FaultsFile(Params):
    """A faults TOML file: ``[[faults]]`` tables."""

    faults: tuple[FaultParams, ...] = quantity((), "", "the faults")


def wind_from(speed_m_s: float, from_deg: float) -> tuple[float, float, float]:
    """The wind velocity [m/s] (x east, y north, z up) of a wind of ``speed_m_s`` blowing
    from the compass direction ``from_deg`` (0: from the north, moving south)."""
    a = math.radians(from_deg)
    return (-speed_m_s * math.sin(a), -speed_m_s * math.cos(a), 0.0)


class GnssSwitch(Protocol):
    """What delivers the receiver's fixes (:class:`sitl.sensor_batch.SensorBatches`)."""

    gps_enabled: bool


class CanFaults(NamedTuple):
    """What the winder's CAN bus suffers now: each frame lost with ``drop_probability``,
    delayed by ``delay_s`` [s]."""

    drop_probability: float = 0.0
    delay_s: float = 0.0

    @property
    def down(self) -> bool:
        """Nothing gets through."""
        return self.drop_probability >= 1.0


def _w20_m_s(wind: WindParams) -> float:
    """The turbulence's W20 [m/s] a wind model uses (0: no turbulence)."""
    if wind.turbulence == "none":
        return 0.0
    return wind.wind_speed_at_6m_m_s or W20_DEFAULT_M_S[wind.turbulence]


class FaultSchedule:
    """``faults`` and the run-time ``SIM_*`` parameters applied to ``plant`` and the
    receiver ``gnss`` (module docstring). :meth:`apply` every control period;
    :attr:`winder_motor_failed` and :attr:`can` are read where the winder's torque and
    frames reach the plant; :meth:`set_sim` sets a parameter (:meth:`sim_values` reads
    them, the run's wind in the wind's)."""

    def __init__(self, faults: tuple[FaultParams, ...], plant: Plant,
                 gnss: GnssSwitch | None) -> None:
        self.faults = tuple(faults)
        self.plant = plant
        self.gnss = gnss
        self._wind0: WindParams = plant.params.wind
        self._wind_now: WindParams = self._wind0
        self._active: tuple[bool, ...] | None = None
        self._sim = {p.name: p.default for p in SIM_PARAMS}
        east, north = self._wind0.steady_m_s[0], self._wind0.steady_m_s[1]
        self._sim["SIM_WIND_SPD"] = math.hypot(east, north)
        self._sim["SIM_WIND_DIR"] = (math.degrees(math.atan2(-east, -north)) % 360.0
                                     if east or north else 0.0)
        self._sim["SIM_WIND_TURB"] = _w20_m_s(self._wind0)
        self._sim_wind = False        # a SIM_WIND_* has been set: its wind replaces the run's
        self._dirty = True
        #: Whether the winder's motor gives no torque now.
        self.winder_motor_failed = False
        #: What the winder's CAN bus suffers now.
        self.can = CanFaults()
        #: Whether the tether is snagged now.
        self.snagged = False

    @property
    def can_down(self) -> bool:
        """Whether the winder's CAN bus is down now."""
        return self.can.down

    def sim_values(self) -> dict[str, float]:
        """The ``SIM_*`` parameters' values now, by name."""
        return dict(self._sim)

    def set_sim(self, name: str, value: float) -> str | None:
        """Set a ``SIM_*`` parameter (it acts from the next :meth:`apply`): None, or why it
        was refused (unknown, out of its range), the value unchanged."""
        why = check_sim_param(name, value)
        if why is not None:
            return why
        self._sim[name] = float(value)
        if name.startswith("SIM_WIND_"):
            self._sim_wind = True
        self._dirty = True
        return None

    def apply(self, t_s: float) -> list[str]:
        """Bring the faults to their state at ``t_s`` [s]; returns what began or ended (a
        line each, for the log)."""
        active = tuple(f.active(t_s) for f in self.faults)
        if active == self._active and not self._dirty:
            return []
        was = self._active if self._active is not None else (False,) * len(active)
        said = [f"fault {f.kind} {'begins' if now else 'ends'} at {t_s:.3f} s"
                for f, now, before in zip(self.faults, active, was, strict=True)
                if now != before]
        self._active = active
        self._dirty = False
        sim = self._sim
        on = [f for f, a in zip(self.faults, active, strict=True) if a]
        kinds = {f.fault_kind for f in on}
        if self.gnss is not None:
            self.gnss.gps_enabled = not (FaultKind.GNSS_LOSS in kinds
                                         or sim["SIM_GPS_DISABLE"] >= 1.0)
        self.winder_motor_failed = (FaultKind.WINDER_MOTOR in kinds
                                    or sim["SIM_TUAV_WDRFAIL"] >= 1.0)
        drop, delay = sim["SIM_TUAV_CANDROP"], sim["SIM_TUAV_CANDLY"] * 1e-3
        for f in on:
            if f.fault_kind == FaultKind.CAN_LOSS:
                drop = 1.0
            elif f.fault_kind == FaultKind.CAN:
                drop, delay = max(drop, f.drop_probability), max(delay, f.delay_ms * 1e-3)
        self.can = CanFaults(drop, delay)
        snagged = FaultKind.TETHER_SNAG in kinds or sim["SIM_TUAV_SNAG"] >= 1.0
        if snagged != self.snagged:
            self.snagged = snagged
            self.plant.set_snag(snagged)
        gains = [1.0, 1.0, 1.0, 1.0]
        mask, mul = round(sim["SIM_ENGINE_FAIL"]), sim["SIM_ENGINE_MUL"]
        for i in range(4):
            if mask >> i & 1:
                gains[i] = mul
        for f in on:
            if f.fault_kind == FaultKind.MOTOR:
                gains[f.motor] = min(gains[f.motor], f.thrust_multiplier)
        self.plant.rotor_gains = tuple(gains)  # type: ignore[assignment]
        base = self._wind0
        if self._sim_wind:
            w20 = sim["SIM_WIND_TURB"]
            base = replace(self._wind0, steady_m_s=wind_from(sim["SIM_WIND_SPD"],
                                                             sim["SIM_WIND_DIR"] % 360.0),
                           turbulence="light" if w20 > 0.0 else "none",
                           wind_speed_at_6m_m_s=w20)
        fault = next((f for f in reversed(on) if f.fault_kind == FaultKind.WIND), None)
        wind = base if fault is None else replace(
            base, steady_m_s=wind_from(fault.wind_speed_m_s, fault.wind_from_deg),
            turbulence=fault.turbulence)
        if wind != self._wind_now:
            self._wind_now = wind
            self.plant.set_wind(wind)
        return said


class CanChannel:
    """The winder's CAN bus under :class:`CanFaults`, for one direction: each frame kept or
    lost (seeded draws: the same run loses the same frames), and the kept ones held until
    ``delay_s`` of simulated time after they were sent."""

    def __init__(self, seed: int = 0) -> None:
        self._rng = random.Random(seed)
        self._held: list[tuple[float, object]] = []
        #: Frames lost.
        self.lost = 0

    def keep(self, faults: CanFaults) -> bool:
        """Whether the next frame gets through (counts it lost otherwise)."""
        p = faults.drop_probability
        if p <= 0.0:
            return True
        if p >= 1.0 or self._rng.random() < p:
            self.lost += 1
            return False
        return True

    def hold(self, t_s: float, item: object) -> None:
        """Keep ``item``, sent at ``t_s`` [s], until it is due."""
        self._held.append((t_s, item))

    def due(self, t_s: float, delay_s: float) -> list:
        """The items held that have arrived by ``t_s`` [s] (sent at least ``delay_s``
        before), oldest first."""
        held = self._held
        if not held:
            return []
        cut = t_s - delay_s + 1e-9
        n = 0
        while n < len(held) and held[n][0] <= cut:
            n += 1
        out = [item for _, item in held[:n]]
        del held[:n]
        return out

    @property
    def pending(self) -> int:
        """Items held, not yet due."""
        return len(self._held)


__all__ = ["CanChannel", "CanFaults", "FaultKind", "FaultParams", "FaultsFile", "FaultSchedule",
           "wind_from"]
