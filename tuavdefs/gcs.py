"""The ground-station side of the vehicle: the MAVLink endpoints and identity it presents
(as ArduPilot SITL does), shared by the companion that serves them and the front end that
announces them."""

from __future__ import annotations

GCS_TCP_PORT_DEFAULT = 5760
"""TCP server for ground stations and scripts on 127.0.0.1 (ArduPilot SITL's SERIAL0)."""
UDP_GCS_PORT_DEFAULT = 14550
"""UDP port MAVLink is pushed to on 127.0.0.1 for ground stations (QGroundControl, MAVProxy)."""
UDP_API_PORT_DEFAULT = 14540
"""UDP port MAVLink is pushed to on 127.0.0.1 for APIs (MAVSDK)."""
INSTANCE_PORT_STEP = 10
"""Every port moves by this much per ``--instance``, as ArduPilot SITL's do."""
SYSTEM_ID = 1
AUTOPILOT_COMPONENT_ID = 1
