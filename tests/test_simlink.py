"""The simulator link: field packing round trips, framing, and the plant's lockstep server
against the companion's client over loopback TCP and Unix-domain sockets."""

from __future__ import annotations

import errno
import math
import os
import socket
import stat
import sys
import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from companion.simlink_client import SimLinkClient
from sitl import simlink_server
from sitl.plant import Plant
from sitl.sensors import SensorNoise
from sitl.simlink_server import SimLinkServer, WinderInputs
from sitl.trim import hover_trim
from tuavdefs import frames as fr
from tuavdefs import simlink as sl
from tuavdefs.params import SystemParams, TetherParams

HOME = (47.397742, 8.545594, 488.0)
HOVER_AT = (12.0, 5.0, 20.0)
HOVER_TETHER_M = 30.0
G = 9.81

# message resolution: 1e-7 deg of latitude is ~1.11 cm; rounding errs by half of it
_LAT_STEP_M = math.radians(1e-7) * 6.4e6
POS_TOL_H = 0.5 * _LAT_STEP_M + 1e-6
POS_TOL_V = 0.5e-3 + 1e-6
VEL_TOL = 0.5e-2 + 1e-9


# ----------------------------------------------------------------- helpers
def _same_rotation(q1, q2, tol=1e-6) -> bool:
    return abs(abs(sum(a * b for a, b in zip(q1, q2, strict=True))) - 1.0) < tol


def _hover():
    # the trim is the catenary's equilibrium (the lumped line pulls 0.6 % harder there)
    params = SystemParams().replace(tether=TetherParams(model="catenary"))
    x, u = hover_trim(params, HOVER_AT, HOVER_TETHER_M)
    return Plant(params, state=x), u


@contextmanager
def serving(server: SimLinkServer, **serve_kw):
    """Run ``server.serve`` in a thread; yields a dict that gets the summary."""
    stop = threading.Event()
    out: dict = {}

    def run():
        try:
            out["summary"] = server.serve(stop_event=stop, **serve_kw)
        except BaseException as e:  # noqa: BLE001 - reported to the test
            out["error"] = e

    th = threading.Thread(target=run, daemon=True)
    th.start()
    out["thread"] = th
    try:
        yield out
    finally:
        stop.set()
        th.join(10.0)
        server.close()
    assert not th.is_alive(), "serve() did not end"
    assert "error" not in out, out.get("error")


def _finish(out: dict, client: SimLinkClient):
    """Disconnect and return serve()'s summary."""
    client.close()
    out["thread"].join(10.0)
    assert not out["thread"].is_alive()
    return out["summary"]


def _client(server: SimLinkServer) -> SimLinkClient:
    if server.unix_path is not None:
        c = SimLinkClient(home=HOME, unix_path=server.unix_path)
    else:
        c = SimLinkClient(port=server.port, home=HOME)
    c.connect(timeout_s=10.0)
    return c


# ----------------------------------------------------------------- conventions
def test_control_period_convention():
    assert sl.SIM_PORT_DEFAULT == 4560
    assert sl.control_period_us(250) == 4000
    assert sl.physics_steps_per_period(250, 0.001) == 4
    assert sl.physics_steps_per_period(50, 0.001) == 20
    with pytest.raises(ValueError):
        sl.control_period_us(300)          # 3333.3 us
    with pytest.raises(ValueError):
        sl.physics_steps_per_period(250, 0.003)
    with pytest.raises(ValueError):
        sl.control_period_us(0)


