"""The UAV and winder truth model against analytic solutions and invariants."""

import math

import numpy as np
import pytest

from sitl.plant import (
    DRUM_ANGLE,
    DRUM_RATE,
    POS,
    QUAT,
    RATES,
    ROTORS,
    VEL,
    Plant,
    PlantInputs,
    PlantModel,
    initial_state,
    rhs,
)
from sitl.trim import hover_trim
from tuavdefs.airframe import Mixer, allocation_matrix, command_to_rotor_speed
from tuavdefs.params import (
    EnvironmentParams,
    SystemParams,
    TetherParams,
    VehicleParams,
    WinderParams,
)

#: A tether too light to matter, for tests that need the UAV on its own (the catenary: a
#: lumped line this light is refused, its stable step being a fraction of a nanosecond).
FEATHER = TetherParams(model="catenary", linear_density_kg_m=1e-12, total_length_m=500.0)


def _params(**groups) -> SystemParams:
    """The defaults with ``groups`` replaced, on the quasi-static catenary unless ``tether``
    says otherwise (these tests hold its equilibria; the lumped line has its own,
    tests/test_lumped_tether.py)."""
    return SystemParams().replace(**{"tether": TetherParams(model="catenary"), **groups})


def _hover_state(params: SystemParams, position, tether_length):
    """State and inputs for which the UAV should be in equilibrium at ``position``."""
    x, u = hover_trim(params, position, tether_length)
    model = PlantModel(params)
    return model, x, u, model.tether.forces(*position, tether_length)


@pytest.mark.parametrize("with_tether", [False, True])
def test_hover_equilibrium(with_tether):
    params = _params() if with_tether else _params(tether=FEATHER)
    # 30 m of tether for a UAV at (12, 5, 20): suspended, pulling down and toward the winder;
    # the feather tether is given slack so it hangs with no tension at all
    length = 30.0 if with_tether else 40.0
    model, x, u, tf = _hover_state(params, (12.0, 5.0, 20.0), length)
    if with_tether:
        assert np.linalg.norm(tf.on_uav_n) > 5.0   # the pull is real
    dx = np.asarray(rhs(0.0, x, u, model))
    assert np.allclose(dx[VEL], 0.0, atol=1e-9), dx[VEL]
    assert np.allclose(dx[RATES], 0.0, atol=1e-9)
    assert np.allclose(dx[ROTORS], 0.0, atol=1e-6)
    assert dx[DRUM_RATE] == 0.0  # brake holds the drum


def test_hover_stays_put_for_a_while():
    model, x, u, _ = _hover_state(_params(), (12.0, 5.0, 20.0), 30.0)
    plant = Plant(model.params, state=x)
    for _ in range(200):
        plant.step(u)
    # an open-loop equilibrium is unstable, but after 0.2 s the drift must be tiny
    assert np.linalg.norm(plant.position_m - [12.0, 5.0, 20.0]) < 1e-6


def test_torque_free_spin_conserves_energy_and_momentum():
    params = _params(
        tether=FEATHER,
        vehicle=VehicleParams(rotational_damping_n_m_s_rad=0.0, drag_coeff_n_s_m=(0, 0, 0),
                              drag_area_m2=(0, 0, 0)),
        environment=SystemParams().environment.replace(gravity_m_s2=1e-12),
    )
    model = PlantModel(params)
    x = initial_state(model, position_m=(0.0, 0.0, 30.0), tether_length_m=60.0)
    # spin mostly about the intermediate axis (y): it tumbles, a demanding case
    x[RATES] = (0.05, 2.0, 0.05)
    plant = Plant(params, state=x)
    inertia = np.array(params.vehicle.inertia_diag)

    def invariants():
        w = plant.body_rates_rad_s
        rmat = np.array(_rotation(plant.quaternion))
        return 0.5 * float(w @ (inertia * w)), rmat @ (inertia * w)

    e0, h0 = invariants()
    roll_extent = 0.0
    for _ in range(60_000):  # 60 s at 1 kHz
        plant.step(PlantInputs())
        roll_extent = max(roll_extent, abs(plant.body_rates_rad_s[0]))
    e1, h1 = invariants()
    # RK4 local error ~ (|omega| dt)^5: bound the 60 s drift at 1e-8 relative
    assert abs(e1 - e0) / e0 < 1e-8
    assert np.linalg.norm(h1 - h0) / np.linalg.norm(h0) < 1e-8
    assert roll_extent > 1.0  # it really tumbled


