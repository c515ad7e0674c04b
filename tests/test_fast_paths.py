"""The fast paths give the same bits as the code they stand in for: the plant stepped many
steps in one compiled call, CPython's hypot compiled, the tether's compiled solve, the
simulator link's own MAVLink packing and parsing (from and to field values in wire order),
its home mapping, the compiled specific force, the sensor channels' per-axis formula
(which the plant's compiled batch repeats), and numba's entry points."""

import io
import math
import random
import re
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from sitl.batch import batch_kernel
from sitl.catenary import catenary_end_forces
from sitl.plant import Plant, PlantInputs
from sitl.pymath import hypot2, hypot3
from sitl.sensors import (
    ISA_RHO0_KG_M3,
    NoiseSpec,
    NoisyChannel,
    SensorNoise,
    airspeed_from,
    gauss_markov_coefficients,
    isa_air,
    plant_acceleration_enu,
    specific_force_flu,
)
from sitl.simlink_server import SimLinkServer
from sitl.tether import Tether, TetherForces
from sitl.trim import hover_trim
from sitl.truth_log import TRUTH_COLUMNS, TruthLog
from tuavdefs import frames as fr
from tuavdefs import simlink as sl
from tuavdefs.jit import BOOL, F64, JIT, Signature, array, entry_point, njit, record
from tuavdefs.params import GustParams, SystemParams, TetherParams, WindParams


def _windy() -> SystemParams:
    return SystemParams().replace(wind=WindParams(
        steady_m_s=(3.0, -1.0, 0.0), turbulence="moderate", seed=4,
        gusts=(GustParams(start_s=0.3, duration_s=0.5, amplitude_m_s=(1.0, 2.0, -0.5)),)))


def _pair(params: SystemParams, state: np.ndarray) -> tuple[Plant, Plant]:
    return Plant(params, state=state), Plant(params, state=state)


def test_advance_is_step_repeated_to_the_bit():
    """Turbulence across a refill of the wind's random draws (4096 steps a block), gusts,
    a torque-driven winder, commands changing between calls."""
    params = _windy()
    x, u = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    a, b = _pair(params, x)
    rng = np.random.default_rng(2)
    done = 0
    while done < 5000:
        cmds = tuple(float(c) for c in rng.uniform(0.6, 0.66, 4))
        ui = u._replace(rotor_commands=cmds, winder_enabled=True,
                        winder_torque_n_m=float(rng.uniform(-0.4, 0.2)))
        n = int(rng.integers(1, 12))
        a.advance(ui, n)
        for _ in range(n):
            b.step(ui)
        done += n
        assert np.array_equal(a.x, b.x) and a.t_s == b.t_s and a.wind_m_s == b.wind_m_s
    assert np.array_equal(a.model.warm, b.model.warm)


def test_advance_through_ground_contact_and_the_drum_stop():
    """Falling onto the ground (the step finished by the interpreter) and the brake."""
    params = SystemParams()
    a, b = Plant(params), Plant(params)
    x = a.x.copy()
    x[2] = 0.6    # above the gear, rotors stopped: it falls and lands
    a.x, b.x = x.copy(), x.copy()
    u = PlantInputs()
    a.advance(u, 700)
    for _ in range(700):
        b.step(u)
    assert np.array_equal(a.x, b.x)
    assert a.x[2] == pytest.approx(params.vehicle.gear_height_m)


def test_compiled_hypot_is_cpythons():
    rng = np.random.default_rng(1)
    for scale in (1.0, 1e-300, 1e300, 1e-3):
        a, b, c = (rng.standard_normal(20000) * scale for _ in range(3))
        want2 = [math.hypot(x, y) for x, y in zip(a.tolist(), b.tolist(), strict=True)]
        want3 = [math.hypot(x, y, z) for x, y, z in zip(a.tolist(), b.tolist(), c.tolist(),
                                                        strict=True)]
        got2 = [hypot2(x, y) for x, y in zip(a, b, strict=True)]
        got3 = [hypot3(x, y, z) for x, y, z in zip(a, b, c, strict=True)]
        assert got2 == want2 and got3 == want3
    for args in ((0.0, -0.0), (math.inf, math.nan), (math.nan, 1.0), (3.0, 4.0), (5e-324, 0.0)):
        assert hypot2(*args) == math.hypot(*args) or (math.isnan(hypot2(*args))
                                                      and math.isnan(math.hypot(*args)))