# ----------------------------------------------------------------- known mappings
def test_known_state_maps_to_ned_frd():
    # nose east (z-up yaw 0), flying east 2 m/s and climbing 1 m/s, rolling right
    # (FLU roll rate -0.1 = FRD +0.1), 10 m north and 3 m up of home
    q = fr.euler_to_quat(0.0, 0.0, 0.0)
    f = sl.hil_state_quaternion_fields(123, (0.0, 10.0, 3.0), (2.0, 0.0, 1.0), q,
                                       (-0.1, 0.2, 0.3), (0.0, 0.0, G), HOME)
    assert f["vx"] == 0 and f["vy"] == 200 and f["vz"] == -100
    assert f["rollspeed"] == pytest.approx(-0.1)
    assert f["pitchspeed"] == pytest.approx(-0.2) and f["yawspeed"] == pytest.approx(-0.3)
    assert f["zacc"] == round(-G / sl.MILLI_G_M_S2) and f["xacc"] == f["yacc"] == 0
    assert f["lat"] > round(HOME[0] * 1e7) and f["lon"] == round(HOME[1] * 1e7)
    assert f["alt"] == round((HOME[2] + 3.0) * 1000)
    # heading east is NED yaw +90 deg
    roll, pitch, yaw = fr.quat_to_euler(tuple(f["attitude_quaternion"]))
    assert yaw == pytest.approx(math.pi / 2) and roll == pytest.approx(0, abs=1e-12)
    g = sl.hil_gps_fields(0, (0.0, 0.0, 0.0), (1.0, 1.0, -0.5), HOME)
    assert (g["vn"], g["ve"], g["vd"], g["vel"]) == (100, 100, 50, 141)
    assert g["cog"] == 4500 and g["fix_type"] == 3
    assert sl.hil_gps_fields(0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), HOME)["cog"] == 65535
    s = sl.hil_sensor_fields(0, (0.1, 0.2, G), (0.01, 0.02, 0.03), (0.0, 0.2, -0.45),
                             1000.0, 110.0, 15.0)
    assert (s["xacc"], s["yacc"], s["zacc"]) == pytest.approx((0.1, -0.2, -G))
    assert (s["xgyro"], s["ygyro"], s["zgyro"]) == pytest.approx((0.01, -0.02, -0.03))
    assert (s["xmag"], s["ymag"], s["zmag"]) == pytest.approx((0.0, -0.2, 0.45))
    assert s["fields_updated"] == sl.SENSOR_FIELDS_FILLED
    assert not s["fields_updated"] & sl.SENSOR_DIFF_PRESSURE


# ----------------------------------------------------------------- round trips
finite = dict(allow_nan=False, allow_infinity=False)
pos_st = st.tuples(st.floats(-500, 500, **finite), st.floats(-500, 500, **finite),
                   st.floats(-10, 400, **finite))
vel_st = st.tuples(*[st.floats(-60, 60, **finite)] * 3)
rate_st = st.tuples(*[st.floats(-20, 20, **finite)] * 3)
quat_st = st.tuples(*[st.floats(-1, 1, **finite)] * 4).filter(
    lambda q: sum(c * c for c in q) > 0.01).map(fr.quat_normalize)
home_st = st.tuples(st.floats(-80, 80, **finite), st.floats(-180, 179.999, **finite),
                    st.floats(-100, 4000, **finite))


def _through_the_wire(frame: bytes):
    msgs = mavlink2.MAVLink(None).parse_buffer(frame)
    assert msgs is not None and len(msgs) == 1
    return msgs[0]


@settings(max_examples=200, deadline=None)
@given(pos_st, vel_st, quat_st, rate_st, home_st)
def test_state_round_trip(pos, vel, q, rates, home):
    enc = sl.Encoder(1, 1)
    fields = sl.hil_state_quaternion_fields(5, pos, vel, q, rates, (0.5, -0.3, G), home)
    msg = _through_the_wire(enc.hil_state_quaternion(fields))
    p2, v2, q2, r2 = sl.state_from_hil_state_quaternion(msg, home)
    assert abs(p2[0] - pos[0]) <= POS_TOL_H and abs(p2[1] - pos[1]) <= POS_TOL_H
    assert abs(p2[2] - pos[2]) <= POS_TOL_V
    assert np.allclose(v2, vel, atol=VEL_TOL, rtol=0)
    assert _same_rotation(q2, q)
    assert np.allclose(r2, rates, rtol=1e-6, atol=1e-7)
    f2 = sl.specific_force_from_hil_state_quaternion(msg)
    assert np.allclose(f2, (0.5, -0.3, G), atol=0.5 * sl.MILLI_G_M_S2 + 1e-12, rtol=0)
    # the same from the field mapping, without the wire
    p3, *_ = sl.state_from_hil_state_quaternion(fields, home)
    assert p3 == p2


@settings(max_examples=200, deadline=None)
@given(pos_st, vel_st, home_st)
def test_gps_round_trip(pos, vel, home):
    fields = sl.hil_gps_fields(7, pos, vel, home, eph_m=0.3, epv_m=0.5)
    msg = _through_the_wire(sl.Encoder(1, 1).hil_gps(fields))
    p2, v2, eph, epv = sl.gps_from_hil_gps(msg, home)
    assert abs(p2[0] - pos[0]) <= POS_TOL_H and abs(p2[1] - pos[1]) <= POS_TOL_H
    assert abs(p2[2] - pos[2]) <= POS_TOL_V
    assert np.allclose(v2, vel, atol=VEL_TOL, rtol=0)
    assert (eph, epv) == (0.3, 0.5)


