"""The system's parameter groups, with the paper's vehicle as the defaults.

Values that the paper (Folorunsho, Ni, Norris) gives are marked "paper"; the others are
chosen here and the reason is stated in ``docs/model.md``. All units are SI.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from tuavdefs.paramspec import Params, quantity

__all__ = [
    "EnvironmentParams", "VehicleParams", "TetherModel", "TetherParams", "WinderParams",
    "GustParams", "WindProfile", "WindParams", "SystemParams",
]


class TetherModel(enum.Enum):
    """Which tether the plant integrates as the truth."""

    CATENARY = "catenary"   #: quasi-static elastic catenary (sitl/catenary.py)
    LUMPED = "lumped"       #: dynamic lumped-mass line with drag (sitl/lumped.py)


#: The truth's line of the stack's runs (a scenario, ``tuav-sitl up``) where none is named;
#: a bare :class:`TetherParams` keeps the catenary (the controllers' model of the line).
DEFAULT_TRUTH_TETHER = TetherModel.LUMPED

class WindProfile(enum.Enum):
    """How the mean wind varies with height above the ground."""

    UNIFORM = "uniform"     #: the same at every height
    LOG = "log"             #: logarithmic: ln(z/z0) / ln(z_ref/z0)
    POWER = "power"         #: power law: (z/z_ref)^alpha


@dataclass(frozen=True)
class EnvironmentParams(Params):
    """Gravity and air."""

    gravity_m_s2: float = quantity(9.81, "m/s^2", "gravitational acceleration (paper)", gt=0)
    air_density_kg_m3: float = quantity(1.225, "kg/m^3", "air density (ISA sea level)", gt=0)


@dataclass(frozen=True)
class VehicleParams(Params):
    """The quadrotor: rigid body, X-configuration rotors, drag, landing gear."""

    mass_kg: float = quantity(2.84, "kg", "mass (paper)", gt=0)
    ixx_kg_m2: float = quantity(0.5192, "kg*m^2", "roll moment of inertia (paper)", gt=0)
    iyy_kg_m2: float = quantity(0.4929, "kg*m^2", "pitch moment of inertia (paper)", gt=0)
    izz_kg_m2: float = quantity(0.0947, "kg*m^2", "yaw moment of inertia (paper)", gt=0)
    arm_length_m: float = quantity(0.405, "m", "centre to rotor axis (paper)", gt=0)
    rotor_thrust_coeff: float = quantity(
        2.0e-5, "N/(rad/s)^2", "rotor thrust = coeff * speed^2", gt=0)
    rotor_torque_coeff: float = quantity(
        3.2e-7, "N*m/(rad/s)^2", "rotor drag torque = coeff * speed^2", gt=0)
    rotor_speed_min_rad_s: float = quantity(
        80.0, "rad/s", "idle rotor speed when armed", ge=0)
    rotor_speed_max_rad_s: float = quantity(1000.0, "rad/s", "maximum rotor speed", gt=0)
    motor_time_constant_s: float = quantity(
        0.03, "s", "first-order lag of rotor speed behind its command", gt=0)
    drag_coeff_n_s_m: tuple[float, ...] = quantity(
        (0.25, 0.25, 0.5), "N*s/m", "linear (rotor) drag per body axis (x forward, y left, "
        "z up) against air-relative velocity", ge=0, length=3)
    drag_area_m2: tuple[float, ...] = quantity(
        (0.06, 0.06, 0.12), "m^2", "quadratic drag C_d*A per body axis (x forward, y left, "
        "z up): F_i = -rho/2 C_dA_i |v_air| v_air_i", ge=0, length=3)
    tether_attachment_m: tuple[float, ...] = quantity(
        (0.0, 0.0, 0.0), "m", "where the tether is attached, body frame (x forward, y left, "
        "z up) from the centre of mass (paper: at the centre of mass)", length=3)
    rotational_damping_n_m_s_rad: float = quantity(
        0.01, "N*m*s/rad", "aerodynamic damping of body rates", ge=0)
    gear_height_m: float = quantity(
        0.2, "m", "height of the centre of mass above flat ground when resting", gt=0)
    ground_friction_coeff: float = quantity(
        0.6, "1", "Coulomb friction of the landing gear on the ground", ge=0)

    def check(self) -> None:
        if self.rotor_speed_min_rad_s >= self.rotor_speed_max_rad_s:
            raise ValueError("rotor_speed_min_rad_s: must be below rotor_speed_max_rad_s")

    @property
    def inertia_diag(self) -> tuple[float, float, float]:
        """(Ixx, Iyy, Izz) [kg m^2]."""
        return (self.ixx_kg_m2, self.iyy_kg_m2, self.izz_kg_m2)

    @property
    def max_rotor_thrust_n(self) -> float:
        """Thrust of one rotor at maximum speed [N]."""
        return self.rotor_thrust_coeff * self.rotor_speed_max_rad_s ** 2

    @property
    def max_total_thrust_n(self) -> float:
        """Thrust of all four rotors at maximum speed [N]."""
        return 4.0 * self.max_rotor_thrust_n


@dataclass(frozen=True)
class TetherParams(Params):
    """The tether: weight, size, stiffness, air drag, ground contact, how much the drum holds,
    and which model of it the plant integrates."""

    model: str = quantity(
        "catenary", "1", "the truth model: quasi-static catenary or dynamic lumped masses",
        choices=tuple(m.value for m in TetherModel))
    linear_density_kg_m: float = quantity(0.034, "kg/m", "mass per unit length (paper)", gt=0)
    diameter_m: float = quantity(
        0.006, "m", "outer diameter (drag, section area); not the paper's 1.1e-4 m^2", gt=0)
    youngs_modulus_pa: float = quantity(
        3.9e9, "Pa", "effective axial modulus on the diameter's section (EA = 1.1e5 N)", gt=0)
    total_length_m: float = quantity(50.0, "m", "length wound on the full drum, L_T", gt=0)
    segments: int = quantity(
        25, "1", "lumped model: segments of the full length L_T (nominal segment L_T/N)",
        ge=1, le=200)
    axial_damping_n_s: float = quantity(
        30.0, "N*s", "lumped model: internal damping BA, tension += BA * strain rate", ge=0)
    normal_drag_coeff: float = quantity(
        1.2, "1", "lumped model: drag coefficient normal to the line, on its diameter", ge=0)
    tangential_drag_coeff: float = quantity(
        0.01, "1", "lumped model: drag coefficient along the line, on pi * diameter", ge=0)
    ground_stiffness_n_m2: float = quantity(
        3000.0, "N/m^2", "lumped model: ground reaction per metre of line per metre of "
        "penetration", gt=0)
    ground_damping_n_s_m2: float = quantity(
        20.0, "N*s/m^2", "lumped model: ground damping per metre of line", ge=0)
    ground_friction_coeff: float = quantity(
        0.5, "1", "lumped model: Coulomb friction of the line on the ground", ge=0)
    ground_friction_speed_m_s: float = quantity(
        0.01, "m/s", "lumped model: sliding speed at which friction reaches its full value",
        gt=0)

    @property
    def kind(self) -> TetherModel:
        """:attr:`model` as its enum."""
        return TetherModel(self.model)

    @property
    def section_area_m2(self) -> float:
        """pi d^2 / 4 [m^2]."""
        return math.pi * self.diameter_m ** 2 / 4.0

    @property
    def axial_stiffness_n(self) -> float:
        """EA [N]."""
        return self.youngs_modulus_pa * self.section_area_m2

    @property
    def segment_length_m(self) -> float:
        """Nominal segment length of the lumped model, L_T / segments [m]."""
        return self.total_length_m / self.segments

    def weight_per_length_n_m(self, gravity_m_s2: float) -> float:
        """w = rho * g [N/m]."""
        return self.linear_density_kg_m * gravity_m_s2


@dataclass(frozen=True)
class WinderParams(Params):
    """The ground winder: drum, motor, friction, brake."""

    drum_radius_m: float = quantity(0.10, "m", "effective radius r_w at which tether leaves", gt=0)
    drum_inner_radius_m: float = quantity(0.06, "m", "inner radius r_i of the hollow drum", gt=0)
    drum_mass_kg: float = quantity(1.5, "kg", "drum mass without tether, m_w bar", gt=0)
    rotor_inertia_kg_m2: float = quantity(
        2.0e-4, "kg*m^2", "motor rotor inertia, added to the drum's", ge=0)
    viscous_friction_n_m_s_rad: float = quantity(
        0.02, "N*m*s/rad", "viscous friction beta_w", ge=0)
    motor_torque_limit_n_m: float = quantity(4.0, "N*m", "motor torque limit", gt=0)
    motor_speed_limit_rad_s: float = quantity(
        60.0, "rad/s", "drum speed limit (6 m/s of tether at the default radius)", gt=0)
    speed_limit_gain_n_m_s_rad: float = quantity(
        2.0, "N*m*s/rad", "torque cut-back slope near the speed limit (motor-controller style)",
        gt=0)
    min_paid_out_m: float = quantity(
        0.3, "m", "hard stop of a full drum: tether that always stays out of the exit", gt=0)
    brake_torque_n_m: float = quantity(
        15.0, "N*m", "holding torque of the brake engaged when the motor is unpowered", ge=0)

    def check(self) -> None:
        if self.drum_inner_radius_m >= self.drum_radius_m:
            raise ValueError("drum_inner_radius_m: must be below drum_radius_m")


@dataclass(frozen=True)
class GustParams(Params):
    """One discrete (1 - cos) gust, MIL-F-8785C shape."""

    start_s: float = quantity(10.0, "s", "time the gust begins", ge=0)
    duration_s: float = quantity(2.0, "s", "time from start to end of the gust", gt=0)
    amplitude_m_s: tuple[float, ...] = quantity(
        (3.0, 0.0, 0.0), "m/s", "peak gust velocity (x east, y north, z up)", length=3)


@dataclass(frozen=True)
class WindParams(Params):
    """Steady wind, Dryden turbulence (MIL-F-8785C, low altitude) and discrete gusts."""

    steady_m_s: tuple[float, ...] = quantity(
        (0.0, 0.0, 0.0), "m/s", "mean wind velocity the air moves with (x east, y north, z up)",
        length=3)
    turbulence: str = quantity(
        "none", "1", "Dryden intensity", choices=("none", "light", "moderate", "severe"))
    wind_speed_at_6m_m_s: float = quantity(
        0.0, "m/s", "W20, the mean wind at 20 ft that scales low-altitude turbulence; "
        "0 takes the MIL-F-8785C value for the intensity", ge=0)
    seed: int = quantity(0, "1", "seed of the turbulence noise", ge=0)
    profile: str = quantity(
        "log", "1", "how the mean wind varies with height (steady_m_s is its value at "
        "reference_height_m)", choices=tuple(p.value for p in WindProfile))
    reference_height_m: float = quantity(
        10.0, "m", "height at which the mean wind is steady_m_s (meteorological 10 m)", gt=0)
    roughness_length_m: float = quantity(
        0.03, "m", "log profile: surface roughness z0 (open flat terrain)", gt=0)
    power_exponent: float = quantity(
        0.143, "1", "power profile: exponent alpha (1/7, open terrain)", gt=0, le=1)

    def check(self) -> None:
        if self.roughness_length_m >= self.reference_height_m:
            raise ValueError("roughness_length_m: must be below reference_height_m")

    @property
    def profile_kind(self) -> WindProfile:
        """:attr:`profile` as its enum."""
        return WindProfile(self.profile)
    gusts: tuple[GustParams, ...] = quantity((), "", "discrete gusts")


@dataclass(frozen=True)
class SystemParams(Params):
    """Everything the plant needs, grouped as the TOML files are."""

    environment: EnvironmentParams = quantity(EnvironmentParams(), "", "gravity and air")
    vehicle: VehicleParams = quantity(VehicleParams(), "", "the quadrotor")
    tether: TetherParams = quantity(TetherParams(), "", "the tether")
    winder: WinderParams = quantity(WinderParams(), "", "the ground winder")
    wind: WindParams = quantity(WindParams(), "", "the wind")

    def hover_thrust_fraction_full_tether(self) -> float:
        """Collective thrust needed to hover with the whole tether hanging vertically,
        as a fraction of the maximum: the sizing rule of the rotor limits."""
        g = self.environment.gravity_m_s2
        need = (self.vehicle.mass_kg + self.tether.linear_density_kg_m
                * self.tether.total_length_m) * g
        return need / self.vehicle.max_total_thrust_n


def hover_rotor_speed_rad_s(vehicle: VehicleParams, thrust_n: float) -> float:
    """Rotor speed at which four equal rotors give ``thrust_n`` in total [rad/s]."""
    return math.sqrt(max(thrust_n, 0.0) / (4.0 * vehicle.rotor_thrust_coeff))
