"""Sensor streams for the navigation filter's tests: analytic truth trajectories sampled
through the plant's own sensor models (``sitl.sensors``), fed to a
:class:`companion.ekf.NavFilter` as the companion would feed it."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from companion.ekf import EstimatorParams, NavFilter
from sitl.sensors import NoiseSpec, SensorNoise, SensorSuite, specific_force_flu
from tuavdefs.frames import euler_to_quat, quat_conjugate, quat_multiply, quat_normalize

G = 9.80665
IMU_HZ = 250.0


class Truth(NamedTuple):
    """The truth at one time: position [m], velocity [m/s], acceleration [m/s^2] (ENU),
    attitude (body FLU -> ENU), body rates [rad/s] (FLU)."""

    pos: tuple[float, float, float]
    vel: tuple[float, float, float]
    acc: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    rates: tuple[float, float, float]


def static(pos=(2.0, 1.0, 20.0), roll=0.0, pitch=0.0, yaw=0.7) -> Callable[[float], Truth]:
    """A vehicle at rest."""
    q = euler_to_quat(roll, pitch, yaw)
    return lambda t: Truth(pos, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), q, (0.0, 0.0, 0.0))


def yaw_spin(rate_rad_s=0.5, start_s=0.0, pos=(0.0, 0.0, 20.0)) -> Callable[[float], Truth]:
    """At rest in position, level; from ``start_s`` [s] on yawing at a constant rate
    [rad/s]."""
    def at(t: float) -> Truth:
        spinning = t >= start_s
        return Truth(pos, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                     euler_to_quat(0.0, 0.0, rate_rad_s * max(t - start_s, 0.0)),
                     (0.0, 0.0, rate_rad_s if spinning else 0.0))
    return at


def _attitude(acc, yaw: float) -> np.ndarray:
    """The rotation body FLU -> ENU whose z axis is along ``acc + g e3`` (the thrust of a
    coordinated flight) and whose x axis points at ``yaw`` [rad] in the horizontal."""
    b3 = np.array([acc[0], acc[1], acc[2] + G])
    b3 /= np.linalg.norm(b3)
    xc = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    b2 = np.cross(b3, xc)
    b2 /= np.linalg.norm(b2)
    return np.column_stack([np.cross(b2, b3), b2, b3])


def _quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (w >= 0) of a rotation matrix."""
    w = math.sqrt(max(1.0 + R[0, 0] + R[1, 1] + R[2, 2], 1e-12)) / 2.0
    return quat_normalize((w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                           (R[1, 0] - R[0, 1]) / (4 * w)))


def circle(radius_m=10.0, speed_m_s=2.0, height_m=20.0, hover_s=3.0,
           ramp_s=5.0) -> Callable[[float], Truth]:
    """Hover at (radius, 0, height), then a horizontal circle about the origin,
    counter-clockwise, the angular rate rising smoothly (``3u^2 - 2u^3``) over ``ramp_s``
    to ``speed/radius``: analytic position, velocity and acceleration; the attitude from
    the acceleration (coordinated, the nose along the path); the body rates from
    ``[w]x = R' dR/dt``, differentiated centrally (h = 10 us)."""
    W = speed_m_s / radius_m

    def angle(t: float) -> tuple[float, float, float]:
        """theta [rad], its rate [rad/s] and acceleration [rad/s^2] at t."""
        u = (t - hover_s) / ramp_s
        if u <= 0.0:
            return 0.0, 0.0, 0.0
        if u >= 1.0:
            return W * ramp_s / 2 + W * (t - hover_s - ramp_s), W, 0.0
        return (W * ramp_s * (u ** 3 - u ** 4 / 2), W * (3 * u * u - 2 * u ** 3),
                W * (6 * u - 6 * u * u) / ramp_s)

    def kinematics(t: float):
        th, dth, ddth = angle(t)
        c, s = math.cos(th), math.sin(th)
        r = radius_m
        pos = (r * c, r * s, height_m)
        vel = (-r * dth * s, r * dth * c, 0.0)
        acc = (-r * ddth * s - r * dth * dth * c, r * ddth * c - r * dth * dth * s, 0.0)
        return pos, vel, acc, _attitude(acc, th + math.pi / 2)

    def at(t: float) -> Truth:
        pos, vel, acc, R = kinematics(t)
        h = 1e-5
        dR = (kinematics(t + h)[3] - kinematics(t - h)[3]) / (2 * h)
        Wx = R.T @ dR
        rates = (0.5 * (Wx[2, 1] - Wx[1, 2]), 0.5 * (Wx[0, 2] - Wx[2, 0]),
                 0.5 * (Wx[1, 0] - Wx[0, 1]))
        return Truth(pos, vel, acc, _quat(R), rates)
    return at


