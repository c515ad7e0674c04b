"""The simulator link: PX4's simulator MAVLink API between the plant and the companion.

The plant plays the part Gazebo plays for PX4 SITL: it listens on TCP (port
:data:`SIM_PORT_DEFAULT`, 127.0.0.1 only), or on a Unix-domain socket (addresses in
:func:`parse_sim_address`), and, once per control period, sends the sensor readings and the
truth state; the companion answers with the rotor commands. Both ends use
this module for the wire conventions, so the frame and unit conversions exist once:

==================== ========================================================================
message              content (MAVLink frames and units)
==================== ========================================================================
HIL_SENSOR (107)     specific force [m/s^2] and rates [rad/s] in body FRD, magnetic field
                     [gauss] in body FRD, static pressure [hPa], pressure altitude [m],
                     temperature [degC]; ``fields_updated`` marks what is filled.
HIL_GPS (113)        lat/lon [degE7], altitude AMSL [mm], eph/epv [cm], ground speed and
                     vn/ve/vd [cm/s] NED, course over ground [cdeg], fix type 3.
HIL_STATE_QUATERNION truth: attitude (body FRD -> NED), body rates FRD [rad/s], lat/lon
(115)                [degE7], altitude AMSL [mm], vx/vy/vz NED [cm/s], airspeeds [cm/s],
                     specific force in body FRD [mG].
HIL_ACTUATOR_CONTROLS rotor commands 1..4 in [0, 1] (order of :mod:`tuavdefs.airframe`) in
(93)                 ``controls[0:4]``, ``mode`` 129 armed / 1 disarmed, ``flags`` bit 0
                     lockstep; ``time_usec`` echoes the HIL_SENSOR it answers.
==================== ========================================================================

Control-period convention (lockstep): simulated time is counted in integer microseconds.
The plant stamps the messages describing its state at time ``t`` with ``time_usec = t``
(``t`` a multiple of :func:`control_period_us` after the start), sends HIL_GPS (when due),
HIL_STATE_QUATERNION and last HIL_SENSOR, which closes the batch. The companion answers with
one HIL_ACTUATOR_CONTROLS whose ``time_usec`` is that same ``t``; the plant holds those
commands over ``[t, t + T)`` (:func:`physics_steps_per_period` physics steps) and sends the
batch for ``t + T``.

Inside the project positions are z-up ENU and the body frame FLU; every conversion to and
from MAVLink's NED/FRD here goes through :mod:`tuavdefs.frames` (the per-period decoders
write its axis swaps and sign changes out, ``tests/test_simlink.py`` checks them).

:class:`FrameParser` splits a TCP byte stream into MAVLink frames, dropping (and counting)
malformed, truncated and corrupted frames and resynchronising on the next valid one.

Two ways through: the ``*_fields`` builders and field-based decoders work on mappings and
pymavlink messages (general, for tools and tests); the link's ends, once every control
period, use the same conversions on *values*, a message's fields in wire order as its
``struct`` packs them (``*_values`` builders, :meth:`Encoder.pack_values`,
:meth:`FrameParser.feed_link` for the usual well-formed input, ``*_from_wire`` decoders),
which skip the dictionaries and message objects. ``tests/test_fast_paths.py`` checks that
both give the same bytes and values.

The package in rooms: :mod:`~tuavdefs.simlink.constants` (ports, addresses, ids, units, the
control period), :mod:`~tuavdefs.simlink.codec` (one message's packing and parsing, the
checksum), :mod:`~tuavdefs.simlink.fields` (the field conversions) and
:mod:`~tuavdefs.simlink.frames` (the encoder, whole frames, the stream parser); their names
are all here.
"""

