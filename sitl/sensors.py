"""The plant's sensors: IMU (accelerometer, gyroscope), magnetometer, barometer and GPS.

Each reads a truth quantity of the plant in the project frames (inertial ENU z-up, body
FLU) and adds a seeded error model: a constant turn-on bias drawn once, a bias random walk,
a first-order Gauss-Markov error and white Gaussian noise per sample (:class:`NoiseSpec`).
The defaults are datasheet-class parts (:class:`SensorNoise`: an ICM-42688-P IMU, an MS5611
barometer, an RM3100 magnetometer, and a GNSS receiver chosen by :class:`GnssPreset`: a
u-blox ZED-F9P in RTK by default, or a standalone M9N/M10 class receiver). With the noise
switched off (:meth:`SensorNoise.off`) every reading is the truth value exactly. The
conversion to MAVLink's NED/FRD happens later, in :mod:`tuavdefs.simlink`.

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
:mod:`tuavdefs.frames` when packed. The receiver's fix is late: the fix sent at time t
describes the truth at ``t - gps_latency_s``. The suite keeps its own short buffer of past
truth (:meth:`SensorSuite.record_truth`, every sample of the truth; the plant's link
records every control period) and interpolates it linearly at the fix's epoch
(:meth:`SensorSuite.gps_fix`); :meth:`SensorSuite.gps` is the fix of a truth given
directly.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from sitl._jit import njit
from sitl.plant import ROTORS, VEL, Plant, PlantInputs, rhs
from tuavdefs.frames import Quat, Vec3, ned_to_enu, quat_conjugate, quat_rotate
from tuavdefs.jit import F64, I64, Signature, array, entry_point, record
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
def _check(owner: str, name: str, value: float, low: float = 0.0, high: float = math.inf,
           low_open: bool = False) -> None:
    """Fail naming the field unless ``value`` is a finite number in [low, high] ((low,
    high] with ``low_open``)."""
    ok = isinstance(value, (int, float)) and math.isfinite(value) and (
        value > low if low_open else value >= low) and value <= high
    if not ok:
        bound = f"> {low}" if low_open else f">= {low}"
        if math.isfinite(high):
            bound += f" and <= {high}"
        raise ValueError(f"{owner}{name}: must be finite and {bound}, got {value!r}")


@dataclass(frozen=True)
class NoiseSpec:
    """Error model of one sensor channel, per axis, in the sensor's unit ``u``.

    ``sigma`` [u]: standard deviation of the white noise of each sample; ``bias_sigma``
    [u]: standard deviation of the constant turn-on bias drawn once; ``bias_walk``
    [u/sqrt(s)]: intensity of the bias random walk (the bias changes by
    ``N(0, bias_walk^2 dt)`` over a sample interval ``dt``); ``gm_sigma`` [u] and
    ``gm_tau_s`` [s]: a first-order Gauss-Markov error of stationary standard deviation
    ``gm_sigma`` and correlation time ``gm_tau_s``, sampled exactly over any interval:
    ``x' = exp(-dt/tau) x + gm_sigma sqrt(1 - exp(-2 dt/tau)) N(0, 1)``, started in its
    stationary distribution (a slowly wandering GNSS error, an IMU's in-run bias).
    A reading is ``truth + bias + x + sigma N(0, 1)``.
    """

    sigma: float = 0.0
    bias_sigma: float = 0.0
    bias_walk: float = 0.0
    gm_sigma: float = 0.0
    gm_tau_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma", "bias_sigma", "bias_walk", "gm_sigma", "gm_tau_s"):
            _check("", name, getattr(self, name))
        if self.gm_sigma > 0.0 and not self.gm_tau_s > 0.0:
            raise ValueError(f"gm_tau_s: must be > 0 s with gm_sigma > 0, got "
                             f"{self.gm_tau_s!r}")

    @property
    def gauss_markov(self) -> bool:
        """Whether the channel has a Gauss-Markov error."""
        return self.gm_sigma > 0.0

    @property
    def stationary_sigma(self) -> float:
        """The standard deviation [u] of one reading's error without the random walk (which
        has none): white noise, turn-on bias and Gauss-Markov error together."""
        return math.sqrt(self.sigma ** 2 + self.bias_sigma ** 2 + self.gm_sigma ** 2)


def noise_density_sigma(density_per_sqrt_hz: float, rate_hz: float) -> float:
    """The per-sample standard deviation [u] of white noise of a (one-sided) density
    [u/sqrt(Hz)] sampled at ``rate_hz`` [Hz]: ``density sqrt(rate)`` (the discrete-time
    noise of a continuous white noise averaged over each sample interval)."""
    return density_per_sqrt_hz * math.sqrt(rate_hz)


_DEG = math.pi / 180.0
_MILLI_G_M_S2 = ISA_G0_M_S2 * 1e-3
#: The IMU's sample rate [Hz]: one HIL_SENSOR per control period.
IMU_RATE_HZ = 250.0
#: The temperature excursion of the board during a flight [K] (1 sigma) that turns the
#: datasheets' temperature coefficients of the offsets into an in-run bias; with the board's
#: thermal time constant [s] as its correlation time. Assumptions, not datasheet numbers.
_IN_RUN_DELTA_T_K = 5.0
_THERMAL_TAU_S = 300.0

#: TDK InvenSense ICM-42688-P gyroscope (datasheet DS-000347): noise spectral density
#: 0.0028 deg/s/sqrt(Hz) -> 7.7e-4 rad/s a sample at 250 Hz; zero-rate output initial
#: tolerance +-0.5 deg/s (as the turn-on bias's 1 sigma); ZRO variation over temperature
#: +-0.005 deg/s/K (x 5 K: the in-run bias, Gauss-Markov, 300 s).
ICM42688P_GYRO = NoiseSpec(
    sigma=noise_density_sigma(0.0028 * _DEG, IMU_RATE_HZ), bias_sigma=0.5 * _DEG,
    gm_sigma=0.005 * _DEG * _IN_RUN_DELTA_T_K, gm_tau_s=_THERMAL_TAU_S)          # rad/s
#: ICM-42688-P accelerometer (DS-000347): noise spectral density 70 ug/sqrt(Hz) ->
#: 0.0109 m/s^2 a sample at 250 Hz; zero-g offset initial tolerance +-20 mg (turn-on bias,
#: 1 sigma); zero-g level change over temperature +-0.15 mg/K (x 5 K, Gauss-Markov, 300 s).
ICM42688P_ACCEL = NoiseSpec(
    sigma=noise_density_sigma(70e-6 * ISA_G0_M_S2, IMU_RATE_HZ),
    bias_sigma=20.0 * _MILLI_G_M_S2,
    gm_sigma=0.15 * _MILLI_G_M_S2 * _IN_RUN_DELTA_T_K, gm_tau_s=_THERMAL_TAU_S)  # m/s^2
#: TE Connectivity MS5611-01BA03 barometer: RMS resolution 0.012 mbar at OSR 4096 (the
#: white noise of a sample: 0.1 m); absolute accuracy +-1.5 mbar at 25 degC, 750..1100 mbar
#: (the turn-on bias, 1 sigma); in flight a thermal and airflow drift of 0.1 hPa (~0.8 m),
#: Gauss-Markov over 300 s (an assumption: the datasheet gives only the error band).
MS5611_BARO = NoiseSpec(sigma=0.012, bias_sigma=1.5, gm_sigma=0.1,
                        gm_tau_s=_THERMAL_TAU_S)                                 # hPa
#: PNI RM3100 magnetometer at 200 cycle counts: 15 nT RMS noise (1.5e-4 G; 13 nT
#: resolution). A magneto-inductive sensor has no offset of its own: the turn-on bias is
#: the vehicle's hard iron left after calibration (0.005 G, an assumption).
RM3100_MAG = NoiseSpec(sigma=15e-9 * 1e4, bias_sigma=0.005)                      # gauss


class GnssPreset(enum.Enum):
    """The GNSS receivers of :meth:`SensorNoise.preset`.

    ``RTK``: a u-blox ZED-F9P with RTK corrections (datasheet: 0.01 m + 1 ppm CEP
    horizontal, 0.01 m + 1 ppm R50 vertical): per axis 4 mm white + a 1 cm Gauss-Markov
    wander over 10 s horizontally (1.1 cm in all), 6 mm + 2 cm vertically (2.1 cm);
    velocity 2 mm/s white + 1 mm/s wander over 10 s; 10 Hz, 50 ms latency.
    ``GNSS``: a standalone u-blox M9N / M10 class receiver (datasheets: 1.5 m CEP, 1.0 m
    CEP with SBAS; velocity 0.05 m/s): per axis a 0.8 m Gauss-Markov error over 8 s + 0.1 m
    white horizontally, 1.0 m + 0.15 m vertically; velocity 0.05 m/s white; 5 Hz, 100 ms
    latency.
    """

    RTK = "rtk"
    GNSS = "gnss"


class GnssModel(NamedTuple):
    """A GNSS receiver's error models [m, m, m/s per axis], fix rate [Hz] and latency [s]."""

    horizontal: NoiseSpec
    vertical: NoiseSpec
    velocity: NoiseSpec
    rate_hz: float
    latency_s: float


