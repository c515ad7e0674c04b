"""The plant's sensors: IMU (accelerometer, gyroscope), magnetometer, barometer and GPS.

Each reads a truth quantity of the plant in the project frames (inertial ENU z-up, body
FLU) and adds a seeded error model: a constant turn-on bias drawn once, a bias random walk
and white Gaussian noise per sample (:class:`NoiseSpec`). With the noise switched off
(:meth:`SensorNoise.off`) every reading is the truth value exactly. The conversion to
MAVLink's NED/FRD happens later, in :mod:`tuavdefs.simlink`.

**Specific force.** An accelerometer measures the non-gravitational force per unit mass,
``f = a - g_vec`` with ``g_vec = (0, 0, -g)`` in the z-up inertial frame, rotated into the
body: ``f_b = R^T (a + g e3)``. Resting level it reads +g along body +z (up), i.e.
``zacc = -g`` in FRD. The acceleration ``a`` is taken from the plant's own state derivative
(:func:`sitl.plant.rhs`) at the sampled state, not by differencing the velocity over the
step: the derivative is the instantaneous acceleration at the same instant as the gyro and
attitude it is sampled with, needs no previous sample at t = 0, and carries no half-period
lag or attitude smearing (a difference over a 4 ms control period would be the mean
acceleration over the period, rotated with the attitude at its end). Ground contact is a
constraint force inside the derivative, so a vehicle on its gear reads +g too. What it
misses are the impulses of the post-step projections (touch-down), which a real IMU would
see as a spike. The tether solver's warm start, which the derivative updates, is restored
so that reading the sensors never perturbs the trajectory.

**Barometer**: the ISA troposphere (valid below 11 km), ``p = p0 (1 - L h / T0)^(g0 /
(R L))`` with p0 = 1013.25 hPa, T0 = 288.15 K, L = 6.5 K/km: 898.75 hPa at 1000 m.
The pressure altitude it reports is the ISA altitude of the (noisy) pressure.

**Magnetometer**: a constant Earth field given in NED [gauss] (default 0.2 G north,
0.45 G down), rotated into the body.

**GPS**: noisy inertial position and velocity, mapped to latitude/longitude/altitude by
:mod:`tuavdefs.frames` when packed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from sitl.plant import ROTORS, VEL, Plant, PlantInputs, rhs
from tuavdefs.frames import Quat, Vec3, ned_to_enu, quat_conjugate, quat_rotate
from tuavdefs.simlink import HOME_DEFAULT

# ----- the International Standard Atmosphere (troposphere)
ISA_P0_HPA = 1013.25
ISA_T0_K = 288.15
ISA_LAPSE_K_M = 0.0065
ISA_R_J_KG_K = 287.05287
ISA_G0_M_S2 = 9.80665
ISA_RHO0_KG_M3 = 1.225
_ISA_EXP = ISA_G0_M_S2 / (ISA_R_J_KG_K * ISA_LAPSE_K_M)   # 5.25588

#: Default Earth magnetic field in NED [gauss]: 0.2 G north, 0 east, 0.45 G down.
EARTH_FIELD_NED_GAUSS_DEFAULT: Vec3 = (0.2, 0.0, 0.45)


def isa_temperature_k(alt_amsl_m: float) -> float:
    """ISA temperature [K] at an altitude [m AMSL] (troposphere)."""
    return ISA_T0_K - ISA_LAPSE_K_M * alt_amsl_m


def isa_air(alt_amsl_m: float) -> tuple[float, float, float]:
    """ISA (static pressure [hPa], temperature [K], density [kg/m^3]) at an altitude [m
    AMSL] (troposphere, below 11 km).

    The altitude is taken as geopotential; the difference from geometric altitude (about
    0.16 m at 1000 m) is far below the barometer's noise.
    """
    t = isa_temperature_k(alt_amsl_m)
    p = ISA_P0_HPA * (t / ISA_T0_K) ** _ISA_EXP
    return p, t, p * 100.0 / (ISA_R_J_KG_K * t)


def isa_pressure_hpa(alt_amsl_m: float) -> float:
    """ISA static pressure [hPa] at an altitude [m AMSL] (:func:`isa_air`)."""
    return isa_air(alt_amsl_m)[0]


def isa_altitude_m(pressure_hpa: float) -> float:
    """ISA pressure altitude [m AMSL] of a static pressure [hPa]."""
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (pressure_hpa / ISA_P0_HPA) ** (1.0 / _ISA_EXP))


def isa_density_kg_m3(alt_amsl_m: float) -> float:
    """ISA air density [kg/m^3] at an altitude [m AMSL] (:func:`isa_air`)."""
    return isa_air(alt_amsl_m)[2]


# ----- truth quantities from the plant
def specific_force_flu(accel_enu_m_s2: Sequence[float], quat_enu_flu: Quat,
                       gravity_m_s2: float) -> Vec3:
    """Specific force in body FLU [m/s^2]: ``R^T (a + g e3)`` for the inertial (ENU, z-up)
    acceleration ``a`` [m/s^2] and attitude quaternion body FLU -> ENU."""
    f = (float(accel_enu_m_s2[0]), float(accel_enu_m_s2[1]),
         float(accel_enu_m_s2[2]) + gravity_m_s2)
    return quat_rotate(quat_conjugate(quat_enu_flu), f)


def plant_acceleration_enu(plant: Plant) -> Vec3:
    """The UAV's inertial acceleration [m/s^2] (ENU) at the plant's current state, from its
    state derivative with the wind of the last step. Leaves the plant untouched (the
    tether solver's warm start is restored)."""
    warm = plant.model.warm.copy()
    try:
        dx = rhs(plant.t_s, plant.x, PlantInputs(), plant.model, plant.wind_m_s,
                 rotor_setpoints=plant.x[ROTORS])
    finally:
        plant.model.warm[:] = warm
    a = dx[VEL]
    return (float(a[0]), float(a[1]), float(a[2]))


def plant_specific_force_flu(plant: Plant) -> Vec3:
    """What an ideal accelerometer at the UAV's centre of mass reads [m/s^2], body FLU:
    :func:`specific_force_flu` of :func:`plant_acceleration_enu`, computed in one compiled
    call (:meth:`sitl.plant.Plant.specific_force_flu`, the same bits)."""
    return plant.specific_force_flu()


def airspeed_from(vel_m_s: Sequence[float], wind_m_s: Sequence[float]) -> float:
    """True airspeed [m/s]: the speed of a velocity [m/s] relative to the wind [m/s]."""
    v, w = vel_m_s, wind_m_s
    return math.sqrt((v[0] - w[0]) ** 2 + (v[1] - w[1]) ** 2 + (v[2] - w[2]) ** 2)


# ----- error models
@dataclass(frozen=True)
class NoiseSpec:
    """Error model of one sensor channel, per axis, in the sensor's unit ``u``.

    ``sigma`` [u]: standard deviation of the white noise of each sample; ``bias_sigma``
    [u]: standard deviation of the constant turn-on bias drawn once; ``bias_walk``
    [u/sqrt(s)]: intensity of the bias random walk (the bias changes by
    ``N(0, bias_walk^2 dt)`` over a sample interval ``dt``).
    """

    sigma: float = 0.0
    bias_sigma: float = 0.0
    bias_walk: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma", "bias_sigma", "bias_walk"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")


