"""The ground station's winder control step: from the winch's measurements and the UAV's
telemetry to the motor's torque request.

What the ground-station process runs for every encoder frame it receives, and what the
offline runner runs in-process: L-bar and its rate from the UAV's position and velocity
(`groundstation.lbar`), then the backstepping torque law (`groundstation.winder_control`),
in one compiled call (:func:`winder_step`) through the same kernels; or, with
``law = "tension"``, the tension-regulating law (:func:`groundstation.tension_law.
tension_step`), L-bar its feed-forward and bound.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from groundstation.lbar import (
    LBarEstimator,
    LBarParams,
    floor_length_m,
    initial_trim_state,
    lbar_kernel,
    lead_room_from,
    slack_floor,
    stop_lead,
    tension_trim,
    weight_estimate,
)
from groundstation.tension_law import Z_STARTED, tension_step
from groundstation.winder_control import (
    WinderCommand,
    WinderController,
    WinderControlParams,
    WinderLaw,
    winder_law,
)
from tuavdefs.jit import entry_point, njit
from tuavdefs.params import TetherParams, WinderParams


class WinderStep(NamedTuple):
    """One winder control step's output."""

    torque_n_m: float
    lbar_m: float
    lbar_rate_m_s: float
    command: WinderCommand


_command = WinderCommand._make


class WinderHost:
    """L-bar estimator + winder torque law, at ``gains.rate_hz``."""

    def __init__(self, gains: WinderControlParams, lbar: LBarParams, winder: WinderParams,
                 tether: TetherParams, gravity_m_s2: float) -> None:
        self.dt_s = 1.0 / gains.rate_hz
        self.lbar = LBarEstimator(lbar, tether.weight_per_length_n_m(gravity_m_s2))
        self.controller = WinderController(gains, winder, tether)
        # load (or compile) the step's machine code now, not at the first encoder frame,
        # and call it without numba's dispatch (the arguments' types never change)
        lb, ctl = self.lbar, self.controller
        self._step = entry_point(winder_step, 1.0, 0.0, 10.0, 0.0, 0.0, 0.0, lb.a_target,
                                 lb._tan_min, lb.p.min_slack_m, math.nan, ctl.params(),
                                 ctl.state, self.dt_s, 10.0, 0.0, 1.0, lb.w, lb.trim_params,
                                 initial_trim_state(), 0.1, math.nan, math.nan,
                                 math.nan, 0.0, 0.0)
        self._tension = None
        if ctl.law is WinderLaw.TENSION:
            state = ctl.tension_state.copy()
            self._tension = entry_point(tension_step, 1.0, 0.0, 10.0, 0.0, 0.0, 0.0,
                                        lb.a_target, lb._tan_min, lb.p.min_slack_m, math.nan,
                                        ctl.tension_params(), state, self.dt_s, 10.0, 0.0,
                                        1.0, lb.w, lb.trim_params, initial_trim_state(),
                                        math.nan)

    def update(self, length_m: float, omega_rad_s: float, drum_tension_n: float,
               uav_pos_m: tuple[float, float, float],
               uav_vel_m_s: tuple[float, float, float],
               exit_elevation_rad: float = math.nan,
               fix_m: tuple[float, float, float] | None = None, join_m: float = 0.0,
               join_rate_m_s: float = 0.0) -> WinderStep:
        """Torque request [N m] for the measured length [m], drum rate [rad/s] and drum
        tension [N], the UAV's position [m] and velocity [m/s], the line's measured
        exit elevation [rad] (NaN: none; the tension trim then uses the model's weight)
        and the UAV's position [m] as the winder's own tether fix places it (None: none
        now; the slack floor is taken back); ``join_m`` [m] and its rate [m/s] are
        added to the reference (a join's gap). With ``law = "tension"`` the tension law
        (:func:`groundstation.tension_law.tension_step`) runs instead: no trim, lead,
        floor or join; the step's length is the measured one plus the drum's lag behind
        its speed set-point, its rate that set-point."""
        lb, ctl = self.lbar, self.controller
        px, py, pz = uav_pos_m
        vx, vy, vz = uav_vel_m_s
        if self._tension is not None:
            # the tension law: the join's gap, the trim, the lead and the fix's floor are
            # the length law's; the paper's law's filter starts afresh when it next runs
            ctl.state[:] = 0.0
            ref_m, rate, lb._root, cmd = self._tension(
                px, py, pz, vx, vy, vz, lb.a_target, lb._tan_min, lb.p.min_slack_m,
                lb._root, ctl.tension_params(), ctl.tension_state, self.dt_s, length_m,
                omega_rad_s, drum_tension_n, lb.w, lb.trim_params, lb.trim_state,
                exit_elevation_rad)
            return WinderStep(cmd[0], ref_m, rate, _command(cmd))
        ctl.tension_state[Z_STARTED] = 0.0
        lbar_m, rate, lb._root, cmd = self._step(
            px, py, pz, vx, vy, vz, lb.a_target, lb._tan_min, lb.p.min_slack_m, lb._root,
            ctl.params(), ctl.state, self.dt_s, length_m, omega_rad_s, drum_tension_n, lb.w,
            lb.trim_params, lb.trim_state, exit_elevation_rad,
            *(fix_m if fix_m is not None else (math.nan, math.nan, math.nan)), join_m,
            join_rate_m_s)
        return WinderStep(cmd[0], lbar_m, rate, _command(cmd))


