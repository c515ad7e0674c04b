"""The drum tension from the winder motor's current: the second, cruder tension source.

The axis reports its q-axis current (ODrive CAN Simple ``Get_Iq``, cyclic every 50 ms,
each one before the encoder frame of its instant). The motor's torque is ``tau = Kt Iq``
and the drum's equation (docs/control.md §4, positive paying out)

    I_w(L) d(omega)/dt = tau + r_w T_drum - beta_w omega

gives the tension at the drum

    T_drum = (I_w(L) d(omega)/dt + beta_w omega - Kt Iq) / r_w,

with ``d(omega)/dt`` the encoder's drum rate differenced over the control period ending at
the current's instant, and the result low-passed (``current_filter_s``), updated with each
current. It is cruder than the load cell: the torque
constant (its datasheet's, within about 10 %), the drum's friction and inertia (the
controller's model) and the differenced rate all enter it, and at a drum radius of 0.1 m
1 N of tension is only 0.1 N m, 1 A at Kt 0.1 N m/A. The winch uses it where the load
cell cannot serve (:class:`groundstation.winch_sensors.TensionSource`): while the load
cell is silent or reports itself unhealthy, and while the two disagree for long. It holds
only while the motor drives the drum (closed loop, the brake released): braked, the brake
takes the pull and the current says nothing of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable


class CurrentTension:
    """The drum tension [N] from the motor's current, the encoder's rate and the drum model.

    ``kt_nm_a`` the torque constant [N m/A], ``r_w_m`` the drum radius [m], ``beta_n_m_s``
    the viscous friction [N m s/rad], ``inertia_kg_m2`` the drum's inertia at a paid-out
    length [kg m^2], ``filter_s`` the low-pass [s] (0: none), ``dt_s`` the encoder frames'
    period [s] (the simulated time between two).
    """

    def __init__(self, kt_nm_a: float, r_w_m: float, beta_n_m_s: float,
                 inertia_kg_m2: Callable[[float], float], filter_s: float,
                 dt_s: float) -> None:
        self.kt = kt_nm_a
        self.r_w = r_w_m
        self.beta = beta_n_m_s
        self.inertia = inertia_kg_m2
        self.dt_s = dt_s
        self._k = 1.0 - math.exp(-dt_s / filter_s) if filter_s > 0.0 else 1.0
        self.iq_a = math.nan                # the last measured q-axis current [A]
        self.iq_frames = 0
        self._fresh = False                 # a current came since the last encoder frame
        self._periods = 0                   # encoder frames since the last update
        self._omega = math.nan              # the drum rate at the last encoder frame
        #: the estimate [N], NaN until a current and two encoder frames came
        self.tension_n = math.nan

    def on_iq(self, measured_a: float) -> None:
        """A ``Get_Iq`` frame's measured current [A] (non-finite: ignored)."""
        if math.isfinite(measured_a):
            self.iq_a = measured_a
            self.iq_frames += 1
            self._fresh = True

    def on_encoder(self, length_m: float, omega_rad_s: float, drives: bool) -> None:
        """An encoder frame: with a current of its instant (one came since the last
        encoder frame) the estimate is updated, while the motor ``drives`` the drum (closed
        loop, no brake); otherwise the motor says nothing of the line (the brake or a stop
        takes the pull) and the estimate is dropped."""
        fresh, self._fresh = self._fresh, False
        self._periods += 1
        if not drives:
            self._omega = self.tension_n = math.nan
            return
        last, self._omega = self._omega, omega_rad_s
        if not (fresh and math.isfinite(last)):
            return
        acc = (omega_rad_s - last) / self.dt_s
        t = (self.inertia(length_m) * acc + self.beta * omega_rad_s
             - self.kt * self.iq_a) / self.r_w
        if not math.isfinite(self.tension_n):
            self.tension_n = t
        else:
            k = 1.0 - (1.0 - self._k) ** self._periods     # the low-pass over the gap
            self.tension_n += k * (t - self.tension_n)
        self._periods = 0
