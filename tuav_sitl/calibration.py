"""The accelerometer calibration a user runs on the vehicle before flying it, run on the
simulated vehicle: what the companion's ``accel_offsets_m_s2`` (ArduPilot's
``INS_ACCOFFS_X/Y/Z``) would hold.

As ArduPilot's six-position calibration: the vehicle is set down still on each of its six
faces in turn (level, upside down, nose up and down, on each side; each held within a few
degrees of true by hand), the accelerometer averaged on each, and the offsets fitted so
that every face's mean less them has gravity's magnitude (a sphere of radius g through the
six means, by Gauss-Newton from the mid-points of opposite faces): the faces' tilts do not
enter. Only the plant's sensor
model's readings are used, as only the sensor's readings are in the field: the offsets
carry the calibration's own noise, and the part's in-run (thermal) drift after it remains.
The calibration and the flight share the part's turn-on offset (one power cycle); the
part's turn-on-to-turn-on repeatability between a calibration day and a flight is not
modelled.
"""

from __future__ import annotations

import functools

import numpy as np

from sitl.sensors import IMU_RATE_HZ, SensorNoise, SensorSuite, specific_force_flu
from tuavdefs.frames import Vec3, euler_to_quat

#: The six faces: (roll, pitch) [rad] putting body +z, -z, +x, -x, +y, -y up.
_FACES = ((0.0, 0.0), (np.pi, 0.0), (0.0, -np.pi / 2), (0.0, np.pi / 2),
          (np.pi / 2, 0.0), (-np.pi / 2, 0.0))
#: What the filter may then assume of the offsets left [m/s^2] (1 sigma per axis): about
#: 2 mg, the part's thermal drift over a flight and the calibration's own error with a margin.
CALIBRATED_ACCEL_BIAS_SIGMA_M_S2 = 0.02
#: How far from true the user holds each face [rad] (1 sigma per axis).
FACE_TILT_SIGMA_RAD = np.radians(2.0)


@functools.lru_cache(maxsize=32)
def accel_calibration(noise: SensorNoise, home: tuple[float, float, float],
                      gravity_m_s2: float, seconds_per_face: float = 2.0,
                      seed: int = 0) -> Vec3:
    """The accelerometer offsets [m/s^2] (body FLU) a six-position calibration of the
    sensors ``noise`` (the plant's part, with its seed) finds, ``seconds_per_face`` [s] on
    each face, the faces held with random tilts (``seed``). A pure function of its
    arguments (the sensors' own seeded streams), remembered: the same part calibrated again
    in one process (repeated runs of a scenario) reads the same offsets."""
    suite = SensorSuite(noise, home)
    rng = np.random.default_rng(seed)
    dt = 1.0 / IMU_RATE_HZ
    n = max(int(round(seconds_per_face * IMU_RATE_HZ)), 1)
    means = []
    for roll, pitch in _FACES:
        dr, dp = rng.normal(0.0, FACE_TILT_SIGMA_RAD, 2)
        q = euler_to_quat(roll + dr, pitch + dp, rng.uniform(-np.pi, np.pi))
        f = specific_force_flu((0.0, 0.0, 0.0), q, gravity_m_s2)
        acc = np.zeros(3)
        for _ in range(n):
            acc += suite.imu(f, (0.0, 0.0, 0.0), q, dt).accel_flu_m_s2
        means.append(acc / n)
    m = np.array(means)
    # axis z up and down on faces 0, 1; x on 2, 3; y on 4, 5: the mid-points to start from
    b = np.array([0.5 * (m[2, 0] + m[3, 0]), 0.5 * (m[4, 1] + m[5, 1]),
                  0.5 * (m[0, 2] + m[1, 2])])
    for _ in range(10):
        d = m - b
        r = np.linalg.norm(d, axis=1)
        # |m_i - b| = g: d|m_i - b|/db = -(m_i - b)/|m_i - b|
        step, *_ = np.linalg.lstsq(-d / r[:, None], gravity_m_s2 - r, rcond=None)
        b += step
        if not np.abs(step).max() > 1e-9:
            break
    return (float(b[0]), float(b[1]), float(b[2]))


__all__ = ["accel_calibration", "CALIBRATED_ACCEL_BIAS_SIGMA_M_S2", "FACE_TILT_SIGMA_RAD"]