def rtk_noise(seed: int = 1) -> SensorNoise:
    """Datasheet-class MEMS IMU, calibrated magnetometer, barometer and an RTK receiver
    (2 cm)."""
    return SensorNoise(
        seed=seed,
        accel=NoiseSpec(sigma=0.02, bias_sigma=0.05, bias_walk=5e-4),
        gyro=NoiseSpec(sigma=0.002, bias_sigma=0.003, bias_walk=2e-5),
        mag=NoiseSpec(sigma=0.002, bias_sigma=0.0005),
        baro=NoiseSpec(sigma=0.012, bias_sigma=0.05, bias_walk=0.001),
        gps_horizontal=NoiseSpec(sigma=0.02), gps_vertical=NoiseSpec(sigma=0.03),
        gps_velocity=NoiseSpec(sigma=0.02))


def walk(spec: NoiseSpec) -> float:
    """The random-walk intensity [u/sqrt(s)] a filter takes for a channel's bias: its walk
    and its Gauss-Markov in-run error (whose short-term increments are a walk of
    ``sigma sqrt(2 / tau)``) together."""
    gm = spec.gm_sigma ** 2 * 2.0 / spec.gm_tau_s if spec.gauss_markov else 0.0
    return math.sqrt(spec.bias_walk ** 2 + gm)


def params_for(noise: SensorNoise, **changes) -> EstimatorParams:
    """The filter's parameters for a sensor set as its datasheets give it (the densities
    of the per-sample noise at the IMU rate)."""
    dt = 1.0 / IMU_HZ
    hpa_m = 8.4          # metres per hPa near sea level
    kw = dict(gyro_noise_rad_s_sqrt_hz=noise.gyro.sigma * math.sqrt(dt),
              accel_noise_m_s2_sqrt_hz=noise.accel.sigma * math.sqrt(dt),
              gyro_bias_walk_rad_s_sqrt_s=max(walk(noise.gyro), 1e-6),
              accel_bias_walk_m_s2_sqrt_s=max(walk(noise.accel), 1e-5),
              baro_offset_walk_m_sqrt_s=max(walk(noise.baro) * hpa_m, 1e-3),
              baro_noise_m=noise.baro.sigma * hpa_m,
              gnss_vel_noise_m_s=noise.gps_velocity.stationary_sigma,
              # the field's noise over its horizontal part (0.2 G), a margin for the
              # calibration's residual
              mag_yaw_noise_rad=max(1.5 * noise.mag.sigma / 0.2, 0.005),
              mag_noise_gauss=max(2.0 * noise.mag.sigma, 0.005),
              mag_bias_sigma_gauss=max(noise.mag.bias_sigma, 1e-4) * 2.0,
              gyro_bias_sigma_rad_s=max(noise.gyro.bias_sigma, 1e-4) * 2.0,
              accel_bias_sigma_m_s2=max(noise.accel.bias_sigma, 1e-3) * 2.0)
    kw.update(changes)
    return EstimatorParams(**kw)


@dataclass
class Run:
    """A run's series, one row per IMU sample after alignment."""

    t: list = field(default_factory=list)
    pos_err: list = field(default_factory=list)
    vel_err: list = field(default_factory=list)
    att_err_rad: list = field(default_factory=list)
    nees: list = field(default_factory=list)
    gnss_accepted: list = field(default_factory=list)
    filt: NavFilter | None = None
    suite: SensorSuite | None = None


def att_error_rad(q_true, q_est) -> float:
    """The angle of the rotation between two attitudes [rad]."""
    d = quat_multiply(quat_conjugate(q_true), q_est)
    return 2.0 * math.atan2(math.sqrt(d[1] ** 2 + d[2] ** 2 + d[3] ** 2), abs(d[0]))


