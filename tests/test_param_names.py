"""The companion's parameters as ArduCopter names, types and units them, served by the real
parameter micro-service to pymavlink-packed requests; the metadata file read as MAVProxy's
param help reads it (lxml objectify).

Truths: ArduCopter 4.5's parameter list (RTL_ALT INT32 cm, LAND_SPEED INT16 cm/s,
WPNAV_* REAL32 cm-based, ANGLE_MAX INT16 centidegrees, DISARM_DELAY INT8 s, RTL_LOIT_TIME
INT32 ms) against the SI fields of the onboard dataclasses; newer ArduPilot's RTL_ALT_M
(metres) as the same value."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.gains import FlightControlParams
from companion.navigation import NavigationParams
from companion.param_metadata import SHIPPED, default_defs, pdef_xml
from companion.param_names import build_defs
from companion.param_protocol import ParamProtocol

M = mavlink2
GCS = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)


def wire(msg):
    out = mavlink2.MAVLink(None).parse_buffer(msg.pack(GCS))
    assert out is not None and len(out) == 1
    return out[0]


class Table:
    """The companion's table over a ParamProtocol, recording what the navigator and the
    flight controller are handed."""

    def __init__(self) -> None:
        self.nav = NavigationParams()
        self.gains = FlightControlParams()
        self.arming = 1
        self.sent: list = []
        self.texts: list[str] = []
        defs = build_defs(self.gains, self.nav, lambda g: setattr(self, "gains", g),
                          lambda n: setattr(self, "nav", n), lambda: self.arming,
                          lambda v: setattr(self, "arming", v))
        self.proto = ParamProtocol(defs, lambda _p, m: self.sent.append(wire(m)),
                                   lambda _s, t: self.texts.append(t))

    def read(self, name: str):
        self.sent.clear()
        self.proto.handle("gcs", wire(M.MAVLink_param_request_read_message(
            1, 1, name.encode(), -1)), 0.0)
        return self.sent[-1]

    def set(self, name: str, value: float, ptype: int):
        self.sent.clear()
        self.proto.handle("gcs", wire(M.MAVLink_param_set_message(
            1, 1, name.encode(), value, ptype)), 0.0)
        return self.sent[-1]


@pytest.mark.parametrize("name, ptype, value", [
    ("RTL_ALT", M.MAV_PARAM_TYPE_INT32, 1000.0),        # 10 m in cm
    ("RTL_ALT_M", M.MAV_PARAM_TYPE_REAL32, 10.0),
    ("LAND_SPEED", M.MAV_PARAM_TYPE_INT16, 50.0),       # 0.5 m/s in cm/s
    ("LAND_ALT_LOW", M.MAV_PARAM_TYPE_INT16, 500.0),
    ("WPNAV_SPEED", M.MAV_PARAM_TYPE_REAL32, 200.0),
    ("WPNAV_SPEED_UP", M.MAV_PARAM_TYPE_REAL32, 150.0),
    ("WPNAV_SPEED_DN", M.MAV_PARAM_TYPE_REAL32, 100.0),
    ("WPNAV_ACCEL", M.MAV_PARAM_TYPE_REAL32, 150.0),
    ("WPNAV_RADIUS", M.MAV_PARAM_TYPE_REAL32, 50.0),
    ("ANGLE_MAX", M.MAV_PARAM_TYPE_INT16, 3500.0),       # 35 degrees
    ("DISARM_DELAY", M.MAV_PARAM_TYPE_INT8, 10.0),
    ("RTL_LOIT_TIME", M.MAV_PARAM_TYPE_INT32, 2000.0),  # 2 s in ms
    ("ARMING_CHECK", M.MAV_PARAM_TYPE_INT32, 1.0),
    ("GUID_TIMEOUT", M.MAV_PARAM_TYPE_REAL32, 3.0),
    ("SCHED_LOOP_RATE", M.MAV_PARAM_TYPE_INT16, 250.0),
    ("FENCE_ENABLE", M.MAV_PARAM_TYPE_INT8, 0.0),
    ("FENCE_TYPE", M.MAV_PARAM_TYPE_INT8, 7.0),
    ("FENCE_RADIUS", M.MAV_PARAM_TYPE_REAL32, 300.0),
    ("FENCE_ALT_MAX", M.MAV_PARAM_TYPE_REAL32, 100.0),
    ("FENCE_ACTION", M.MAV_PARAM_TYPE_INT8, 1.0),
])
def test_arducopter_names_types_and_units_at_the_defaults(name, ptype, value):
    v = Table().read(name)
    assert (v.param_id, v.param_type) == (name, ptype)
    assert v.param_value == pytest.approx(value)


def test_rtl_alt_in_cm_and_rtl_alt_m_are_one_value_the_navigator_gets_in_metres():
    t = Table()
    assert t.set("RTL_ALT", 1250, M.MAV_PARAM_TYPE_INT32).param_value == 1250
    assert t.nav.rtl_alt_m == pytest.approx(12.5)
    assert t.read("RTL_ALT_M").param_value == pytest.approx(12.5)
    assert t.set("RTL_ALT_M", 15.0, M.MAV_PARAM_TYPE_REAL32).param_value == 15.0
    assert t.nav.rtl_alt_m == 15.0 and t.read("RTL_ALT").param_value == 1500


def test_scaled_sets_reach_the_si_fields():
    t = Table()
    t.set("WPNAV_SPEED", 350.0, M.MAV_PARAM_TYPE_REAL32)
    t.set("LAND_SPEED", 30, M.MAV_PARAM_TYPE_INT16)
    t.set("RTL_LOIT_TIME", 5000, M.MAV_PARAM_TYPE_INT32)
    t.set("ANGLE_MAX", 3000, M.MAV_PARAM_TYPE_INT16)
    t.set("DISARM_DELAY", 0, M.MAV_PARAM_TYPE_INT8)
    assert t.nav.speed_m_s == pytest.approx(3.5)
    assert t.nav.land_speed_m_s == pytest.approx(0.3)
    assert t.nav.rtl_loiter_s == pytest.approx(5.0)
    assert t.nav.disarm_delay_s == 0.0
    assert t.gains.max_tilt_rad == pytest.approx(math.radians(30.0))
    assert t.set("ARMING_CHECK", 0, M.MAV_PARAM_TYPE_INT32).param_value == 0
    assert t.arming == 0


def test_bounds_apply_in_wire_units_and_read_only_rate():
    t = Table()
    # WPNAV_SPEED is <= 20 m/s: 2500 cm/s refused, the value unchanged, said why
    assert t.set("WPNAV_SPEED", 2500.0, M.MAV_PARAM_TYPE_REAL32).param_value == 200.0
    assert "WPNAV_SPEED" in t.texts[-1] and "20" in t.texts[-1]
    # INT8: 300 s does not fit DISARM_DELAY
    assert t.set("DISARM_DELAY", 300, M.MAV_PARAM_TYPE_INT8).param_value == 10
    assert t.set("SCHED_LOOP_RATE", 400, M.MAV_PARAM_TYPE_INT16).param_value == 250
    assert "read-only" in t.texts[-1]


def test_names_fit_mavlink_and_project_ones_are_prefixed():
    names = [d.name for d in default_defs()]
    assert len(names) == len(set(names))
    arducopter = {"SCHED_LOOP_RATE", "ANGLE_MAX", "WPNAV_SPEED", "WPNAV_SPEED_UP",
                  "WPNAV_SPEED_DN", "WPNAV_ACCEL", "WPNAV_RADIUS", "LAND_SPEED",
                  "LAND_ALT_LOW", "RTL_ALT", "RTL_ALT_M", "RTL_LOIT_TIME", "DISARM_DELAY",
                  "GUID_TIMEOUT", "ARMING_CHECK", "FENCE_ENABLE", "FENCE_TYPE", "FENCE_RADIUS",
                  "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN", "FS_GCS_ENABLE",
                  "FS_GCS_TIMEOUT"}
    assert arducopter <= set(names)
    # the simulator's fault parameters: ArduPilot SITL's, and the project's as SIM_TUAV_
    sitl = {"SIM_WIND_SPD", "SIM_WIND_DIR", "SIM_WIND_TURB", "SIM_GPS_DISABLE",
            "SIM_ENGINE_FAIL", "SIM_ENGINE_MUL"}
    assert sitl <= set(names)
    assert all(n in arducopter or n in sitl or n.startswith(("TUAV_", "SIM_TUAV_"))
               for n in names)


def test_the_shipped_metadata_is_the_tables_and_reads_as_mavproxy_reads_it():
    objectify = pytest.importorskip("lxml.objectify")
    text = pdef_xml(default_defs())
    assert SHIPPED.read_text(encoding="utf-8") == text, \
        "regenerate: python -m companion.param_metadata"
    tree = objectify.fromstring(text.encode())
    help_tree = {p.get("name").split(":")[1]: p for p in tree.vehicles.parameters.param}
    for lib in tree.libraries.parameters:
        for p in lib.param:
            help_tree[p.get("name")] = p
    assert set(help_tree) == {d.name for d in default_defs()}
    fields = {f.get("name"): str(f) for f in help_tree["RTL_ALT"].field}
    assert fields["Units"] == "cm" and fields["Increment"] == "1"
    lo, hi = (float(x) for x in {f.get("name"): str(f)
                                 for f in help_tree["WPNAV_SPEED"].field}["Range"].split())
    assert (lo, hi) == (0.0, 2000.0)
    assert "tether" in help_tree["TUAV_TETH_REACH"].get("documentation")