#: The receivers of :class:`GnssPreset`.
GNSS_MODELS: dict[GnssPreset, GnssModel] = {
    GnssPreset.RTK: GnssModel(
        horizontal=NoiseSpec(sigma=0.004, gm_sigma=0.01, gm_tau_s=10.0),
        vertical=NoiseSpec(sigma=0.006, gm_sigma=0.02, gm_tau_s=10.0),
        velocity=NoiseSpec(sigma=0.002, gm_sigma=0.001, gm_tau_s=10.0),
        rate_hz=10.0, latency_s=0.05),
    GnssPreset.GNSS: GnssModel(
        horizontal=NoiseSpec(sigma=0.1, gm_sigma=0.8, gm_tau_s=8.0),
        vertical=NoiseSpec(sigma=0.15, gm_sigma=1.0, gm_tau_s=8.0),
        velocity=NoiseSpec(sigma=0.05),
        rate_hz=5.0, latency_s=0.1),
}
#: The longest GNSS latency the suite's truth buffer is for [s].
GPS_LATENCY_MAX_S = 1.0
_RTK = GNSS_MODELS[GnssPreset.RTK]


@dataclass(frozen=True)
class SensorNoise:
    """Error models of all sensors, the GNSS receiver's rate and latency, and the seed of
    their random streams.

    ``enabled=False`` makes every reading the exact truth (the GNSS latency still applies:
    :meth:`off` sets it to 0). Each channel draws from its own stream spawned from
    ``seed``, so the readings of one do not depend on how often the others are sampled.
    The defaults are the datasheet parts (module constants ``ICM42688P_GYRO``,
    ``ICM42688P_ACCEL``, ``RM3100_MAG``, ``MS5611_BARO``) and the RTK receiver
    (:class:`GnssPreset`): ``SensorNoise() == SensorNoise.preset(GnssPreset.RTK)``.
    ``gps_rate_hz`` [Hz]: fixes a second (a whole number of microseconds apart);
    ``gps_latency_s`` [s]: the age of the truth a fix describes, 0 to 1 s.
    """

    enabled: bool = True
    seed: int = 0
    accel: NoiseSpec = ICM42688P_ACCEL                                              # m/s^2
    gyro: NoiseSpec = ICM42688P_GYRO                                                # rad/s
    mag: NoiseSpec = RM3100_MAG                                                     # gauss
    baro: NoiseSpec = MS5611_BARO                                                   # hPa
    gps_horizontal: NoiseSpec = _RTK.horizontal                                     # m
    gps_vertical: NoiseSpec = _RTK.vertical                                         # m
    gps_velocity: NoiseSpec = _RTK.velocity                                         # m/s
    gps_rate_hz: float = _RTK.rate_hz
    gps_latency_s: float = _RTK.latency_s

    def __post_init__(self) -> None:
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed: must be an integer >= 0, got {self.seed!r}")
        for name in ("accel", "gyro", "mag", "baro", "gps_horizontal", "gps_vertical",
                     "gps_velocity"):
            if not isinstance(getattr(self, name), NoiseSpec):
                raise ValueError(f"{name}: must be a NoiseSpec, got {getattr(self, name)!r}")
        _check("", "gps_rate_hz", self.gps_rate_hz, low_open=True)
        period = 1e6 / self.gps_rate_hz
        if abs(period - round(period)) > 1e-6 or round(period) < 1:
            raise ValueError(f"gps_rate_hz: {self.gps_rate_hz} Hz is not a whole number of "
                             "microseconds")
        _check("", "gps_latency_s", self.gps_latency_s, high=GPS_LATENCY_MAX_S)

    @classmethod
    def off(cls, gnss: GnssPreset | str = GnssPreset.RTK) -> SensorNoise:
        """No noise, no bias and no GNSS latency: readings are the truth, now (at the rate,
        and with the reported accuracies, of the receiver ``gnss``)."""
        return replace(cls.preset(gnss), enabled=False, gps_latency_s=0.0)

    @classmethod
    def preset(cls, gnss: GnssPreset | str = GnssPreset.RTK, seed: int = 0) -> SensorNoise:
        """The datasheet suite with the GNSS receiver ``gnss`` (a :class:`GnssPreset` or
        its name, "rtk" or "gnss"), seeded with ``seed``."""
        try:
            model = GNSS_MODELS[GnssPreset(gnss)]
        except ValueError:
            names = ", ".join(p.value for p in GnssPreset)
            raise ValueError(f"gnss: must be one of {names}, got {gnss!r}") from None
        return cls(seed=seed, gps_horizontal=model.horizontal, gps_vertical=model.vertical,
                   gps_velocity=model.velocity, gps_rate_hz=model.rate_hz,
                   gps_latency_s=model.latency_s)

    @property
    def gps_eph_m(self) -> float:
        """The horizontal accuracy [m] the receiver reports (HIL_GPS ``eph``): its
        horizontal channel's 1-sigma per axis (:attr:`NoiseSpec.stationary_sigma`), at
        least 1 cm (the field's resolution)."""
        return max(self.gps_horizontal.stationary_sigma, 0.01)

    @property
    def gps_epv_m(self) -> float:
        """The vertical accuracy [m] the receiver reports (HIL_GPS ``epv``), likewise."""
        return max(self.gps_vertical.stationary_sigma, 0.01)

    @property
    def gps_velocity_accuracy_m_s(self) -> float:
        """The velocity accuracy [m/s] the receiver would report (1 sigma per axis; HIL_GPS
        has no field for it)."""
        return self.gps_velocity.stationary_sigma


