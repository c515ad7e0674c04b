"""The simulator's run-time fault parameters (``SIM_*``, :mod:`tuavdefs.sim_params`) served
to ground stations while the companion is attached to a simulator.

The companion only relays them: a ground station's PARAM_SET is checked against the
parameter's range here (refused as any parameter is: the value unchanged, a STATUSTEXT),
then forwarded to the plant over the simulator link, which applies it to the truth and
answers with the value it holds. What ground stations read is the plant's last word (its
announcement at the session's start, then its answers), or the value just forwarded until
the plant answers. Nothing on board reads them.
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from companion.param_protocol import ParamDef
from tuavdefs.sim_params import SIM_PARAMS, SimParam, check_sim_param


def sim_param_defs(values: dict[str, float], forward: Callable[[str, float], None]
                   ) -> list[ParamDef]:
    """The ``SIM_*`` parameters: read from ``values`` (the plant's word, updated in place
    by the link), a set checked and handed to ``forward(name, value)`` (the link's
    PARAM_SET); the value forwarded shows until the plant answers."""

    def one(p: SimParam) -> ParamDef:
        def get() -> float:
            return float(values.get(p.name, p.default))

        def set_(value: float) -> str | None:
            why = check_sim_param(p.name, value)
            if why is None:
                forward(p.name, value)
                values[p.name] = float(value)
            return why

        ptype = mavlink2.MAV_PARAM_TYPE_INT32 if p.integer else mavlink2.MAV_PARAM_TYPE_REAL32
        return ParamDef(p.name, ptype, get, set_, p.unit, p.description, p.low, p.high)

    return [one(p) for p in SIM_PARAMS]


__all__ = ["sim_param_defs"]
