"""Tests of sitl.tether: the 3-D tether between the winder exit point and the UAV."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl.catenary import CatenaryInputError, CatenaryRegime, catenary_end_forces
from sitl.tether import Tether, TetherForces
from tuavdefs.params import TetherParams

G = 9.81
R = CatenaryRegime


@pytest.fixture
def tether() -> Tether:
    return Tether(TetherParams(), G)


def test_built_from_the_parameters(tether):
    p = TetherParams()
    assert tether.ea_n == pytest.approx(p.youngs_modulus_pa * p.section_area_m2)
    assert tether.w_n_per_m == pytest.approx(p.linear_density_kg_m * G)
    soft = Tether(TetherParams(youngs_modulus_pa=1e8, linear_density_kg_m=0.1), 3.7)
    assert soft.ea_n == pytest.approx(1e8 * p.section_area_m2)
    assert soft.w_n_per_m == pytest.approx(0.37)


def test_matches_the_planar_catenary(tether):
    x, y, z, L = 12.0, -16.0, 30.0, 36.0
    f = tether.forces(x, y, z, L)
    assert isinstance(f, TetherForces)
    fah, fav, fbh, fbv, _ = catenary_end_forces(20.0, z, L, tether.ea_n, tether.w_n_per_m)
    ux, uy = 0.6, -0.8
    assert f.on_uav_n == pytest.approx((fbh * ux, fbh * uy, fbv), rel=1e-9)
    assert f.on_exit_n == pytest.approx((fah * ux, fah * uy, fav), rel=1e-9)


def cross2(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


@pytest.mark.parametrize("pos, L", [
    ((20.0, 10.0, 30.0), 37.0),   # suspended
    ((20.0, 10.0, 30.0), 45.0),   # touchdown
    ((-5.0, 30.0, 2.0), 30.0),    # stretched, nearly flat
])
def test_force_directions(tether, pos, L):
    f = tether.forces(*pos, L)
    h = np.array(pos[:2]) / math.hypot(*pos[:2])
    uav_h, exit_h = np.array(f.on_uav_n[:2]), np.array(f.on_exit_n[:2])
    # the tether pulls the UAV towards the winder and down ...
    assert np.dot(uav_h, h) < 0 and abs(cross2(uav_h, h)) <= 1e-12 * np.linalg.norm(uav_h)
    assert f.on_uav_n[2] < 0
    # ... and the exit point towards the UAV, never into the ground
    assert np.dot(exit_h, h) > 0 and abs(cross2(exit_h, h)) <= 1e-12 * np.linalg.norm(exit_h)
    assert f.on_exit_n[2] >= 0


def test_vertical_and_slack_cases(tether):
    w = tether.w_n_per_m
    up = tether.forces(0.0, 0.0, 30.0, 29.99)  # taut, straight up
    assert up.info.regime == R.VERTICAL
    assert up.on_uav_n[:2] == (0.0, 0.0) and up.on_exit_n[:2] == (0.0, 0.0)
    assert up.on_uav_n[2] < -w * 29.99 < 0 < up.on_exit_n[2]
    slack = tether.forces(3.0, 4.0, 20.0, 40.0)  # hangs straight down, the rest on the ground
    assert slack.info.regime == R.SLACK
    assert slack.on_exit_n == (0.0, 0.0, 0.0)
    assert slack.on_uav_n[:2] == (0.0, 0.0)
    assert -slack.on_uav_n[2] == pytest.approx(w * 20.0, rel=1e-4)  # the weight of 20 m
    on_ground = tether.forces(3.0, 4.0, 0.0, 40.0)  # UAV landed, tether slack on the ground
    assert on_ground.info.regime == R.FLAT
    assert on_ground.on_uav_n == (0.0, 0.0, 0.0)


positions = st.tuples(st.floats(-50.0, 50.0), st.floats(-50.0, 50.0), st.floats(0.0, 45.0))
lengths = st.floats(1.0, 50.0)


def tolerance(f: TetherForces, pos, L) -> float:
    """Force tolerance for comparing transformed configurations: the solver's accuracy plus the
    rounding of the transformed coordinates (~1e-15 of them) times the axial stiffness EA/L,
    which a line lying almost exactly taut amplifies."""
    ea = TetherParams().axial_stiffness_n
    return 1e-9 * f.top_tension_n + 1e-12 * ea / L * (sum(map(abs, pos)) + L) + 1e-12


def rot_z(v, phi):
    c, s = math.cos(phi), math.sin(phi)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])


@settings(max_examples=300, deadline=None)
@given(positions, lengths, st.floats(0.0, 2 * math.pi))
def test_rotational_symmetry_about_z(pos, L, phi):
    f = Tether(TetherParams(), G).forces(*pos, L)
    g = Tether(TetherParams(), G).forces(*rot_z(pos, phi), L)
    scale = tolerance(f, pos, L)
    assert g.on_uav_n == pytest.approx(rot_z(f.on_uav_n, phi), abs=scale)
    assert g.on_exit_n == pytest.approx(rot_z(f.on_exit_n, phi), abs=scale)
    assert g.drum_tension_n == pytest.approx(f.drum_tension_n, abs=scale)


@settings(max_examples=300, deadline=None)
@given(positions, lengths, st.floats(0.0, math.pi))
def test_mirror_symmetry_in_a_vertical_plane(pos, L, phi):
    """Reflection in the vertical plane through the origin at angle phi to the x axis."""
    c, s = math.cos(2 * phi), math.sin(2 * phi)

    def mirror(v):
        return (c * v[0] + s * v[1], s * v[0] - c * v[1], v[2])

    f = Tether(TetherParams(), G).forces(*pos, L)
    g = Tether(TetherParams(), G).forces(*mirror(pos), L)
    scale = tolerance(f, pos, L)
    assert g.on_uav_n == pytest.approx(mirror(f.on_uav_n), abs=scale)
    assert g.on_exit_n == pytest.approx(mirror(f.on_exit_n), abs=scale)
    # the plain y -> -y mirror, exactly
    h = Tether(TetherParams(), G).forces(pos[0], -pos[1], pos[2], L)
    assert h.on_uav_n == (f.on_uav_n[0], -f.on_uav_n[1], f.on_uav_n[2])


@settings(max_examples=400, deadline=None)
@given(positions, lengths, st.sampled_from([1e7, 1e9, 1e10]))
def test_force_balance(pos, L, youngs_modulus_pa):
    """Frictionless ground: the ground only pushes up, so horizontally the two end forces
    cancel; vertically they carry exactly the weight of the part off the ground (the ground
    carries the rest): on_uav_z + on_exit_z = -w (L - L_ground)."""
    tether = Tether(TetherParams(youngs_modulus_pa=youngs_modulus_pa), G)
    f = tether.forces(*pos, L)
    for i in (0, 1):
        assert f.on_uav_n[i] + f.on_exit_n[i] == pytest.approx(0.0, abs=1e-12 * f.top_tension_n)
    suspended = L - f.info.length_on_ground_m
    weight = tether.w_n_per_m * suspended
    # (to the rounding of L - L_ground)
    assert f.on_uav_n[2] + f.on_exit_n[2] == pytest.approx(
        -weight, rel=1e-9, abs=1e-9 * f.top_tension_n + 1e-12 * tether.w_n_per_m * L)
    assert f.drum_tension_n == pytest.approx(math.hypot(*f.on_exit_n), rel=1e-12, abs=1e-300)
    assert f.top_tension_n == pytest.approx(math.hypot(*f.on_uav_n), rel=1e-12, abs=1e-300)
    assert f.top_tension_n >= f.drum_tension_n  # tension grows up the line
    assert all(math.isfinite(v) for v in (*f.on_uav_n, *f.on_exit_n))


def test_warm_start_persists_across_calls(tether):
    assert tether.warm_start == (0.0, 0.0)
    first = tether.forces(20.0, 5.0, 30.0, 40.0)
    assert not first.info.warm_started
    assert tether.warm_start == (first.info.hf_n, first.info.vf_n)
    assert tether.last_info == first.info
    iterations = []
    for k in range(1, 20):  # the UAV drifts by a millimetre per step
        f = tether.forces(20.0 + 1e-3 * k, 5.0, 30.0 - 5e-4 * k, 40.0 + 2e-4 * k)
        assert f.info.warm_started
        assert tether.warm_start == (f.info.hf_n, f.info.vf_n)
        cold = catenary_end_forces(math.hypot(20.0 + 1e-3 * k, 5.0), 30.0 - 5e-4 * k,
                                   40.0 + 2e-4 * k, tether.ea_n, tether.w_n_per_m)
        assert f.on_uav_n[2] == pytest.approx(cold[3], rel=1e-12)
        assert f.info.iterations < cold[4].iterations
        iterations.append(f.info.iterations)
    assert max(iterations) <= 3
    tether.reset_warm_start()
    assert not tether.forces(20.0, 5.0, 30.0, 40.0).info.warm_started


def test_bad_warm_start_still_gives_the_right_answer(tether):
    reference = Tether(TetherParams(), G).forces(20.0, 5.0, 30.0, 40.0)
    tether._hf0, tether._vf0 = 1e12, 1e-12  # nonsense left over from elsewhere
    f = tether.forces(20.0, 5.0, 30.0, 40.0)
    assert f.on_uav_n == pytest.approx(reference.on_uav_n, rel=1e-10)
    assert f.on_exit_n == pytest.approx(reference.on_exit_n, rel=1e-10, abs=1e-12)


def test_shape(tether):
    pos, L = (12.0, -9.0, 8.0), 30.0  # touchdown: part of the tether lies on the ground
    pts = tether.shape(*pos, L, n_points=60)
    assert pts.shape == (60, 3)
    assert pts[0] == pytest.approx((0, 0, 0), abs=1e-12)
    assert pts[-1] == pytest.approx(pos, abs=1e-9)
    assert (pts[:, 2] >= -1e-12).all() and (pts[:, 2] == 0.0).sum() >= 2
    # all in the vertical plane through the exit point and the UAV
    assert np.abs(pts[:, 0] * pos[1] - pts[:, 1] * pos[0]).max() <= 1e-9
    assert tether.warm_start == (0.0, 0.0)  # shape() does not touch the warm start
    straight_up = tether.shape(0.0, 0.0, 20.0, 40.0, n_points=10)
    assert (straight_up[:, :2] == 0.0).all() and straight_up[-1, 2] == pytest.approx(20.0)


@pytest.mark.parametrize("args, name", [
    ((1.0, 2.0, -0.1, 10.0), "z_m"),
    ((1.0, 2.0, -1e-12, 10.0), "z_m"),
    ((1.0, 2.0, math.nan, 10.0), "z_m"),
    ((1.0, 2.0, math.inf, 10.0), "z_m"),
    ((1.0, 2.0, 3.0, 0.0), "length_m"),
    ((1.0, 2.0, 3.0, -5.0), "length_m"),
    ((1.0, 2.0, 3.0, math.nan), "length_m"),
    ((math.nan, 2.0, 3.0, 10.0), "x_m"),
    ((1.0, -math.inf, 3.0, 10.0), "y_m"),
])
def test_input_errors(tether, args, name):
    with pytest.raises(CatenaryInputError, match=name):
        tether.forces(*args)
    with pytest.raises(CatenaryInputError, match=name):
        tether.shape(*args)
    assert tether.warm_start == (0.0, 0.0)


def test_bad_gravity():
    with pytest.raises(ValueError, match="gravity_m_s2"):
        Tether(TetherParams(), 0.0)