@njit
def winder_step(px: float, py: float, pz: float, vx: float, vy: float, vz: float,
                a_target: float, tan_min: float, min_slack: float, root_guess: float,
                law_p: np.ndarray, law_s: np.ndarray, dt_s: float, length_m: float,
                omega_rad_s: float, drum_tension_n: float, w_n_m: float,
                trim_p: np.ndarray, trim_s: np.ndarray, elevation_rad: float,
                fix_x: float, fix_y: float, fix_z: float, join_m: float,
                join_rate_m_s: float
                ) -> tuple[float, float, float, tuple[float, float, float, float, float, bool]]:
    """:meth:`WinderHost.update` in scalars: L-bar and its rate (:func:`lbar_kernel`), the
    line's weight (:func:`weight_estimate`, from the exit elevation ``elevation_rad``
    [rad]; the model's ``w_n_m`` without one), the tension trim's offset
    (:func:`tension_trim` on that weight, both advanced in place), the stop lead
    (:func:`stop_lead`, on the UAV's position and velocity, bounded by
    :func:`lead_room_m <groundstation.lbar.lead_room_m>` (from the last period's root,
    ``trim_s[12]``) and held while the measured exit elevation is below the bound's
    angle), the slack floor (:func:`slack_floor`, on the length
    :func:`floor_length_m` asks at the winder's own fix, (``fix_x``, ``fix_y``,
    ``fix_z``) [m], NaN: none), plus ``join_m`` [m] moving at ``join_rate_m_s``
    [m/s] (a join's gap), then the torque law
    (:func:`winder_law`, its filter ``law_s`` advanced in place) on L-bar + offset + lead
    + floor + join (the join's gap at most what that asks beyond ``length_m``, written to
    ``trim_s[13]``). Returns
    (the length reference, its rate, the exit-angle root for next time, the WinderCommand's
    fields)."""
    lbar_m, rate, a, root = lbar_kernel(px, py, pz, vx, vy, vz, a_target, tan_min,
                                        min_slack, root_guess)
    w = weight_estimate(trim_p, trim_s, dt_s, w_n_m, drum_tension_n, elevation_rad,
                        length_m, pz)
    tension_trim(trim_p, trim_s, dt_s, a, px, py, pz, w, drum_tension_n)
    lbar_m += trim_s[0]
    rate += trim_s[1]
    room = 0.0
    if trim_p[9] > 0.0:
        room, trim_s[12] = lead_room_from(px, py, pz, trim_p[18], min_slack, trim_s[12])
        room -= lbar_m
    # L-bar's least slack is the vehicle's governor's margin, not room to stop in
    stop_lead(trim_p, trim_s, dt_s, px, py, pz, vx, vy, vz, lbar_m - min_slack, room,
              elevation_rad)
    lbar_m += trim_s[4]
    rate += trim_s[5]
    needed = floor_length_m(fix_x, fix_y, fix_z, trim_p[19] * a_target, trim_p[14])
    slack_floor(trim_p, trim_s, dt_s, lbar_m, needed)
    # a join's gap after the floor: it defers what the floor pays out too (on the lumped
    # line the winder's fix, thrown by the line's motion, asked 2 m/s at an in-air start
    # and snapped the line at 92 N); the over-tension pay-out stays the backstop
    lbar_m += trim_s[7]
    rate += trim_s[8]
    # the join's gap defers a pay-out and never winds the line in: a reference falling
    # into it (a first estimate settling lower) takes it, the measured length held
    gap = -join_m
    if gap > 0.0 and lbar_m - length_m < gap:
        gap = max(lbar_m - length_m, 0.0)
        join_rate_m_s = -rate if gap > 0.0 else 0.0
    trim_s[13] = max(gap, 0.0)
    lbar_m -= gap
    rate += join_rate_m_s
    cmd = winder_law(law_p, law_s, dt_s, length_m, omega_rad_s, drum_tension_n, lbar_m,
                     rate)
    return lbar_m, rate, root, cmd
