"""What the simulator link would deliver to the companion, offline.

The offline runner has no simulator link; :class:`SensorFeed` builds, every control period,
the batch the plant process would send (:class:`sitl.sensor_batch.SensorBatches`: HIL_GPS
when due, HIL_STATE_QUATERNION, HIL_SENSOR, from the plant's sensor models) and decodes it as
the companion's simulator-link client does (:class:`companion.simlink_client.BatchDecoder`):
offline, the companion sees the same sensor messages, with their resolution, as over the
link.

With ``wire`` (``OfflineRunner(wire=True)``, :mod:`tuav_sitl.offline_links`) every batch's
bytes are parsed as the companion's client parses its socket's (checksums checked,
:meth:`companion.simlink_client.BatchDecoder.feed`). Without it (the default) the bytes
never cross a wire, so :meth:`SensorFeed.read` hands the companion's decoder the field
values the batch's frames carry, as the batch's law wrote them
(:meth:`sitl.batch.BatchPacker.sensor_values`, :meth:`~sitl.batch.BatchPacker.gps_values`:
HIL_SENSOR's floats as float32, HIL_GPS's integers), without packing and unpacking them;
HIL_STATE_QUATERNION, which the onboard step does not read, is not decoded (the runner
hands the companion the plant's state itself, which flies on it only with
``EstimatorParams.kind`` "truth", and then no sensor feed is built).
``tests/test_fast_paths.py`` checks both against the decoder reading the batch's bytes.
"""

from __future__ import annotations

from companion.simlink_client import BatchDecoder, SimState
from sitl.plant import Plant
from sitl.sensor_batch import SensorBatches
from sitl.sensors import SensorNoise, SensorSuite
from tuavdefs import simlink as sl

_GPS = sl.MSG_HIL_GPS


class SensorFeed:
    """The plant's batches every control period of ``period_s`` [s]; ``home`` is the
    winder's (latitude deg, longitude deg, ground altitude m AMSL); ``wire`` whether each
    batch's bytes are parsed as over the link (module docstring)."""

    def __init__(self, plant: Plant, noise: SensorNoise, home: tuple[float, float, float],
                 period_s: float, wire: bool = False) -> None:
        self.wire = wire
        suite = SensorSuite(noise, home)
        self.batches = SensorBatches(plant, suite, home, sl.control_period_us(1.0 / period_s),
                                     sl.control_period_us(suite.gps_rate_hz),
                                     sl.Encoder(sl.PLANT_SYSID, sl.PLANT_COMPID))
        self.decoder = BatchDecoder(home, truth=False)   # (as the companion on its estimate)

    def read(self, t_s: float) -> SimState:
        """The period's batch at ``t_s`` [s], decoded: its IMU sample, and its GNSS fix
        (``gps_updated`` when one came in this batch); its ``truth`` is not decoded
        (module docstring)."""
        batches, decoder = self.batches, self.decoder
        data = batches.batch(round(t_s * 1e6))
        if self.wire:
            (state,) = decoder.feed(bytes(data))
            return state
        packer = batches.packer
        if batches.last_gps:
            decoder.absorb((_GPS, packer.gps_values()))
        return decoder.sensor_state(packer.sensor_values())