@given(vel_st, rate_st, vel_st, st.floats(500, 1100, **finite))
def test_sensor_round_trip(acc, gyro, mag, pressure):
    fields = sl.hil_sensor_fields(9, acc, gyro, mag, pressure, 100.0, 10.0)
    msg = _through_the_wire(sl.Encoder(1, 200).hil_sensor(fields))
    a2, g2, m2, p2, alt2, t2 = sl.imu_from_hil_sensor(msg)
    for got, want in ((a2, acc), (g2, gyro), (m2, mag)):
        assert np.allclose(got, want, rtol=1e-6, atol=1e-30)
    assert p2 == pytest.approx(pressure, rel=1e-6)
    assert (alt2, t2) == (100.0, 10.0)


@given(st.tuples(*[st.floats(0, 1, **finite)] * 4), st.booleans(), st.booleans())
def test_actuator_round_trip(cmds, armed, lockstep):
    fields = sl.actuator_controls_fields(cmds, armed, lockstep)
    assert len(fields["controls"]) == 16 and fields["controls"][4:] == [0.0] * 12
    assert fields["mode"] == (129 if armed else 1)
    msg = _through_the_wire(sl.Encoder(1, 1).hil_actuator_controls(42, fields))
    assert msg.time_usec == 42
    got, armed2 = sl.rotor_commands_from_controls(msg.controls, msg.mode)
    assert armed2 == armed and sl.lockstep_flag(msg.flags) == lockstep
    assert np.allclose(got, cmds, rtol=1e-7, atol=1e-12)


def test_actuator_commands_are_cleaned():
    f = sl.actuator_controls_fields((1.5, -0.2, float("nan"), 0.5), armed=True)
    assert f["controls"][:4] == [1.0, 0.0, 0.0, 0.5]
    cmds, armed = sl.rotor_commands_from_controls([2.0, float("nan"), -1.0, 0.25] + [0] * 12,
                                                  mode=128)
    assert cmds == (1.0, 0.0, 0.0, 0.25) and armed
    assert sl.rotor_commands_from_controls([0.5] * 16, mode=1)[1] is False
    with pytest.raises(ValueError):
        sl.actuator_controls_fields((0.5, 0.5, 0.5), armed=True)


# ----------------------------------------------------------------- framing
def _answer_frame(t_us=0, cmds=(0.5, 0.5, 0.5, 0.5)) -> bytes:
    return sl.Encoder(1, 1).hil_actuator_controls(
        t_us, sl.actuator_controls_fields(cmds, True))


def test_parser_splits_any_way():
    frames = b"".join(_answer_frame(t) for t in range(5))
    p = sl.FrameParser()
    got = []
    for i in range(len(frames)):                 # byte by byte
        got += p.feed(frames[i:i + 1])
    assert [m.time_usec for m in got] == list(range(5))
    assert (p.bad_frames, p.bad_bytes, p.pending_bytes) == (0, 0, 0)


@pytest.mark.parametrize("junk", [
    b"hello, not mavlink",                             # no start marker
    _answer_frame(99)[:15],                            # truncated frame
    b"\xfd\xff\x00" + b"\x01" * 20,                    # header claiming 255 bytes
    bytes([0xfd, 4, 0x80]) + b"\x00" * 20,             # impossible incompat flags
    b"\xfe\x05\x00\x01\x01\xf0abcde\x00\x00",            # MAVLink 1, unknown id
])
def test_parser_drops_junk_and_resyncs(junk):
    good = _answer_frame(7)
    corrupt = bytearray(_answer_frame(8))
    corrupt[12] ^= 0xFF                                # payload byte: CRC fails
    for stream in (junk + good, bytes(corrupt) + good, good + junk + good):
        p = sl.FrameParser()
        got = p.feed(stream)
        assert [m.time_usec for m in got][-1] == 7
        assert all(m.time_usec == 7 for m in got)
        assert p.bad_frames == 1 and p.bad_bytes > 0 and p.pending_bytes == 0
    # split at every position: same result
    stream = junk + good
    for cut in range(1, len(stream)):
        p = sl.FrameParser()
        got = p.feed(stream[:cut]) + p.feed(stream[cut:])
        assert [m.time_usec for m in got] == [7] and p.bad_frames == 1


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_parser_never_raises_and_finds_the_frame_after_garbage(garbage):
    p = sl.FrameParser()
    got = p.feed(garbage) + p.feed(_answer_frame(3))
    assert any(m.get_msgId() == sl.MSG_HIL_ACTUATOR_CONTROLS and m.time_usec == 3
               for m in got)