def _rotation(q):
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def test_free_fall_matches_gravity():
    params = _params(tether=FEATHER, vehicle=VehicleParams(drag_coeff_n_s_m=(0, 0, 0),
                                                                drag_area_m2=(0, 0, 0)))
    x = initial_state(PlantModel(params), position_m=(3.0, 4.0, 100.0), tether_length_m=200.0)
    plant = Plant(params, state=x)
    for _ in range(2000):
        plant.step(PlantInputs())
    g = params.environment.gravity_m_s2
    t = plant.t_s
    assert plant.position_m[2] == pytest.approx(100.0 - 0.5 * g * t * t, rel=1e-9)
    assert plant.velocity_m_s[2] == pytest.approx(-g * t, rel=1e-9)
    assert np.allclose(plant.position_m[:2], (3.0, 4.0), atol=1e-9)


def test_fall_with_linear_drag_matches_analytic():
    c = 0.8
    params = _params(tether=FEATHER, vehicle=VehicleParams(drag_coeff_n_s_m=(0.3, 0.3, c),
                                                                drag_area_m2=(0, 0, 0)))
    x = initial_state(PlantModel(params), position_m=(0.0, 0.0, 100.0), tether_length_m=200.0)
    plant = Plant(params, state=x)
    for _ in range(3000):
        plant.step(PlantInputs())
    m, g, t = params.vehicle.mass_kg, params.environment.gravity_m_s2, plant.t_s
    v_term = m * g / c
    want_v = -v_term * (1.0 - math.exp(-c * t / m))
    want_z = 100.0 - v_term * (t - m / c * (1.0 - math.exp(-c * t / m)))
    assert plant.velocity_m_s[2] == pytest.approx(want_v, rel=1e-9)
    assert plant.position_m[2] == pytest.approx(want_z, rel=1e-9)


def test_fall_with_quadratic_drag_matches_analytic():
    # m dv/dt = -m g + rho/2 CdA v^2: v = -v_t tanh(g t / v_t), z = z0 - v_t^2/g ln cosh(g t/v_t)
    cda, rho = 0.12, 1.1
    params = _params(tether=FEATHER, environment=EnvironmentParams(air_density_kg_m3=rho),
                     vehicle=VehicleParams(drag_coeff_n_s_m=(0, 0, 0),
                                           drag_area_m2=(0.5, 0.7, cda)))
    x = initial_state(PlantModel(params), position_m=(0.0, 0.0, 150.0), tether_length_m=300.0)
    plant = Plant(params, state=x)
    for _ in range(4000):
        plant.step(PlantInputs())
    m, g, t = params.vehicle.mass_kg, params.environment.gravity_m_s2, plant.t_s
    v_t = math.sqrt(2.0 * m * g / (rho * cda))
    assert plant.velocity_m_s[2] == pytest.approx(-v_t * math.tanh(g * t / v_t), rel=1e-9)
    want_z = 150.0 - v_t ** 2 / g * math.log(math.cosh(g * t / v_t))
    assert plant.position_m[2] == pytest.approx(want_z, rel=1e-9)


def test_resting_on_the_ground_stays_put():
    plant = Plant()
    x0 = plant.x.copy()
    for _ in range(5000):
        plant.step(PlantInputs())
    assert np.allclose(plant.x[POS], x0[POS], atol=1e-12)
    assert np.allclose(plant.x[VEL], 0.0, atol=1e-12)
    assert np.allclose(plant.x[QUAT], x0[QUAT], atol=1e-12)
    assert plant.x[DRUM_ANGLE] == x0[DRUM_ANGLE]


