"""The lumped-mass tether (sitl/lumped.py) against independent truths: MoorPy's catenary
(statics), the conservation of energy, the taut string's transverse frequency, MoorDyn (the
same line in the same air: frequency and top tension under a prescribed top motion), and
the coupled plant (hover on the lumped line, its pull and moment at an offset attachment)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sitl.kernel import max_line_nodes, pack_line_params
from sitl.lumped import (
    MERGE,
    lay_line,
    line_energy_j,
    line_rhs,
    line_rk4_prescribed,
    line_state_size,
    manage_nodes,
    node_count,
    relax,
)
from sitl.plant import Plant, PlantInputs
from sitl.tether import Tether
from sitl.trim import hover_trim
from tuavdefs.params import (
    EnvironmentParams,
    SystemParams,
    TetherParams,
    VehicleParams,
    WindParams,
)
from tuavdefs.paramspec import ParameterError

G = 9.81


class Line:
    """A lumped line alone, its top held or prescribed, in still air."""

    def __init__(self, length_m: float, **tether) -> None:
        fields = {"total_length_m": 60.0, "segments": 60, **tether}
        self.params = SystemParams().replace(tether=TetherParams(**fields))
        self.tp = self.params.tether
        self.lp = pack_line_params(self.params)
        n = max_line_nodes(self.params)
        self.ls = np.zeros(line_state_size(n))
        self.scratch = np.zeros((5, self.ls.size))
        self.node_wind = np.zeros((n, 3))
        self.top_wind = np.zeros(6)
        self.length = length_m

    def lay(self, top: tuple[float, float, float]) -> None:
        """On the elastic catenary to ``top`` (the plant's own solver)."""
        cat = Tether(self.tp, G)
        cat.forces(*top, self.length)
        lay_line(self.ls, self.lp, cat.shape(*top, self.length, 2001), self.length)

    def settle(self, top, seconds: float = 6.0, h: float = 2e-4) -> tuple:
        b = np.array([*top, 0.0, 0.0, 0.0])
        return relax(self.ls, self.scratch, self.lp, h, round(seconds / h), b, self.length,
                     self.node_wind, self.top_wind, 0.998)

    def forces(self, top, vel=(0.0, 0.0, 0.0)) -> tuple:
        return line_rhs(self.ls, self.scratch[0], self.lp, *top, *vel, self.length, 0.0,
                        self.node_wind, self.top_wind)

    @property
    def n(self) -> int:
        return int(self.ls[0])

    def node(self, k: int) -> np.ndarray:
        return self.ls[1 + 6 * k:7 + 6 * k]


# --- statics against MoorPy ----------------------------------------------------------

moorpy_catenary = pytest.importorskip("moorpy.Catenary").catenary

# (span, height, length, regime): suspended, lying on the ground, near taut, short steep
STATIC_CASES = [
    (20.0, 20.0, 31.0, "suspended"),
    (25.0, 10.0, 30.0, "on the ground"),
    (24.0, 18.0, 30.05, "near taut"),
    (4.0, 12.0, 13.0, "steep"),
]


@pytest.mark.parametrize(("span", "height", "length", "regime"), STATIC_CASES)
def test_static_end_forces_match_moorpy(span, height, length, regime):
    line = Line(length, ground_friction_coeff=0.0, normal_drag_coeff=0.0,
                tangential_drag_coeff=0.0)
    top = (span, 0.0, height)
    line.lay(top)
    fx, fy, fz, drum, _, ex, ey, ez = line.settle(top)
    ea, w = line.tp.axial_stiffness_n, line.tp.linear_density_kg_m * G
    fah, fav, fbh, fbv, info = moorpy_catenary(span, height, length, ea, w, CB=0.0)
    # MoorPy: forces on the ends (A the anchor, B the top), horizontal along A -> B
    scale = math.hypot(fbh, fbv)
    assert fx == pytest.approx(fbh, abs=0.01 * scale), regime
    assert fz == pytest.approx(fbv, abs=0.01 * scale), regime
    assert fy == pytest.approx(0.0, abs=1e-9)
    assert ex == pytest.approx(fah, abs=0.01 * scale), regime
    assert ez == pytest.approx(max(fav, 0.0), abs=0.01 * scale), regime
    assert drum == pytest.approx(math.hypot(fah, fav), abs=0.01 * scale), regime


def test_slack_line_misses_at_most_half_a_node_s_weight():
    # hanging straight down onto the ground (MoorPy: H = 0, V = w h): the node where the
    # line meets the ground rests on it, so the lumped top carries up to half its weight less
    line = Line(30.0, ground_friction_coeff=0.0)
    top = (15.0, 0.0, 10.0)
    line.lay(top)
    fx, _, fz, *_ = line.settle(top)
    w = line.tp.linear_density_kg_m * G
    assert abs(fx) < 1e-3
    assert -fz == pytest.approx(w * 10.0, abs=0.5 * w * line.tp.segment_length_m + 1e-3)


# --- energy ---------------------------------------------------------------------------

def test_energy_is_conserved_without_drag_and_damping():
    line = Line(30.0, axial_damping_n_s=0.0, normal_drag_coeff=0.0,
                tangential_drag_coeff=0.0)
    top = (22.0, 0.0, 20.0)
    line.lay(top)
    line.settle(top)
    # a transverse (y) and an in-plane kick: half a sine over the line
    n = line.n
    for k in range(n):
        s = (k + 1) / (n + 1)
        line.node(k)[4] = 1.5 * math.sin(math.pi * s)
        line.node(k)[5] = 0.8 * math.sin(2 * math.pi * s)
    b = np.array([*top, 0.0, 0.0, 0.0])
    h = 2.5e-4
    e0 = line_energy_j(line.ls, line.lp, *top, line.length)
    energies = []
    for _ in range(round(10.0 / h)):
        line_rk4_prescribed(line.ls, line.scratch, line.lp, h, b, b, b, line.length,
                            line.node_wind, line.top_wind)
        energies.append(line_energy_j(line.ls, line.lp, *top, line.length))
    energies = np.array(energies)
    kinetic0 = sum(0.5 * line.tp.linear_density_kg_m * line.tp.segment_length_m
                   * float(line.node(k)[3:] @ line.node(k)[3:]) for k in range(n))
    assert kinetic0 > 0.0
    drift = np.max(np.abs(energies - e0))
    # 0.1 % of the total (gravity referred to the exit's level) and of what moves
    assert drift < 1e-3 * abs(e0)
    assert drift < 1e-3 * (np.max(energies) - np.min(energies) + e0 - np.min(energies)) or \
        drift < 1e-3 * abs(e0)


# --- drag: the steady shape in a uniform wind ------------------------------------------

def _cable_in_wind(top, length, ea, w, cn, wind):
    """The elastic cable's static shape from the exit (the origin) to ``top`` under its
    weight ``w`` [N/m] and the normal drag ``cn |v_n| v_n`` [N/m] of a uniform ``wind``
    (3) [m/s], as the continuous equations give it (tension vector T along the line:
    dT/ds = -f, dr/ds = (1 + |T|/EA) T/|T|), solved by shooting on the exit's tension:
    (the exit's tension vector, the dense solution over unstretched arc length)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import fsolve

    u = np.asarray(wind, float)

    def rhs(_s, y):
        t = y[3:]
        tn = math.sqrt(t @ t)
        c = t / tn
        vn = u - (u @ c) * c
        f = cn * math.sqrt(vn @ vn) * vn - np.array([0.0, 0.0, w])
        return np.concatenate(((1.0 + tn / ea) * c, -f))

    def solve(t0):
        return solve_ivp(rhs, (0.0, length), [0.0, 0.0, 0.0, *t0], rtol=1e-11,
                         atol=1e-11, dense_output=True)

    t0 = fsolve(lambda t0: solve(t0).y[:3, -1] - np.asarray(top), [4.0, 0.0, 2.0],
                xtol=1e-12)
    return t0, solve(t0)


@pytest.mark.parametrize("wind", [(5.0, 0.0, 0.0), (10.0, 0.0, 0.0), (0.0, 8.0, 0.0)])
def test_steady_shape_in_uniform_wind_matches_the_loaded_cable(wind):
    # suspended all along, normal drag only (C_dt 0): the nodes on the continuous cable's
    # shape and the end forces within 1 % of its tensions
    pytest.importorskip("scipy")
    length, top = 30.0, (20.0, 0.0, 20.0)
    line = Line(length, tangential_drag_coeff=0.0, ground_friction_coeff=0.0)
    tp = line.tp
    cn = 0.5 * EnvironmentParams().air_density_kg_m3 * tp.diameter_m * tp.normal_drag_coeff
    t_exit, sol = _cable_in_wind(top, length, tp.axial_stiffness_n,
                                 tp.linear_density_kg_m * G, cn, wind)
    line.node_wind[:] = wind
    line.top_wind[:3] = wind
    line.lay(top)
    fx, fy, fz, _, _, ex, ey, ez = line.settle(top, seconds=30.0)   # the sideways swing is slow
    t_top = sol.y[3:, -1]
    scale = math.sqrt(t_top @ t_top)
    drag = cn * float(np.dot(wind, wind)) * length
    assert drag > 0.3 * tp.linear_density_kg_m * G * length   # the wind shapes the line
    np.testing.assert_allclose((fx, fy, fz), -t_top, atol=0.01 * scale)
    np.testing.assert_allclose((ex, ey, ez), t_exit, atol=0.01 * scale)
    for k in range(line.n):
        s = length - (k + 1) * tp.segment_length_m      # the node's arc length from the exit
        assert np.linalg.norm(line.node(k)[:3] - sol.sol(s)[:3]) < 0.01
        assert line.node(k)[2] > 0.0
    if wind[1]:
        assert max(line.node(k)[1] for k in range(line.n)) > 1.0   # blown sideways


# --- the taut string's transverse frequency ------------------------------------------

def _zero_crossing_frequency(t: np.ndarray, y: np.ndarray) -> float:
    s = np.signbit(y)
    idx = np.nonzero(s[1:] != s[:-1])[0]
    # linear interpolation of the crossings
    tc = t[idx] - y[idx] * (t[idx + 1] - t[idx]) / (y[idx + 1] - y[idx])
    return 0.5 / float(np.mean(np.diff(tc)))


def test_transverse_frequency_of_a_taut_line_is_the_strings():
    # weightless (g = 0), vertical, stretched 0.2 %: a string of point masses, T uniform
    length, stretch = 30.0, 1.002
    params = SystemParams().replace(
        environment=EnvironmentParams(gravity_m_s2=1e-9),
        tether=TetherParams(total_length_m=60.0, segments=60, axial_damping_n_s=0.0,
                            normal_drag_coeff=0.0, tangential_drag_coeff=0.0))
    lp = pack_line_params(params)
    tp = params.tether
    n_max = max_line_nodes(params)
    ls = np.zeros(line_state_size(n_max))
    top = (0.0, 0.0, length * stretch)
    points = np.column_stack((np.zeros(101), np.zeros(101), np.linspace(0, top[2], 101)))
    lay_line(ls, lp, points, length)
    n = int(ls[0])
    assert length - n * tp.segment_length_m == pytest.approx(tp.segment_length_m)
    amp = 0.01
    for k in range(n):
        z = ls[3 + 6 * k]
        ls[1 + 6 * k] = amp * math.sin(math.pi * z / top[2])
    scratch = np.zeros((5, ls.size))
    b = np.array([*top, 0.0, 0.0, 0.0])
    h = 2.5e-4
    mid = n // 2
    ts, ys = [], []
    for i in range(round(6.0 / h)):
        ts.append(i * h)
        ys.append(ls[1 + 6 * mid])
        line_rk4_prescribed(ls, scratch, lp, h, b, b, b, length, np.zeros((n_max, 3)),
                            np.zeros(6))
    f = _zero_crossing_frequency(np.array(ts), np.array(ys))
    tension = tp.axial_stiffness_n * (stretch - 1.0)
    segs = n + 1
    m = tp.linear_density_kg_m * tp.segment_length_m
    d = top[2] / segs
    discrete = 2.0 * math.sqrt(tension / (m * d)) * math.sin(math.pi / (2 * segs)) / (2 * math.pi)
    continuous = math.sqrt(tension / (tp.linear_density_kg_m * length / top[2])) / (2 * top[2])
    assert f == pytest.approx(discrete, rel=2e-3)
    assert f == pytest.approx(continuous, rel=2e-3)


# --- nodes at the exit -----------------------------------------------------------------

def test_paying_out_and_in_conserves_mass_and_momentum():
    line = Line(20.0)
    top = (12.0, 0.0, 14.0)
    line.lay(top)
    rng = np.random.default_rng(4)
    for k in range(line.n):
        line.node(k)[3:] = rng.normal(size=3)

    def totals(length):
        n, ls_m = line.n, line.tp.segment_length_m
        exit_len = length - n * ls_m
        masses = [ls_m] * (n - 1) + [0.5 * (ls_m + exit_len)]
        rho = line.tp.linear_density_kg_m
        mom = sum(rho * m * line.node(k)[3:] for k, m in enumerate(masses))
        # free nodes plus the top's half segment plus the exit's half segment
        mass = rho * (sum(masses) + 0.5 * ls_m + 0.5 * exit_len)
        return mass, mom

    seen = set()
    rho, ls_m = line.tp.linear_density_kg_m, line.tp.segment_length_m
    for length in np.concatenate((np.linspace(20.0, 26.0, 300), np.linspace(26.0, 20.0, 300))):
        before = totals(length)[1]
        change = manage_nodes(line.ls, line.lp, length, 0.0, 1.0, np.array([*top, 0, 0, 0.0]))
        seen.add(change)
        mass, mom = totals(length)
        assert mass == pytest.approx(rho * length)
        if change > 0:
            # a split: the free nodes' momentum is the same
            np.testing.assert_allclose(mom, before, rtol=1e-12, atol=1e-14)
        elif change < 0:
            # a merge: the survivor moves at the two nodes' mean velocity, and the half
            # segment that joins the exit's share carries that velocity into the exit
            v = line.node(line.n - 1)[3:]
            np.testing.assert_allclose(mom + rho * 0.5 * ls_m * v, before, rtol=1e-12,
                                       atol=1e-14)
    assert {1, -1} <= seen
    assert line.n == int(line.ls[0])


def test_a_merge_keeps_the_exit_segment_s_tension():
    # reeling in past a merge on a bent line: the chord that replaces the two segments at
    # the exit is shorter than their path; the exit segment keeps its strain (the
    # allowance), so the drum's tension does not drop
    ls_m = 2.0
    line = Line(7 * ls_m + MERGE * ls_m + 1e-9, total_length_m=50.0, segments=25,
                ground_friction_coeff=0.0)
    top = (10.0, 0.0, 11.0)
    line.lay(top)
    line.settle(top, seconds=4.0, h=2e-4)
    assert line.n == 7
    def exit_tension():   # the exit segment's tension: its pull with its half weight back
        f = line.forces(top)
        exit_len = line.length - line.n * ls_m
        return math.hypot(f[5], f[6], f[7] + 0.5 * exit_len * line.tp.linear_density_kg_m * G)

    before = exit_tension()
    line.length -= 2e-9                    # now just short of MERGE nominal lengths
    assert manage_nodes(line.ls, line.lp, line.length, 0.0, 1.0, np.array([*top, 0, 0, 0.0])) == -1
    allowance = line.ls[-1]
    assert 1e-4 < allowance < 0.1          # the bend's shortfall, held as allowance
    assert before > 1.0
    assert exit_tension() == pytest.approx(before, rel=0.01)
    # without the allowance the shorter chord leaves the exit segment slack
    line.ls[-1] = 0.0
    assert exit_tension() < 0.5 * before


def test_every_rk4_stage_reads_the_allowance_of_the_state():
    # the allowance is part of the line's state: the stages of a step must carry it, not
    # whatever the scratch array held (they read a stale 0, the exit segment went slack in
    # three of four stages after each merge, and the drum lurched: 45-160 N snaps)
    line = Line(20.0, total_length_m=50.0, segments=25)
    top = (12.0, 0.0, 12.0)
    line.lay(top)
    line.settle(top, seconds=2.0, h=2e-4)
    line.ls[-1] = 4e-3
    b = np.array([*top, 0.0, 0.0, 0.0])
    results = []
    for stale in (0.0, 0.05):
        ls = line.ls.copy()
        scratch = np.zeros_like(line.scratch)
        scratch[4, -1] = stale
        line_rk4_prescribed(ls, scratch, line.lp, 1e-3, b, b, b, line.length,
                            line.node_wind, line.top_wind)
        results.append(ls)
    assert np.array_equal(results[0], results[1])


def test_coupled_step_reads_the_allowance_of_the_state():
    params = SystemParams().replace(tether=TetherParams(model="lumped"))
    x0, _ = hover_trim(params, (14.0, 0.0, 14.0), 21.0)
    out = []
    for stale in (0.0, 0.05):
        plant = Plant(params, dt_s=1e-3)
        plant.x[:] = x0
        plant.lay_line()
        plant.model.line[-1] = 4e-3
        plant.model.line_scratch[4, -1] = stale
        plant.advance(PlantInputs(), 1)
        out.append(plant.model.line.copy())
    assert np.array_equal(out[0], out[1])


def test_the_allowance_fades_from_rest_as_the_critically_damped_decay():
    # after a merge the allowance a fades as a(t) = a0 (1 + t/tau) exp(-t/tau): line let
    # out at the exit at a rate that starts from zero
    line = Line(20.0, total_length_m=50.0, segments=25)
    top = (12.0, 0.0, 12.0)
    line.lay(top)
    a0, tau, dt = 5e-3, 0.1, 1e-3
    line.ls[-1], line.ls[-2] = a0, 0.0
    top6 = np.array([*top, 0.0, 0.0, 0.0])
    for k in range(1, 301):
        assert manage_nodes(line.ls, line.lp, line.length, 0.0, math.exp(-dt / tau),
                            top6) == 0
        t = k * dt
        assert line.ls[-1] == pytest.approx(a0 * (1 + t / tau) * math.exp(-t / tau),
                                            rel=1e-9)
    # the first step's change is second order in dt/tau
    line.ls[-1], line.ls[-2] = a0, 0.0
    manage_nodes(line.ls, line.lp, line.length, 0.0, math.exp(-dt / tau), top6)
    assert a0 - line.ls[-1] < a0 * (dt / tau) ** 2


@pytest.mark.parametrize("segments", [25, 50, 100])
def test_a_line_dragged_along_the_ground_is_caught_at_the_exit_with_the_string_s_impedance(
        segments):
    # a straight line lying on the ground slides along itself at v (dragged, its top
    # pulled at v), its exit segment 1 % short: when that goes taut, the exit's tension
    # steps to the continuous string's wave impedance times v, sqrt(EA rho) v, and holds
    # it until the wave's reflection from the top comes back (2 L / c). The lumped line
    # carries it whatever its segments (2, 1, 0.5 m): a snap of 70 N from 1.15 m/s is
    # what the line's motion makes, not the integration (docs/model.md)
    v, length, short, h = 1.15, 10.0, 0.01, 1e-4
    line = Line(length, total_length_m=50.0, segments=segments)
    tp = line.tp
    ls_m = tp.segment_length_m
    n = node_count(length, ls_m)
    exit_len = length - n * ls_m
    line.ls[:] = 0.0
    line.ls[0] = n
    sink = -tp.linear_density_kg_m * G / tp.ground_stiffness_n_m2   # resting on the ground
    x0 = exit_len * (1.0 - short)
    for k in range(n):
        line.ls[1 + 6 * k:7 + 6 * k] = (x0 + (n - 1 - k) * ls_m, 0.0, sink, v, 0.0, 0.0)
    top0 = x0 + n * ls_m
    c = math.sqrt(tp.axial_stiffness_n / tp.linear_density_kg_m)
    caught = exit_len * short / v
    t, exit_t = 0.0, []
    while t < caught + 2.0 * length / c:
        b0, b1, b2 = (np.array([top0 + v * s, 0.0, 0.0, v, 0.0, 0.0])
                      for s in (t, t + 0.5 * h, t + h))
        line_rk4_prescribed(line.ls, line.scratch, line.lp, h, b0, b1, b2, length,
                            line.node_wind, line.top_wind)
        t += h
        exit_t.append((t, line.forces(b2[:3], b2[3:])[3]))
    impedance = math.sqrt(tp.axial_stiffness_n * tp.linear_density_kg_m) * v
    before = [f for s, f in exit_t if s < caught - 5 * h]
    assert max(before) == 0.0                        # slack until its 1 % is taken up
    # the plateau between the catch's rise and the reflection's return
    plateau = [f for s, f in exit_t if caught + 0.3 * length / c < s < caught + length / c]
    assert len(plateau) > 10
    assert min(plateau) == pytest.approx(impedance, rel=0.05)
    assert max(plateau) == pytest.approx(impedance, rel=0.05)


# --- MoorDyn ---------------------------------------------------------------------------

moordyn = pytest.importorskip("moordyn")

DEPTH = 100.0   # MoorDyn's seabed depth; our exit sits on it, everything in its "water"


def _moordyn_system(tmp_path: Path, tp: TetherParams, length: float, segs: int,
                    top: tuple[float, float, float], rho_air: float, dt: float):
    text = f"""--------------------- MoorDyn Input File ------------------------------------
a tether in air
---------------------- LINE TYPES ------------------------------------------------------
TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx
(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)
tether {tp.diameter_m} {tp.linear_density_kg_m} {tp.axial_stiffness_n} {tp.axial_damping_n_s} 0 {tp.normal_drag_coeff} 0 {tp.tangential_drag_coeff} 0
---------------------- POINTS --------------------------------------------------------
ID Attachment X Y Z Mass Volume CdA Ca
(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)
1 Fixed 0 0 {-DEPTH} 0 0 0 0
2 Coupled {top[0]} {top[1]} {top[2] - DEPTH} 0 0 0 0
---------------------- LINES --------------------------------------------------------
ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs
(#) (name) (#) (#) (m) (-) (-)
1 tether 1 2 {length} {segs} -
---------------------- OPTIONS -----------------------------------------------------
{dt} dtM
RK4 tScheme
{G} g
{rho_air} rho
{DEPTH} WtrDpth
{tp.ground_stiffness_n_m2 / tp.diameter_m} kBot
{tp.ground_damping_n_s_m2 / tp.diameter_m} cBot
0 writeLog
1 disableOutput
1 disableOutTime
------------------------- need this line -------------------------------------------
"""  # noqa: E501
    path = tmp_path / "tether.txt"
    path.write_text(text)
    system = moordyn.Create(str(path))
    x0 = [top[0], top[1], top[2] - DEPTH]
    assert moordyn.Init(system, x0, [0.0, 0.0, 0.0]) == 0
    return system


def _top_motion(t: float, top0, amp: float, freq: float) -> np.ndarray:
    """The top's (position, velocity): from rest, a figure of eight in x and y with a
    vertical bob."""
    w = 2 * math.pi * freq
    s = math.sin(w * t)
    c = math.cos(w * t)
    s2 = math.sin(2 * w * t)
    c2 = math.cos(2 * w * t)
    return np.array([top0[0] + amp * (1 - c), top0[1] + 0.25 * amp * (1 - c2),
                     top0[2] + 0.2 * amp * (1 - c), amp * w * s, 0.5 * amp * w * s2,
                     0.2 * amp * w * s])


def _top_tension_rms_against_moordyn(tmp_path: Path, top0: tuple[float, float, float],
                                     **tether) -> tuple[float, float, float]:
    """The top tension of the same line in ours and MoorDyn's under the same prescribed top
    motion (0.3 m, 0.5 Hz, 8 s): (RMS difference over MoorDyn's RMS, MoorDyn's peak-to-peak
    over its mean, our lowest node's height [m])."""
    length, segs = 30.0, 15
    tp = TetherParams(total_length_m=60.0, segments=30, **tether)   # 2 m segments
    line = Line(length, total_length_m=60.0, segments=30, **tether)
    assert line.tp.segment_length_m * segs == pytest.approx(length)
    # MoorDyn's initial state is its own static solution; ours is relaxed likewise
    line.lay(top0)
    line.settle(top0, seconds=20.0, h=2.5e-4)
    assert line.n == segs - 1
    dt = 2.5e-4
    system = _moordyn_system(tmp_path, tp, length, segs, top0, 1.225, 1e-4)
    amp, freq, duration = 0.3, 0.5, 8.0
    ours, theirs = [], []
    t = 0.0
    lowest = math.inf
    for _ in range(round(duration / dt)):
        b0 = _top_motion(t, top0, amp, freq)
        b1 = _top_motion(t + 0.5 * dt, top0, amp, freq)
        b2 = _top_motion(t + dt, top0, amp, freq)
        line_rk4_prescribed(line.ls, line.scratch, line.lp, dt, b0, b1, b2, length,
                            line.node_wind, line.top_wind)
        f = moordyn.Step(system, [b2[0], b2[1], b2[2] - DEPTH], list(b2[3:]), t, dt)
        t += dt
        fx, fy, fz = line.forces(b2[:3], b2[3:])[:3]
        ours.append(math.sqrt(fx * fx + fy * fy + fz * fz))
        theirs.append(math.sqrt(f[0] ** 2 + f[1] ** 2 + f[2] ** 2))
        lowest = min(lowest, min(line.node(k)[2] for k in range(line.n)))
    moordyn.Close(system)
    skip = round(1.0 / dt)        # MoorDyn's first step settles its coupled point
    ours_a, theirs_a = np.array(ours)[skip:], np.array(theirs)[skip:]
    rms = math.sqrt(np.mean((ours_a - theirs_a) ** 2)) / math.sqrt(np.mean(theirs_a ** 2))
    return rms, float(np.ptp(theirs_a) / np.mean(theirs_a)), lowest


def test_top_tension_under_prescribed_motion_matches_moordyn(tmp_path):
    # the line suspended all along (no ground contact): the same equations, 1.9 % RMS
    rms, swing, lowest = _top_tension_rms_against_moordyn(tmp_path, (18.0, 0.0, 23.0))
    assert lowest > 0.5
    assert swing > 1.0             # the motion did load the line: it swings 27 N about 14
    assert rms < 0.05


def test_top_tension_of_a_line_touching_down_against_moordyn(tmp_path):
    # the foot of the line on the ground, both without friction (MoorDyn's default): 9 %
    # RMS, where two of MoorDyn's simplifications act that this model leaves out on
    # purpose: its internal damping acts in slack segments too (and may push), and its
    # seabed's damper may pull a node that rises (ours only pushes). Giving ours MoorDyn's
    # damping takes the 9 % to 7.7 %. docs/model.md
    rms, swing, lowest = _top_tension_rms_against_moordyn(tmp_path, (18.0, 0.0, 19.0),
                                                          ground_friction_coeff=0.0)
    assert lowest < 0.01
    assert swing > 1.0
    assert rms < 0.10


def test_transverse_frequency_matches_moordyn(tmp_path):
    # the same taut line in both, plucked sideways: the midpoint's frequency
    length, segs = 30.0, 15
    top = (18.0, 0.0, 24.2)
    tp = TetherParams(total_length_m=60.0, segments=30, normal_drag_coeff=0.0,
                      tangential_drag_coeff=0.0)
    line = Line(length, total_length_m=60.0, segments=30, normal_drag_coeff=0.0,
                tangential_drag_coeff=0.0)
    line.lay(top)
    line.settle(top, seconds=10.0, h=2.5e-4)
    system = _moordyn_system(tmp_path, tp, length, segs, top, 1.225, 1e-4)
    dt = 2.5e-4
    # a sideways push of the top for 0.2 s, then held: both lines ring
    mid = line.n // 2
    ours, theirs, ts = [], [], []
    t = 0.0
    for _ in range(round(8.0 / dt)):
        def top_at(tt):
            y = 0.3 * (1 - math.cos(math.pi * min(tt, 0.2) / 0.2)) / 2
            v = 0.3 * math.pi / 0.4 * math.sin(math.pi * tt / 0.2) if tt < 0.2 else 0.0
            return np.array([top[0], y, top[2], 0.0, v, 0.0])
        b0, b1, b2 = top_at(t), top_at(t + dt / 2), top_at(t + dt)
        line_rk4_prescribed(line.ls, line.scratch, line.lp, dt, b0, b1, b2, length,
                            line.node_wind, line.top_wind)
        moordyn.Step(system, [b2[0], b2[1], b2[2] - DEPTH], list(b2[3:]), t, dt)
        t += dt
        ts.append(t)
        ours.append(line.node(mid)[1])
        # MoorDyn numbers its nodes from the anchor: our node k is its node segs - 1 - k
        theirs.append(moordyn.GetLineNodePos(moordyn.GetLine(system, 1), segs - 1 - mid)[1])
    moordyn.Close(system)
    ts = np.array(ts)
    keep = ts > 1.0
    y_ours = np.array(ours)[keep] - 0.3 * (segs - 1 - mid) / segs
    y_theirs = np.array(theirs)[keep] - 0.3 * (segs - 1 - mid) / segs
    f_ours = _zero_crossing_frequency(ts[keep], y_ours - y_ours.mean())
    f_theirs = _zero_crossing_frequency(ts[keep], y_theirs - y_theirs.mean())
    assert f_ours == pytest.approx(f_theirs, rel=0.02)


# --- coupled with the UAV --------------------------------------------------------------

def _lumped(**vehicle) -> SystemParams:
    p = SystemParams()
    return p.replace(tether=p.tether.replace(model="lumped"),
                     vehicle=p.vehicle.replace(**vehicle) if vehicle else p.vehicle)


def test_hover_trim_holds_on_the_lumped_line():
    params = _lumped()
    x, u = hover_trim(params, (22.0, 0.0, 20.0), 31.0)
    plant = Plant(params, state=x)
    cat = Tether(params.tether, G).forces(22.0, 0.0, 20.0, 31.0)
    lump = plant.tether_forces()
    np.testing.assert_allclose(lump.on_uav_n, cat.on_uav_n, atol=0.01 * cat.top_tension_n)
    assert lump.drum_tension_n == pytest.approx(cat.drum_tension_n, rel=0.01)
    plant.advance(u, 3000)
    # the trim was the catenary's: within 1 % of its pull the UAV barely moves in 3 s
    assert np.linalg.norm(plant.position_m - (22.0, 0.0, 20.0)) < 0.1
    nodes = plant.line_nodes_m()
    assert nodes.shape[0] == int(plant.model.line[0]) + 2
    np.testing.assert_allclose(nodes[0], 0.0)
    np.testing.assert_allclose(nodes[-1], plant.position_m)


def test_hover_trim_in_wind_is_the_catenary_s_and_holds_on_the_lumped_line():
    # the trim's drag passes read the plant's acceleration; a lumped line's pull there is
    # the one its nodes hold, none before they are laid: it was taken for spare thrust (a
    # 15 m hover in a 3 m/s wind trimmed 7 N short and fell 1.6 m in 1.4 s)
    wind = WindParams(steady_m_s=(3.0, 0.0, 0.0))
    lumped = _lumped().replace(wind=wind)
    catenary = SystemParams().replace(wind=wind)
    start = (8.0, 4.0, 15.0)
    x_l, u_l = hover_trim(lumped, start, 17.85)
    x_c, u_c = hover_trim(catenary, start, 17.85)
    np.testing.assert_array_equal(x_l, x_c)
    assert u_l == u_c
    plant = Plant(lumped, state=x_l)
    plant.advance(u_l, 1000)
    # what is left is the line's own drag (about 0.6 N at the top): centimetres in 1 s
    assert np.linalg.norm(plant.position_m - start) < 0.15


def test_offset_attachment_tilts_the_trim_by_the_pull_s_moment():
    # tether 0.1 m below the centre of mass: held still, the pull F at r_a makes a moment
    # r_a x R^T F that the rotors must cancel
    r_a = (0.0, 0.0, -0.1)
    params = _lumped(tether_attachment_m=r_a)
    x, u = hover_trim(params, (22.0, 0.0, 20.0), 31.0)
    plant = Plant(params, state=x)
    f = np.array(plant.tether_forces().on_uav_n)
    from sitl.plant import rhs
    dx = rhs(0.0, plant.x, u, plant.model, plant.wind_m_s, rotor_setpoints=plant.x[13:17])
    from tuavdefs.frames import quat_rotate
    q = plant.quaternion
    f_body = np.array(quat_rotate((q[0], -q[1], -q[2], -q[3]), tuple(f)))
    torque = np.cross(r_a, f_body)
    j = np.array(params.vehicle.inertia_diag)
    np.testing.assert_allclose(dx[10:13] * j, torque, rtol=1e-9, atol=1e-9)
    # the pull is backwards (towards the winder) and down: pitch moment about body y
    assert abs(torque[1]) > 0.3


def test_plant_lumped_energy_with_no_losses():
    # the UAV unpowered, swinging on the line with no drag, damping or friction: the UAV's
    # energy plus the line's is constant
    params = SystemParams().replace(
        tether=TetherParams(model="lumped", axial_damping_n_s=0.0, normal_drag_coeff=0.0,
                            tangential_drag_coeff=0.0, ground_damping_n_s_m2=0.0,
                            ground_friction_coeff=0.0),
        vehicle=VehicleParams(drag_coeff_n_s_m=(0, 0, 0), drag_area_m2=(0, 0, 0),
                              rotational_damping_n_m_s_rad=0.0))
    x, _ = hover_trim(params, (20.0, 0.0, 24.0), 32.0)
    x[13:17] = 0.0
    x[3:6] = (0.0, 2.0, 0.0)
    plant = Plant(params, state=x)
    def total():
        return plant.energy_j() + plant.line_energy_j()
    e0 = total()
    es = []
    for _ in range(100):    # 1 s: falling and swinging, above the ground
        plant.advance(PlantInputs(), 10)
        es.append(total())
    assert plant.position_m[2] > 1.0
    assert max(abs(e - e0) for e in es) < 1e-3 * abs(e0)


def test_the_first_node_of_a_slack_line_hangs_below_the_chord_at_rest_lengths():
    # a line without free nodes (a take-off: the UAV 3.7 m from the exit) paid out past
    # SPLIT nominal lengths gains its first node where the slack line hangs: both parts at
    # their unstretched lengths, in the chord's vertical plane, below the chord (on the
    # chord it fell free until the line caught it: a 31-59 N snap at the take-off climb)
    line = Line(3.0, total_length_m=50.0, segments=25)
    assert line.n == 0
    top = np.array([1.0, 0.5, 3.5, 0.2, 0.0, 1.0])
    assert manage_nodes(line.ls, line.lp, 4.01, 0.0, 1.0, top) == 1
    ls_m = line.tp.segment_length_m
    q = line.node(0)[:3]
    assert np.linalg.norm(q) == pytest.approx(4.01 - ls_m, rel=1e-12)
    assert np.linalg.norm(top[:3] - q) == pytest.approx(ls_m, rel=1e-12)
    # in the vertical plane of the chord, below it
    assert np.dot(np.cross(top[:3], [0.0, 0.0, 1.0]), q) == pytest.approx(0.0, abs=1e-12)
    on_chord_z = q @ top[:3] / (top[:3] @ top[:3]) * top[2]
    assert q[2] < on_chord_z
    # neither part is stretched: the top feels at most the half segment's weight
    fx, fy, fz, *_ = line_rhs(line.ls, line.scratch[0], line.lp, *top, 4.01, 0.5,
                              line.node_wind, line.top_wind)
    assert math.hypot(fx, fy, fz) < 1.0


def test_a_taut_line_s_first_node_is_laid_on_the_chord_to_the_top():
    # a stretched chord (4.01 m of line, the top 4.04 m away) keeps the new node on the
    # chord, where both parts keep the segment's strain
    line = Line(3.0, total_length_m=50.0, segments=25)
    top = np.array([1.0, 0.5, 3.89, 0.0, 0.0, 0.0])
    assert np.linalg.norm(top[:3]) > 4.01
    assert manage_nodes(line.ls, line.lp, 4.01, 0.0, 1.0, top) == 1
    f = (4.01 - line.tp.segment_length_m) / 4.01
    np.testing.assert_allclose(line.node(0)[:3], f * top[:3], rtol=1e-12)


def test_a_slack_line_lying_low_gains_no_node_below_the_ground():
    # the chord almost along the ground: the hanging place would be underground
    line = Line(3.0, total_length_m=50.0, segments=25)
    top = np.array([3.0, 0.0, 0.2, 0.0, 0.0, 0.0])
    assert manage_nodes(line.ls, line.lp, 4.01, 0.0, 1.0, top) == 1
    assert line.node(0)[2] >= 0.0


def test_a_split_while_paying_out_keeps_the_segment_s_strain_rate():
    # paying out at 1.5 m/s: the new node moves along the chord so that both parts stretch
    # (or slacken) at the old segment's rate; interpolating towards the exit at rest would
    # have stretched the upper part at once (a 31 N snap at take-off)
    line = Line(3.0, total_length_m=50.0, segments=25)
    top = np.array([1.0, 0.5, 3.9, 0.2, 0.0, 1.0])          # the chord 4.04 m: stretched
    length, rate, ls_m = 4.01, 1.5, line.tp.segment_length_m
    p, v = top[:3], top[3:]
    d = np.linalg.norm(p)
    before = (p @ v) / (d * length) - d * rate / length ** 2
    assert manage_nodes(line.ls, line.lp, length, rate, 1.0, top) == 1
    q, w = line.node(0)[:3], line.node(0)[3:]
    lower = (q @ w) / (np.linalg.norm(q) * (length - ls_m)) - (np.linalg.norm(q) * rate
                                                              / (length - ls_m) ** 2)
    u = p - q
    upper = (u @ (v - w)) / (np.linalg.norm(u) * ls_m)
    assert lower == pytest.approx(before, rel=1e-9)
    assert upper == pytest.approx(before, rel=1e-9)


def test_a_line_too_light_to_integrate_is_refused_with_its_field(tmp_path: Path) -> None:
    """A lumped line whose stable RK4 step is far below the plant's (1e-12 kg/m: 0.1 ns,
    billions of sub-steps) is refused when the plant is built, naming the field, instead of
    stalling it; the plant process says so and exits 2, as for any bad parameter. The
    paper's line takes one sub-step."""
    import subprocess
    import sys

    feather = TetherParams(model="lumped", linear_density_kg_m=1e-12, total_length_m=500.0)
    with pytest.raises(ParameterError, match=r"TetherParams\.model.*sub-steps"):
        Plant(SystemParams().replace(tether=feather), dt_s=1e-3)
    assert Plant(SystemParams().replace(tether=TetherParams(model="lumped")),
                 dt_s=1e-3)._n_sub == 1
    path = tmp_path / "feather.toml"
    path.write_text('[tether]\nmodel = "lumped"\nlinear_density_kg_m = 1e-12\n'
                    'total_length_m = 500.0\n')
    run = subprocess.run([sys.executable, "-m", "sitl", "--params", str(path)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "plant: bad parameter: TetherParams.model" in run.stderr


# --- what a split or a merge at the exit conserves --------------------------------------

def _moving_line(stretch, length, seed):
    """A 2 m-segment line of 8 free nodes paid out to ``length`` [m] (its exit segment
    near SPLIT or MERGE nominal lengths), settled with its top where the chord is
    ``1 + stretch`` times the length, then given random velocities [m/s]; returns the
    line and the top (position, velocity)."""
    d = length * (1.0 + stretch)
    top = (0.6 * d, 0.0, 0.8 * d)
    line = Line(17.6, total_length_m=50.0, segments=25, ground_friction_coeff=0.0)
    line.lay(top)
    assert line.n == 8
    line.length = length
    line.settle(top, seconds=3.0, h=2e-4)
    rng = np.random.default_rng(seed)
    for k in range(line.n):
        line.node(k)[3:] = rng.normal(scale=0.5, size=3)
    return line, np.array([*top, *rng.normal(scale=0.5, size=3)])


def _ledger(line, top6, length):
    """(energy [J], momentum [kg m/s], the pull on the top and the exit segment's on the
    exit (6 floats) [N], the elastic energy [J], the exit segment's strain) of the line at
    ``length`` with the exit's share at rest."""
    rho, ea = line.tp.linear_density_kg_m, line.tp.axial_stiffness_n
    ls_m, n = line.tp.segment_length_m, line.n
    exit_len = length - n * ls_m
    masses = [ls_m] * (n - 1) + [0.5 * (ls_m + exit_len)]
    mom = sum(rho * m * line.node(k)[3:] for k, m in enumerate(masses))
    f = line_rhs(line.ls, line.scratch[0], line.lp, *top6, length, 0.0, line.node_wind,
                 line.top_wind)
    pts = [top6[:3]] + [line.node(k)[:3] for k in range(n)] + [np.zeros(3)]
    rest = [ls_m] * n + [exit_len - line.ls[-1]]
    elastic = sum(0.5 * ea * max(np.linalg.norm(a - b) - l0, 0.0) ** 2 / l0
                  for a, b, l0 in zip(pts[:-1], pts[1:], rest, strict=True))
    energy = line_energy_j(line.ls, line.lp, *top6[:3], length)
    # the exit segment's own pull: its lower half's weight (the ground's) given back
    # where the pull lifts it
    lift = 0.5 * rho * G * exit_len if f[7] > 0.0 else 0.0
    f = np.array([f[0], f[1], f[2], f[5], f[6], f[7] + lift])
    exit_strain = np.linalg.norm(pts[-2]) / rest[-1] - 1.0
    return energy, mom, f, elastic, exit_strain


#: the chord over the line's length, less one: 22 N of pull, or 30 % of slack
STRETCH = {"taut": 2e-4, "slack": -0.3}


@pytest.mark.parametrize("state", ["taut", "slack"])
def test_a_split_adds_no_energy_and_keeps_momentum_and_the_end_pulls(state):
    # paying out past SPLIT nominal lengths on a moving line: the new node takes its mass
    # from the exit's share (at rest), so the free nodes' momentum is the same; the elastic
    # energy is the same (a taut segment's two parts keep its strain; a slack one's stay
    # slack); the kinetic energy can only fall (the interpolated velocity is a mean); and
    # the pulls at the top and at the exit are the same as before
    line, top6 = _moving_line(STRETCH[state], 8 * 2.0 + 2.0 * 2.0 - 1e-6, seed=3)
    line.length += 2e-6                   # (the line paid out joins the exit's share)
    e0, p0, f0, el0, strain = _ledger(line, top6, line.length)
    assert (strain > 0.0) == (state == "taut")
    assert manage_nodes(line.ls, line.lp, line.length, 0.0, 1.0, top6) == 1
    e1, p1, f1, el1, _ = _ledger(line, top6, line.length)
    np.testing.assert_allclose(p1, p0, rtol=1e-9, atol=1e-12)
    assert el1 == pytest.approx(el0, rel=1e-6, abs=1e-12)
    assert e1 <= e0 + 1e-9
    assert e0 - e1 < 0.05 * e0              # what the mean velocity takes, not more
    np.testing.assert_allclose(f1, f0, rtol=1e-6, atol=1e-6 * max(1.0, abs(f0).max()))


@pytest.mark.parametrize("state", ["taut", "slack"])
def test_a_merge_adds_no_energy_and_keeps_momentum_and_the_end_pulls(state):
    # reeling in past MERGE nominal lengths on a moving line: the two nodes at the exit
    # become one at their mean velocity (the half segment that joins the exit's share
    # carrying its momentum there); a taut exit segment keeps its strain (the allowance)
    # and strain rate, so its elastic energy and both end pulls stay; no energy is added
    line, top6 = _moving_line(STRETCH[state], 8 * 2.0 + MERGE * 2.0 + 1e-6, seed=5)
    line.length -= 2e-6
    e0, p0, f0, el0, strain = _ledger(line, top6, line.length)
    assert (strain > 0.0) == (state == "taut")
    assert manage_nodes(line.ls, line.lp, line.length, 0.0, 1.0, top6) == -1
    e1, p1, f1, el1, _ = _ledger(line, top6, line.length)
    q, v = line.node(line.n - 1)[:3], line.node(line.n - 1)[3:]
    gone = line.tp.linear_density_kg_m * 0.5 * line.tp.segment_length_m
    change = p1 + gone * v - p0
    if state == "taut":
        # the survivor's speed along the new chord is set to keep the strain rate: an
        # impulse exchanged with the exit along that chord, none across it
        change -= (change @ q) * q / (q @ q)
    np.testing.assert_allclose(change, 0.0, atol=1e-9 * np.abs(p0).max())
    assert el1 == pytest.approx(el0, rel=0.02, abs=1e-12)
    assert e1 + 0.5 * gone * (v @ v) <= e0 + 1e-9
    np.testing.assert_allclose(f1, f0, rtol=0.02, atol=0.02 * max(1.0, abs(f0).max()))