def simulate(truth: Callable[[float], Truth], noise: SensorNoise, duration_s: float,
             params: EstimatorParams | None = None, gnss_hz: float = 10.0,
             gnss_delay_s: float = 0.1, gnss_error: Callable[[float], tuple] | None = None,
             eph_m: float | None = None, epv_m: float | None = None,
             t_align_s: float = 0.0,
             tether_fix: Callable[[float, tuple], tuple] | None = None) -> Run:
    """Sample ``truth`` for ``duration_s`` [s] through the plant's sensors (IMU, baro,
    mag at 250 Hz; GNSS at ``gnss_hz``, each fix of the truth ``gnss_delay_s`` old when
    it arrives, plus ``gnss_error(t)`` [m] if given) and run a filter on them; with
    ``tether_fix(t, true_pos)`` -> (position [m], covariance [m^2]) also a tether fix at
    10 Hz, taken at ``t``, arriving 20 ms later."""
    suite = SensorSuite(noise=noise)
    params = params or params_for(noise, gnss_delay_s=gnss_delay_s)
    field_enu = suite.earth_field_enu_gauss
    filt = NavFilter(params, G, field_enu)
    run = Run(filt=filt, suite=suite)
    dt = 1.0 / IMU_HZ
    n = int(round(duration_s * IMU_HZ))
    every = int(round(IMU_HZ / gnss_hz))
    home_alt = suite.home[2]
    for k in range(n + 1):
        t = k * dt
        tr = truth(t)
        f = specific_force_flu(tr.acc, tr.quat, G)
        imu = suite.imu(f, tr.rates, tr.quat, dt)
        filt.predict(t, imu.gyro_flu_rad_s, imu.accel_flu_m_s2)
        filt.fuse_baro(t, suite.baro(home_alt + tr.pos[2], dt).pressure_alt_m)
        filt.fuse_mag(t, imu.mag_flu_gauss)
        if k % every == 0 and t >= gnss_delay_s:
            old = truth(t - gnss_delay_s)
            fix = suite.gps(old.pos, old.vel, 1.0 / gnss_hz)
            pos = fix.position_enu_m
            if gnss_error is not None:
                e = gnss_error(t - gnss_delay_s)
                pos = (pos[0] + e[0], pos[1] + e[1], pos[2] + e[2])
            acc = filt.fuse_gnss(t, pos, fix.velocity_enu_m_s,
                                 fix.eph_m if eph_m is None else eph_m,
                                 fix.epv_m if epv_m is None else epv_m)
            if filt.aligned:
                run.gnss_accepted.append((t, acc))
        if tether_fix is not None and k % 25 == 0 and t >= 0.02:
            pos, cov = tether_fix(t - 0.02, truth(t - 0.02).pos)
            filt.fuse_tether(t, t - 0.02, pos, cov)
        if not filt.aligned:
            continue
        p, v, q, _ = filt.state()
        ep = np.subtract(p, tr.pos)
        ev = np.subtract(v, tr.vel)
        run.t.append(t)
        run.pos_err.append(ep)
        run.vel_err.append(ev)
        run.att_err_rad.append(att_error_rad(tr.quat, q))
        e = np.concatenate([ep, ev])
        P = filt.covariance[0:6, 0:6]
        run.nees.append(float(e @ np.linalg.solve(P, e)))
    return run


def gauss_markov(sigma_m: float, tau_s: float, seed: int, dims: int = 3,
                 vertical_sigma_m: float | None = None) -> Callable[[float], tuple]:
    """A first-order Gauss-Markov wander [m] (per axis, stationary ``sigma_m``, time
    constant ``tau_s``), as a function of time sampled in increasing order."""
    rng = np.random.default_rng(seed)
    sig = np.array([sigma_m, sigma_m, vertical_sigma_m or sigma_m])
    state = {"t": None, "e": rng.normal(0.0, 1.0, 3) * sig}

    def at(t: float) -> tuple:
        if state["t"] is not None:
            a = math.exp(-(t - state["t"]) / tau_s)
            state["e"] = a * state["e"] + math.sqrt(1 - a * a) * sig * rng.normal(0, 1, 3)
        state["t"] = t
        return tuple(state["e"])
    return at