def test_idle_rotors_do_not_lift_off_and_full_thrust_does():
    plant = Plant()
    idle = PlantInputs(rotor_commands=(0.0,) * 4, armed=True)
    for _ in range(1000):
        plant.step(idle)
    assert plant.position_m[2] == pytest.approx(SystemParams().vehicle.gear_height_m)
    full = PlantInputs(rotor_commands=(0.9,) * 4, armed=True)
    for _ in range(1000):
        plant.step(full)
    assert plant.position_m[2] > 1.0
    assert abs(plant.euler_rad[0]) < 1e-9 and abs(plant.euler_rad[1]) < 1e-9


def test_ground_cannot_be_penetrated():
    params = _params(tether=FEATHER)
    x = initial_state(PlantModel(params), position_m=(0.0, 5.0, 3.0), tether_length_m=50.0)
    plant = Plant(params, state=x)
    for _ in range(3000):
        plant.step(PlantInputs())
        assert plant.position_m[2] >= params.vehicle.gear_height_m
    assert plant.velocity_m_s[2] == 0.0


# ---------------------------------------------------------------- mixer
def test_allocation_and_mixer_round_trip():
    veh = VehicleParams()
    a = allocation_matrix(veh)
    mixer = Mixer(veh)
    for wrench in [(30.0, 0.5, -0.3, 0.05), (45.0, -1.0, 1.0, -0.1), (20.0, 0.0, 0.0, 0.0)]:
        out = mixer.mix(wrench[0], wrench[1:])
        assert not out.saturated
        speeds = [command_to_rotor_speed(c, veh, True) for c in out.commands]
        thrusts = veh.rotor_thrust_coeff * np.square(speeds)
        assert np.allclose(a @ thrusts, wrench, rtol=1e-9, atol=1e-9)


def test_mixer_gives_up_yaw_before_roll_and_keeps_thrust():
    veh = VehicleParams()
    mixer = Mixer(veh)
    a = allocation_matrix(veh)
    out = mixer.mix(40.0, (2.0, 0.0, 5.0))   # far too much yaw
    assert out.saturated
    speeds = [command_to_rotor_speed(c, veh, True) for c in out.commands]
    got = a @ (veh.rotor_thrust_coeff * np.square(speeds))
    assert got[0] == pytest.approx(40.0, rel=1e-9)
    assert got[1] == pytest.approx(2.0, rel=1e-9)
    assert 0.0 <= got[3] < 5.0


def test_rotor_layout_signs():
    """More thrust on the left rotors rolls right-wing-down (+x torque, FLU)."""
    veh = VehicleParams()
    a = allocation_matrix(veh)
    left = a @ np.array([0.0, 1.0, 1.0, 0.0])     # rotors 2 (back-left) and 3 (front-left)
    back = a @ np.array([0.0, 1.0, 0.0, 1.0])     # rotors 2 and 4: nose down = +y torque
    ccw = a @ np.array([1.0, 1.0, 0.0, 0.0])      # CCW rotors yaw the body clockwise
    assert left[1] > 0 and abs(left[2]) < 1e-12
    assert back[2] > 0 and abs(back[1]) < 1e-12
    assert ccw[3] < 0


def test_rotor_limits_sized_for_the_full_tether():
    assert SystemParams().hover_thrust_fraction_full_tether() <= 0.6


# ---------------------------------------------------------------- winder
def test_length_angle_relation_and_inertia():
    params = _params()
    model = PlantModel(params)
    w, t = params.winder, params.tether
    assert model.winder.length_m(model.winder.theta_rad(12.5)) == pytest.approx(12.5)
    assert model.winder.length_m(1.0) == pytest.approx(w.drum_radius_m)
    full = model.winder.inertia_kg_m2(0.0)
    empty = model.winder.inertia_kg_m2(t.total_length_m)
    r2 = w.drum_radius_m ** 2 + w.drum_inner_radius_m ** 2
    m_full = w.drum_mass_kg + t.total_length_m * t.linear_density_kg_m
    assert full == pytest.approx(0.5 * m_full * r2 + w.rotor_inertia_kg_m2)
    assert empty == pytest.approx(0.5 * w.drum_mass_kg * r2 + w.rotor_inertia_kg_m2)


