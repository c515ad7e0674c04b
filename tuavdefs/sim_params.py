"""The simulator's run-time fault parameters (``SIM_*``), as ArduPilot's SITL offers them.

Any ground station sets them on the vehicle (the companion serves them while it is attached
to a simulator and forwards each accepted change to the plant over the simulator link as
``PARAM_SET``; the plant checks it again, applies it and echoes ``PARAM_VALUE``; the
companion never reads them for control). This module is their one definition: names,
units, ranges and what each does, shared by both ends.

ArduPilot's names where ArduPilot has the parameter; the tethered system's own ones carry
``SIM_TUAV_``:

- ``SIM_WIND_SPD`` [m/s], ``SIM_WIND_DIR`` [deg, the direction it blows from, 0 north,
  90 east]: the mean wind at the profile's reference height; ``SIM_WIND_TURB`` [m/s]: the
  Dryden turbulence's scale W20 (MIL-F-8785C's wind at 20 ft; sigma_w = 0.1 W20; 0: no
  turbulence). The plant announces the run's own wind in them at the start;
- ``SIM_GPS_DISABLE`` (0/1): the receiver delivers no fix;
- ``SIM_ENGINE_FAIL`` (bitmask, bit i: motor i + 1 in ArduPilot's quad-X numbering, the
  rotor order of :mod:`tuavdefs.airframe`) with ``SIM_ENGINE_MUL`` (the share of its
  command a failed motor gives);
- ``SIM_TUAV_SNAG`` (0/1): the tether snags at the winder's exit (``sitl.faults``);
- ``SIM_TUAV_WDRFAIL`` (0/1): the winder's motor gives no torque;
- ``SIM_TUAV_CANDROP`` (0..1): each CAN frame of the winder's bus, either way, is lost with
  this probability (1: the bus is down);
- ``SIM_TUAV_CANDLY`` [ms]: each CAN frame arrives this late (simulated time).
"""

from __future__ import annotations

import math
from typing import NamedTuple


class SimParam(NamedTuple):
    """One run-time fault parameter: its name, unit (ArduPilot's spelling), range on the
    wire (inclusive), whether it is an integer, its default (no fault) and what it does."""

    name: str
    unit: str
    low: float
    high: float
    integer: bool
    default: float
    description: str


SIM_PARAMS: tuple[SimParam, ...] = (
    SimParam("SIM_WIND_SPD", "m/s", 0.0, 40.0, False, 0.0,
             "simulated mean wind speed at the reference height"),
    SimParam("SIM_WIND_DIR", "deg", 0.0, 360.0, False, 0.0,
             "direction the simulated wind blows from (0 north, 90 east)"),
    SimParam("SIM_WIND_TURB", "m/s", 0.0, 25.0, False, 0.0,
             "simulated Dryden turbulence scale W20 (0: none)"),
    SimParam("SIM_GPS_DISABLE", "", 0.0, 1.0, True, 0.0,
             "1: the simulated GNSS receiver gives no fix"),
    SimParam("SIM_ENGINE_FAIL", "", 0.0, 15.0, True, 0.0,
             "bitmask of the simulated motors that fail (bit 0: motor 1)"),
    SimParam("SIM_ENGINE_MUL", "", 0.0, 1.0, False, 1.0,
             "share of its command a failed simulated motor gives"),
    SimParam("SIM_TUAV_SNAG", "", 0.0, 1.0, True, 0.0,
             "1: the simulated tether snags at the winder's exit"),
    SimParam("SIM_TUAV_WDRFAIL", "", 0.0, 1.0, True, 0.0,
             "1: the simulated winder motor gives no torque"),
    SimParam("SIM_TUAV_CANDROP", "", 0.0, 1.0, False, 0.0,
             "probability a simulated winder CAN frame is lost"),
    SimParam("SIM_TUAV_CANDLY", "ms", 0.0, 1000.0, False, 0.0,
             "delay of every simulated winder CAN frame"),
)

#: The parameters by name.
SIM_PARAM_BY_NAME: dict[str, SimParam] = {p.name: p for p in SIM_PARAMS}


def check_sim_param(name: str, value: float) -> str | None:
    """Why ``value`` cannot be set on parameter ``name`` (None: it can; an integer one must
    be whole)."""
    p = SIM_PARAM_BY_NAME.get(name)
    if p is None:
        return f"unknown simulator parameter {name}"
    if not math.isfinite(value):
        return f"{value} rejected"
    if not p.low <= value <= p.high:
        return f"{value:g} outside {p.low:g}..{p.high:g}"
    if p.integer and value != round(value):
        return f"{value:g} is not a whole number"
    return None


__all__ = ["SIM_PARAMS", "SIM_PARAM_BY_NAME", "SimParam", "check_sim_param"]
