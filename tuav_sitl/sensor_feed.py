"""What the simulator link would deliver to the companion, offline.

The offline runner has no simulator link; :class:`SensorFeed` builds, every control period,
the batch the plant process would send (:class:`sitl.sensor_batch.SensorBatches`: HIL_GPS
when due, HIL_STATE_QUATERNION, HIL_SENSOR, from the plant's sensor models) and decodes it as
the companion's simulator-link client does (:class:`companion.simlink_client.BatchDecoder`):
offline, the companion sees the same sensor messages, with their resolution, as over the
link.
"""

from __future__ import annotations

from companion.simlink_client import BatchDecoder, SimState
from sitl.plant import Plant
from sitl.sensor_batch import SensorBatches
from sitl.sensors import SensorNoise, SensorSuite
from tuavdefs import simlink as sl


class SensorFeed:
    """The plant's batches every control period of ``period_s`` [s]; ``home`` is the
    winder's (latitude deg, longitude deg, ground altitude m AMSL)."""

    def __init__(self, plant: Plant, noise: SensorNoise, home: tuple[float, float, float],
                 period_s: float) -> None:
        suite = SensorSuite(noise, home)
        self.batches = SensorBatches(plant, suite, home, sl.control_period_us(1.0 / period_s),
                                     sl.control_period_us(suite.gps_rate_hz),
                                     sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID))
        self.decoder = BatchDecoder(home)

    def read(self, t_s: float) -> SimState:
        """The period's batch at ``t_s`` [s], decoded: its IMU sample, and its GNSS fix
        (``gps_updated`` when one came in this batch)."""
        (state,) = self.decoder.feed(bytes(self.batches.batch(round(t_s * 1e6))))
        return state
