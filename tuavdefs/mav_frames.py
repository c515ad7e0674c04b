"""MAVLink's coordinate frames as the vehicle reads them: the one table of which frames are
global (latitude, longitude and an altitude of some reference) and which local, and the
conversion of a global position into the inertial z-up frame (origin at the winder).

The companion (commands, guided targets, mission items), the mission files and the import
of an ``up`` run all read frames here, so they agree on what an altitude means.
"""

from __future__ import annotations

from enum import Enum

from pymavlink.dialects.v20 import common as _mav

from tuavdefs.frames import Vec3, global_to_local_enu


class AltitudeReference(Enum):
    """What a global frame's altitude is measured from."""

    AMSL = "amsl"
    """Mean sea level."""
    HOME = "home"
    """The ground the winder stands on (relative and terrain frames: the ground is flat)."""


#: Frames whose x, y are latitude and longitude, and the reference of their altitude. The
#: non-INT variants are included because QGC and MAVProxy send them with scaled integers too.
GLOBAL_FRAMES: dict[int, AltitudeReference] = {
    _mav.MAV_FRAME_GLOBAL: AltitudeReference.AMSL,
    _mav.MAV_FRAME_GLOBAL_INT: AltitudeReference.AMSL,
    _mav.MAV_FRAME_GLOBAL_RELATIVE_ALT: AltitudeReference.HOME,
    _mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: AltitudeReference.HOME,
    _mav.MAV_FRAME_GLOBAL_TERRAIN_ALT: AltitudeReference.HOME,
    _mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: AltitudeReference.HOME,
}
#: Frames whose x, y are positions in metres (13-19 are the retired local frames, now
#: reserved).
LOCAL_FRAMES = frozenset({
    _mav.MAV_FRAME_LOCAL_NED, _mav.MAV_FRAME_LOCAL_ENU,
    _mav.MAV_FRAME_LOCAL_OFFSET_NED, _mav.MAV_FRAME_BODY_NED,
    _mav.MAV_FRAME_BODY_OFFSET_NED, _mav.MAV_FRAME_BODY_FRD,
    *range(13, 20), _mav.MAV_FRAME_LOCAL_FRD, _mav.MAV_FRAME_LOCAL_FLU,
})
#: The frame a message without one (COMMAND_LONG) is read in, as ArduCopter reads it.
DEFAULT_GLOBAL_FRAME = _mav.MAV_FRAME_GLOBAL


def altitude_reference(frame: int | None) -> AltitudeReference:
    """The altitude reference of a global ``frame`` (None: :data:`DEFAULT_GLOBAL_FRAME`).
    KeyError for a frame that is not global."""
    return GLOBAL_FRAMES[DEFAULT_GLOBAL_FRAME if frame is None else frame]


def altitude_to_z(alt_m: float, frame: int | None, origin: tuple[float, float, float]
                  ) -> float:
    """Height [m] above the winder's ground of ``alt_m`` [m] given in the global ``frame``;
    ``origin`` is the winder's (latitude deg, longitude deg, altitude m AMSL)."""
    if altitude_reference(frame) is AltitudeReference.AMSL:
        return alt_m - origin[2]
    return alt_m


def global_to_local(lat_deg: float, lon_deg: float, alt_m: float, frame: int | None,
                    origin: tuple[float, float, float]) -> Vec3:
    """A global position in ``frame`` to the inertial z-up frame [m] (origin at the winder,
    whose global position is ``origin``)."""
    x, y, _ = global_to_local_enu(lat_deg, lon_deg, alt_m, origin)
    return (x, y, altitude_to_z(alt_m, frame, origin))