# ----------------------------------------------------------------- the server
def test_server_only_on_loopback():
    plant, _ = _hover()
    with pytest.raises(ValueError):
        SimLinkServer(plant, host="0.0.0.0", port=0)
    with pytest.raises(ValueError):      # 300 Hz is no whole number of microseconds
        SimLinkServer(plant, port=0, control_rate_hz=300)


def test_lockstep_one_period_per_answer_and_truth_matches():
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    period = server.period_us
    assert (period, server.physics_steps, server.pacing) == (4000, 4, "lockstep")
    with serving(server) as out:
        client = _client(server)
        gps_steps = []
        for k in range(60):
            s = client.receive_state(timeout_s=10)
            # the plant is frozen until answered: its state is the one just sent
            assert s.time_usec == k * period and server.steps == k
            assert plant.t_s == pytest.approx(k * period * 1e-6, abs=1e-9)
            tr = s.truth
            assert tr is not None and tr.time_usec == s.time_usec
            pos, vel = plant.position_m, plant.velocity_m_s
            assert abs(tr.position_enu_m[0] - pos[0]) <= POS_TOL_H
            assert abs(tr.position_enu_m[1] - pos[1]) <= POS_TOL_H
            assert abs(tr.position_enu_m[2] - pos[2]) <= POS_TOL_V
            assert np.allclose(tr.velocity_enu_m_s, vel, atol=VEL_TOL, rtol=0)
            assert _same_rotation(tr.quaternion, plant.quaternion)
            assert np.allclose(tr.body_rates_flu_rad_s, plant.body_rates_rad_s, atol=1e-6)
            # noise off: the IMU reads the truth to float32
            assert np.allclose(s.imu.gyro_flu_rad_s, plant.body_rates_rad_s, atol=1e-6)
            assert s.imu.fields_updated == sl.SENSOR_FIELDS_FILLED
            if s.gps_updated:
                gps_steps.append(k)
                assert s.gps.time_usec == s.time_usec
                assert np.allclose(s.gps.position_enu_m, pos, atol=POS_TOL_H)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        assert gps_steps == [0, 25, 50]          # HIL_GPS at 10 Hz

        # no step without an answer: hold the answer back
        s = client.receive_state(timeout_s=10)
        t_held, steps_held = plant.t_s, server.steps
        with pytest.raises(TimeoutError):
            client.receive_state(timeout_s=0.3)
        # an answer to another time does not release the lockstep either
        client.send_actuators(s.time_usec - period, u.rotor_commands, armed=True)
        with pytest.raises(TimeoutError):
            client.receive_state(timeout_s=0.3)
        assert (plant.t_s, server.steps) == (t_held, steps_held)
        client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        s2 = client.receive_state(timeout_s=10)
        assert s2.time_usec == s.time_usec + period and server.steps == steps_held + 1
        assert server.companion_lockstep and server.last_inputs.armed
        summary = _finish(out, client)
    assert summary.end_reason == "disconnected"
    assert summary.steps == 61 and summary.sim_time_s == pytest.approx(61 * 0.004)
    assert summary.ignored_messages == 1 and summary.bad_frames == 0
    assert summary.missed_deadlines == 0 and summary.pacing == "lockstep"
    # hover trim held: the UAV is still where it was
    assert np.linalg.norm(plant.position_m - HOVER_AT) < 1e-3


