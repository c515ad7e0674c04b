"""The companion's component link: MAVLink between the flight computer and onboard-style
components, here the ground station's winch.

The companion listens on TCP 127.0.0.1:5762 (ArduPilot SITL's second serial port) and sends
the UAV's ``LOCAL_POSITION_NED`` (100 Hz of simulated time); the winch component (system 1,
component 169 ``MAV_COMP_ID_WINCH``) sends ``WINCH_STATUS`` and a ``HEARTBEAT`` with
autopilot ``MAV_AUTOPILOT_INVALID`` and type ``MAV_TYPE_WINCH`` so that ground stations do
not take it for a second vehicle. MAVLink 2, signed with the vehicle's key when it has
one (the companion hands the winch a new key with ``SETUP_SIGNING`` from component 1).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.signing import SigningMavlink

COMPONENT_PORT_DEFAULT = 5762
SYSTEM_ID = 1
AUTOPILOT_COMPONENT_ID = 1
WINCH_COMPONENT_ID = mavlink2.MAV_COMP_ID_WINCH          # 169
POSITION_RATE_HZ = 100.0


def winch_status_flags(brake_engaged: bool, moving: bool, healthy: bool = True) -> int:
    """``MAV_WINCH_STATUS_FLAG`` bits of the winch's state."""
    flags = mavlink2.MAV_WINCH_STATUS_HEALTHY if healthy else 0
    if moving:
        flags |= mavlink2.MAV_WINCH_STATUS_MOVING
    if brake_engaged:
        flags |= mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    return flags


def new_mavlink(component_id: int) -> mavlink2.MAVLink:
    """A MAVLink 2 packer/parser for system 1 and ``component_id`` (signing as
    ``tuavdefs.signing`` checks it, once a key is set on its ``signing``)."""
    mav = SigningMavlink(None, srcSystem=SYSTEM_ID, srcComponent=component_id)
    mav.robust_parsing = True
    return mav


#: ``MAV_CMD_DO_WINCH`` is taken when addressed to the winch, to the autopilot (which
#: forwards it to the winch) or to every component.
DO_WINCH_TARGET_COMPONENTS = (WINCH_COMPONENT_ID, AUTOPILOT_COMPONENT_ID, 0)
#: Winch instance numbers (``param1``) the winch answers to.
WINCH_INSTANCES = (0, 1)


def winch_status_flag(name: str) -> int:
    """The ``MAV_WINCH_STATUS_<name>`` bit, or 0 where the installed common dialect does not
    define it (pymavlink 2.4.x knows HEALTHY, FULLY_RETRACTED, MOVING, CLUTCH_ENGAGED; newer
    common.xml adds LOCKED, RETRACTING, ...)."""
    return int(getattr(mavlink2, f"MAV_WINCH_STATUS_{name}", 0))