def test_spin_down_with_friction_is_exponential():
    # a feather tether lying slack on the ground puts no tension on the drum, and keeps
    # the inertia constant, so omega(t) = omega0 exp(-beta t / I)
    params = _params(tether=FEATHER)
    model = PlantModel(params)
    x = initial_state(model, tether_length_m=100.0, drum_rate_rad_s=20.0)
    plant = Plant(params, state=x)
    free = PlantInputs(winder_enabled=True, winder_torque_n_m=0.0)
    for _ in range(3000):
        plant.step(free)
    inertia = model.winder.inertia_kg_m2(100.0)
    beta = params.winder.viscous_friction_n_m_s_rad
    t = plant.t_s
    assert plant.drum_rate_rad_s == pytest.approx(20.0 * math.exp(-beta * t / inertia), rel=1e-9)
    want_len = 100.0 + params.winder.drum_radius_m * 20.0 * inertia / beta * (
        1 - math.exp(-beta * t / inertia))
    assert plant.tether_length_m == pytest.approx(want_len, rel=1e-9)


def test_spin_down_with_changing_inertia_matches_ode_solution():
    from scipy.integrate import solve_ivp

    # a heavy tether on a light drum, so the inertia changes a lot as it pays out
    params = _params(tether=TetherParams(model="catenary", linear_density_kg_m=1.0,
                                        total_length_m=40.0),
                     winder=WinderParams(drum_mass_kg=0.1))
    model = PlantModel(params)
    x = initial_state(model, position_m=(0.5, 0.0, params.vehicle.gear_height_m),
                      tether_length_m=5.0, drum_rate_rad_s=50.0)
    # lay the tether out far along the ground so it stays slack and tension-free
    plant = Plant(params, state=x)
    free = PlantInputs(winder_enabled=True)
    for _ in range(2000):
        plant.step(free)
    w = model.winder
    beta = params.winder.viscous_friction_n_m_s_rad

    def f(_t, y):
        return [y[1], -beta * y[1] / w.inertia_kg_m2(w.length_m(y[0]))]

    sol = solve_ivp(f, (0.0, plant.t_s), [w.theta_rad(5.0), 50.0], rtol=1e-12, atol=1e-12)
    assert plant.drum_rate_rad_s == pytest.approx(sol.y[1, -1], rel=1e-8)
    assert plant.x[DRUM_ANGLE] == pytest.approx(sol.y[0, -1], rel=1e-8)
    # and the inertia really changed on the way
    assert w.inertia_kg_m2(plant.tether_length_m) < 0.8 * w.inertia_kg_m2(5.0)


def test_brake_holds_against_tension():
    model, x, u, tf = _hover_state(_params(), (12.0, 5.0, 20.0), 24.2)
    assert tf.drum_tension_n * SystemParams().winder.drum_radius_m > 0.1
    plant = Plant(model.params, state=x)
    for _ in range(300):
        plant.step(u)   # winder not enabled: brake engaged
    assert plant.drum_rate_rad_s == 0.0
    assert plant.tether_length_m == pytest.approx(24.2, abs=1e-12)


def test_weak_brake_slips_under_tension():
    params = _params(winder=WinderParams(brake_torque_n_m=0.3))
    model, x, u, tf = _hover_state(params, (12.0, 5.0, 20.0), 24.2)
    assert tf.drum_tension_n * params.winder.drum_radius_m > 0.3
    plant = Plant(params, state=x)
    for _ in range(300):
        plant.step(u)
    assert plant.drum_rate_rad_s > 0.0     # tension pulls line out past the brake


def test_motor_torque_limit_and_speed_cutback():
    model = PlantModel(_params())
    w = model.winder
    p = SystemParams().winder
    assert w.motor_torque_n_m(100.0, 0.0, True) == p.motor_torque_limit_n_m
    assert w.motor_torque_n_m(-100.0, 0.0, True) == -p.motor_torque_limit_n_m
    assert w.motor_torque_n_m(1.0, 0.0, False) == 0.0
    assert w.motor_torque_n_m(float("nan"), 0.0, True) == 0.0
    # at the speed limit no more torque in the direction of motion; braking still allowed
    assert w.motor_torque_n_m(1.0, p.motor_speed_limit_rad_s, True) == pytest.approx(0.0)
    assert w.motor_torque_n_m(-1.0, p.motor_speed_limit_rad_s, True) == -1.0
    # the drum driven flat out settles at the speed limit
    params = _params(tether=FEATHER)
    plant = Plant(params, state=initial_state(PlantModel(params), tether_length_m=10.0))
    for _ in range(4000):
        plant.step(PlantInputs(winder_enabled=True, winder_torque_n_m=100.0))
    assert plant.drum_rate_rad_s <= p.motor_speed_limit_rad_s
    assert plant.drum_rate_rad_s > 0.95 * p.motor_speed_limit_rad_s


