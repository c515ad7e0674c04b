"""The simulator link's batches: what the plant sends the companion every control period.

:class:`SensorBatches` builds each period's batch (HIL_GPS when due, HIL_STATE_QUATERNION,
HIL_SENSOR, stamped with the period's time) from the plant's state and its sensor models
(:class:`sitl.sensors.SensorSuite`): in one compiled call (:class:`sitl.batch.BatchPacker`)
where it can, interpreted otherwise (the packer's reference, and the path for what it
leaves alone). The simulator-link server sends them; the offline runner decodes them as the
companion would (``tuav_sitl/sensor_feed.py``).
"""

from __future__ import annotations

import math

from sitl.batch import batch_packer
from sitl.plant import POS, QUAT, RATES, VEL, Plant
from sitl.sensors import ISA_RHO0_KG_M3, SensorSuite, airspeed_from, isa_air
from tuavdefs import simlink as sl


class SensorBatches:
    """The batches of ``plant`` and ``sensors`` every ``period_us`` [us], HIL_GPS every
    ``gps_period_us`` [us], framed by ``encoder``; ``home`` is the winder's (latitude deg,
    longitude deg, ground altitude m AMSL)."""

    def __init__(self, plant: Plant, sensors: SensorSuite, home: tuple[float, float, float],
                 period_us: int, gps_period_us: int, encoder: sl.Encoder) -> None:
        self.plant = plant
        self.sensors = sensors
        self.home = home
        self.period_us = period_us
        self.gps_period_us = gps_period_us
        self.encoder = encoder
        self.home_map = sl.home_map(home)
        #: The batches in one compiled call (None without numba: :meth:`interpreted`).
        self.packer = batch_packer(plant, sensors, home, encoder, period_us)
        self._last_gps_us: int | None = None
        #: Whether the receiver delivers fixes (False: a GNSS-loss fault, sitl.faults).
        self.gps_enabled = True
        #: Whether the last batch was the packer's (its field values then in
        #: :meth:`BatchPacker.sensor_values`) and whether it held a HIL_GPS.
        self.last_packed = False
        self.last_gps = False

    def reset(self) -> None:
        """A new session: the GPS schedule starts again and the recorded truth is
        forgotten."""
        self._last_gps_us = None
        self.sensors.reset_truth()

    def batch(self, t_us: int) -> bytes | memoryview:
        """The batch for the plant's current state, stamped ``t_us`` [us] (HIL_GPS in it
        when one is due)."""
        gps_dt: float | None = None
        last = self._last_gps_us
        if self.gps_enabled and (last is None or t_us - last >= self.gps_period_us):
            gps_dt = (self.gps_period_us if last is None else t_us - last) * 1e-6
            self._last_gps_us = t_us
        data = None if self.packer is None else self.packer.pack(t_us, gps_dt)
        self.last_gps = gps_dt is not None
        self.last_packed = data is not None
        return data if data is not None else self.interpreted(t_us, gps_dt)

    def interpreted(self, t_us: int, gps_dt: float | None) -> bytes:
        """The batch for the current state at ``t_us`` [us] (with HIL_GPS, its channels read
        ``gps_dt`` [s] after the last fix, unless None), interpreted: the reference of
        :class:`sitl.batch.BatchPacker`, and the path for what it leaves alone."""
        p = self.plant
        dt = self.period_us * 1e-6
        x = p.x.tolist()
        pos, vel, quat, rates = (tuple(x[POS]), tuple(x[VEL]), tuple(x[QUAT]),
                                 tuple(x[RATES]))
        s, enc, home = self.sensors, self.encoder, self.home_map
        s.record_truth_us(t_us, pos, vel)    # (first: whatever fails below, it is kept)
        f_flu = p.specific_force_flu()
        pressure_hpa, temperature_k, density = isa_air(self.home[2] + pos[2])
        tas = airspeed_from(vel, p.wind_m_s)
        ias = tas * math.sqrt(density / ISA_RHO0_KG_M3)
        chunks = []
        if gps_dt is not None:
            fix = s.gps_fix_us(t_us, gps_dt)
            chunks.append(enc.pack_values(sl.MSG_HIL_GPS, sl.hil_gps_values(
                t_us, fix.position_enu_m, fix.velocity_enu_m_s, home, fix.eph_m, fix.epv_m)))
        chunks.append(enc.pack_values(sl.MSG_HIL_STATE_QUATERNION,
                                      sl.hil_state_quaternion_values(
                                          t_us, pos, vel, quat, rates, f_flu, home, tas, ias)))
        chunks.append(enc.pack_values(sl.MSG_HIL_SENSOR, sl.hil_sensor_values(
            t_us, *s.imu(f_flu, rates, quat, dt),
            *s.baro_of_air(pressure_hpa, temperature_k, dt))))
        return b"".join(chunks)
