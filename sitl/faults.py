"""Faults the plant injects at given times: the truth side of a failure, as ArduPilot's SITL
injects them through its ``SIM_*`` parameters.

A :class:`FaultParams` is one fault over a window of simulated time (``start_s`` to
``end_s``); :class:`FaultSchedule` applies a list of them to a plant every control period
(:meth:`FaultSchedule.apply`), in the offline runner and in the plant process alike
(scenario ``[[faults]]``, ``python -m sitl --faults FILE``, ``tuav-sitl up --faults FILE``):

- ``gnss_loss``: the receiver delivers no fix (ArduPilot's ``SIM_GPS_DISABLE``): no HIL_GPS
  on the simulator link;
- ``wind``: the mean wind becomes ``wind_speed_m_s`` from ``wind_from_deg`` (the compass
  direction it blows from, at the profile's reference height) with the Dryden intensity
  ``turbulence`` (``SIM_WIND_SPD``, ``SIM_WIND_DIR``, ``SIM_WIND_TURB``); the scenario's
  wind returns at the end;
- ``motor``: rotor ``motor`` (0-3, tuavdefs.airframe's order) gives ``thrust_multiplier``
  of its commanded output (``SIM_ENGINE_FAIL``, ``SIM_ENGINE_MUL``);
- ``winder_motor``: the winder's motor produces no torque (its drive failed; the brake stays
  as the drive last set it);
- ``can_loss``: the winder's CAN bus carries nothing, either way (the axis's watchdog then
  disarms it: the drum brakes; the ground station hears no encoder and its winch reports
  unhealthy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum
from typing import Protocol

from sitl.plant import Plant
from tuavdefs.params import WindParams
from tuavdefs.paramspec import Params, quantity

#: ``end_s`` of a fault that never ends [s] (TOML has no infinity the loader takes).
NEVER_S = 1.0e9


class FaultKind(Enum):
    """What fails (module docstring)."""

    GNSS_LOSS = "gnss_loss"
    WIND = "wind"
    MOTOR = "motor"
    WINDER_MOTOR = "winder_motor"
    CAN_LOSS = "can_loss"


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


class FaultSchedule:
    """``faults`` applied to ``plant`` and the receiver ``gnss`` (module docstring).
    :meth:`apply` every control period; :attr:`winder_motor_failed` and :attr:`can_down`
    are read where the winder's torque and frames reach the plant."""

    def __init__(self, faults: tuple[FaultParams, ...], plant: Plant,
                 gnss: GnssSwitch | None) -> None:
        self.faults = tuple(faults)
        self.plant = plant
        self.gnss = gnss
        self._wind0: WindParams = plant.params.wind
        self._wind_fault: FaultParams | None = None
        self._active: tuple[bool, ...] = (False,) * len(self.faults)
        #: Whether the winder's motor gives no torque now.
        self.winder_motor_failed = False
        #: Whether the winder's CAN bus is down now.
        self.can_down = False

    def apply(self, t_s: float) -> list[str]:
        """Bring the faults to their state at ``t_s`` [s]; returns what began or ended (a
        line each, for the log)."""
        active = tuple(f.active(t_s) for f in self.faults)
        if active == self._active:
            return []
        said = [f"fault {f.kind} {'begins' if now else 'ends'} at {t_s:.3f} s"
                for f, now, was in zip(self.faults, active, self._active, strict=True)
                if now != was]
        self._active = active
        on = [f for f, a in zip(self.faults, active, strict=True) if a]
        kinds = {f.fault_kind for f in on}
        if self.gnss is not None:
            self.gnss.gps_enabled = FaultKind.GNSS_LOSS not in kinds
        self.winder_motor_failed = FaultKind.WINDER_MOTOR in kinds
        self.can_down = FaultKind.CAN_LOSS in kinds
        gains = [1.0, 1.0, 1.0, 1.0]
        for f in on:
            if f.fault_kind == FaultKind.MOTOR:
                gains[f.motor] = min(gains[f.motor], f.thrust_multiplier)
        self.plant.rotor_gains = tuple(gains)
        wind = next((f for f in reversed(on) if f.fault_kind == FaultKind.WIND), None)
        if wind is not self._wind_fault:
            self._wind_fault = wind
            self.plant.set_wind(self._wind0 if wind is None else replace(
                self._wind0, steady_m_s=wind_from(wind.wind_speed_m_s, wind.wind_from_deg),
                turbulence=wind.turbulence))
        return said


__all__ = ["FaultKind", "FaultParams", "FaultsFile", "FaultSchedule", "wind_from"]
