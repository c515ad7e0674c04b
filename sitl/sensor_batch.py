"""The simulator link's batches: what the plant sends the companion every control period.

:class:`SensorBatches` builds each period's batch (HIL_GPS when due, HIL_STATE_QUATERNION,
HIL_SENSOR, stamped with the period's time) from the plant's state and its sensor models
(:class:`sitl.sensors.SensorSuite`) in one call of :class:`sitl.batch.BatchPacker`: the
batch's one law, compiled, or the same code interpreted without numba
(``TUAV_NO_JIT=1``). The simulator-link server sends them; the offline runner hands them
to the companion as its client would decode them (``tuav_sitl/sensor_feed.py``).
"""

from __future__ import annotations

from sitl.batch import BatchPacker
from sitl.plant import Plant
from sitl.sensors import SensorSuite
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
        #: The batches' law (its field values after each batch:
        #: :meth:`BatchPacker.sensor_values`, :meth:`BatchPacker.gps_values`).
        self.packer = BatchPacker(plant, sensors, home, encoder, period_us)
        self._last_gps_us: int | None = None
        #: Whether the receiver delivers fixes (False: a GNSS-loss fault, sitl.faults).
        self.gps_enabled = True
        #: Whether the last batch held a HIL_GPS.
        self.last_gps = False

    def reset(self) -> None:
        """A new session: the GPS schedule starts again and the recorded truth is
        forgotten."""
        self._last_gps_us = None
        self.sensors.reset_truth()

    def batch(self, t_us: int) -> bytes | memoryview:
        """The batch for the plant's current state, stamped ``t_us`` [us] (HIL_GPS in it
        when one is due). Raises ValueError for a state the link cannot carry (not
        finite, beyond the ISA's air or a field's range: :data:`sitl.batch.REFUSALS`),
        the sensors and the encoder then as they were."""
        gps_dt: float | None = None
        last = self._last_gps_us
        if self.gps_enabled and (last is None or t_us - last >= self.gps_period_us):
            gps_dt = (self.gps_period_us if last is None else t_us - last) * 1e-6
            self._last_gps_us = t_us
        # the IMU's sample covers the period before t_us: a touchdown in it is felt
        self.plant.take_contact_impulse(self.period_us * 1e-6)
        data = self.packer.pack(t_us, gps_dt)
        self.last_gps = gps_dt is not None
        return data