#: Standard normal draws fetched from a channel's stream at a time (speed only).
_BLOCK = 256
#: Most axes of a channel (the layout of :class:`NoiseState`'s arrays).
_MAX_DIM = 3
#: Draws per axis and sample: bias walk, white noise, Gauss-Markov.
_DRAWS = 3
#: Columns of :attr:`NoiseState.params`.
_P_ENABLED, _P_SIGMA, _P_WALK, _P_GM_SIGMA, _P_GM_TAU, _N_PARAMS = range(6)


class NoiseState(NamedTuple):
    """The state of ``n`` noisy channels in arrays, so that compiled code
    (:mod:`sitl.batch`) can read them as :class:`NoisyChannel` does: per channel ``k``,
    ``draws[k]`` its current block of standard normal draws (``_BLOCK`` samples x [bias
    walk, white noise, Gauss-Markov] x ``_MAX_DIM`` axes, of which its own ``dim`` first
    are used, and the Gauss-Markov draws only by a channel that has one), ``bias[k]`` its
    bias per axis [unit of the channel], ``gm[k]`` its Gauss-Markov error per axis,
    ``cursor[k]`` the next sample of the block, ``params[k]`` (enabled as 0/1, sigma, bias
    walk, gm_sigma, gm_tau_s) of its :class:`NoiseSpec`."""

    draws: np.ndarray
    bias: np.ndarray
    gm: np.ndarray
    cursor: np.ndarray
    params: np.ndarray

    #: Its type for a compiled kernel (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(4), array(2), array(2), array(1, I64), array(2))

    @classmethod
    def empty(cls, n: int) -> NoiseState:
        """Arrays for ``n`` channels, all zero."""
        return cls(np.zeros((n, _BLOCK, _DRAWS, _MAX_DIM)), np.zeros((n, _MAX_DIM)),
                   np.zeros((n, _MAX_DIM)), np.zeros(n, dtype=np.int64),
                   np.zeros((n, _N_PARAMS)))