def test_tether_forces_are_the_catenary_wrappers():
    t = Tether(TetherParams(), 9.81)
    hf, vf = 0.0, 0.0
    rng = random.Random(5)
    for i in range(3000):
        x, y, z = rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(0.0, 40.0)
        if i % 50 == 0:
            x = y = 0.0
        length = math.dist((x, y, z), (0, 0, 0)) * rng.uniform(0.97, 1.6) + 0.1
        span = math.hypot(x, y)
        fah, fav, fbh, fbv, info = catenary_end_forces(span, z, length, t.ea_n, t.w_n_per_m,
                                                       hf, vf)
        ux, uy = (x / span, y / span) if span > 0 else (0.0, 0.0)
        want = TetherForces((fbh * ux, fbh * uy, fbv), (fah * ux, fah * uy, fav),
                            math.hypot(fah, fav), math.hypot(fbh, fbv), info)
        assert t.forces(x, y, z, length) == want
        hf, vf = info.hf_n, info.vf_n


def test_the_links_mavlink_packing_and_parsing_are_pymavlinks():
    rng = random.Random(3)

    class Sink:
        def __init__(self) -> None:
            self.frames: list[bytes] = []

        def write(self, data: bytes) -> None:
            self.frames.append(bytes(data))

    for k in range(400):
        ref = mavlink2.MAVLink(Sink(), srcSystem=rng.randint(0, 255),
                               srcComponent=rng.randint(0, 255))
        enc = sl.Encoder(ref.srcSystem, ref.srcComponent)
        ref.seq = enc.mav.seq = rng.randint(0, 255)
        if k % 3 == 0:
            f = sl.hil_sensor_fields(rng.randint(0, 2**40), *(tuple(rng.uniform(-9, 9)
                                                                     for _ in range(3))
                                                               for _ in range(3)),
                                     rng.uniform(900, 1013), rng.uniform(0, 500), 15.0)
            if k % 6 == 0:
                f = {n: 0 if isinstance(v, int) else 0.0 for n, v in f.items()}
            ours = enc.hil_sensor(f)
            ref.send(ref.hil_sensor_encode(**f))
        elif k % 3 == 1:
            f = sl.hil_state_quaternion_fields(
                rng.randint(0, 2**40), (rng.uniform(-99, 99), rng.uniform(-99, 99), 20.0),
                (0.5, -0.3, 0.1), (0.9, 0.1, -0.3, 0.2), (0.1, 0.2, 0.3), (0.0, 0.1, 9.8),
                sl.HOME_DEFAULT, 3.0)
            ours = enc.hil_state_quaternion(f)
            ref.send(ref.hil_state_quaternion_encode(**f))
        else:
            f = sl.actuator_controls_fields(tuple(rng.uniform(0, 1) for _ in range(4)),
                                            k % 2 == 0)
            ours = enc.hil_actuator_controls(k, f)
            ref.send(ref.hil_actuator_controls_encode(k, **f))
        assert ours == ref.file.frames[-1] and enc.mav.seq == ref.seq
        (fast,) = sl.FrameParser().feed(ours)
        slow = mavlink2.MAVLink(None).decode(bytearray(ours))
        da, db = dict(vars(fast)), dict(vars(slow))
        assert vars(da.pop("_header")) == vars(db.pop("_header"))
        assert da == db and type(fast) is type(slow)
    bad = bytearray(ours)
    bad[12] ^= 0x10
    parser = sl.FrameParser()
    assert parser.feed(bytes(bad)) == [] and parser.bad_frames == 1


def test_an_entry_point_is_the_kernel():
    """An entry point made from a declared signature gives the kernel's results and its
    updates in place, a record's fields converted as loose arguments are; a declaration
    the kernel cannot be compiled for is said at once."""
    @njit
    def kernel(a: float, rec: tuple, out: np.ndarray) -> float:
        flag, (scale, arr) = rec
        out[0] += a
        arr[0] += 1.0
        return a * scale if flag else -a

    out, arr = np.zeros(1), np.zeros(2)
    sig = Signature(F64, record(BOOL, record(F64, array())), array())
    fast = entry_point(kernel, sig)
    assert entry_point(kernel, sig) is fast
    assert fast(3, (1, (2, arr)), out) == kernel(3.0, (True, (2.0, arr)), out) == 6.0
    assert fast(2.5, (False, (2.0, arr)), out) == -2.5 and out[0] == 8.5 and arr[0] == 3.0
    if JIT:
        with pytest.raises(Exception):   # noqa: B017 - numba's typing error, whichever
            entry_point(kernel, Signature(F64, F64, array()))


