"""The links between the offline runner's parts: each message with what its fields carry,
through its bytes or not.

The three processes talk over links: the plant's simulator link to the companion (the
sensor batch: HIL_GPS, HIL_SENSOR), the component link between the companion and the winch
(LOCAL_POSITION_NED to the winch, ODOMETRY, the tether fix, back), the CAN bus between the
winch and the winder's axis and sensors. Offline all of them are inside one process. Each
message reaches its reader with its fields' resolution either way:

- :class:`Links` (the default, ``OfflineRunner(wire=False)``) hands each message's field
  values as the message carries them, without its bytes: float32 fields rounded to float32,
  times in their integer units;
- :class:`WireLinks` (``wire=True``) packs each message into its bytes and parses them with
  the receiving process's own parser (checksums checked), as over the link.

Both give bit-identical runs (``tests/test_offline_links.py``): every field's resolution
is applied on the direct path, so it is exact. The CAN frames are the one hop framed
in both modes: the winch's only entry is a frame (:class:`tuav_sitl.offline_ground.
GroundStation`). Not yet through here: WINCH_STATUS and DO_WINCH reach the companion and the
winch as the runner's doubles in both modes, where the component link carries float32
fields (giving them their resolution moves every scenario's series).
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.winch_link import local_positions
from tuavdefs import component_link as cl
from tuavdefs.frames import ned_to_enu

#: LOCAL_POSITION_NED's six position and velocity fields (float32)
_F32X6 = struct.Struct("<6f")
#: ODOMETRY's position (x, y, z) and its covariance's nine entries (float32 on the wire)
_F32X3 = struct.Struct("<3f")
_F32X1 = struct.Struct("<f")
_F32X9 = struct.Struct("<9f")

#: (position [m], velocity [m/s]) z-up, and the vehicle's time_boot_ms
Report = tuple[tuple[tuple[float, ...], tuple[float, ...]], int]


class Links:
    """The component link's messages as their fields carry them, without their bytes (the
    sensor batch's mode is :class:`tuav_sitl.sensor_feed.SensorFeed`'s ``wire``)."""

    wire = False

    def local_position(self, t_s: float, pos_m: tuple[float, float, float],
                       vel_m_s: tuple[float, float, float]) -> Report:
        """The companion's LOCAL_POSITION_NED of ``t_s`` [s] as the winch reads it: position
        [m] and velocity [m/s] (z up) as float32, the time in whole milliseconds (the NED
        axes' swap and sign change are exact)."""
        f32 = _F32X6.unpack(_F32X6.pack(*pos_m, *vel_m_s))
        return (f32[0:3], f32[3:6]), int(t_s * 1000)

    def odometry(self, fix: cl.ExternalPosition) -> cl.ExternalPosition | None:
        """The winch's tether fix as the vehicle takes it from ODOMETRY: its time in whole
        microseconds, position and covariance as float32, the covariance's upper triangle
        mirrored; None when the vehicle would refuse it (:func:`tuavdefs.component_link.
        external_position`). (The message object without its bytes: the same conversions
        and checks as the autopilot's; the NED axes' swap and sign change commute with
        the float32 rounding.)"""
        pos = _F32X3.unpack(_F32X3.pack(*fix.pos_m))
        c = _F32X9.unpack(_F32X9.pack(*fix.cov_m2[0], *fix.cov_m2[1], *fix.cov_m2[2]))
        return cl.external_position(cl.odometry_message(cl.ExternalPosition(
            fix.t_s, pos, (c[0:3], c[3:6], c[6:9]))))


    def tether_reading(self, r: cl.TetherReading) -> cl.TetherReading | None:
        """The winch's raw tether reading as the vehicle takes it from DEBUG_FLOAT_ARRAY:
        its time in whole microseconds, its values as float32."""
        return cl.tether_reading(cl.tether_reading_message(r._replace(
            length_m=_f32(r.length_m), tension_n=_f32(r.tension_n),
            azimuth_rad=_f32(r.azimuth_rad), elevation_rad=_f32(r.elevation_rad),
            weight_n_m=_f32(r.weight_n_m))))


def _f32(v: float) -> float:
    return _F32X1.unpack(_F32X1.pack(v))[0]


class WireLinks(Links):
    """The component link's messages packed into MAVLink 2 frames and parsed by the
    receiving side's parser, as between the processes."""

    wire = True

    def __init__(self) -> None:
        self._companion = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
        self._winch = cl.new_mavlink(cl.WINCH_COMPONENT_ID)

    def local_position(self, t_s: float, pos_m: tuple[float, float, float],
                       vel_m_s: tuple[float, float, float]) -> Report:
        """LOCAL_POSITION_NED packed as the companion's component server sends it (NED) and
        read as the winch's link client reads it (``local_positions``, back to z up)."""
        data = mavlink2.MAVLink_local_position_ned_message(
            int(t_s * 1000), pos_m[1], pos_m[0], -pos_m[2], vel_m_s[1], vel_m_s[0],
            -vel_m_s[2]).pack(self._companion)
        (ms, x, y, z, vx, vy, vz), = local_positions(data)
        return (ned_to_enu((x, y, z)), ned_to_enu((vx, vy, vz))), int(ms)

    def odometry(self, fix: cl.ExternalPosition) -> cl.ExternalPosition | None:
        """ODOMETRY packed as the winch's link sends it and parsed as the autopilot takes
        it (pymavlink's parser, then ``external_position``)."""
        data = cl.odometry_message(fix).pack(self._winch)
        msg, = self._companion.parse_buffer(data)
        return cl.external_position(msg)

    def tether_reading(self, r: cl.TetherReading) -> cl.TetherReading | None:
        """DEBUG_FLOAT_ARRAY "TETHER" packed as the winch's link sends it and parsed as the
        autopilot takes it."""
        msg, = self._companion.parse_buffer(cl.tether_reading_message(r).pack(self._winch))
        return cl.tether_reading(msg)
