"""What the simulator link would deliver to the companion, offline: the plant's sensors.

The offline runner has no simulator link; :class:`SensorFeed` reads the plant's sensor
models (:class:`sitl.sensors.SensorSuite`, the same models and the same order of readings
as the plant process's batch: the truth recorded, the GNSS fix when due, then the IMU,
magnetometer and barometer) at every control period and hands them to the companion in the
forms its simulator-link client decodes (:class:`companion.simlink_client.ImuSample`,
:class:`companion.simlink_client.GpsFix`), with HIL_GPS's resolution of position (1e-7 deg,
1 mm) left out: offline the fix keeps its full precision.
"""

from __future__ import annotations

from companion.simlink_client import GpsFix, ImuSample
from sitl.plant import POS, QUAT, RATES, VEL, Plant
from sitl.sensors import SensorNoise, SensorSuite, isa_air
from tuavdefs.frames import local_enu_to_global
from tuavdefs.simlink import SENSOR_FIELDS_FILLED


class SensorFeed:
    """The plant's sensors read every control period of ``period_s`` [s]; ``home`` is the
    winder's (latitude deg, longitude deg, ground altitude m AMSL)."""

    def __init__(self, plant: Plant, noise: SensorNoise, home: tuple[float, float, float],
                 period_s: float) -> None:
        self.plant = plant
        self.home = home
        self.period_s = period_s
        self.suite = SensorSuite(noise, home)
        self._gps_period_us = round(1e6 / self.suite.gps_rate_hz)
        self._last_gps_us: int | None = None

    def read(self, t_s: float) -> tuple[ImuSample, GpsFix | None]:
        """The period's IMU sample and, when one is due, the GNSS fix (else None)."""
        p, s = self.plant, self.suite
        t_us = round(t_s * 1e6)
        x = p.x.tolist()
        pos, vel, quat, rates = (tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]),
                                 tuple(x[RATES]))
        s.record_truth_us(t_us, pos, vel)
        fix = None
        last = self._last_gps_us
        if last is None or t_us - last >= self._gps_period_us:
            dt = (self._gps_period_us if last is None else t_us - last) * 1e-6
            self._last_gps_us = t_us
            g = s.gps_fix_us(t_us, dt)
            lat, lon, alt = local_enu_to_global(g.position_enu_m, self.home)
            fix = GpsFix(t_us, g.position_enu_m, g.velocity_enu_m_s, lat, lon, alt, g.eph_m,
                         g.epv_m, 3, 16)
        pressure_hpa, temperature_k, _ = isa_air(self.home[2] + pos[2])
        imu = s.imu(p.specific_force_flu(), rates, quat, self.period_s)
        baro = s.baro_of_air(pressure_hpa, temperature_k, self.period_s)
        return ImuSample(t_us, imu.accel_flu_m_s2, imu.gyro_flu_rad_s, imu.mag_flu_gauss,
                         baro.pressure_hpa, baro.pressure_alt_m, baro.temperature_c,
                         SENSOR_FIELDS_FILLED), fix
