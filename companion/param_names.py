"""The companion's parameters as ground stations see them: ArduCopter's names, units and
MAV_PARAM_TYPEs where ArduCopter has the parameter, the project's own with the ``TUAV_``
prefix.

The onboard parameter dataclasses stay in SI (``NavigationParams.rtl_alt_m`` in metres);
the table converts at the wire: ``RTL_ALT`` is ArduCopter's INT32 in centimetres, and the
same field is also served as ``RTL_ALT_M`` (REAL32 metres), the name newer ArduPilot
releases and MAVSDK 4.x use. Every name here is checked against ``params_to_defs``'s rules
(upper case, at most 16 characters) when the table is built.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink2

from companion.failsafes import FailsafeParams
from companion.gains import FlightControlParams
from companion.geofence import FenceParams
from companion.navigation import NavigationParams
from companion.param_protocol import ParamDef, WireName, apply_parm_text, params_to_defs

__all__ = ["ARMING_CHECK_ALL", "FAILSAFE_NAMES", "FENCE_NAMES", "GAIN_NAMES", "NAV_NAMES",
           "arming_check_def", "build_defs", "check_parm_text"]

M = mavlink2
_CM = 100.0
_I8, _I16, _I32 = M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32

#: Flight-control gains (``companion.gains.FlightControlParams``): the backstepping laws'
#: gains are the project's own; the tilt limit is ArduCopter's ANGLE_MAX (centidegrees) and
#: the control rate its SCHED_LOOP_RATE (read-only here: the plant sets it).
GAIN_NAMES: dict[str, str | WireName | tuple[WireName, ...]] = {
    "rate_hz": WireName("SCHED_LOOP_RATE", param_type=_I16),
    "pos_k1_1_s": "TUAV_PSC_K1", "pos_k2_1_s": "TUAV_PSC_K2",
    "disturbance_gain_1_s2": "TUAV_PSC_DGAIN", "disturbance_limit_m_s2": "TUAV_PSC_DLIM",
    "max_tilt_rad": WireName("ANGLE_MAX", scale=_CM * 180.0 / math.pi, param_type=_I16,
                             unit="cdeg"),
    "max_thrust_fraction": "TUAV_PSC_THRMAX",
    "att_k3_1_s": "TUAV_ATC_K3", "att_k4_n_m_s": "TUAV_ATC_K4",
    "att_disturbance_gain_n_m_rad": "TUAV_ATC_DGAIN",
    "att_disturbance_limit_n_m": "TUAV_ATC_DLIM",
    "command_filter_hz": "TUAV_ATC_FLT_HZ", "command_filter_damping": "TUAV_ATC_FLT_Z",
    "command_filter_pole_hz": "TUAV_ATC_FLT_P",
    "use_tether_model": "TUAV_TETH_MODEL", "use_measured_tension": "TUAV_TETH_TENS",
}

#: Navigation parameters (``companion.navigation.NavigationParams``), as ArduCopter 4.5
#: names and types them (WPNAV_* REAL32 in cm, cm/s, cm/s/s; LAND_SPEED, LAND_ALT_LOW INT16
#: in cm/s, cm; RTL_ALT INT32 cm; RTL_LOIT_TIME INT32 ms; DISARM_DELAY INT8 s; GUID_TIMEOUT
#: REAL32 s), RTL_ALT also as the newer RTL_ALT_M (REAL32 m).
NAV_NAMES: dict[str, str | WireName | tuple[WireName, ...]] = {
    "speed_m_s": WireName("WPNAV_SPEED", scale=_CM, unit="cm/s"),
    "speed_up_m_s": WireName("WPNAV_SPEED_UP", scale=_CM, unit="cm/s"),
    "speed_down_m_s": WireName("WPNAV_SPEED_DN", scale=_CM, unit="cm/s"),
    "acc_m_s2": WireName("WPNAV_ACCEL", scale=_CM, unit="cm/s/s"),
    "land_speed_m_s": WireName("LAND_SPEED", scale=_CM, param_type=_I16, unit="cm/s"),
    "land_alt_low_m": WireName("LAND_ALT_LOW", scale=_CM, param_type=_I16, unit="cm"),
    "rtl_alt_m": (WireName("RTL_ALT", scale=_CM, param_type=_I32, unit="cm"),
                  WireName("RTL_ALT_M")),
    "rtl_loiter_s": WireName("RTL_LOIT_TIME", scale=1000.0, param_type=_I32, unit="ms"),
    "acceptance_radius_m": WireName("WPNAV_RADIUS", scale=_CM, unit="cm"),
    "takeoff_accept_m": "TUAV_TKOFF_ACC",
    "disarm_delay_s": WireName("DISARM_DELAY", param_type=_I8),
    "land_detect_s": "TUAV_LAND_DET_T", "land_stall_m": "TUAV_LAND_STALL",
    "reach_fraction": "TUAV_TETH_REACH", "reach_slack_m": "TUAV_TETH_SLACK",
    "guided_velocity_timeout_s": "GUID_TIMEOUT",
    "tension_limit_n": "TUAV_TENS_MAX", "tension_step_m": "TUAV_TENS_STEP",
    "tension_time_s": "TUAV_TENS_TIME",
    "tether_governor": WireName("TUAV_TETH_GOV", param_type=_I8),
    "tether_brake_acc_m_s2": "TUAV_TETH_BRK", "tether_latency_s": "TUAV_TETH_LAT",
    "tether_margin_m": "TUAV_TETH_MARG", "tether_sigma_k": "TUAV_TETH_SIGK",
}

#: Link failsafes (``companion.failsafes.FailsafeParams``): ArduCopter's FS_GCS_ENABLE
#: (INT8) and FS_GCS_TIMEOUT (REAL32 s); the winder's the project's own.
FAILSAFE_NAMES: dict[str, str | WireName | tuple[WireName, ...]] = {
    "gcs_action": WireName("FS_GCS_ENABLE", param_type=_I8),
    "gcs_timeout_s": "FS_GCS_TIMEOUT",
    "winch_action": WireName("TUAV_FS_WINCH", param_type=_I8),
    "winch_timeout_s": "TUAV_FS_WINCH_TO",
    "winch_brake_after_s": "TUAV_FS_WINCH_BR",
}

#: Fence parameters (``companion.geofence.FenceParams``), as ArduCopter's (FENCE_ENABLE,
#: FENCE_TYPE, FENCE_ACTION INT8; FENCE_RADIUS, FENCE_ALT_MAX, FENCE_MARGIN REAL32 m).
FENCE_NAMES: dict[str, str | WireName | tuple[WireName, ...]] = {
    "enable": "FENCE_ENABLE", "type_mask": WireName("FENCE_TYPE", param_type=_I8),
    "radius_m": "FENCE_RADIUS", "alt_max_m": "FENCE_ALT_MAX",
    "action": WireName("FENCE_ACTION", param_type=_I8), "margin_m": "FENCE_MARGIN",
}

#: ARMING_CHECK's "all checks" bit (ArduPilot's bitmask; 0 skips them).
ARMING_CHECK_ALL = 1


def arming_check_def(get: Callable[[], int], set_: Callable[[int], None]) -> ParamDef:
    """ARMING_CHECK (INT32 bitmask, as ArduPilot): 0 skips the pre-arm checks (the
    estimator's health), any other value runs them."""

    def setter(value: float) -> str | None:
        if value < 0:
            return "must be >= 0"
        set_(int(value))
        return None

    return ParamDef("ARMING_CHECK", _I32, lambda: float(get()), setter, unit="",
                    description="pre-arm checks: 1 all (the estimator's health), 0 none",
                    low=0, high=2**31 - 1)


def build_defs(gains: FlightControlParams, nav: NavigationParams,
               set_gains: Callable[[FlightControlParams], None],
               set_nav: Callable[[NavigationParams], None],
               get_arming: Callable[[], int], set_arming: Callable[[int], None],
               fence: FenceParams | None = None,
               set_fence: Callable[[FenceParams], None] = lambda _f: None,
               failsafes: FailsafeParams | None = None,
               set_failsafes: Callable[[FailsafeParams], None] = lambda _f: None
               ) -> list[ParamDef]:
    """Every parameter of the companion, in index order: the gains (SCHED_LOOP_RATE
    read-only), the navigation parameters, ARMING_CHECK, the fence's, the failsafes'."""

    def read_only_rate(value: float) -> str | None:
        if value == round(gains.rate_hz):
            return None
        return "SCHED_LOOP_RATE is read-only: the plant sets the control rate"

    defs = [d if d.name != "SCHED_LOOP_RATE" else dataclasses.replace(d, set=read_only_rate)
            for d in params_to_defs(gains, GAIN_NAMES, set_gains)]
    defs += params_to_defs(nav, NAV_NAMES, set_nav)
    defs.append(arming_check_def(get_arming, set_arming))
    defs += params_to_defs(fence if fence is not None else FenceParams(), FENCE_NAMES,
                           set_fence)
    defs += params_to_defs(failsafes if failsafes is not None else FailsafeParams(),
                           FAILSAFE_NAMES, set_failsafes)
    return defs


def check_parm_text(text: str, source: str) -> list[str]:
    """What a parameter file (.parm) would not apply on a companion with the default
    parameters and the simulator's ``SIM_*``: a ``SOURCE:LINE: ...`` warning per line
    (:func:`companion.param_protocol.apply_parm_text`), nothing if every line applies.
    Checked on copies of the defaults, so that a start (``tuav-sitl up --parm``) can refuse
    a bad file before anything runs."""
    from companion.sim_params import sim_param_defs

    arming = [1]
    defs = build_defs(FlightControlParams(), NavigationParams(), lambda _g: None,
                      lambda _n: None, lambda: arming[0],
                      lambda v: arming.__setitem__(0, v))
    defs += sim_param_defs({}, lambda _name, _value: None)
    return apply_parm_text(defs, text, source)