# ----------------------------------------------------------------- the simulator link
def _random_link_values(rng: random.Random, k: int) -> tuple[int, tuple]:
    """One of the link's messages with random field values, from the fast value builders."""
    home = sl.home_map((rng.uniform(-80, 80), rng.uniform(-180, 180), rng.uniform(-100, 4000)))

    def vec(scale: float) -> tuple[float, float, float]:
        return (rng.uniform(-scale, scale), rng.uniform(-scale, scale),
                rng.uniform(-scale, scale))

    kind = k % 4
    if kind == 0:
        q = vec(1.0)
        return sl.MSG_HIL_STATE_QUATERNION, sl.hil_state_quaternion_values(
            rng.randint(0, 2**40), vec(400.0), vec(400.0 if k % 8 == 0 else 30.0),
            (rng.uniform(-1, 1), *q), vec(5.0), vec(20.0 if k % 8 else 400.0), home,
            rng.uniform(0, 30), rng.uniform(0, 30))
    if kind == 1:
        vel = (0.0, 0.0, 0.0) if k % 8 == 1 else vec(30.0)
        return sl.MSG_HIL_GPS, sl.hil_gps_values(rng.randint(0, 2**40), vec(400.0), vel,
                                                 home, rng.uniform(0, 3), rng.uniform(0, 3))
    if kind == 2:
        return sl.MSG_HIL_SENSOR, sl.hil_sensor_values(
            rng.randint(0, 2**40), vec(20.0), vec(5.0), vec(0.6), rng.uniform(800, 1013),
            rng.uniform(0, 500), rng.uniform(-20, 40))
    cmds = tuple(rng.choice((rng.uniform(-0.5, 1.5), math.nan, 0.0, 1.0)) for _ in range(4))
    return sl.MSG_HIL_ACTUATOR_CONTROLS, sl.actuator_controls_values(
        rng.randint(0, 2**40), cmds, rng.random() < 0.5, rng.random() < 0.5)


def test_the_links_value_packers_are_pymavlinks():
    """Frames packed straight from the values are pymavlink's bytes for the same fields."""
    rng = random.Random(11)
    for k in range(2000):
        enc = sl.Encoder(rng.randint(0, 255), rng.randint(0, 255))
        ref = mavlink2.MAVLink(None, srcSystem=enc.mav.srcSystem,
                               srcComponent=enc.mav.srcComponent)
        ref.seq = enc.mav.seq = rng.randint(0, 255)
        msg_id, values = _random_link_values(rng, k)
        fields = sl._CODECS[msg_id].fields(values)
        want = mavlink2.mavlink_map[msg_id](**fields).pack(ref)
        assert enc.pack_values(msg_id, values) == want
        assert enc.mav.seq == (ref.seq + 1) % 256


def test_the_links_field_builders_are_the_value_builders():
    rng = random.Random(12)
    home = (47.397742, 8.545594, 488.0)
    hm = sl.home_map(home)
    for _ in range(300):
        pos, vel, f = (tuple(rng.uniform(-99, 99) for _ in range(3)) for _ in range(3))
        q = (0.9, 0.1, -0.3, 0.2)
        values = sl.hil_state_quaternion_values(5, pos, vel, q, (0.1, 0.2, 0.3), f, hm, 3.0,
                                                2.5)
        fields = sl.hil_state_quaternion_fields(5, pos, vel, q, (0.1, 0.2, 0.3), f, home,
                                                3.0, 2.5)
        assert sl._CODECS[sl.MSG_HIL_STATE_QUATERNION].wire_of(fields) == values
        values = sl.hil_gps_values(6, pos, vel, hm, 0.4, 0.6)
        assert sl._CODECS[sl.MSG_HIL_GPS].wire_of(
            sl.hil_gps_fields(6, pos, vel, home, 0.4, 0.6)) == values


def test_the_home_map_is_the_frames_mapping():
    """:class:`HomeMap` gives the bits of :mod:`tuavdefs.frames`' functions."""
    rng = random.Random(13)
    for _ in range(5000):
        home = (rng.uniform(-80, 80), rng.uniform(-180, 180), rng.uniform(-100, 4000))
        pos = tuple(rng.uniform(-600, 600) for _ in range(3))
        lat, lon, alt = fr.local_enu_to_global(pos, home)
        want = (round(lat * 1e7), round(((lon + 180.0) % 360.0 - 180.0) * 1e7),
                round(alt * 1000.0))
        got = sl.home_map(home).global_fields(pos)
        assert got == want
        assert sl.home_map(home).local(*got) == fr.global_to_local_enu(
            got[0] * 1e-7, got[1] * 1e-7, got[2] * 1e-3, home)


