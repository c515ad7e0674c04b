"""The ground station's own parameters: what its controllers believe and how they are
tuned, apart from the system's (``tuavdefs.params.SystemParams``: the winder, the tether).

One TOML file, its tables named as a scenario's (``[winder_control]``, ``[lbar]``,
``[winch]``, ``[tether_fix]``), each field checked at load time: ``python -m groundstation
--control FILE``, and ``tuav-sitl up --ground-params FILE``, which writes the run's copy
(``groundstation.toml`` in the run folder) and hands it to the process, as it hands the
companion its ``estimator.toml``. A table not given keeps its defaults.
"""

from __future__ import annotations

from dataclasses import dataclass

from groundstation.lbar import LBarParams
from groundstation.tether_fix import TetherFixParams
from groundstation.winch import WinchParams
from groundstation.winder_control import WinderControlParams
from tuavdefs.paramspec import Params, quantity


@dataclass(frozen=True)
class GroundStationParams(Params):
    """The ground station's tables, as a scenario has them."""

    winder_control: WinderControlParams = quantity(
        WinderControlParams(), "", "the winder's torque law (law = paper | tension) and its "
        "gains")
    lbar: LBarParams = quantity(LBarParams(), "", "the L-bar estimator")
    winch: WinchParams = quantity(WinchParams(), "", "the winch component")
    tether_fix: TetherFixParams = quantity(
        TetherFixParams(), "", "the winch's tether fix: its model of the line and the wind "
        "it is given")
