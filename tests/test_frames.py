"""Frame conversions: round trips, and known states mapped to what MAVLink expects."""

import math
import random
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tuavdefs import frames as fr

angles = st.floats(-math.pi, math.pi, allow_nan=False)
pitches = st.floats(-1.5, 1.5, allow_nan=False)
coords = st.floats(-1e3, 1e3, allow_nan=False)


def _close(a, b, tol=1e-9):
    return np.allclose(np.asarray(a, float), np.asarray(b, float), atol=tol, rtol=0)


def _same_rotation(q1, q2, tol=1e-9):
    return abs(abs(sum(a * b for a, b in zip(q1, q2, strict=True))) - 1.0) < tol


@given(coords, coords, coords)
def test_position_round_trip(x, y, z):
    assert fr.ned_to_enu(fr.enu_to_ned((x, y, z))) == (x, y, z)
    assert fr.frd_to_flu(fr.flu_to_frd((x, y, z))) == (x, y, z)


@given(angles, pitches, angles)
def test_euler_quaternion_round_trip(roll, pitch, yaw):
    q = fr.euler_to_quat(roll, pitch, yaw)
    r2, p2, y2 = fr.quat_to_euler(q)
    assert _same_rotation(fr.euler_to_quat(r2, p2, y2), q)
    assert math.isclose(p2, pitch, abs_tol=1e-9)


@given(angles, pitches, angles)
def test_attitude_round_trip_enu_ned(roll, pitch, yaw):
    q = fr.euler_to_quat(roll, pitch, yaw)
    back = fr.quat_ned_frd_to_enu_flu(fr.quat_enu_flu_to_ned_frd(q))
    assert _same_rotation(back, q)


@given(angles, pitches, angles, coords, coords, coords)
def test_attitude_conversion_rotates_vectors_consistently(roll, pitch, yaw, x, y, z):
    """A body vector rotated into the world must be the same physical vector in both."""
    q_enu = fr.euler_to_quat(roll, pitch, yaw)
    q_ned = fr.quat_enu_flu_to_ned_frd(q_enu)
    v_flu = (x, y, z)
    world_enu = fr.quat_rotate(q_enu, v_flu)
    world_ned = fr.quat_rotate(q_ned, fr.flu_to_frd(v_flu))
    assert _close(fr.enu_to_ned(world_enu), world_ned, 1e-6)


def test_known_position_and_velocity_map_to_ned():
    # 3 m east, 4 m north, 20 m up; climbing at 1 m/s while flying north at 2 m/s.
    assert fr.enu_to_ned((3.0, 4.0, 20.0)) == (4.0, 3.0, -20.0)
    assert fr.enu_to_ned((0.0, 2.0, 1.0)) == (2.0, 0.0, -1.0)


@pytest.mark.parametrize(
    "enu_euler, ned_euler",
    [
        # level, nose east: NED heading 90 deg
        ((0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2)),
        # level, nose north: NED heading 0
        ((0.0, 0.0, math.pi / 2), (0.0, 0.0, 0.0)),
        # nose east and 0.2 rad nose-down (positive pitch about FLU y): NED pitch -0.2
        ((0.0, 0.2, 0.0), (0.0, -0.2, math.pi / 2)),
        # right wing down by 0.3 rad: positive roll in both conventions
        ((0.3, 0.0, math.pi / 2), (0.3, 0.0, 0.0)),
        # nose west
        ((0.0, 0.0, math.pi), (0.0, 0.0, -math.pi / 2)),
    ],
)
def test_known_attitudes_map_to_ned(enu_euler, ned_euler):
    q_ned = fr.quat_enu_flu_to_ned_frd(fr.euler_to_quat(*enu_euler))
    got = fr.quat_to_euler(q_ned)
    assert _close([got[0], got[1]], ned_euler[:2], 1e-12)
    assert math.isclose(fr.wrap_pi(got[2] - ned_euler[2]), 0.0, abs_tol=1e-12)
    # and the yaw helper agrees with the full conversion
    assert math.isclose(fr.wrap_pi(fr.yaw_enu_to_ned(enu_euler[2]) - ned_euler[2]), 0.0,
                        abs_tol=1e-12)


def test_positive_flu_roll_lowers_the_right_side():
    q = fr.euler_to_quat(0.3, 0.0, 0.0)
    right_flu = (0.0, -1.0, 0.0)
    assert fr.quat_rotate(q, right_flu)[2] < 0.0


def test_positive_flu_pitch_lowers_the_nose():
    q = fr.euler_to_quat(0.0, 0.2, 0.0)
    assert fr.quat_rotate(q, (1.0, 0.0, 0.0))[2] < 0.0


