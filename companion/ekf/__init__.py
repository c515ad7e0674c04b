"""The onboard navigation filter: an error-state (multiplicative) extended Kalman filter,
in the manner of PX4's EKF2 and ArduPilot's EKF3 (docs/estimation.md has the equations).

What the companion knows of its own position, velocity and attitude from its sensors alone
(the IMU, GNSS, barometer and magnetometer the simulator link delivers, the winch's tether
fix). One module per concern:

- :mod:`~companion.ekf.filter`: the facade, :class:`NavFilter`;
- :mod:`~companion.ekf.params`: :class:`EstimatorParams`, the filter's own sensor model;
- :mod:`~companion.ekf.layout`: the state's layout, the work array's, the aid sources';
- :mod:`~companion.ekf.memory`: the arrays, with named views;
- :mod:`~companion.ekf.covariance`: the prediction (state, covariance, ring buffer);
- :mod:`~companion.ekf.update`: the measurement update's kernels, shared by every source;
- :mod:`~companion.ekf.output`: the output predictor (what the vehicle flies on);
- :mod:`~companion.ekf.aid_source`: one status record type, one gate/fail/reset policy;
- one module per source: :mod:`~companion.ekf.gnss`, :mod:`~companion.ekf.baro`,
  :mod:`~companion.ekf.mag`, :mod:`~companion.ekf.tether`, :mod:`~companion.ekf.drag`
  (the drag's specific force, with the wind states),
  :mod:`~companion.ekf.zero_velocity`, :mod:`~companion.ekf.const_pos`;
- :mod:`~companion.ekf.alignment`: the initialisation;
- :mod:`~companion.ekf.health`: health, flags, :class:`FilterStatus`;
- :mod:`~companion.ekf.rotation`: the quaternion kernels.
"""

from companion.ekf.aid_source import AidSourcePolicy, AidSourceStatus, FusionOutcome
from companion.ekf.filter import NavFilter
from companion.ekf.health import (
    AidSource,
    EstimatorFlags,
    FilterHealth,
    FilterStatus,
    HealthReason,
)
from companion.ekf.layout import IDX_BG, IDX_BP, N_ERR, AidSourceKind
from companion.ekf.params import (
    ESTIMATOR_KINDS,
    MAG_FUSIONS,
    DragFusionParams,
    EstimatorParams,
    MagFusion,
)

__all__ = ["AidSource", "AidSourceKind", "AidSourcePolicy", "AidSourceStatus", "DragFusionParams",
           "ESTIMATOR_KINDS", "EstimatorFlags", "EstimatorParams", "FilterHealth",
           "FilterStatus", "FusionOutcome", "HealthReason", "IDX_BG", "IDX_BP", "MAG_FUSIONS",
           "MagFusion", "N_ERR", "NavFilter"]
