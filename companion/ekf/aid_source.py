"""One status record per aid source, and the one policy every source's fusion follows.

Every measurement the filter fuses (:class:`AidSourceKind`) has an :class:`AidSourceStatus`
(PX4 EKF2's ``estimator_aid_source`` records): its latest innovation, innovation variance
and test ratio (written by the fusion kernels into the source's row of the work array,
:func:`companion.ekf.update.set_aid_row`), and the times and counts this module keeps
(:meth:`AidSourceStatus.record`, the one function that takes a fusion's outcome).

The policy (:class:`AidSourcePolicy`, set for each source from the parameters by
:func:`policies`): a measurement whose test ratio exceeds 1 (its innovation beyond
``gate_sigma`` standard deviations) is rejected; a source rejected without a break for
``fail_s`` is failing (the filter unhealthy, :mod:`companion.ekf.health`); for ``reset_s``
its state is due a reset to the measurement (the source's control does it and says so,
:meth:`AidSourceStatus.reset_done`); a source not fused for ``timeout_s`` is no longer in
use; samples closer than ``min_interval_s`` to the last one are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, IntEnum

import numpy as np

from companion.ekf.layout import (
    AID_INNOV,
    AID_INNOV_VAR,
    AID_TEST_RATIO,
    FUSED,
    NUMERIC,
    REJECTED,
    AidSourceKind,
)
from companion.ekf.params import EstimatorParams


class FusionOutcome(IntEnum):
    """What became of one measurement (the fusion kernels' return codes)."""

    REJECTED = REJECTED
    """Its test ratio exceeded 1: not fused."""
    FUSED = FUSED
    NUMERIC = NUMERIC
    """Refused numerically (a variance would turn negative, a covariance not positive
    definite, no horizontal field): not fused, and neither a pass nor a failure."""


class IntervalFrom(Enum):
    """What a source's ``min_interval_s`` counts from."""

    ATTEMPT = "attempt"
    """The last sample that reached its fusion (the sensor's own output rate)."""
    FUSED = "fused"
    """The last sample fused (a rejected sample lets the next one try at once)."""


@dataclass(frozen=True)
class AidSourcePolicy:
    """How one source is gated, judged and reset (module docstring)."""

    gate_sigma: float
    """The innovation gate [standard deviations] (inf: ungated)."""
    timeout_s: float
    """In use while fused within this [s]."""
    fail_s: float = math.inf
    """Rejected without a break this long [s]: failing."""
    reset_s: float = math.inf
    """Rejected without a break this long [s]: its state is due a reset (inf: never)."""
    min_interval_s: float = 0.0
    """Samples closer than this [s] to the last (``interval_from``) are skipped."""
    interval_from: IntervalFrom = IntervalFrom.FUSED


#: How often constant-position mode fuses its held position [s].
CONST_POS_INTERVAL_S = 0.2


def policies(p: EstimatorParams) -> dict[AidSourceKind, AidSourcePolicy]:
    """Each source's policy from the filter's parameters: the one place they are set."""
    k = AidSourceKind
    fail = p.innovation_fail_s
    return {
        k.GNSS_POS: AidSourcePolicy(p.gnss_pos_gate_sigma, p.gnss_timeout_s, fail,
                                    p.gnss_reset_s),
        k.GNSS_HGT: AidSourcePolicy(p.gnss_pos_gate_sigma, p.gnss_timeout_s, fail),
        k.GNSS_VEL: AidSourcePolicy(p.gnss_vel_gate_sigma, p.gnss_timeout_s, fail),
        k.BARO: AidSourcePolicy(p.baro_gate_sigma, p.gnss_timeout_s, fail,
                                min_interval_s=p.baro_min_interval_s,
                                interval_from=IntervalFrom.ATTEMPT),
        k.MAG: AidSourcePolicy(p.mag_gate_sigma, p.gnss_timeout_s, fail,
                               min_interval_s=p.mag_min_interval_s),
        k.TETHER: AidSourcePolicy(p.tether_gate_sigma, p.tether_timeout_s, fail,
                                  p.tether_reset_s),
        k.ZERO_VEL: AidSourcePolicy(math.inf, p.stationary_interval_s,
                                    min_interval_s=p.stationary_interval_s,
                                    interval_from=IntervalFrom.ATTEMPT),
        k.CONST_POS: AidSourcePolicy(math.inf, math.inf, min_interval_s=CONST_POS_INTERVAL_S,
                                     interval_from=IntervalFrom.ATTEMPT),
        k.DRAG: AidSourcePolicy(p.drag.gate_sigma, 10.0 * p.drag.interval_s,
                                reset_s=p.drag.reset_s, min_interval_s=p.drag.interval_s,
                                interval_from=IntervalFrom.ATTEMPT),
        k.TETHER_LINE: AidSourcePolicy(p.drag.tether_line.gate_sigma, p.tether_timeout_s,
                                       fail, p.tether_reset_s),
    }


class AidSourceStatus:
    """One source's record: what its kernel wrote of its latest measurement (``row``, a
    view of its row of the work array) and the times and counts of its fusions [s]."""

    __slots__ = ("kind", "policy", "_row", "time_last_fused", "time_last_attempt",
                 "fail_since", "rejected", "resets", "numeric_refusals")

    def __init__(self, kind: AidSourceKind, policy: AidSourcePolicy,
                 row: np.ndarray) -> None:
        self.kind = kind
        self.policy = policy
        self._row = row
        #: when it was last fused (or its state last set from it) [s]
        self.time_last_fused = -math.inf
        #: when a sample last reached its fusion [s]
        self.time_last_attempt = -math.inf
        #: since when it has been rejected without a break [s] (inf: not rejected)
        self.fail_since = math.inf
        #: whether its latest measurement was rejected (and not reset to since)
        self.rejected = False
        #: times the state was reset to it
        self.resets = 0
        #: its measurements refused numerically
        self.numeric_refusals = 0

    # ----- what the kernel wrote
    @property
    def innovation(self) -> tuple[float, float, float]:
        """The latest innovation (measurement - prediction; unused axes 0)."""
        r = self._row
        return (float(r[AID_INNOV]), float(r[AID_INNOV + 1]), float(r[AID_INNOV + 2]))

    @property
    def innovation_variance(self) -> tuple[float, float, float]:
        """The latest innovation's variance per axis (unused axes 0)."""
        r = self._row
        return (float(r[AID_INNOV_VAR]), float(r[AID_INNOV_VAR + 1]),
                float(r[AID_INNOV_VAR + 2]))

    @property
    def test_ratio(self) -> float:
        """The latest test ratio (1 at the gate; above 1 rejected)."""
        return float(self._row[AID_TEST_RATIO])

    # ----- the policy
    def record(self, t_s: float, outcome: FusionOutcome | int, numeric: bool = False) -> bool:
        """Take a fusion's ``outcome`` at ``t_s`` [s] (``numeric``: some axis was refused
        numerically though the measurement passed). Returns whether the source has now
        been rejected for its ``reset_s`` (its control then resets and calls
        :meth:`reset_done`)."""
        if outcome == FUSED:
            self.time_last_fused = t_s
            self.fail_since = math.inf
            self.rejected = False
        elif outcome == REJECTED:
            if t_s < self.fail_since:
                self.fail_since = t_s
            self.rejected = True
        if numeric or outcome == NUMERIC:
            self.numeric_refusals += 1
        return t_s - self.fail_since >= self.policy.reset_s

    def reset_done(self, t_s: float) -> None:
        """The state was reset to this source's measurement at ``t_s`` [s]."""
        self.resets += 1
        self.time_last_fused = t_s
        self.fail_since = math.inf
        self.rejected = False

    def too_soon(self, t_s: float) -> bool:
        """Whether a sample at ``t_s`` [s] comes within ``min_interval_s`` of the last
        (attempted or fused, as the policy says)."""
        last = (self.time_last_attempt if self.policy.interval_from is IntervalFrom.ATTEMPT
                else self.time_last_fused)
        return t_s - last < self.policy.min_interval_s

    def in_use(self, t_s: float) -> bool:
        """Whether it was fused within ``timeout_s`` of ``t_s`` [s]."""
        return t_s - self.time_last_fused <= self.policy.timeout_s

    def failing(self, t_s: float) -> bool:
        """Whether it has been rejected without a break for ``fail_s`` at ``t_s`` [s]."""
        return t_s - self.fail_since >= self.policy.fail_s


class AidSources:
    """Every source's :class:`AidSourceStatus`, by kind (``sources[kind]``) and by name
    (``sources.gnss_pos``)."""

    __slots__ = ("gnss_pos", "gnss_hgt", "gnss_vel", "baro", "mag", "tether", "zero_vel",
                 "const_pos", "drag", "tether_line", "_by_kind")

    def __init__(self, params: EstimatorParams, rows: np.ndarray) -> None:
        pol = policies(params)
        self._by_kind = {k: AidSourceStatus(k, pol[k], rows[k]) for k in AidSourceKind}
        for k, st in self._by_kind.items():
            setattr(self, k.name.lower(), st)

    def __getitem__(self, kind: AidSourceKind) -> AidSourceStatus:
        return self._by_kind[kind]

    def __iter__(self):  # noqa: ANN204 - an iterator of records
        return iter(self._by_kind.values())