from tuavdefs.simlink.codec import (
    _CODECS,
    LINK_CODECS,
    _Codec,
    count_sent,
    frame_codecs,
    mavlink_crc,
)
from tuavdefs.simlink.constants import (
    COMPANION_COMPID,
    COMPANION_SYSID,
    CONTROL_RATE_HZ_DEFAULT,
    FLAG_LOCKSTEP,
    GPS_FIX_3D,
    GPS_RATE_HZ_DEFAULT,
    GPS_SATELLITES_VISIBLE,
    HOME_DEFAULT,
    MILLI_G_M_S2,
    MODE_ARMED,
    MODE_DISARMED,
    MODE_FLAG_ARMED,
    MODE_FLAG_CUSTOM,
    MSG_HIL_ACTUATOR_CONTROLS,
    MSG_HIL_GPS,
    MSG_HIL_SENSOR,
    MSG_HIL_STATE_QUATERNION,
    MSG_PARAM_SET,
    MSG_PARAM_VALUE,
    N_CONTROLS,
    N_ROTORS,
    PLANT_COMPID,
    PLANT_SYSID,
    SENSOR_ABS_PRESSURE,
    SENSOR_ACCEL,
    SENSOR_DIFF_PRESSURE,
    SENSOR_FIELDS_FILLED,
    SENSOR_GYRO,
    SENSOR_MAG,
    SENSOR_PRESSURE_ALT,
    SENSOR_TEMPERATURE,
    SIM_HOST_DEFAULT,
    SIM_PORT_DEFAULT,
    TCP_SCHEME,
    UINT16_UNKNOWN,
    UNIX_SCHEME,
    control_period_us,
    format_sim_address,
    parse_sim_address,
    physics_steps_per_period,
    time_usec,
    timeval,
    unix_sockaddr,
)
from tuavdefs.simlink.fields import (
    HomeMap,
    actuator_controls_fields,
    actuator_controls_values,
    airspeeds_from_hil_state_quaternion,
    answer_from_wire,
    gps_from_hil_gps,
    gps_from_wire,
    hil_gps_fields,
    hil_gps_values,
    hil_sensor_fields,
    hil_sensor_values,
    hil_state_quaternion_fields,
    hil_state_quaternion_values,
    home_map,
    imu_from_hil_sensor,
    imu_from_wire,
    lockstep_flag,
    rotor_commands_from_controls,
    round_clamp,
    specific_force_from_hil_state_quaternion,
    state_from_hil_state_quaternion,
    truth_from_wire,
    wrap_lon,
)
from tuavdefs.simlink.frames import (
    Encoder,
    FrameParser,
    link_values,
    param_set_frame,
    param_value_frame,
    whole_frames,
)

__all__ = [
    "COMPANION_COMPID",
    "COMPANION_SYSID",
    "CONTROL_RATE_HZ_DEFAULT",
    "Encoder",
    "FLAG_LOCKSTEP",
    "FrameParser",
    "GPS_FIX_3D",
    "GPS_RATE_HZ_DEFAULT",
    "GPS_SATELLITES_VISIBLE",
    "HOME_DEFAULT",
    "HomeMap",
    "LINK_CODECS",
    "MILLI_G_M_S2",
    "MODE_ARMED",
    "MODE_DISARMED",
    "MODE_FLAG_ARMED",
    "MODE_FLAG_CUSTOM",
    "MSG_HIL_ACTUATOR_CONTROLS",
    "MSG_HIL_GPS",
    "MSG_HIL_SENSOR",
    "MSG_HIL_STATE_QUATERNION",
    "MSG_PARAM_SET",
    "MSG_PARAM_VALUE",
    "N_CONTROLS",
    "N_ROTORS",
    "PLANT_COMPID",
    "PLANT_SYSID",
    "SENSOR_ABS_PRESSURE",
    "SENSOR_ACCEL",
    "SENSOR_DIFF_PRESSURE",
    "SENSOR_FIELDS_FILLED",
    "SENSOR_GYRO",
    "SENSOR_MAG",
    "SENSOR_PRESSURE_ALT",
    "SENSOR_TEMPERATURE",
    "SIM_HOST_DEFAULT",
    "SIM_PORT_DEFAULT",
    "TCP_SCHEME",
    "UINT16_UNKNOWN",
    "UNIX_SCHEME",
    "_CODECS",
    "_Codec",
    "actuator_controls_fields",
    "actuator_controls_values",
    "airspeeds_from_hil_state_quaternion",
    "answer_from_wire",
    "control_period_us",
    "count_sent",
    "format_sim_address",
    "frame_codecs",
    "gps_from_hil_gps",
    "gps_from_wire",
    "hil_gps_fields",
    "hil_gps_values",
    "hil_sensor_fields",
    "hil_sensor_values",
    "hil_state_quaternion_fields",
    "hil_state_quaternion_values",
    "home_map",
    "imu_from_hil_sensor",
    "imu_from_wire",
    "link_values",
    "lockstep_flag",
    "mavlink_crc",
    "param_set_frame",
    "param_value_frame",
    "parse_sim_address",
    "physics_steps_per_period",
    "rotor_commands_from_controls",
    "round_clamp",
    "specific_force_from_hil_state_quaternion",
    "state_from_hil_state_quaternion",
    "time_usec",
    "timeval",
    "truth_from_wire",
    "unix_sockaddr",
    "whole_frames",
    "wrap_lon",
]
