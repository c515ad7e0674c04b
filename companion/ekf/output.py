"""The output predictor: what the vehicle flies on (EKF2's output predictor,
``EKF2_TAU_POS/VEL``). Each fusion's correction of position and velocity is not flown at
once but taken up over ``output_tau_s``: the output lags the filter by a part of the
corrections (the lag block of the work array), decaying with each IMU step, so the
controllers see no step at each GNSS fix. A reset is flown at once (:meth:`reset`)."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.covariance import predict_kernel
from companion.ekf.layout import PRM_OUT_TAU, W_LAG, W_PRM, W_RATES, W_X, X_P, X_Q, X_V
from companion.flight_controller import VehicleState
from tuavdefs.jit import njit


@njit
def predict_output_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                          t_s: float, dt_s: float, gx: float, gy: float, gz: float,
                          ax: float, ay: float, az: float) -> None:
    """:func:`companion.ekf.covariance.predict_kernel`, then the output's lag behind the
    filter decayed over ``dt_s`` [s] at the time constant ``output_tau_s``."""
    predict_kernel(w, P, buf, meta, t_s, dt_s, gx, gy, gz, ax, ay, az)
    tau_s = w[W_PRM + PRM_OUT_TAU]
    if tau_s > 0.0:
        decay = math.exp(-dt_s / tau_s)
        for i in range(6):
            w[W_LAG + i] *= decay


@njit
def take_up(w: np.ndarray, before: np.ndarray) -> None:
    """The output takes up a fusion's correction of position and velocity (the state's
    change from ``before``, its (p, v)) over ``output_tau_s`` (at once where that is 0)."""
    if w[W_PRM + PRM_OUT_TAU] > 0.0:
        for i in range(6):
            w[W_LAG + i] += w[W_X + i] - before[i]


class OutputPredictor:
    """The state the vehicle flies on, from the work array ``w`` of a filter."""

    __slots__ = ("_x", "_lag", "_rates")

    def __init__(self, w: np.ndarray) -> None:
        self._x = w[W_X + X_P:W_X + X_Q + 4]
        self._lag = w[W_LAG:W_LAG + 6]
        self._rates = w[W_RATES:W_RATES + 3]

    def state(self) -> VehicleState:
        """(position [m], velocity [m/s], attitude quaternion body FLU -> inertial, body
        rates [rad/s] = the last gyro sample minus the bias), as the flight controller
        takes it."""
        px, py, pz, vx, vy, vz, qw, qx, qy, qz = self._x.tolist()
        r0, r1, r2, r3, r4, r5 = self._lag.tolist()
        # (built as the tuple it is, without its Python-level constructor: every period)
        return tuple.__new__(VehicleState, ((px - r0, py - r1, pz - r2),
                                            (vx - r3, vy - r4, vz - r5), (qw, qx, qy, qz),
                                            tuple(self._rates.tolist())))

    def reset(self, velocity: bool = True) -> None:
        """A reset of the position (and the velocity) is flown at once: its lag dropped."""
        if velocity:
            self._lag[:] = 0.0
        else:
            self._lag[0:3] = 0.0


assert X_P == 0 and X_V == 3 and X_Q == 6   # state() reads p, v, q as one slice