@dataclass(frozen=True)
class SensorNoise:
    """Error models of all sensors, and the seed of their random streams.

    ``enabled=False`` makes every reading the exact truth. Each channel draws from its own
    stream spawned from ``seed``, so the readings of one do not depend on how often the
    others are sampled. Defaults are those of a small flight controller's MEMS sensors and
    a consumer GPS receiver.
    """

    enabled: bool = True
    seed: int = 0
    accel: NoiseSpec = NoiseSpec(sigma=0.05, bias_sigma=0.05, bias_walk=0.002)      # m/s^2
    gyro: NoiseSpec = NoiseSpec(sigma=0.003, bias_sigma=0.003, bias_walk=1e-4)      # rad/s
    mag: NoiseSpec = NoiseSpec(sigma=0.003, bias_sigma=0.005)                        # gauss
    baro: NoiseSpec = NoiseSpec(sigma=0.012, bias_sigma=0.05, bias_walk=0.002)       # hPa
    gps_horizontal: NoiseSpec = NoiseSpec(sigma=0.3)                                 # m
    gps_vertical: NoiseSpec = NoiseSpec(sigma=0.5)                                   # m
    gps_velocity: NoiseSpec = NoiseSpec(sigma=0.05)                                  # m/s

    @classmethod
    def off(cls) -> SensorNoise:
        """No noise and no bias: readings are the truth."""
        return cls(enabled=False)


#: Standard normal draws fetched from a channel's stream at a time (speed only).
_BLOCK = 256
#: Most axes of a channel (the layout of :class:`NoiseState`'s arrays).
_MAX_DIM = 3