def test_raw_stream_decodes_with_pymavlink_and_hover_accel():
    """Independent of the project's client: a raw socket, pymavlink's own parser."""
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    with serving(server) as out:
        sock = socket.create_connection(("127.0.0.1", server.port), timeout=10)
        pending: list = []
        for k in range(30):
            batch = []
            while not batch or batch[-1].get_type() != "HIL_SENSOR":
                while not pending:
                    msgs = mav.parse_buffer(sock.recv(4096))
                    pending += msgs or []
                batch.append(pending.pop(0))
            types = [m.get_type() for m in batch]
            assert types == (["HIL_GPS"] if k % 25 == 0 else []) + [
                "HIL_STATE_QUATERNION", "HIL_SENSOR"]
            sens, state = batch[-1], batch[-2]
            t_us = k * 4000
            assert sens.time_usec == state.time_usec == t_us
            assert sens.get_srcSystem() == 1 and sens.get_srcComponent() == 200
            # accelerometer: the specific force balances gravity at hover, so along body
            # z (FRD, down) it reads -g cos(tilt); tilt from the plant's attitude
            r = fr.quat_to_matrix(plant.quaternion)
            cos_tilt = r[2][2]
            assert 0.99 < cos_tilt < 1.0                       # the trim is tilted
            assert sens.zacc == pytest.approx(-G * cos_tilt, abs=2e-3)
            assert sens.xacc == pytest.approx(G * r[2][0], abs=2e-3)     # FRD x = FLU x
            assert sens.yacc == pytest.approx(-G * r[2][1], abs=2e-3)    # FRD y = -FLU y
            assert sens.fields_updated == 0x1BFF
            q_ned = fr.quat_enu_flu_to_ned_frd(plant.quaternion)
            assert _same_rotation(state.attitude_quaternion, q_ned)
            lat, lon, alt = fr.local_enu_to_global(tuple(plant.position_m), HOME)
            assert (state.lat, state.lon, state.alt) == (
                round(lat * 1e7), round(lon * 1e7), round(alt * 1e3))
            if types[0] == "HIL_GPS":
                assert (batch[0].lat, batch[0].lon) == (state.lat, state.lon)
            # answer packed by pymavlink itself
            ans = mav.hil_actuator_controls_encode(
                t_us, list(u.rotor_commands) + [0.0] * 12, 129, 1)
            sock.sendall(ans.pack(mav))
            mav.seq = (mav.seq + 1) % 256
        sock.close()
        out["thread"].join(10)
        summary = out["summary"]
    assert summary.steps == 30 and summary.bad_frames == 0
    assert server.last_inputs.rotor_commands == pytest.approx(u.rotor_commands, rel=1e-6)


def _fly(noise: SensorNoise, n: int, unix_path: str | None = None):
    """n lockstep periods with varying commands (over TCP, or the Unix-domain socket
    ``unix_path``); returns (batches, final state, server)."""
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=noise, unix_path=unix_path)
    seen = []
    with serving(server) as out:
        client = _client(server)
        for k in range(n):
            s = client.receive_state(timeout_s=10)
            seen.append(s)
            cmds = tuple(c + 0.02 * math.sin(0.05 * k + i)
                         for i, c in enumerate(u.rotor_commands))
            client.send_actuators(s.time_usec, cmds, armed=True)
        _finish(out, client)
    return seen, plant.x.copy(), server


def test_determinism_and_no_perturbation_of_the_plant():
    noise = SensorNoise(seed=7)
    a, xa, server = _fly(noise, 150)
    b, xb, _ = _fly(noise, 150)
    assert a == b                        # every field of every batch
    assert np.array_equal(xa, xb)        # bit-identical trajectory
    assert a[-1].imu != _fly(SensorNoise(seed=8), 150)[0][-1].imu   # the seed matters
    # the link (and reading the sensors) leaves the physics exactly as stepping it directly
    plant, u = _hover()
    for k in range(150):
        # the commands cross the wire as float32
        cmds = tuple(float(np.float32(c + 0.02 * math.sin(0.05 * k + i)))
                     for i, c in enumerate(u.rotor_commands))
        step_u = u._replace(rotor_commands=cmds)
        for _ in range(server.physics_steps):
            plant.step(step_u)
    assert np.array_equal(plant.x, xa)
    assert np.linalg.norm(plant.position_m - HOVER_AT) > 1e-3   # the commands did something


ABSTRACT = pytest.mark.skipif(not sys.platform.startswith("linux"),
                              reason="abstract socket names are Linux's")


@pytest.mark.parametrize("where", ["file", pytest.param("abstract", marks=ABSTRACT)])
def test_a_unix_domain_link_carries_the_same_lockstep(tmp_path, where):
    """Over a Unix-domain socket (a file, or an abstract name) the batches and the flight
    are those over TCP, to the bit; the socket file goes with the server."""
    noise = SensorNoise(seed=3)
    tcp, x_tcp, _ = _fly(noise, 60)
    path = str(tmp_path / "sim.sock") if where == "file" else f"@tuav-test-{os.getpid()}"
    unix, x_unix, server = _fly(noise, 60, unix_path=path)
    assert unix == tcp and np.array_equal(x_unix, x_tcp)
    assert server.address == f"unix:{path}" and server.port == 0
    assert not os.path.lexists(path)