def gauss_markov_coefficients(gm_sigma: float, gm_tau_s: float, dt_s: float
                              ) -> tuple[float, float]:
    """(phi, q) of a Gauss-Markov error over ``dt_s`` [s]: ``x' = phi x + q N(0, 1)`` with
    ``phi = exp(-dt/tau)``, ``q = gm_sigma sqrt(1 - exp(-2 dt/tau))`` (the compiled batch
    computes the same, in the same order)."""
    return (math.exp(-dt_s / gm_tau_s),
            gm_sigma * math.sqrt(-math.expm1(-2.0 * dt_s / gm_tau_s)))


class NoisyChannel:
    """A ``dim``-axis reading = truth + bias + Gauss-Markov error + white noise, with its
    own random stream.

    The stream is consumed in blocks of standard normal draws (per axis and sample: bias
    walk, white noise, and with a Gauss-Markov error its draw), so a channel's readings
    depend only on its seed and on how often it has been read. The next block is drawn as
    soon as one is used up, so that the state is always ready for a read. The channel's
    state lives in slot ``slot`` of a :class:`NoiseState` (its own if none is given), where
    compiled code can read the channel too. At construction the stream gives the turn-on
    bias, then the Gauss-Markov error's start (its stationary distribution), then the first
    block.
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
        self._state, self._slot = st, slot
        # the read's results before they are committed, and the reading
        self._out = np.zeros(_MAX_DIM)
        shape = st.bias.shape
        self._scratch = (np.zeros(shape), np.zeros(shape), self._out)
        self._step: Any = None    # channel_step's entry point, taken at the first read
        self._block = st.draws[slot, :, :, :dim]
        self._bias_a = st.bias[slot, :dim]
        self._gm_a = st.gm[slot, :dim]
        self._cursor = st.cursor[slot:slot + 1]
        st.params[slot] = (1.0 if enabled else 0.0, spec.sigma, spec.bias_walk,
                           spec.gm_sigma, spec.gm_tau_s)
        #: Draws per axis and sample taken from the stream.
        self._k = _DRAWS if spec.gauss_markov else 2
        if enabled:
            if spec.bias_sigma > 0:
                self._bias_a[:] = rng.normal(0.0, spec.bias_sigma, dim)
            if spec.gauss_markov:
                self._gm_a[:] = rng.normal(0.0, spec.gm_sigma, dim)
            self.refill()

    @property
    def bias(self) -> np.ndarray:
        """The current bias, per axis [unit of the channel]."""
        return self._bias_a.copy()

    @property
    def gauss_markov_error(self) -> np.ndarray:
        """The current Gauss-Markov error, per axis [unit of the channel]."""
        return self._gm_a.copy()

    def refill(self) -> None:
        """Draw the next block of the stream (the last one is used up)."""
        self._block[:, :self._k, :] = self._rng.standard_normal((_BLOCK, self._k, self.dim))
        self._cursor[0] = 0

    def load(self) -> Any:
        """Take the reading's compiled step (:func:`channel_step`'s entry point: loaded
        from numba's cache, or compiled, now) if this channel has not yet; the first
        :meth:`read` takes it otherwise."""
        if self._step is None:
            self._step = entry_point(channel_step, CHANNEL_STEP_SIGNATURE)
        return self._step

    def read(self, truth: Sequence[float], dt_s: float) -> tuple[float, ...]:
        """One reading of ``truth`` taken ``dt_s`` [s] after the previous one
        (:func:`channel_read`, then its state committed)."""
        if not self.enabled:
            return tuple(float(v) for v in truth)
        dim = self.dim
        t0 = float(truth[0])
        t1 = float(truth[1]) if dim > 1 else 0.0
        t2 = float(truth[2]) if dim > 2 else 0.0
        out, step = self._out, self._step
        if step is None:
            step = self.load()
        if step(self._slot, dim, t0, t1, t2, float(dt_s), self._state, self._scratch):
            self.refill()
        return tuple(out[:dim].tolist())


#: :func:`channel_step`'s arguments: the channel, its axes, the truth, the interval [s],
#: the :class:`NoiseState`, the scratch (bias and Gauss-Markov error read, the reading).
CHANNEL_STEP_SIGNATURE = Signature(I64, I64, F64, F64, F64, F64, NoiseState.RECORD,
                                   record(array(2), array(2), array()))


@njit
def channel_step(c: int, dim: int, t0: float, t1: float, t2: float, dt: float,
                 state: tuple, scratch: tuple) -> bool:
    """:func:`channel_read` of channel ``c`` of ``state`` (a :class:`NoiseState`) into
    ``scratch`` = (new bias, new Gauss-Markov error, reading), committed
    (:func:`channel_commit`); whether its block of draws is used up (to refill now)."""
    draws, bias, gm, cursor, params = state
    new_bias, new_gm, out = scratch
    channel_read(c, dim, t0, t1, t2, dt, draws, bias, gm, cursor, params, new_bias, new_gm,
                 out)
    return channel_commit(c, bias, gm, cursor, new_bias, new_gm)


@njit
def channel_commit(c: int, bias: np.ndarray, gm: np.ndarray, cursor: np.ndarray,
                   new_bias: np.ndarray, new_gm: np.ndarray) -> bool:
    """Channel ``c``'s read committed: its bias and Gauss-Markov error are those of the
    read, its cursor on the next sample; whether its block of draws is used up."""
    for a in range(bias.shape[1]):
        bias[c, a] = new_bias[c, a]
        gm[c, a] = new_gm[c, a]
    cursor[c] += 1
    return cursor[c] == _BLOCK


@njit
def channel_read(c: int, dim: int, t0: float, t1: float, t2: float, dt: float,
                 draws: np.ndarray, bias: np.ndarray, gm: np.ndarray, cursor: np.ndarray,
                 params: np.ndarray, new_bias: np.ndarray, new_gm: np.ndarray,
                 out: np.ndarray) -> None:
    """The reading of channel ``c`` of a :class:`NoiseState` (``draws`` .. ``params``),
    ``dim`` axes of the truth ``t0, t1, t2``, taken ``dt`` [s] after its last, into
    ``out``: truth + bias (walked) + Gauss-Markov error (stepped) + white noise, on the
    cursor's draws; its bias and Gauss-Markov error after the read into ``new_bias[c]``,
    ``new_gm[c]``. The state itself is committed by the caller (:meth:`NoisyChannel.read`
    at once; the compiled batch, :mod:`sitl.batch`, once the whole batch is known good)."""
    if params[c, _P_ENABLED] == 0.0:   # disabled: the truth
        out[0], out[1], out[2] = t0, t1, t2
        return
    i = cursor[c]
    sigma, walk, gm_sigma = params[c, _P_SIGMA], params[c, _P_WALK], params[c, _P_GM_SIGMA]
    k = walk * math.sqrt(dt) if walk > 0.0 else 0.0
    phi, q = 0.0, 0.0
    if gm_sigma > 0.0:
        phi, q = _gm_coefficients(gm_sigma, params[c, _P_GM_TAU], dt)
    for a in range(dim):
        b = bias[c, a]
        if walk > 0.0:
            b = b + k * draws[c, i, 0, a]
        new_bias[c, a] = b
        t = t0 if a == 0 else (t1 if a == 1 else t2)
        if gm_sigma > 0.0:
            g = phi * gm[c, a] + q * draws[c, i, 2, a]
            new_gm[c, a] = g
            out[a] = t + b + g + sigma * draws[c, i, 1, a]
        else:
            new_gm[c, a] = gm[c, a]
            out[a] = t + b + sigma * draws[c, i, 1, a]


_gm_coefficients = njit(gauss_markov_coefficients)


# ----- the truth buffer of the GNSS latency
#: Samples of past truth the suite keeps: with the latency at most 1 s, enough for truth
#: recorded up to 1 kHz.
TRUTH_BUFFER_LEN = 1024


class TruthBuffer(NamedTuple):
    """Past truth in a ring, for compiled code too (:mod:`sitl.batch`): ``time_us[i]`` [us,
    as float] and ``pos_vel[i]`` (ENU position [m], velocity [m/s]) of sample ``i``;
    ``ring`` = (index of the newest sample, number of samples)."""

    time_us: np.ndarray
    pos_vel: np.ndarray
    ring: np.ndarray

    #: Its type for a compiled kernel (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(), array(2), array(1, I64))

    @classmethod
    def empty(cls) -> TruthBuffer:
        """An empty buffer of :data:`TRUTH_BUFFER_LEN` samples."""
        return cls(np.zeros(TRUTH_BUFFER_LEN), np.zeros((TRUTH_BUFFER_LEN, 6)),
                   np.array([TRUTH_BUFFER_LEN - 1, 0], dtype=np.int64))


def truth_push(t_us: float, px: float, py: float, pz: float, vx: float, vy: float,
               vz: float, time_us: np.ndarray, pos_vel: np.ndarray, ring: np.ndarray
               ) -> tuple[int, int]:
    """Write a sample at ``t_us`` into the slot after the newest of a
    :class:`TruthBuffer` (its arrays) and return the ring's (newest, count) with it, without
    committing them to ``ring``. A time before the newest (a new session, time restarted)
    forgets the older samples. (Compiled by :mod:`sitl.batch`.)"""
    n = time_us.shape[0]
    newest, count = ring[0], ring[1]
    if count > 0 and t_us < time_us[newest]:
        count = 0
    slot = (newest + 1) % n
    time_us[slot] = t_us
    pos_vel[slot, 0], pos_vel[slot, 1], pos_vel[slot, 2] = px, py, pz
    pos_vel[slot, 3], pos_vel[slot, 4], pos_vel[slot, 5] = vx, vy, vz
    return slot, min(count + 1, n)


def truth_at(t_us: float, latency_us: float, time_us: np.ndarray, pos_vel: np.ndarray,
             newest: int, count: int, out: np.ndarray) -> None:
    """The truth at ``t_us - latency_us`` into ``out`` (6 values) from a
    :class:`TruthBuffer`'s arrays with ``count`` samples up to ``newest``: linear
    interpolation between the samples around it; the newest sample if it is later than
    them all, the oldest if it is earlier. (Compiled by :mod:`sitl.batch`.)"""
    n = time_us.shape[0]
    target = t_us - latency_us
    later = -1
    for k in range(count):
        i = (newest - k) % n
        if time_us[i] <= target:
            if later < 0:
                for j in range(6):
                    out[j] = pos_vel[i, j]
            else:
                w = (target - time_us[i]) / (time_us[later] - time_us[i])
                for j in range(6):
                    out[j] = pos_vel[i, j] + w * (pos_vel[later, j] - pos_vel[i, j])
            return
        later = i
    i = (newest - count + 1) % n     # all later than the target: the oldest
    for j in range(6):
        out[j] = pos_vel[i, j]


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

    The GNSS latency: the suite keeps a buffer of past truth (:attr:`truth_buffer`).
    Record every sample of the truth with :meth:`record_truth` and take the fixes with
    :meth:`gps_fix`, which reads the buffer at ``t - gps_latency_s`` (linear interpolation;
    before the buffer reaches back that far, its oldest sample). :meth:`gps` is the fix of a
    truth given directly (the caller's own delayed truth, or none).
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
        if on:   # the reading's machine code now, not at a first read in a process's loop
            for ch in self.channels:
                ch.load()
        self._field_enu = ned_to_enu(tuple(float(v) for v in self.earth_field_ned_gauss))
        #: Past truth for the GNSS latency (:meth:`record_truth`).
        self.truth_buffer = TruthBuffer.empty()
        #: The GNSS latency in whole microseconds.
        self.gps_latency_us = round(n.gps_latency_s * 1e6)
        self._truth_out = np.zeros(6)

    @property
    def gps_rate_hz(self) -> float:
        """The receiver's fixes a second [Hz] (the preset's)."""
        return self.noise.gps_rate_hz

    @property
    def gps_latency_s(self) -> float:
        """The age [s] of the truth a fix describes (the preset's)."""
        return self.noise.gps_latency_s

    def reset_truth(self) -> None:
        """Forget the recorded truth (a new session)."""
        self.truth_buffer.ring[1] = 0

    def record_truth(self, t_s: float, pos_enu_m: Sequence[float],
                     vel_enu_m_s: Sequence[float]) -> None:
        """Record the true position [m] and velocity [m/s] (ENU) at ``t_s`` [s] for the
        fixes of :meth:`gps_fix` (times in microseconds; a time before the last forgets the
        buffer)."""
        self.record_truth_us(round(t_s * 1e6), pos_enu_m, vel_enu_m_s)

    def record_truth_us(self, t_us: int, pos: Sequence[float], vel: Sequence[float]) -> None:
        """:meth:`record_truth` at ``t_us`` [us] (the link's time)."""
        b = self.truth_buffer
        newest, count = truth_push(float(t_us), float(pos[0]), float(pos[1]), float(pos[2]),
                                   float(vel[0]), float(vel[1]), float(vel[2]), b.time_us,
                                   b.pos_vel, b.ring)
        b.ring[0], b.ring[1] = newest, count

    def delayed_truth(self, t_s: float) -> tuple[Vec3, Vec3]:
        """The recorded (position [m], velocity [m/s]) at ``t_s - gps_latency_s``."""
        return self.delayed_truth_us(round(t_s * 1e6))

    def delayed_truth_us(self, t_us: int) -> tuple[Vec3, Vec3]:
        """:meth:`delayed_truth` at ``t_us`` [us]."""
        b = self.truth_buffer
        if b.ring[1] == 0:
            raise RuntimeError("no truth recorded: record_truth before the fix")
        out = self._truth_out
        with np.errstate(all="ignore"):   # (a state not finite: the fix's packing fails)
            truth_at(float(t_us), float(self.gps_latency_us), b.time_us, b.pos_vel,
                     int(b.ring[0]), int(b.ring[1]), out)
        v = out.tolist()
        return (v[0], v[1], v[2]), (v[3], v[4], v[5])

    def gps_fix(self, t_s: float, dt_s: float) -> GpsReading:
        """The fix sent at ``t_s`` [s], ``dt_s`` [s] after the last fix: of the truth
        recorded (:meth:`record_truth`, up to ``t_s``) at ``t_s - gps_latency_s``."""
        return self.gps(*self.delayed_truth(t_s), dt_s)

    def gps_fix_us(self, t_us: int, dt_s: float) -> GpsReading:
        """:meth:`gps_fix` at ``t_us`` [us] (the link's time)."""
        return self.gps(*self.delayed_truth_us(t_us), dt_s)

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
        last fix (no latency: the truth given is the fix's; :meth:`gps_fix` delays it)."""
        e, n = self.gps_horizontal.read((pos_enu_m[0], pos_enu_m[1]), dt_s)
        (u,) = self.gps_vertical.read((pos_enu_m[2],), dt_s)
        v = self.gps_velocity.read(vel_enu_m_s, dt_s)
        return GpsReading((e, n, u), v,  # type: ignore[arg-type]
                          self.noise.gps_eph_m, self.noise.gps_epv_m)

    def barometric_altitude_amsl_m(self, pos_enu_m: Sequence[float]) -> float:
        """True altitude [m AMSL] of an inertial position [m]."""
        return self.home[2] + float(pos_enu_m[2])