class NoiseState(NamedTuple):
    """The state of ``n`` noisy channels in arrays, so that compiled code
    (:mod:`sitl.batch`) can read them as :class:`NoisyChannel` does: per channel ``k``,
    ``draws[k]`` its current block of standard normal draws (``_BLOCK`` samples x [bias
    walk, white noise] x ``_MAX_DIM`` axes, of which its own ``dim`` first are used),
    ``bias[k]`` its bias per axis [unit of the channel], ``cursor[k]`` the next sample of
    the block, ``params[k]`` (enabled as 0/1, sigma, bias walk) of its
    :class:`NoiseSpec`."""

    draws: np.ndarray
    bias: np.ndarray
    cursor: np.ndarray
    params: np.ndarray

    @classmethod
    def empty(cls, n: int) -> NoiseState:
        """Arrays for ``n`` channels, all zero."""
        return cls(np.zeros((n, _BLOCK, 2, _MAX_DIM)), np.zeros((n, _MAX_DIM)),
                   np.zeros(n, dtype=np.int64), np.zeros((n, 3)))


class NoisyChannel:
    """A ``dim``-axis reading = truth + bias + white noise, with its own random stream.

    The stream is consumed in blocks of standard normal draws (two per axis and sample:
    bias walk, white noise), so a channel's readings depend only on its seed and on how
    often it has been read. The next block is drawn as soon as one is used up, so that
    the state is always ready for a read. The channel's state lives in slot ``slot`` of a
    :class:`NoiseState` (its own if none is given), where compiled code can read the
    channel too.
    """

    def __init__(self, spec: NoiseSpec, dim: int, rng: np.random.Generator,
                 enabled: bool = True, state: NoiseState | None = None,
                 slot: int = 0) -> None:
        if not 1 <= dim <= _MAX_DIM:
            raise ValueError(f"a channel has 1 to {_MAX_DIM} axes, not {dim}")
        self.spec = spec
        self.dim = dim
        self.enabled = enabled
        self._rng = rng
        st = NoiseState.empty(1) if state is None else state
        self._block = st.draws[slot, :, :, :dim]
        self._bias_a = st.bias[slot, :dim]
        self._cursor = st.cursor[slot:slot + 1]
        st.params[slot] = (1.0 if enabled else 0.0, spec.sigma, spec.bias_walk)
        self._z: list | None = None   # the block as lists (for the interpreter)
        self._sigma = spec.sigma
        self._walk = spec.bias_walk
        if enabled:
            if spec.bias_sigma > 0:
                self._bias_a[:] = rng.normal(0.0, spec.bias_sigma, dim)
            self.refill()

    @property
    def bias(self) -> np.ndarray:
        """The current bias, per axis [unit of the channel]."""
        return self._bias_a.copy()

    def refill(self) -> None:
        """Draw the next block of the stream (the last one is used up)."""
        self._block[...] = self._rng.standard_normal((_BLOCK, 2, self.dim))
        self._cursor[0] = 0
        self._z = None

    def _draw(self) -> list:
        """This sample's draws: [bias walk per axis, white noise per axis]."""
        i = int(self._cursor[0])
        z = self._z
        if z is None:
            z = self._z = self._block.tolist()
        if i + 1 < _BLOCK:
            self._cursor[0] = i + 1
        else:
            self.refill()
        return z[i]  # type: ignore[no-any-return]

    def read(self, truth: Sequence[float], dt_s: float) -> tuple[float, ...]:
        """One reading of ``truth`` taken ``dt_s`` [s] after the previous one."""
        if not self.enabled:
            return tuple(float(v) for v in truth)
        z_walk, z_noise = self._draw()
        sigma = self._sigma
        bias = self._bias_a.tolist()
        if self._walk > 0.0:
            k = self._walk * math.sqrt(dt_s)
            bias = [b + k * z for b, z in zip(bias, z_walk, strict=True)]
            self._bias_a[:] = bias
        return tuple([float(t) + b + sigma * z
                      for t, b, z in zip(truth, bias, z_noise, strict=True)])


class ImuReading(NamedTuple):
    """Accelerometer (specific force) [m/s^2], gyroscope [rad/s] and magnetometer [gauss],
    all in body FLU."""

    accel_flu_m_s2: Vec3
    gyro_flu_rad_s: Vec3
    mag_flu_gauss: Vec3


class BaroReading(NamedTuple):
    """Static pressure [hPa], its ISA pressure altitude [m AMSL], air temperature [degC]."""

    pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float


class GpsReading(NamedTuple):
    """GPS position [m] and velocity [m/s] in the inertial ENU frame, and the accuracies
    [m] the receiver claims (horizontal, vertical)."""

    position_enu_m: Vec3
    velocity_enu_m_s: Vec3
    eph_m: float
    epv_m: float