def test_a_unix_socket_path_in_use_is_refused_and_left_alone(tmp_path):
    """A second plant on the same path fails as on a TCP port in use (EADDRINUSE) without
    touching the first, which still serves; a plain file there is not replaced either."""
    path = tmp_path / "sim.sock"
    plant, u = _hover()
    first = SimLinkServer(plant, home=HOME, unix_path=str(path))
    assert stat.S_ISSOCK(os.lstat(path).st_mode)
    with pytest.raises(OSError) as info:
        SimLinkServer(_hover()[0], home=HOME, unix_path=str(path))
    assert info.value.errno == errno.EADDRINUSE and "a socket is already there" in str(
        info.value)
    with serving(first) as out:
        client = _client(first)
        s = client.receive_state(timeout_s=10)
        client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        assert client.receive_state(timeout_s=10).time_usec == s.time_usec + first.period_us
        _finish(out, client)
    assert not path.exists()
    other = tmp_path / "notes.txt"
    other.write_text("keep me")
    with pytest.raises(OSError, match="a file is already there"):
        SimLinkServer(plant, home=HOME, unix_path=str(other))
    assert other.read_text() == "keep me"


def test_close_leaves_a_socket_file_that_is_no_longer_its_own(tmp_path):
    path = tmp_path / "sim.sock"
    server = SimLinkServer(_hover()[0], home=HOME, unix_path=str(path))
    os.unlink(path)
    path.write_text("someone else's")
    server.close()
    assert path.read_text() == "someone else's"


def test_client_names_the_unix_socket_it_did_not_find(tmp_path):
    client = SimLinkClient(home=HOME, unix_path=str(tmp_path / "none.sock"))
    with pytest.raises(TimeoutError, match=f"no simulator at unix:{tmp_path}/none.sock"):
        client.connect(timeout_s=0.1)


@pytest.mark.parametrize(("text", "address"), [
    ("127.0.0.1:4560", ("127.0.0.1", 4560)), ("tcp:127.0.0.1:5000", ("127.0.0.1", 5000)),
    (":4570", ("127.0.0.1", 4570)), ("unix:/run/tuav/sim.sock", "/run/tuav/sim.sock"),
    ("unix:@tuav-sitl-sim-0", "@tuav-sitl-sim-0"), ("unix:rel/sim.sock", "rel/sim.sock")])
def test_sim_addresses_parse_and_print_back(text, address):
    assert sl.parse_sim_address(text) == address
    assert sl.parse_sim_address(sl.format_sim_address(address)) == address
    if isinstance(address, str):
        want = "\0" + address[1:] if address.startswith("@") else address
        assert sl.unix_sockaddr(address) == want


@pytest.mark.parametrize("text", ["", "unix:", "unix:@", "4560", "host:port", "h:0",
                                  "h:65536", "tcp:", "unix:a\0b"])
def test_bad_sim_addresses_are_refused(text):
    with pytest.raises(ValueError):
        sl.parse_sim_address(text)


def test_disarmed_commands_stop_the_rotors():
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    with serving(server) as out:
        client = _client(server)
        for _ in range(125):      # 0.5 s
            s = client.receive_state(timeout_s=10)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=False)
        client.receive_state(timeout_s=10)
        assert not server.armed and not server.last_inputs.armed
        assert np.all(plant.rotor_speeds_rad_s < 1.0)
        assert plant.velocity_m_s[2] < -1.0                    # falling
        _finish(out, client)


def test_winder_inputs_are_the_callers():
    plant, u = _hover()
    seen = []
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off(),
                           winder_inputs=WinderInputs(0.5, True),
                           on_step=lambda srv: seen.append(srv.last_inputs))
    with serving(server) as out:
        client = _client(server)
        for k in range(6):
            s = client.receive_state(timeout_s=10)
            if k == 3:
                server.winder_inputs = WinderInputs(-1.0, True)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        _finish(out, client)
    assert [i.winder_torque_n_m for i in seen] == [0.5, 0.5, 0.5, -1.0, -1.0, -1.0]
    assert all(i.winder_enabled and i.armed for i in seen)


