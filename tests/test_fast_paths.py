"""The fast paths give the same bits as the code they stand in for: the plant stepped many
steps in one compiled call, CPython's hypot compiled, the tether's compiled solve, the
simulator link's own MAVLink packing and parsing, and numba's entry points."""

import math
import random

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from sitl.catenary import catenary_end_forces
from sitl.plant import Plant, PlantInputs
from sitl.pymath import hypot2, hypot3
from sitl.tether import Tether, TetherForces
from sitl.trim import hover_trim
from tuavdefs import simlink as sl
from tuavdefs.jit import entry_point, njit
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
    @njit
    def kernel(a: float, flag: bool, out: np.ndarray) -> float:
        out[0] += a
        return a * 2.0 if flag else -a

    out = np.zeros(1)
    fast = entry_point(kernel, 1.0, True, out)
    assert fast(3, 1, out) == kernel(3.0, True, out) == 6.0   # ints converted
    assert fast(2.5, False, out) == -2.5 and out[0] == 8.5