@dataclass
class SensorSuite:
    """All the UAV's sensors, sampled from truth quantities in the project frames.

    ``home`` is (lat deg, lon deg, alt m AMSL) of the inertial origin (for the barometer's
    altitude; the GPS's mapping to latitude/longitude happens at packing);
    ``earth_field_ned_gauss`` the Earth's magnetic field in NED [gauss].
    """

    noise: SensorNoise = field(default_factory=SensorNoise)
    home: tuple[float, float, float] = HOME_DEFAULT
    earth_field_ned_gauss: Vec3 = EARTH_FIELD_NED_GAUSS_DEFAULT

    def __post_init__(self) -> None:
        n = self.noise
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(n.seed).spawn(7)]
        on = n.enabled
        #: The channels' state, slots in the order of :attr:`channels`.
        self.noise_state = st = NoiseState.empty(7)
        self.accel = NoisyChannel(n.accel, 3, streams[0], on, st, 0)
        self.gyro = NoisyChannel(n.gyro, 3, streams[1], on, st, 1)
        self.mag = NoisyChannel(n.mag, 3, streams[2], on, st, 2)
        self.baro_channel = NoisyChannel(n.baro, 1, streams[3], on, st, 3)
        self.gps_horizontal = NoisyChannel(n.gps_horizontal, 2, streams[4], on, st, 4)
        self.gps_vertical = NoisyChannel(n.gps_vertical, 1, streams[5], on, st, 5)
        self.gps_velocity = NoisyChannel(n.gps_velocity, 3, streams[6], on, st, 6)
        self.channels = (self.accel, self.gyro, self.mag, self.baro_channel,
                         self.gps_horizontal, self.gps_vertical, self.gps_velocity)
        self._field_enu = ned_to_enu(tuple(float(v) for v in self.earth_field_ned_gauss))

    @property
    def earth_field_enu_gauss(self) -> Vec3:
        """The Earth's magnetic field in the inertial ENU frame [gauss]."""
        return self._field_enu

    def magnetic_field_flu(self, quat_enu_flu: Quat) -> Vec3:
        """The true Earth field in body FLU [gauss] at attitude body FLU -> ENU."""
        return quat_rotate(quat_conjugate(quat_enu_flu), self._field_enu)

    def imu(self, specific_force_flu_m_s2: Sequence[float], rates_flu_rad_s: Sequence[float],
            quat_enu_flu: Quat, dt_s: float) -> ImuReading:
        """Accelerometer, gyroscope and magnetometer readings, ``dt_s`` [s] after the last."""
        return ImuReading(self.accel.read(specific_force_flu_m_s2, dt_s),  # type: ignore[arg-type]
                          self.gyro.read(rates_flu_rad_s, dt_s),
                          self.mag.read(self.magnetic_field_flu(quat_enu_flu), dt_s))

    def baro(self, alt_amsl_m: float, dt_s: float) -> BaroReading:
        """Barometer reading at a true altitude [m AMSL], ``dt_s`` [s] after the last."""
        pressure_hpa, temperature_k, _ = isa_air(alt_amsl_m)
        return self.baro_of_air(pressure_hpa, temperature_k, dt_s)

    def baro_of_air(self, pressure_hpa: float, temperature_k: float,
                    dt_s: float) -> BaroReading:
        """Barometer reading in air of a true static pressure [hPa] and temperature [K]
        (the ISA's at an altitude: :func:`isa_air`), ``dt_s`` [s] after the last."""
        p = self.baro_channel.read((pressure_hpa,), dt_s)[0]
        return BaroReading(p, isa_altitude_m(p), temperature_k - 273.15)

    def gps(self, pos_enu_m: Sequence[float], vel_enu_m_s: Sequence[float],
            dt_s: float) -> GpsReading:
        """GPS fix of a true position [m] and velocity [m/s] (ENU), ``dt_s`` [s] after the
        last fix."""
        e, n = self.gps_horizontal.read((pos_enu_m[0], pos_enu_m[1]), dt_s)
        (u,) = self.gps_vertical.read((pos_enu_m[2],), dt_s)
        v = self.gps_velocity.read(vel_enu_m_s, dt_s)
        return GpsReading((e, n, u), v,  # type: ignore[arg-type]
                          max(self.noise.gps_horizontal.sigma, 0.01),
                          max(self.noise.gps_vertical.sigma, 0.01))

    def barometric_altitude_amsl_m(self, pos_enu_m: Sequence[float]) -> float:
        """True altitude [m AMSL] of an inertial position [m]."""
        return self.home[2] + float(pos_enu_m[2])