def test_garbage_on_the_socket_is_counted_and_dropped():
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    enc = sl.Encoder(1, 1)
    junk_by_step = {
        2: b"this is not mavlink at all",
        4: _answer_frame(123)[:17],                      # truncated frame
        6: bytes(b ^ 0xFF if i == 14 else b for i, b in enumerate(_answer_frame(4))),
        8: b"\xfd\xff\x00\x00" + bytes(range(1, 40)),    # header promising 255 bytes
    }
    with serving(server) as out:
        client = _client(server)
        for k in range(12):
            s = client.receive_state(timeout_s=10)
            answer = enc.hil_actuator_controls(
                s.time_usec, sl.actuator_controls_fields(u.rotor_commands, True))
            if k in junk_by_step:
                client.send_raw(junk_by_step[k] + answer)
            elif k == 10:       # a valid message that is not an answer: ignored
                client.send_raw(enc.pack(enc.mav.heartbeat_encode(18, 8, 0, 0, 0)) + answer)
            else:
                client.send_raw(answer)
        client.receive_state(timeout_s=10)
        summary = _finish(out, client)
    assert summary.steps == 12 and summary.end_reason == "disconnected"
    assert summary.bad_frames == len(junk_by_step)
    assert summary.bad_bytes >= sum(len(j) for j in junk_by_step.values())
    assert summary.ignored_messages == 1
    assert client.bad_frames == 0


def test_end_of_serve():
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    # disconnect while the plant waits for an answer
    with serving(server) as out:
        client = _client(server)
        for _ in range(10):
            s = client.receive_state(timeout_s=10)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        client.receive_state(timeout_s=10)
        summary = _finish(out, client)
    assert (summary.end_reason, summary.steps) == ("disconnected", 10)
    assert summary.sim_time_s == pytest.approx(0.04)
    assert summary.wall_time_s > 0 and summary.steps_per_s > 0

    # a simulated-time limit: the client then sees the link close
    plant, u = _hover()
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off())
    with serving(server, max_sim_time_s=0.1) as out:
        client = _client(server)
        with pytest.raises(ConnectionError):
            for _ in range(100):
                s = client.receive_state(timeout_s=10)
                client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        out["thread"].join(10)
        summary = out["summary"]
        client.close()
    assert (summary.end_reason, summary.steps) == ("max_sim_time", 25)
    assert plant.t_s == pytest.approx(0.1)

    # nobody connects
    plant, _ = _hover()
    server = SimLinkServer(plant, port=0)
    with serving(server, accept_timeout_s=0.2) as out:
        out["thread"].join(10)
    assert out["summary"].end_reason == "no_client" and out["summary"].steps == 0


@pytest.mark.parametrize("real_time", [True, False])
def test_late_answers_miss_deadlines_only_in_real_time(real_time):
    plant, u = _hover()
    rate = 50.0                       # 20 ms periods
    server = SimLinkServer(plant, port=0, home=HOME, control_rate_hz=rate,
                           real_time=real_time, sensor_noise=SensorNoise.off())
    assert server.pacing == ("real-time" if real_time else "lockstep")
    late_steps = {5, 6, 7}
    with serving(server) as out:
        client = _client(server)
        answered = 0
        while answered < 15:
            s = client.receive_state(timeout_s=10)
            if answered in late_steps:
                time.sleep(2.5 / rate)    # answer more than a period late
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
            answered += 1
        summary = _finish(out, client)
    assert summary.pacing == server.pacing
    if real_time:
        # each deliberately late answer misses its deadline (later ones may too)
        assert summary.missed_deadlines >= len(late_steps)
        assert summary.late_answers >= 1
    else:
        assert summary.missed_deadlines == 0 and summary.late_answers == 0
        assert summary.steps == 15


def test_the_written_out_decoders_are_the_frame_conversions():
    """truth_from_wire and imu_from_wire spell out the frames module's conversions; the
    same floats come out as through them, payloads short of their trailing zeros too."""
    rng = np.random.default_rng(9)
    hm = sl.home_map(HOME)
    enc = sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID)
    for k in range(400):
        pos, vel, rates, force, mag = (tuple(rng.uniform(-30.0, 30.0, 3)) for _ in range(5))
        if k % 4 == 0:
            force = (force[0], force[1], 0.0)   # zacc 0: the payload loses its last bytes
        q = fr.euler_to_quat(*rng.uniform(-3.0, 3.0, 3))
        data = (enc.pack_values(sl.MSG_HIL_STATE_QUATERNION, sl.hil_state_quaternion_values(
                    4000 * k, pos, vel, q, rates, force, hm, 3.0, 2.5))
                + enc.pack_values(sl.MSG_HIL_SENSOR, sl.hil_sensor_values(
                    4000 * k, force, rates, mag, 990.0, 210.0, 12.0)))
        items = sl.FrameParser().feed_link(data)
        assert items == [sl.link_values(m) for m in sl.FrameParser().feed(data)]
        (_, v), (_, w) = items
        assert sl.truth_from_wire(v, hm) == (
            hm.local(v[8], v[9], v[10]), fr.ned_to_enu((v[11] * 0.01, v[12] * 0.01,
                                                        v[13] * 0.01)),
            fr._quat_ned_frd_to_enu_flu_products(v[1:5]), fr.frd_to_flu(v[5:8]),
            fr.frd_to_flu(tuple(x * sl.MILLI_G_M_S2 for x in v[16:19])),
            v[15] * 0.01, v[14] * 0.01)
        assert sl.imu_from_wire(w) == (fr.frd_to_flu(w[1:4]), fr.frd_to_flu(w[4:7]),
                                       fr.frd_to_flu(w[7:10]), w[10], w[12], w[13])