def test_the_links_fast_parsing_is_the_general_parsers():
    """:meth:`FrameParser.feed_link` and the wire decoders give what the general parser and
    the field-based decoders give; anything unusual is left to the general parser."""
    rng = random.Random(14)
    home = (47.397742, 8.545594, 488.0)
    hm = sl.home_map(home)
    enc = sl.Encoder(1, 200)
    for k in range(600):
        batch = [_random_link_values(rng, k + i) for i in range(rng.randint(1, 4))]
        data = b"".join(enc.pack_values(mid, v) for mid, v in batch)
        fast, slow = sl.FrameParser(), sl.FrameParser()
        got = fast.feed_link(data)
        msgs = slow.feed(data)
        assert got == [sl.link_values(m) for m in msgs]
        assert (fast.frames, fast.bad_frames) == (slow.frames, slow.bad_frames) == (
            len(batch), 0)
        for (mid, values), msg in zip(got, msgs, strict=True):
            if mid == sl.MSG_HIL_STATE_QUATERNION:
                truth = sl.truth_from_wire(values, hm)
                ias, tas = sl.airspeeds_from_hil_state_quaternion(msg)
                assert truth == (*sl.state_from_hil_state_quaternion(msg, home),
                                 sl.specific_force_from_hil_state_quaternion(msg), tas, ias)
            elif mid == sl.MSG_HIL_GPS:
                assert sl.gps_from_wire(values, hm) == sl.gps_from_hil_gps(msg, home)
            elif mid == sl.MSG_HIL_SENSOR:
                assert sl.imu_from_wire(values) == sl.imu_from_hil_sensor(msg)
            else:
                cmds, armed = sl.rotor_commands_from_controls(msg.controls, msg.mode)
                assert sl.answer_from_wire(values) == (
                    msg.time_usec, cmds, armed, sl.lockstep_flag(msg.flags))
        # not the usual case: left to feed(), nothing counted
        corrupt = bytearray(data)
        corrupt[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        other = enc.pack(enc.mav.heartbeat_encode(18, 8, 0, 0, 0))
        for unusual in (bytes(corrupt), data[:-1], data + other, other + data, b"\0" + data):
            p = sl.FrameParser()
            assert p.feed_link(unusual) is None and (p.frames, p.bad_frames) == (0, 0)
        p = sl.FrameParser()
        p.feed(data[:5])
        assert p.feed_link(data[5:]) is None and p.pending_bytes == 5


def test_the_compiled_specific_force_is_the_python_one():
    params = _windy()
    x, u = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    plant = Plant(params, state=x)
    rng = np.random.default_rng(3)
    for _ in range(300):
        cmds = tuple(float(c) for c in rng.uniform(0.3, 0.9, 4))
        plant.advance(u._replace(rotor_commands=cmds), 4)
        x_before, warm = plant.x.copy(), plant.model.warm.copy()
        want = specific_force_flu(plant_acceleration_enu(plant), plant.quaternion,
                                  plant.model.g)
        plant.model.warm[:] = warm
        assert plant.specific_force_flu() == want
        assert np.array_equal(plant.x, x_before) and np.array_equal(plant.model.warm, warm)


def test_the_sensor_channels_are_the_per_axis_formula():
    """A 1-, 2- and 3-axis channel's reading is the per-axis formula: the same draws, the
    same operations in the same order (what sitl/batch.py compiles)."""
    spec = NoiseSpec(sigma=0.05, bias_sigma=0.1, bias_walk=0.02)
    for dim in (1, 2, 3):
        ch = NoisyChannel(spec, dim, np.random.default_rng(dim))
        ref = np.random.default_rng(dim)
        bias = [float(b) for b in ref.normal(0.0, spec.bias_sigma, dim)]
        z = []
        for i in range(600):
            if i % 256 == 0:
                z = ref.standard_normal((256, 2, dim)).tolist()
            z_walk, z_noise = z[i % 256]
            dt = 0.004 if i % 7 else 0.1
            k = spec.bias_walk * math.sqrt(dt)
            bias = [b + k * w for b, w in zip(bias, z_walk, strict=True)]
            truth = [float(t) for t in np.random.default_rng(i).uniform(-9, 9, dim)]
            want = tuple(t + b + spec.sigma * n
                         for t, b, n in zip(truth, bias, z_noise, strict=True))
            assert ch.read(truth, dt) == want


def test_the_gauss_markov_channels_are_the_per_axis_formula():
    """With a Gauss-Markov error: three draws per axis and sample (bias walk, white noise,
    Gauss-Markov), its start drawn after the turn-on bias, the exact discrete step."""
    spec = NoiseSpec(sigma=0.05, bias_sigma=0.1, bias_walk=0.02, gm_sigma=0.7, gm_tau_s=6.0)
    for dim in (1, 2, 3):
        ch = NoisyChannel(spec, dim, np.random.default_rng(dim))
        ref = np.random.default_rng(dim)
        bias = [float(b) for b in ref.normal(0.0, spec.bias_sigma, dim)]
        gm = [float(g) for g in ref.normal(0.0, spec.gm_sigma, dim)]
        z = []
        for i in range(600):
            if i % 256 == 0:
                z = ref.standard_normal((256, 3, dim)).tolist()
            z_walk, z_noise, z_gm = z[i % 256]
            dt = 0.004 if i % 7 else 0.2
            k = spec.bias_walk * math.sqrt(dt)
            bias = [b + k * w for b, w in zip(bias, z_walk, strict=True)]
            phi = math.exp(-dt / spec.gm_tau_s)
            q = spec.gm_sigma * math.sqrt(-math.expm1(-2.0 * dt / spec.gm_tau_s))
            assert gauss_markov_coefficients(spec.gm_sigma, spec.gm_tau_s, dt) == (phi, q)
            gm = [phi * g + q * w for g, w in zip(gm, z_gm, strict=True)]
            truth = [float(t) for t in np.random.default_rng(i).uniform(-9, 9, dim)]
            want = tuple(t + b + g + spec.sigma * n
                         for t, b, g, n in zip(truth, bias, gm, z_noise, strict=True))
            assert ch.read(truth, dt) == want


# ----------------------------------------------------------------- the plant's batch
def _random_state(rng: np.random.Generator, k: int, x0: np.ndarray) -> np.ndarray:
    """A state near ``x0``, now and then with values the fields clamp (fast, high, spun,
    stopped) or that no field can carry (far, hot, not finite)."""
    x = x0.copy()
    x[0:3] += rng.uniform(-30.0, 30.0, 3)
    x[3:6] = rng.normal(0.0, 5.0, 3)
    q = rng.normal(size=4)
    x[6:10] = q / np.linalg.norm(q)
    x[10:13] = rng.normal(0.0, 1.0, 3)
    edge = k % 23
    if edge == 1:
        x[3:6] = rng.choice((-1.0, 1.0), 3) * rng.uniform(327.0, 800.0, 3)   # clamped speeds
    elif edge == 2:
        x[3:6] = 0.0    # course unknown
    elif edge == 3:
        x[10:13] = rng.uniform(-1e3, 1e3, 3)   # large rates and specific force
        x[13:17] *= 3.0
    elif edge == 4:
        x[2] = 30000.0 + rng.uniform(0, 20000.0)   # thin (or no) air
    elif edge == 5:
        x[0] = 3e9    # beyond the link's longitude integers
    elif edge == 6:
        x[rng.integers(0, 19)] = rng.choice((math.nan, math.inf))
    elif edge == 7:
        x[10] = 1e39   # beyond a float32
    return x


def _reference_batch(server: SimLinkServer, t_us: int, gps_dt: float | None) -> bytes:
    """The batch of ``server``'s plant at ``t_us`` [us] from its sensor suite's own reads
    (:meth:`sitl.sensors.SensorSuite.gps_fix_us`, ``imu``, ``baro_of_air``), the ISA and
    the link's value builders (:func:`tuavdefs.simlink.hil_gps_values` and the others),
    packed by its encoder: what the batch's law must send."""
    p, s, enc, hm = server.plant, server.sensors, server._encoder, sl.home_map(server.home)
    dt = server.period_us * 1e-6
    x = p.x.tolist()
    pos, vel, quat, rates = (tuple(x[0:3]), tuple(x[3:6]), tuple(x[6:10]), tuple(x[10:13]))
    s.record_truth_us(t_us, pos, vel)
    f_flu = p.specific_force_flu()
    pressure_hpa, temperature_k, density = isa_air(server.home[2] + pos[2])
    tas = airspeed_from(vel, p.wind_m_s)
    ias = tas * math.sqrt(density / ISA_RHO0_KG_M3)
    chunks = []
    if gps_dt is not None:
        fix = s.gps_fix_us(t_us, gps_dt)
        chunks.append(enc.pack_values(sl.MSG_HIL_GPS, sl.hil_gps_values(
            t_us, fix.position_enu_m, fix.velocity_enu_m_s, hm, fix.eph_m, fix.epv_m)))
    chunks.append(enc.pack_values(sl.MSG_HIL_STATE_QUATERNION, sl.hil_state_quaternion_values(
        t_us, pos, vel, quat, rates, f_flu, hm, tas, ias)))
    chunks.append(enc.pack_values(sl.MSG_HIL_SENSOR, sl.hil_sensor_values(
        t_us, *s.imu(f_flu, rates, quat, dt), *s.baro_of_air(pressure_hpa, temperature_k, dt))))
    return b"".join(chunks)


def _sensor_state(server: SimLinkServer) -> list:
    """What a batch advances: the channels' state, the truth buffer, the encoder's
    counters."""
    mav = server._encoder.mav
    return [*(a.copy() for a in server.sensors.noise_state),
            *(a.copy() for a in server.sensors.truth_buffer),
            (mav.seq, mav.total_packets_sent, mav.total_bytes_sent)]


def _committed(server: SimLinkServer) -> list:
    """What a refused batch must leave as it was: the channels' state, the truth buffer's
    ring (its next slot, past the ring, may hold the refused state's truth), the
    encoder's counters."""
    state = _sensor_state(server)
    n = len(server.sensors.noise_state)
    return [*state[:n], state[n + 2], state[-1]]


def _same_state(a: list, b: list) -> bool:
    return all(np.array_equal(u, v, equal_nan=True) if isinstance(u, np.ndarray) else u == v
               for u, v in zip(a, b, strict=True))


@pytest.mark.parametrize("noise, home", [
    (SensorNoise(seed=7), sl.HOME_DEFAULT),          # the datasheet parts, RTK: 50 ms late
    (SensorNoise.preset("gnss", seed=9), sl.HOME_DEFAULT),   # wandering 0.8 m, 100 ms late
    (SensorNoise.off(), (-33.9, 179.99995, 12.0)),
    (SensorNoise(enabled=False, gps_latency_s=0.037), sl.HOME_DEFAULT),   # latency alone
    (SensorNoise(seed=8, baro=NoiseSpec(0.0, 0.0, 0.5), gps_vertical=NoiseSpec(0.0),
                 gyro=NoiseSpec(0.01, 0.0, 0.0),
                 gps_velocity=NoiseSpec(0.1, 0.0, 0.0, 0.2, 0.5)), (89.0, -179.99998, 4000.0)),
])
def test_the_batch_is_the_link_builders_of_the_sensors_reads(noise: SensorNoise,
                                                           home: tuple[float, float, float]):
    """The batch's one law (:class:`sitl.batch.BatchPacker`) sends the bytes the sensor
    suite's reads and the link's value builders give, and leaves the sensors and the
    encoder as they leave them, over thousands of periods (the channels' blocks of draws
    refilled, Gauss-Markov errors, GPS periods and the truth buffer of their latency,
    clamped and unknown fields); the compiled kernel is its own Python source to the bit
    (refusals included); a state no field carries (far, hot, not finite) is refused with
    ValueError, nothing changed."""
    params = _windy()
    x0, u = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    servers = [SimLinkServer(Plant(params, state=x0), port=0, sensor_noise=noise, home=home)
               for _ in range(3)]
    fast, ref, source = servers
    source.batches.packer._kernel = getattr(batch_kernel, "py_func", batch_kernel)
    periods = 3000 if JIT else 300
    rng = np.random.default_rng(5)
    t_us = 0
    refused = 0
    try:
        for k in range(periods):
            if k % 50 == 0:   # a real step now and then (wind, warm start)
                for s in servers:
                    s.plant.x = x0.copy()
                    s.plant.advance(u, 4)
            else:
                x = _random_state(rng, k, x0)
                for s in servers:
                    s.plant.x = x.copy()
            t_us += 4000 * int(rng.integers(1, 4))
            gps_dt = 0.004 * int(rng.integers(1, 30)) if k % 7 == 0 else None
            interpreted = k < 300
            before = _committed(fast)
            try:
                got = bytes(fast.batches.packer.pack(t_us, gps_dt))
            except ValueError as e:
                assert "no simulator-link batch" in str(e), k
                assert k % 50 and k % 23 in (4, 5, 6, 7), (k, str(e))   # only there
                assert _same_state(_committed(fast), before), k
                if interpreted:
                    with pytest.raises(ValueError, match=re.escape(str(e))):
                        source.batches.packer.pack(t_us, gps_dt)
                    assert _same_state(_committed(source), before), k
                refused += 1
                continue
            assert got == _reference_batch(ref, t_us, gps_dt), k
            assert _same_state(_sensor_state(fast), _sensor_state(ref)), k
            assert np.array_equal(fast.plant.model.warm, ref.plant.model.warm)
            if interpreted:
                assert bytes(source.batches.packer.pack(t_us, gps_dt)) == got, k
                assert _same_state(_sensor_state(source), _sensor_state(fast)), k
        assert 0 < refused < periods * 4 // 23   # (edges 4 to 7: some of them carried)
    finally:
        for s in servers:
            s._sock = None
            s.close()


def test_a_signed_batch_is_the_unsigned_ones_messages():
    """With signing on, the batch's frames are signed by pymavlink and parse, with the
    key, to the messages of the same batch unsigned."""
    params = _windy()
    x0, _ = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    servers = [SimLinkServer(Plant(params, state=x0), port=0, sensor_noise=SensorNoise(seed=3))
               for _ in range(2)]
    signed, plain = servers
    key = bytes(range(32))
    signed._encoder.mav.signing.secret_key = key
    signed._encoder.mav.signing.sign_outgoing = True
    signed._encoder.mav.signing.link_id = 1
    signed._encoder.mav.signing.timestamp = 1
    reader = mavlink2.MAVLink(None)
    reader.signing.secret_key = key
    reader.signing.link_id = 1
    other = mavlink2.MAVLink(None)
    try:
        for k in range(20):
            t_us = 4000 * k
            gps = 0.1 if k % 5 == 0 else None
            a = bytes(signed.batches.packer.pack(t_us, gps))
            b = bytes(plain.batches.packer.pack(t_us, gps))
            assert a != b and len(a) == len(b) + 13 * (3 if gps else 2)
            got, want = reader.parse_buffer(a), other.parse_buffer(b)
            assert all(m._signed for m in got)
            assert [m.to_dict() for m in got] == [m.to_dict() for m in want]
    finally:
        for s in servers:
            s.close()


def test_the_truth_logs_row_is_each_values_repr():
    """A row of the plant's truth log is the repr of each column's value as a float (the
    columns of :data:`sitl.truth_log.TRUTH_COLUMNS`), for any state: gimbal lock, negative
    zeros, integer commands."""
    plant = Plant(SystemParams())
    server = SimpleNamespace(plant=plant, armed=False, rotor_commands=(0.0, 0.0, 0.0, 0.0))
    stream = io.StringIO()
    log = TruthLog(stream, 1)
    rng = np.random.default_rng(9)
    rows = []
    for k in range(500):
        x = plant.x.copy()
        x[:6] = rng.normal(0.0, 10.0, 6)
        q = rng.normal(size=4)
        x[6:10] = (q / np.linalg.norm(q) if k % 5 else
                   fr.euler_to_quat(0.0, math.copysign(math.pi / 2, k % 2 - 0.5), 0.3))
        x[17:19] = rng.uniform(1.0, 50.0), -0.0 if k % 3 == 0 else rng.normal()
        plant.x, plant.t_s = x, k * 0.004
        server.armed = bool(k % 2)
        server.rotor_commands = ((1, 0, 1, 0) if k % 7 == 0
                                 else tuple(rng.uniform(0, 1, 4).tolist()))
        log.record(server)  # type: ignore[arg-type]
        row = (plant.t_s, *x[0:3].tolist(), *x[3:6].tolist(), *fr.quat_to_euler(
            x[6:10].tolist()), plant.tether_length_m, plant.drum_rate_rad_s,
            int(server.armed), *server.rotor_commands, *plant.wind_m_s)
        rows.append(",".join(map(repr, map(float, row))))
    lines = stream.getvalue().splitlines()
    assert lines == [",".join(TRUTH_COLUMNS), *rows]


def test_the_answers_usual_case_is_the_general_decoding():
    """:func:`tuavdefs.simlink.answer_from_wire` of an answer parsed by
    :meth:`tuavdefs.simlink.FrameParser.feed_link` (its inline usual case, commands in
    [0, 1]) is what :func:`rotor_commands_from_controls` and :func:`lockstep_flag` read,
    whatever the commands."""
    rng = random.Random(15)
    enc = sl.Encoder(sl.COMPANION_SYSID, sl.COMPANION_COMPID)
    odd = (math.nan, -math.inf, math.inf, -0.0, 0.0, 1.0, -1e-9, 1.0000001, 3.0)
    for k in range(3000):
        cmds = tuple(rng.choice(odd) if rng.random() < 0.2 else rng.uniform(-0.1, 1.1)
                     for _ in range(4))
        frame = enc.pack_values(sl.MSG_HIL_ACTUATOR_CONTROLS, sl.actuator_controls_values(
            rng.randint(0, 2**63), (0.5,) * 4, k % 2 == 0, k % 3 == 0))
        ((_, values),) = sl.FrameParser().feed_link(frame)
        values = (*values[:2], *struct.unpack("<4f", struct.pack("<4f", *cmds)), *values[6:])
        got = sl.answer_from_wire(values)
        want = (int(values[0]), *sl.rotor_commands_from_controls(values[2:6], values[18]),
                sl.lockstep_flag(values[1]))
        assert repr(got) == repr(want) and got[0] == values[0]


@pytest.mark.parametrize("gnss", ["rtk", "gnss"])
def test_the_offline_sensor_feed_is_the_companions_decoding(gnss: str):
    """The offline runner's sensor feed (tuav_sitl/sensor_feed.py: the frames' payloads
    unpacked without their checksums, HIL_STATE_QUATERNION left undecoded) hands the
    companion the same IMU sample and GNSS fix, to the bit, as its simulator-link decoder
    reading the same batch's bytes; through a GNSS outage too."""
    from companion.simlink_client import BatchDecoder
    from tuav_sitl.sensor_feed import SensorFeed

    params = _windy()
    x, u = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    plant = Plant(params, state=x)
    home = sl.HOME_DEFAULT
    fast = SensorFeed(plant, SensorNoise.preset(gnss, 7), home, 0.004)
    slow = SensorFeed(plant, SensorNoise.preset(gnss, 7), home, 0.004)
    decoder = BatchDecoder(home)
    fixes = 0
    for k in range(600):
        t = k * 0.004
        fast.batches.gps_enabled = slow.batches.gps_enabled = not 200 <= k < 300
        got = fast.read(t)
        (want,) = decoder.feed(bytes(slow.batches.batch(round(t * 1e6))))
        assert got.time_usec == want.time_usec
        assert got.imu == want.imu
        assert got.gps == want.gps and got.gps_updated == want.gps_updated
        fixes += got.gps_updated
        plant.advance(u, 4)
    assert fixes >= 8        # 5 or 10 Hz, but for the outage


def test_a_decoder_for_a_vehicle_on_its_estimate_takes_no_truth():
    """BatchDecoder(truth=False), the companion's when it flies on its estimate: the
    batch's HIL_STATE_QUATERNION (the simulator's own state) is not decoded, so no state
    reaches the onboard step but the sensors'; the sensors are the same as with it."""
    from companion.simlink_client import BatchDecoder
    from tuav_sitl.sensor_feed import SensorFeed

    params = _windy()
    x, _ = hover_trim(params, (12.0, 5.0, 20.0), 24.5)
    plant = Plant(params, state=x)
    home = sl.HOME_DEFAULT
    feed = SensorFeed(plant, SensorNoise.preset("rtk", 3), home, 0.004)
    data = bytes(feed.batches.batch(0))
    (seen,) = BatchDecoder(home).feed(data)
    (blind,) = BatchDecoder(home, truth=False).feed(data)
    assert seen.truth is not None and blind.truth is None
    assert blind.imu == seen.imu and blind.gps == seen.gps


def test_the_scalar_piecewise_is_horners_to_the_bit():
    """companion.planner.Piecewise evaluates a one-dimensional piece's four derivatives in
    one loop (the shorter led by zeros): the same bits as _horner on each, before, inside
    and after the pieces, degree 0 included."""
    from companion.planner import Piecewise, _horner

    rng = np.random.default_rng(5)
    for degree in (0, 1, 3, 5, 7):
        pieces = [(float(rng.uniform(0.1, 3.0)), rng.normal(0.0, 10.0, (1, degree + 1)))
                  for _ in range(3)]
        pw = Piecewise(float(rng.uniform(-5.0, 5.0)), pieces, None, 1)
        for i in range(len(pieces)):
            for tau in (*rng.uniform(-1.0, 4.0, 200), 0.0, -0.0, 1e-300, -1e-300):
                got = pw._eval_piece(i, float(tau))
                want = tuple((_horner(store[i][0], float(tau)),)
                             for store in (pw._p, pw._v, pw._a, pw._j))
                assert struct.pack("4d", *(v for (v,) in got)) == \
                    struct.pack("4d", *(v for (v,) in want))