def test_hard_stop_at_full_drum():
    params = _params(tether=FEATHER)
    x = initial_state(PlantModel(params), position_m=(0.1, 0.0, params.vehicle.gear_height_m),
                      tether_length_m=1.0)
    plant = Plant(params, state=x)
    for _ in range(3000):
        plant.step(PlantInputs(winder_enabled=True, winder_torque_n_m=-2.0))
    assert plant.tether_length_m == pytest.approx(params.winder.min_paid_out_m)
    assert plant.drum_rate_rad_s == 0.0


def test_hard_stop_at_empty_drum():
    params = _params()
    plant = Plant(params, state=initial_state(
        PlantModel(params), position_m=(1.0, 0.0, params.vehicle.gear_height_m),
        tether_length_m=49.0))
    for _ in range(3000):
        plant.step(PlantInputs(winder_enabled=True, winder_torque_n_m=2.0))
    assert plant.tether_length_m == pytest.approx(params.tether.total_length_m)
    assert plant.drum_rate_rad_s <= 0.0


def test_deterministic_for_a_seed():
    from tuavdefs.params import WindParams

    params = _params(wind=WindParams(steady_m_s=(3.0, 1.0, 0.0), turbulence="moderate",
                                     seed=7))
    model, x, u, _ = _hover_state(params, (12.0, 5.0, 20.0), 30.0)
    runs = []
    for _ in range(2):
        plant = Plant(params, state=x)
        for _ in range(500):
            plant.step(u)
        runs.append(plant.x.copy())
    assert np.array_equal(runs[0], runs[1])
    assert not np.allclose(runs[0][POS], (12.0, 5.0, 20.0), atol=1e-4)  # the wind acted


def test_the_accelerometer_feels_the_touchdown():
    """A fall onto the gear: the ground's projection stops the UAV within a step, which the
    state derivative does not see. The accelerometer's samples (one a 4 ms period, as the
    batches read them) must integrate to the velocity the UAV lost, as a real IMU's delta
    velocity does, or a filter fed them sinks on: the mission's landing left the onboard
    estimate 23 cm below the gear, its GNSS height then gated out. Truth: the plant's own
    velocity before and after."""
    params = _params(tether=FEATHER, vehicle=VehicleParams(drag_coeff_n_s_m=(0, 0, 0),
                                                                drag_area_m2=(0, 0, 0)))
    gear = params.vehicle.gear_height_m
    x = initial_state(PlantModel(params), position_m=(3.0, 4.0, gear + 0.05),
                      tether_length_m=200.0)
    plant = Plant(params, state=x)
    g = params.environment.gravity_m_s2
    period = 0.004
    felt = 0.0
    v0 = float(plant.velocity_m_s[2])
    for _ in range(60):
        plant.advance(PlantInputs(), 4)
        plant.take_contact_impulse(period)
        felt += (plant.specific_force_flu()[2] - g) * period      # level: body z is up
    assert plant.position_m[2] == pytest.approx(gear)              # it landed
    lost = float(plant.velocity_m_s[2]) - v0                       # 0: fell and stopped
    # a fall of 5 cm: ~0.1 s at -g, then stopped; the samples at the period's end state
    assert felt == pytest.approx(lost, abs=0.02)
    # without the impulse the samples say the UAV still falls at ~1 m/s
    plant2 = Plant(params, state=x)
    felt2 = 0.0
    for _ in range(60):
        plant2.advance(PlantInputs(), 4)
        felt2 += (plant2.specific_force_flu()[2] - g) * period
    assert felt2 < -0.8
