"""The plant's sensor models: truth readings with the noise off, known attitudes, the ISA
barometer, and noise statistics against the configured sigmas."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sitl.plant import Plant, initial_state
from sitl.sensors import (
    GNSS_MODELS,
    ICM42688P_ACCEL,
    ICM42688P_GYRO,
    IMU_RATE_HZ,
    MS5611_BARO,
    RM3100_MAG,
    GnssPreset,
    NoiseSpec,
    NoisyChannel,
    SensorNoise,
    SensorSuite,
    isa_altitude_m,
    isa_density_kg_m3,
    isa_pressure_hpa,
    isa_temperature_k,
    plant_acceleration_enu,
    plant_specific_force_flu,
    specific_force_flu,
)
from sitl.trim import hover_trim
from tuavdefs import frames as fr
from tuavdefs import simlink as sl
from tuavdefs.params import SystemParams, TetherParams

G = 9.81
OFF = SensorNoise.off()
#: Every channel noisy, no bias walk (so the bias is constant while the statistics are taken).
STEADY = SensorNoise(seed=3, accel=NoiseSpec(0.05, 0.04), gyro=NoiseSpec(0.003, 0.002),
                     mag=NoiseSpec(0.004, 0.01), baro=NoiseSpec(0.02, 0.1),
                     gps_horizontal=NoiseSpec(0.4), gps_vertical=NoiseSpec(0.7, 0.2),
                     gps_velocity=NoiseSpec(0.06))
angles = st.floats(-math.pi, math.pi, allow_nan=False)
pitches = st.floats(-1.5, 1.5, allow_nan=False)


# ----------------------------------------------------------------- barometer
def test_isa():
    assert isa_pressure_hpa(0.0) == pytest.approx(1013.25, abs=1e-9)
    assert isa_pressure_hpa(1000.0) == pytest.approx(898.75, abs=0.01)
    # altitudes are geopotential: 540.20 hPa at 5000 m (540.48 at 5000 m geometric)
    assert isa_pressure_hpa(5000.0) == pytest.approx(540.20, abs=0.01)
    assert isa_temperature_k(0.0) - 273.15 == pytest.approx(15.0)
    assert isa_temperature_k(1000.0) - 273.15 == pytest.approx(8.5)
    assert isa_density_kg_m3(0.0) == pytest.approx(1.225, abs=1e-3)
    for h in (-200.0, 0.0, 488.0, 3000.0, 10000.0):
        assert isa_altitude_m(isa_pressure_hpa(h)) == pytest.approx(h, abs=1e-6)


def test_barometer_reads_the_isa_at_the_altitude():
    suite = SensorSuite(OFF, home=(47.0, 8.0, 1000.0))
    b = suite.baro(1000.0, 0.004)
    assert b.pressure_hpa == pytest.approx(898.75, abs=0.01)
    assert b.pressure_alt_m == pytest.approx(1000.0, abs=1e-6)
    assert b.temperature_c == pytest.approx(8.5)
    assert suite.barometric_altitude_amsl_m((3.0, 4.0, 20.0)) == 1020.0


# ----------------------------------------------------------------- accelerometer
def test_resting_level_reads_plus_g_up():
    params = SystemParams()
    plant = Plant(params)                 # on its gear, level, rotors stopped
    a = plant_acceleration_enu(plant)
    assert a == (0.0, 0.0, 0.0)
    f = plant_specific_force_flu(plant)
    assert f == pytest.approx((0.0, 0.0, G), abs=1e-12)
    imu = SensorSuite(OFF).imu(f, (0.0, 0.0, 0.0), plant.quaternion, 0.004)
    assert imu.accel_flu_m_s2 == f        # noise off: exactly the truth
    fields = sl.hil_sensor_fields(0, imu.accel_flu_m_s2, imu.gyro_flu_rad_s,
                                  imu.mag_flu_gauss, 1013.25, 0.0, 15.0)
    assert fields["zacc"] == pytest.approx(-G, abs=1e-12)       # FRD: -g
    assert fields["xacc"] == pytest.approx(0.0, abs=1e-12)


def test_free_fall_reads_zero():
    # (the catenary: a lumped line this light is refused)
    feather = TetherParams(model="catenary", linear_density_kg_m=1e-12, total_length_m=500.0)
    params = SystemParams().replace(tether=feather)
    x = initial_state(Plant(params).model, position_m=(0.0, 0.0, 50.0), tether_length_m=80.0,
                      euler_rad=(0.3, -0.2, 1.0))
    plant = Plant(params, state=x)
    assert plant_acceleration_enu(plant)[2] == pytest.approx(-G, abs=1e-9)
    assert plant_specific_force_flu(plant) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)


@given(angles, pitches, angles)
def test_specific_force_at_rest_is_gravity_up_in_the_body(roll, pitch, yaw):
    q = fr.euler_to_quat(roll, pitch, yaw)
    f = specific_force_flu((0.0, 0.0, 0.0), q, G)
    # the world's up axis seen in the body: third row of R
    r = fr.quat_to_matrix(q)
    assert f == pytest.approx((G * r[2][0], G * r[2][1], G * r[2][2]), abs=1e-9)


def test_known_roll():
    roll = 0.4
    f = specific_force_flu((0.0, 0.0, 0.0), fr.euler_to_quat(roll, 0.0, 0.0), G)
    assert f == pytest.approx((0.0, G * math.sin(roll), G * math.cos(roll)), abs=1e-12)
    # accelerating 2 m/s^2 east while level and nose east: the accelerometer feels it forward
    f = specific_force_flu((2.0, 0.0, 0.0), fr.euler_to_quat(0.0, 0.0, 0.0), G)
    assert f == pytest.approx((2.0, 0.0, G), abs=1e-12)


def test_hover_reading_and_no_side_effects():
    # the trim is the catenary's equilibrium (the lumped line pulls 0.6 % harder there)
    params = SystemParams().replace(tether=TetherParams(model="catenary"))
    x, _ = hover_trim(params, (12.0, 5.0, 20.0), 30.0)
    plant = Plant(params, state=x)
    x_before, warm_before = plant.x.copy(), plant.model.warm.copy()
    f = plant_specific_force_flu(plant)
    r = fr.quat_to_matrix(plant.quaternion)
    assert f == pytest.approx((G * r[2][0], G * r[2][1], G * r[2][2]), abs=1e-8)
    assert r[2][2] < 0.99999                      # tilted against the tether's pull
    assert np.array_equal(plant.x, x_before)
    assert np.array_equal(plant.model.warm, warm_before)


# ----------------------------------------------------------------- magnetometer
@pytest.mark.parametrize("euler, expected_flu", [
    ((0.0, 0.0, 0.0), (0.0, 0.2, -0.45)),             # nose east: north is to the left
    ((0.0, 0.0, math.pi / 2), (0.2, 0.0, -0.45)),     # nose north
    ((math.pi, 0.0, math.pi / 2), (0.2, 0.0, 0.45)),  # nose north, upside down
    ((0.0, 0.0, -math.pi / 2), (-0.2, 0.0, -0.45)),   # nose south
])
def test_magnetometer_known_attitudes(euler, expected_flu):
    suite = SensorSuite(OFF)
    imu = suite.imu((0.0, 0.0, G), (0.0, 0.0, 0.0), fr.euler_to_quat(*euler), 0.004)
    assert imu.mag_flu_gauss == pytest.approx(expected_flu, abs=1e-12)


def test_magnetometer_level_nose_north_reads_ned_field_in_frd():
    suite = SensorSuite(OFF, earth_field_ned_gauss=(0.21, 0.02, 0.43))
    imu = suite.imu((0.0, 0.0, G), (0.0, 0.0, 0.0), fr.euler_to_quat(0, 0, math.pi / 2), 0.0)
    f = sl.hil_sensor_fields(0, imu.accel_flu_m_s2, imu.gyro_flu_rad_s, imu.mag_flu_gauss,
                             1013.25, 0.0, 15.0)
    assert (f["xmag"], f["ymag"], f["zmag"]) == pytest.approx((0.21, 0.02, 0.43), abs=1e-6)


@given(angles, pitches, angles)
def test_magnetometer_any_attitude(roll, pitch, yaw):
    q = fr.euler_to_quat(roll, pitch, yaw)
    m = SensorSuite(OFF).magnetic_field_flu(q)
    # rotating the body reading back into the world gives the ENU field
    assert fr.quat_rotate(q, m) == pytest.approx((0.0, 0.2, -0.45), abs=1e-12)


# ----------------------------------------------------------------- GPS
def test_gps_without_noise_is_the_truth():
    suite = SensorSuite(OFF)
    fix = suite.gps((12.5, -3.25, 20.0), (0.5, 0.25, -0.125), 0.1)
    assert fix.position_enu_m == (12.5, -3.25, 20.0)
    assert fix.velocity_enu_m_s == (0.5, 0.25, -0.125)
    # the accuracies the (RTK) receiver reports: its channels' 1 sigma, noise off or on
    assert (fix.eph_m, fix.epv_m) == (math.hypot(0.004, 0.01), math.hypot(0.006, 0.02))


# ----------------------------------------------------------------- noise
def test_noise_off_is_exact_even_with_sigmas_configured():
    noisy_specs = SensorNoise(enabled=False, accel=NoiseSpec(1.0, 1.0, 1.0))
    suite = SensorSuite(noisy_specs)
    for _ in range(3):
        imu = suite.imu((0.1, 0.2, 9.7), (0.01, -0.02, 0.03), fr.euler_to_quat(0.1, 0, 0), 0.1)
        assert imu.accel_flu_m_s2 == (0.1, 0.2, 9.7)
        assert imu.gyro_flu_rad_s == (0.01, -0.02, 0.03)
    assert np.array_equal(suite.accel.bias, np.zeros(3))


def _samples(suite: SensorSuite, n: int):
    q = fr.euler_to_quat(0.1, -0.05, 0.7)
    truth_f, truth_w = (0.3, -0.2, 9.8), (0.02, 0.01, -0.03)
    acc, gyr, mag, baro, gpos, gvel = [], [], [], [], [], []
    for _ in range(n):
        imu = suite.imu(truth_f, truth_w, q, 0.004)
        acc.append(np.subtract(imu.accel_flu_m_s2, truth_f))
        gyr.append(np.subtract(imu.gyro_flu_rad_s, truth_w))
        mag.append(np.subtract(imu.mag_flu_gauss, suite.magnetic_field_flu(q)))
        baro.append(suite.baro(600.0, 0.004).pressure_hpa - isa_pressure_hpa(600.0))
        fix = suite.gps((10.0, 20.0, 30.0), (1.0, -1.0, 0.5), 0.1)
        gpos.append(np.subtract(fix.position_enu_m, (10.0, 20.0, 30.0)))
        gvel.append(np.subtract(fix.velocity_enu_m_s, (1.0, -1.0, 0.5)))
    return [np.array(v) for v in (acc, gyr, mag, baro, gpos, gvel)]


def _check(err: np.ndarray, bias: np.ndarray, sigma: float):
    n = err.shape[0]
    mean = err.mean(axis=0)
    # the mean error is the bias, to within 5 standard errors
    assert np.all(np.abs(mean - bias) < 5 * sigma / math.sqrt(n) + 1e-12), (mean, bias)
    # the scatter is the white noise's sigma: 5 % (the estimate's own error is ~0.7 %)
    std = err.std(axis=0, ddof=1)
    assert np.all(np.abs(std / sigma - 1.0) < 0.05), (std, sigma)


def test_noise_statistics_match_the_sigmas():
    suite = SensorSuite(STEADY)
    acc, gyr, mag, baro, gpos, gvel = _samples(suite, 10000)
    _check(acc, suite.accel.bias, STEADY.accel.sigma)
    _check(gyr, suite.gyro.bias, STEADY.gyro.sigma)
    _check(mag, suite.mag.bias, STEADY.mag.sigma)
    _check(baro[:, None], suite.baro_channel.bias, STEADY.baro.sigma)
    _check(gpos[:, :2], suite.gps_horizontal.bias, STEADY.gps_horizontal.sigma)
    _check(gpos[:, 2:], suite.gps_vertical.bias, STEADY.gps_vertical.sigma)
    _check(gvel, suite.gps_velocity.bias, STEADY.gps_velocity.sigma)
    # biases were drawn where configured, and are absent where not
    assert np.all(suite.accel.bias != 0) and np.all(suite.gps_horizontal.bias == 0)


def test_turn_on_biases_follow_their_sigma():
    biases = np.array([SensorSuite(SensorNoise(seed=s, accel=NoiseSpec(0.05, 0.04)))
                       .accel.bias for s in range(1500)]).ravel()
    assert abs(biases.mean()) < 5 * 0.04 / math.sqrt(biases.size)
    assert biases.std(ddof=1) / 0.04 == pytest.approx(1.0, abs=0.05)


def test_bias_random_walk_increments():
    walk, dt = 0.01, 0.004
    suite = SensorSuite(SensorNoise(seed=1, gyro=NoiseSpec(0.0, 0.0, walk)))
    b = []
    for _ in range(8000):
        suite.imu((0, 0, G), (0, 0, 0), (1.0, 0.0, 0.0, 0.0), dt)
        b.append(suite.gyro.bias.copy())
    steps = np.diff(np.array(b), axis=0)
    assert steps.std(ddof=1) / (walk * math.sqrt(dt)) == pytest.approx(1.0, abs=0.05)
    assert abs(steps.mean()) < 5 * walk * math.sqrt(dt) / math.sqrt(steps.size)


def test_seeded_streams():
    a, b = SensorSuite(SensorNoise(seed=5)), SensorSuite(SensorNoise(seed=5))
    c = SensorSuite(SensorNoise(seed=6))
    ra, rb, rc = (_samples(s, 20) for s in (a, b, c))
    assert all(np.array_equal(x, y) for x, y in zip(ra, rb, strict=True))
    assert not np.array_equal(ra[0], rc[0])
    # each sensor has its own stream: sampling the GPS less often leaves the IMU unchanged
    d = SensorSuite(SensorNoise(seed=5))
    q = fr.euler_to_quat(0.1, -0.05, 0.7)
    imu_d = [d.imu((0.3, -0.2, 9.8), (0.02, 0.01, -0.03), q, 0.004) for _ in range(20)]
    assert np.allclose(np.subtract([i.accel_flu_m_s2 for i in imu_d], (0.3, -0.2, 9.8)), ra[0])


def test_noise_spec_validation():
    with pytest.raises(ValueError, match="sigma"):
        NoiseSpec(sigma=-1.0)
    with pytest.raises(ValueError, match="bias_walk"):
        NoiseSpec(bias_walk=float("nan"))
    with pytest.raises(ValueError, match="gm_tau_s"):
        NoiseSpec(gm_sigma=0.1)              # a Gauss-Markov error needs its time
    with pytest.raises(ValueError, match="gm_sigma"):
        NoiseSpec(gm_sigma=-0.1, gm_tau_s=1.0)
    assert NoiseSpec() == NoiseSpec(0.0, 0.0, 0.0)
    for kw, field in (({"gps_rate_hz": 0.0}, "gps_rate_hz"), ({"gps_rate_hz": 3.0},
                                                               "gps_rate_hz"),
                      ({"gps_latency_s": -0.01}, "gps_latency_s"),
                      ({"gps_latency_s": 2.0}, "gps_latency_s"), ({"seed": -1}, "seed"),
                      ({"accel": 0.1}, "accel")):
        with pytest.raises(ValueError, match=field):
            SensorNoise(**kw)
    with pytest.raises(ValueError, match="gnss"):
        SensorNoise.preset("dgps")


# ----------------------------------------------------------------- the datasheet parts
def _static_errors(spec: NoiseSpec, n: int, seed: int, dt_s: float = 1.0 / IMU_RATE_HZ):
    """n readings of a zero truth by a 3-axis channel of ``spec``: their errors."""
    ch = NoisyChannel(spec, 3, np.random.default_rng(seed))
    return np.array([ch.read((0.0, 0.0, 0.0), dt_s) for _ in range(n)])


@pytest.mark.parametrize("spec, density, unit", [
    (ICM42688P_GYRO, 0.0028, math.pi / 180.0),       # deg/s/sqrt(Hz) -> rad/s
    (ICM42688P_ACCEL, 70e-6, 9.80665),               # g/sqrt(Hz) -> m/s^2
])
def test_a_static_imus_white_noise_is_the_datasheet_density(spec, density, unit):
    """The sample-to-sample scatter of a static IMU at 250 Hz is the datasheet's noise
    density x sqrt(rate): the differences of consecutive samples remove the slow biases
    (the Allan deviation at one sample, sqrt(2) sigma per difference)."""
    err = _static_errors(spec, 20000, seed=4)
    sigma = density * unit * math.sqrt(IMU_RATE_HZ)
    assert spec.sigma == pytest.approx(sigma, rel=1e-12)
    d = np.diff(err, axis=0) / math.sqrt(2.0)
    assert np.all(np.abs(d.std(axis=0, ddof=1) / sigma - 1.0) < 0.03)
    # Allan deviation at tau0 = 1/250 s: the same sigma (white noise dominates there)
    adev = np.sqrt(0.5 * np.mean(np.diff(err, axis=0) ** 2, axis=0))
    assert np.all(np.abs(adev / sigma - 1.0) < 0.03)


def test_the_datasheet_presets():
    deg = math.pi / 180.0
    assert ICM42688P_GYRO.sigma == pytest.approx(7.727e-4, rel=1e-3)        # rad/s
    assert ICM42688P_GYRO.bias_sigma == pytest.approx(0.5 * deg)
    assert ICM42688P_ACCEL.sigma == pytest.approx(0.010854, rel=1e-3)       # m/s^2
    assert ICM42688P_ACCEL.bias_sigma == pytest.approx(0.02 * 9.80665)
    assert MS5611_BARO.sigma == 0.012 and MS5611_BARO.bias_sigma == 1.5     # hPa
    assert RM3100_MAG.sigma == pytest.approx(1.5e-4)                        # 15 nT in G
    n = SensorNoise()
    assert (n.accel, n.gyro, n.mag, n.baro) == (ICM42688P_ACCEL, ICM42688P_GYRO, RM3100_MAG,
                                                MS5611_BARO)


# ----------------------------------------------------------------- Gauss-Markov
@pytest.mark.parametrize("gm_sigma, tau_s, dt_s", [(0.8, 8.0, 0.2), (0.01, 10.0, 0.1)])
def test_the_gauss_markov_channel_has_its_variance_and_correlation_time(gm_sigma, tau_s,
                                                                        dt_s):
    """Seeded: the stationary sigma, and the autocorrelation exp(-lag/tau) at lags of tau/2,
    tau and 2 tau, and the lag where it falls to 1/e, over 100 channels of 50 tau each
    (5000 correlation times: the estimates' standard errors are about 0.02)."""
    spec = NoiseSpec(gm_sigma=gm_sigma, gm_tau_s=tau_s)
    n_steps, n_chan = int(50 * tau_s / dt_s), 100
    x = np.empty((n_chan, n_steps))
    for c in range(n_chan):
        ch = NoisyChannel(spec, 1, np.random.default_rng(1000 + c))
        x[c] = [ch.read((0.0,), dt_s)[0] for _ in range(n_steps)]
    assert x.std() / gm_sigma == pytest.approx(1.0, abs=0.04)
    # the mean's standard error: sigma sqrt(2 tau / T), T the 5000 tau in all
    assert abs(x.mean()) < 5 * gm_sigma * math.sqrt(2.0 / 5000)

    def acf(k: int) -> float:
        return float(np.mean(x[:, :n_steps - k] * x[:, k:]) / gm_sigma ** 2)

    for lag_tau in (0.5, 1.0, 2.0):
        k = round(lag_tau * tau_s / dt_s)
        assert acf(k) == pytest.approx(math.exp(-lag_tau), abs=0.06), lag_tau
    # the correlation time: the first lag where the autocorrelation falls below 1/e
    k = next(k for k in range(1, n_steps) if acf(k) < math.exp(-1.0) * acf(0))
    assert k * dt_s == pytest.approx(tau_s, rel=0.1)


def test_a_gauss_markov_step_is_exact_for_any_interval():
    """One step of dt and two of dt/2 have the same statistics: the one-step variance
    (1 - exp(-2 dt/tau)) sigma^2 conditional on the start."""
    spec = NoiseSpec(gm_sigma=1.0, gm_tau_s=5.0)
    dt = 0.5
    starts, ends = [], []
    for s in range(4000):
        ch = NoisyChannel(spec, 1, np.random.default_rng(s))
        starts.append(float(ch.gauss_markov_error[0]))
        ends.append(ch.read((0.0,), dt)[0])
    resid = np.array(ends) - math.exp(-dt / 5.0) * np.array(starts)
    assert resid.std(ddof=1) == pytest.approx(math.sqrt(1 - math.exp(-2 * dt / 5.0)),
                                              rel=0.04)


# ----------------------------------------------------------------- GNSS presets, latency
def test_the_gnss_presets():
    rtk, gnss = SensorNoise.preset(GnssPreset.RTK, seed=3), SensorNoise.preset("gnss")
    assert SensorNoise() == SensorNoise.preset() == SensorNoise.preset("rtk")   # default
    assert rtk.seed == 3
    assert (rtk.gps_rate_hz, rtk.gps_latency_s) == (10.0, 0.05)
    assert (gnss.gps_rate_hz, gnss.gps_latency_s) == (5.0, 0.1)
    # the accuracies: RTK about 1 cm horizontally, 2 cm vertically, 2 mm/s; standalone
    # about 0.8 m and 1 m, wandering over seconds; 0.05 m/s
    assert 0.01 <= rtk.gps_eph_m <= 0.02 and 0.02 <= rtk.gps_epv_m <= 0.03
    assert rtk.gps_velocity.sigma == 0.002 and rtk.gps_velocity_accuracy_m_s < 0.003
    assert 0.5 <= gnss.gps_eph_m <= 1.0 and 0.9 <= gnss.gps_epv_m <= 1.2
    assert 5.0 <= gnss.gps_horizontal.gm_tau_s <= 10.0
    assert gnss.gps_velocity.sigma == 0.05
    suite = SensorSuite(gnss)
    assert (suite.gps_rate_hz, suite.gps_latency_s, suite.gps_latency_us) == (5.0, 0.1,
                                                                               100000)
    off = SensorNoise.off("gnss")
    assert not off.enabled and off.gps_latency_s == 0.0 and off.gps_rate_hz == 5.0
    assert set(GNSS_MODELS) == set(GnssPreset)


def test_a_fix_is_the_truth_latency_earlier():
    """Noise off, latency on: the fix sent at t is the truth recorded at t - latency
    (exactly, on a recorded sample; interpolated linearly between two); before the buffer
    reaches back that far, the oldest sample; a new session forgets the buffer."""
    noise = SensorNoise(enabled=False, gps_latency_s=0.05)
    suite = SensorSuite(noise)

    def truth(t_s):
        return (3.0 * t_s, -2.0 * t_s + 1.0, 10.0 + t_s ** 2), (3.0, -2.0, 2 * t_s)

    recorded = []
    for k in range(60):                        # recorded every 10 ms
        t = k * 0.01
        recorded.append(truth(t))
        suite.record_truth(t, *recorded[-1])
        fix = suite.gps_fix(t, 0.1)
        # 5 samples earlier, exactly (the first 5: the oldest, the first sample)
        assert (fix.position_enu_m, fix.velocity_enu_m_s) == recorded[max(k - 5, 0)], k
    # between samples: linear interpolation (exact for the linear east and north)
    t = 0.6
    suite.record_truth(t, *truth(t))
    suite.record_truth(0.612, *truth(0.612))
    fix = suite.gps_fix(0.612, 0.1)   # the truth at 0.562: between 0.56 and 0.57
    assert fix.position_enu_m[:2] == pytest.approx(truth(0.562)[0][:2], abs=1e-12)
    assert fix.position_enu_m[2] == pytest.approx(truth(0.562)[0][2], abs=1e-4)
    suite.reset_truth()
    suite.record_truth(5.0, *truth(5.0))
    assert suite.gps_fix(5.0, 0.1).position_enu_m == truth(5.0)[0]
    with pytest.raises(RuntimeError):
        SensorSuite(noise).gps_fix(0.0, 0.1)   # nothing recorded


class _Sink:
    """A connected socket's stand-in: keeps what is sent."""

    def __init__(self, sent: list[bytes]) -> None:
        self.sent = sent

    def sendall(self, data: bytes) -> None:
        self.sent.append(bytes(data))


def test_the_links_fixes_are_the_truth_latency_earlier():
    """Over the simulator link (noise off, the standalone receiver's 100 ms and 5 Hz): the
    HIL_GPS sent at t carries the truth of the state sent 100 ms (25 periods) earlier, as
    the interpreted and the compiled batch both build it."""
    from sitl.batch import batch_kernel
    from sitl.simlink_server import SimLinkServer

    noise = SensorNoise(enabled=False, gps_latency_s=0.1, gps_rate_hz=5.0)
    x0, _ = hover_trim(SystemParams(), (2.0, 0.0, 10.0), 12.0)
    for compiled in (True, False):
        server = SimLinkServer(Plant(SystemParams(), state=x0), port=0, sensor_noise=noise)
        if not compiled:   # the batch's law, its Python source
            server.batches.packer._kernel = getattr(batch_kernel, "py_func", batch_kernel)
        assert server.gps_period_us == 200000
        sent: list[bytes] = []
        server._sock = _Sink(sent)  # type: ignore[assignment]
        hm = sl.home_map(server.home)
        positions = {}
        try:
            for k in range(120):
                x = x0.copy()
                x[0] += 4.0 * k * 0.004      # moving east at 4 m/s
                x[3] = 4.0
                server.plant.x = x
                positions[k] = (float(x[0]), float(x[1]), float(x[2]))
                server.send_batch(k * 4000)
        finally:
            server._sock = None
            server.close()
        fixes = []
        for k, data in enumerate(sent):
            for mid, values in sl.FrameParser().feed_link(data):
                if mid == sl.MSG_HIL_GPS:
                    fixes.append((k, sl.gps_from_wire(values, hm)))
        assert [k for k, _ in fixes] == [0, 50, 100]
        for k, (pos, vel, _, _) in fixes:
            want = positions[max(k - 25, 0)]
            assert pos == pytest.approx(want, abs=0.012)   # (1e-7 deg, 1 mm on the wire)
            assert vel[0] == pytest.approx(4.0, abs=0.01)
        assert fixes[1][1][0][0] < positions[50][0] - 0.39   # 0.4 m behind the truth now


def test_the_plant_cli_chooses_the_receiver():
    from sitl.__main__ import build_parser

    args = build_parser().parse_args(["--gnss", "gnss", "--sensor-seed", "4"])
    assert (args.gnss, args.sensor_seed) == ("gnss", 4)
    assert SensorNoise.preset(args.gnss, args.sensor_seed) == SensorNoise.preset(
        GnssPreset.GNSS, seed=4)
    defaults = build_parser().parse_args([])
    assert (defaults.gnss, defaults.sensor_seed, defaults.no_noise) == ("rtk", 0, False)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--gnss", "dgps"])
