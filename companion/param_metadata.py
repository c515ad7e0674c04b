"""The companion's parameter metadata in ArduPilot's ``apm.pdef.xml`` form, for ground
stations that show ranges, units and descriptions (MAVProxy: ``param set_xml_filepath
FILE``, then ``param help NAME``; Mission Planner and QGC read the same form).

The file is generated from the parameter table (``companion.param_names``) at the
default values' types and ranges: ``python -m companion.param_metadata [OUT]`` writes it
(the shipped copy, ``companion/data/apm.pdef.xml``, is checked against the table by the
tests). ArduCopter's own parameters go under ``<vehicles>`` as ``ArduCopter:NAME``; the
project's (``TUAV_``) under ``<libraries>``.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path
from xml.sax.saxutils import quoteattr

from pymavlink.dialects.v20 import common as mavlink2

from companion.gains import FlightControlParams
from companion.geofence import FenceParams
from companion.navigation import NavigationParams
from companion.param_names import build_defs
from companion.param_protocol import ParamDef
from companion.sim_params import sim_param_defs

__all__ = ["SHIPPED", "default_defs", "pdef_xml"]

#: The metadata file shipped with the package.
SHIPPED = Path(__file__).resolve().parent / "data" / "apm.pdef.xml"
_PROJECT_PREFIX = "TUAV_"
_INT_TYPES = {mavlink2.MAV_PARAM_TYPE_INT8, mavlink2.MAV_PARAM_TYPE_INT16,
              mavlink2.MAV_PARAM_TYPE_INT32, mavlink2.MAV_PARAM_TYPE_UINT8,
              mavlink2.MAV_PARAM_TYPE_UINT16, mavlink2.MAV_PARAM_TYPE_UINT32}


def default_defs() -> list[ParamDef]:
    """The companion's parameters at their defaults (what a fresh companion serves, the
    simulator's SIM_* last)."""
    return build_defs(FlightControlParams(), NavigationParams(), lambda _p: None,
                      lambda _p: None, lambda: 1, lambda _v: None, FenceParams()) + \
        sim_param_defs({}, lambda _n, _v: None)


def _number(v: float) -> str:
    return f"{v:.10g}"


def _param(d: ParamDef, qualified: str) -> str:
    fields = []
    if d.low is not None or d.high is not None:
        lo = d.low if d.low is not None else -3.4e38
        hi = d.high if d.high is not None else 3.4e38
        fields.append(f'<field name="Range">{_number(lo)} {_number(hi)}</field>')
    if d.param_type in _INT_TYPES:
        fields.append('<field name="Increment">1</field>')
    if d.unit and d.unit != "1":
        fields.append(f'<field name="Units">{d.unit}</field>')
    values = ""
    if d.param_type == mavlink2.MAV_PARAM_TYPE_INT8 and d.low is None and d.high is None:
        values = ('<values><value code="0">Disabled</value>'
                  '<value code="1">Enabled</value></values>')
    human = d.description.split(" (")[0][:60] or d.name
    body = "".join(fields) + values
    return (f"      <param humanName={quoteattr(human[:1].upper() + human[1:])} "
            f"name={quoteattr(qualified)} documentation={quoteattr(d.description)} "
            f'user="Standard">{body}</param>\n')


def pdef_xml(defs: Iterable[ParamDef]) -> str:
    """``defs`` as an ``apm.pdef.xml`` document."""
    defs = list(defs)
    own = [d for d in defs if not d.name.startswith(_PROJECT_PREFIX)]
    project = [d for d in defs if d.name.startswith(_PROJECT_PREFIX)]
    out = ['<?xml version="1.0" encoding="utf-8"?>\n<paramfile>\n  <vehicles>\n',
           '    <parameters name="ArduCopter">\n']
    out += [_param(d, f"ArduCopter:{d.name}") for d in own]
    out.append('    </parameters>\n  </vehicles>\n  <libraries>\n')
    out.append(f'    <parameters name="{_PROJECT_PREFIX}">\n')
    out += [_param(d, d.name) for d in project]
    out.append('    </parameters>\n  </libraries>\n</paramfile>\n')
    return "".join(out)


def main(argv: list[str] | None = None) -> int:
    """Write the metadata of the default parameters to the path given (default: the shipped
    file)."""
    args = sys.argv[1:] if argv is None else argv
    out = Path(args[0]) if args else SHIPPED
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(pdef_xml(default_defs()), encoding="utf-8")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