def test_rotation_matrix_is_zyx():
    roll, pitch, yaw = 0.1, -0.4, 2.0
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    want = rz @ ry @ rx
    got = np.array(fr.quat_to_matrix(fr.euler_to_quat(roll, pitch, yaw)))
    assert _close(got, want, 1e-12)
    # The paper's R has C_psi in row 2, column 1; the correct entry is C_theta S_psi.
    assert math.isclose(want[1, 0], cp * sy, abs_tol=1e-15)


def test_gimbal_lock_is_handled():
    q = fr.euler_to_quat(0.0, math.pi / 2, 0.7)
    roll, pitch, yaw = fr.quat_to_euler(q)
    assert math.isclose(pitch, math.pi / 2, abs_tol=1e-6)
    assert _same_rotation(fr.euler_to_quat(roll, pitch, yaw), q, 1e-9)


@given(st.floats(-80, 80), st.floats(-179, 179), st.floats(-100, 3000),
       st.floats(-500, 500), st.floats(-500, 500), st.floats(-100, 500))
def test_global_round_trip(lat0, lon0, alt0, e, n, u):
    home = (lat0, lon0, alt0)
    lat, lon, alt = fr.local_enu_to_global((e, n, u), home)
    back = fr.global_to_local_enu(lat, lon, alt, home)
    assert _close(back, (e, n, u), 1e-6)


def test_global_mapping_scale():
    # At the equator one degree of latitude is ~110.574 km and of longitude ~111.320 km.
    lat, lon, _ = fr.local_enu_to_global((111320.0, 110574.0, 0.0), (0.0, 0.0, 0.0))
    assert math.isclose(lat, 1.0, abs_tol=2e-3)
    assert math.isclose(lon, 1.0, abs_tol=2e-3)


def _quat_cases(n: int):
    """Random unit-range quaternions, half of them with components among the values that
    make products zero or exact (signed zeros, +-1, +-sqrt(1/2), subnormals)."""
    rnd = random.Random(20261122)
    special = [0.0, -0.0, 1.0, -1.0, 0.5, -0.5, math.sqrt(0.5), -math.sqrt(0.5), 1e-300,
               -5e-324, 3.0, math.nan, math.inf]
    for i in range(n):
        yield tuple(rnd.choice(special) if i % 2 and rnd.random() < 0.5
                    else rnd.uniform(-1.0, 1.0) for _ in range(4))


def _outcome(fn, q):
    try:
        return struct.pack("<4d", *fn(q))      # bit for bit, the zeros' signs included
    except ValueError as e:
        return str(e)


def test_the_written_out_attitude_conversion_is_the_products_bit_for_bit():
    for q in _quat_cases(50_000):
        assert (_outcome(fr.quat_ned_frd_to_enu_flu, q)
                == _outcome(fr._quat_ned_frd_to_enu_flu_products, q)), q


def test_the_yaw_alone_is_the_euler_yaw():
    cases = [fr.euler_to_quat(r, p, y) for r, p, y in
             np.random.default_rng(3).uniform(-3.2, 3.2, (2000, 3))]
    cases += [fr.euler_to_quat(0.3, s * math.pi / 2, 1.0) for s in (-1, 1)]   # gimbal lock
    cases += [(1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (math.nan, 0.0, 0.0, 0.0)]
    for q in cases:
        assert struct.pack("<d", fr.quat_to_yaw(q)) == struct.pack("<d", fr.quat_to_euler(q)[2])


def test_mav_frames_table_reads_each_altitude_reference():
    """The one frame table: AMSL frames subtract the winder's altitude, relative and
    terrain frames are heights above its (flat) ground, local frames are not global, and a
    position 100 m north of the winder lands 100 m along +y."""
    from pymavlink.dialects.v20 import common as mav

    from tuavdefs.frames import local_enu_to_global
    from tuavdefs.mav_frames import (
        GLOBAL_FRAMES,
        LOCAL_FRAMES,
        AltitudeReference,
        altitude_to_z,
        global_to_local,
    )

    origin = (47.0, 8.0, 500.0)
    assert altitude_to_z(510.0, mav.MAV_FRAME_GLOBAL, origin) == 10.0
    assert altitude_to_z(510.0, None, origin) == 10.0          # COMMAND_LONG: AMSL
    for frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
        assert GLOBAL_FRAMES[frame] is AltitudeReference.HOME
        assert altitude_to_z(10.0, frame, origin) == 10.0
    assert not set(GLOBAL_FRAMES) & LOCAL_FRAMES
    lat, lon, _ = local_enu_to_global((0.0, 100.0, 0.0), origin)
    x, y, z = global_to_local(lat, lon, 12.0, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, origin)
    assert abs(x) < 1e-6 and abs(y - 100.0) < 1e-6 and z == 12.0
    with pytest.raises(KeyError):
        altitude_to_z(1.0, mav.MAV_FRAME_LOCAL_NED, origin)