def test_the_actuator_frame_is_the_general_packing():
    """Encoder.actuator_controls sends the bytes pack_values sends for
    actuator_controls_values, commands to clean included, and counts alike."""
    rnd = np.random.default_rng(4)
    fast, ref = sl.Encoder(1, 1), sl.Encoder(1, 1)
    odd = [0.0, -0.0, 1.0, 1, 0, 1.5, -0.25, math.nan, math.inf, -math.inf, np.float32(0.3)]
    for k in range(2000):
        cmds = tuple(odd[int(rnd.integers(len(odd)))] if rnd.random() < 0.3
                     else float(rnd.random()) for _ in range(4))
        armed, lockstep = bool(k % 3), bool(k % 5)
        t_us = int(rnd.integers(0, 2**50))
        assert fast.actuator_controls(t_us, cmds, armed, lockstep) == ref.pack_values(
            sl.MSG_HIL_ACTUATOR_CONTROLS, sl.actuator_controls_values(t_us, cmds, armed,
                                                                      lockstep))
    assert (fast.mav.seq, fast.mav.total_packets_sent, fast.mav.total_bytes_sent) == (
        ref.mav.seq, ref.mav.total_packets_sent, ref.mav.total_bytes_sent)
    with pytest.raises(ValueError):
        fast.actuator_controls(0, (0.5,) * 3, True)


class _SmallWindowClient(SimLinkClient):
    """The companion's client with a 2 KiB receive buffer (set before it connects, so the
    TCP window is that small): a companion that stops reading fills the link at once."""

    def _open(self, timeout_s: float) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
        sock.settimeout(timeout_s)
        try:
            sock.connect((self.host, self.port))
        except OSError:
            sock.close()
            raise
        return sock


def test_real_time_flies_on_when_the_companion_stops_reading():
    """A companion that stops reading (stalled) must not freeze the physics: the plant
    drops the batches its link cannot take, flies on the held commands, and says so."""
    plant, u = _hover()
    said: list[str] = []
    server = SimLinkServer(plant, port=0, home=HOME, real_time=True,
                           sensor_noise=SensorNoise.off(), log=said.append)
    with serving(server) as out:
        client = _SmallWindowClient(port=server.port, home=HOME)
        client.connect(timeout_s=10.0)
        for _ in range(20):
            s = client.receive_state(timeout_s=10)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        t_stall = server.plant.t_s
        time.sleep(4.0)                 # stalled: reads nothing, answers nothing
        advanced_s = server.plant.t_s - t_stall
        # reading again: until the plant says so (its backlog drained; on a busy machine
        # that takes more than a few periods), at most 20 s of wall time
        end = time.monotonic() + 20.0
        n = 0
        while n < 50 or (not any("reads again" in t for t in said)
                         and time.monotonic() < end):
            s = client.receive_state(timeout_s=10)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
            n += 1
        summary = _finish(out, client)
    # blocked in sendall, the plant stood still once the small window and its own
    # buffer were full (a few tenths of a second); flying on, it kept up with the clock
    assert advanced_s > 2.0
    assert server.dropped_batches > 0
    assert any("does not read" in t and "last commands" in t for t in said)
    assert any("reads again" in t for t in said)
    assert summary.missed_deadlines > 0


def test_lockstep_says_it_is_waiting_for_the_companion():
    plant, u = _hover()
    said: list[str] = []
    server = SimLinkServer(plant, port=0, home=HOME, sensor_noise=SensorNoise.off(),
                           log=said.append)
    with serving(server) as out:
        client = _client(server)
        for k in range(6):
            s = client.receive_state(timeout_s=10)
            if k == 3:
                time.sleep(simlink_server.LOCKSTEP_NOTICE_S + 1.0)
            client.send_actuators(s.time_usec, u.rotor_commands, armed=True)
        summary = _finish(out, client)
    assert summary.steps >= 5
    assert any("lockstep: waiting for the companion" in t for t in said)
    assert any("answered after" in t for t in said)
