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
    LB_A_TARGET,
    LB_MIN_SLACK,
    LB_TAN_MIN,
    LB_W,
    LS_ROOT,
    TP_FLOOR,
    TP_FLOOR_TENSION_RATIO,
    TP_LEAD_ACC,
    TP_LEAD_TAN_MIN,
    TP_TRIM_FILTER,
    TS_FLOOR,
    TS_FLOOR_RATE,
    TS_JOIN_GAP,
    TS_LEAD,
    TS_LEAD_RATE,
    TS_OFFSET,
    TS_OFFSET_RATE,
    TS_ROOM_ROOT,
    TS_TENSION,
    LBarEstimator,
    LBarParams,
    floor_length_m,
    lbar_kernel,
    lead_room_from,
    slack_floor,
    stop_lead,
    tension_trim,
    weight_estimate,
)
from groundstation.tension_law import (
    Q_APPROACH,
    Q_BOUND_M,
    Q_FLOOR,
    Z_LAG,
    Z_LAID,
    Z_LIFTED,
    Z_SETPOINT,
    Z_SPEED,
    Z_STARTED,
    Z_STIFFNESS,
    heavy_scale,
    lay_down_share,
    string_slack_m,
    taut_line_stiffness_n_m,
    tension_law,
    tension_setpoint_n,
)
from groundstation.winder_control import (
    S_STARTED,
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

# Named indices of the step's input records (one record a concern: tuples of floats built
# for each call)
#: the UAV as the vehicle reports it: position [m], velocity [m/s], z-up from the exit
U_PX, U_PY, U_PZ, U_VX, U_VY, U_VZ = range(6)
N_UAV = 6
#: the winch's measurements: paid-out length [m], drum rate [rad/s], drum tension [N],
#: the line's exit elevation [rad] (NaN: none)
M_LENGTH, M_OMEGA, M_TENSION, M_ELEVATION = range(4)
N_MEASURED = 4
#: the winder's own tether fix of the UAV [m] (NaN: none now), and the join's gap [m] added
#: to the reference and its rate [m/s]
F_X, F_Y, F_Z, F_JOIN, F_JOIN_RATE = range(5)
N_FIX = 5


class StepRecords(NamedTuple):
    """:func:`winder_step`'s arguments after its three per-call records (the UAV, the
    measurements, the fix: tuples of floats), in its order: the arrays it reads and
    advances in place."""

    lbar_p: np.ndarray          #: L-bar's parameters, groundstation.lbar.LB_*
    lbar_s: np.ndarray          #: L-bar's state, groundstation.lbar.LS_* (advanced)
    law_p: np.ndarray           #: the length law's packed gains and drum model
    law_s: np.ndarray           #: its reference filter (advanced)
    trim_p: np.ndarray          #: L-bar's trim, lead and floor parameters (TP_*)
    trim_s: np.ndarray          #: their state (TS_*, advanced)
    dt_s: float                 #: the control period [s]


class TensionRecords(NamedTuple):
    """:func:`tension_step`'s arguments after its two per-call records (the UAV, the
    measurements), in its order (the arrays advanced in place)."""

    lbar_p: np.ndarray          #: L-bar's parameters, groundstation.lbar.LB_*
    lbar_s: np.ndarray          #: L-bar's state, groundstation.lbar.LS_* (advanced)
    law_p: np.ndarray           #: the tension law's packed parameters (tension_law.Q_*)
    law_s: np.ndarray           #: its state (tension_law.Z_*, advanced)
    trim_p: np.ndarray          #: L-bar's trim, lead and floor parameters (TP_*)
    trim_s: np.ndarray          #: their state (TS_*, advanced: the low-passed tension,
                                #: the weight estimate, the room's root)
    dt_s: float                 #: the control period [s]


class WinderHost:
    """L-bar estimator + winder torque law, at ``gains.rate_hz``."""

    def __init__(self, gains: WinderControlParams, lbar: LBarParams, winder: WinderParams,
                 tether: TetherParams, gravity_m_s2: float) -> None:
        self.dt_s = 1.0 / gains.rate_hz
        self.lbar = LBarEstimator(lbar, tether.weight_per_length_n_m(gravity_m_s2))
        self.controller = WinderController(gains, winder, tether)
        ctl = self.controller
        # load (or compile) the step's machine code now, not at the first encoder frame,
        # and call it without numba's dispatch (the arguments' types never change)
        self._rec: StepRecords | None = None
        self._step = entry_point(winder_step, (0.0,) * N_UAV, (0.0,) * N_MEASURED,
                                 (0.0,) * N_FIX, *self._args())
        self._tension = None
        #: the tension law's step's arguments as last built (again when the controller
        #: repacks its gains: :meth:`_tension_args`)
        self._tension_rec: TensionRecords | None = None
        if ctl.law is WinderLaw.TENSION:
            self._tension = entry_point(tension_step, (0.0,) * N_UAV, (0.0,) * N_MEASURED,
                                        *self._tension_args())

    @property
    def takes_fix(self) -> bool:
        """Whether :meth:`update` takes the winder's own tether fix (``fix_m``) and a
        join's gap: the length law's step does; the tension law's does not (a caller need
        not compute them for it)."""
        return self._tension is None

    def _records(self) -> StepRecords:
        """The step's arguments now (the controller's packed gains as they stand)."""
        lb, ctl = self.lbar, self.controller
        return StepRecords(lb.packed, lb.state, ctl.params(), ctl.state, lb.trim_params,
                           lb.trim_state, self.dt_s)

    def _tension_records(self) -> TensionRecords:
        """The tension law's step's arguments now."""
        lb, ctl = self.lbar, self.controller
        return TensionRecords(lb.packed, lb.state, ctl.tension_params(), ctl.tension_state,
                              lb.trim_params, lb.trim_state, self.dt_s)

    def _args(self) -> StepRecords:
        """:meth:`_records`, built again only when the controller has repacked its
        gains."""
        p = self.controller.params()
        rec = self._rec
        if rec is None or rec.law_p is not p:
            rec = self._rec = self._records()
        return rec

    def _tension_args(self) -> TensionRecords:
        """:meth:`_tension_records`, built again only when the controller's packed
        parameters are no longer the ones they hold (a gain replaced: it repacks)."""
        q = self.controller.tension_params()
        rec = self._tension_rec
        if rec is None or rec.law_p is not q:
            rec = self._tension_rec = self._tension_records()
        return rec

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
        (:func:`tension_step`) runs instead: no trim, lead,
        floor or join; the step's length is the measured one plus the drum's lag behind
        its speed set-point, its rate that set-point."""
        ctl = self.controller
        px, py, pz = uav_pos_m
        vx, vy, vz = uav_vel_m_s
        u = (px, py, pz, vx, vy, vz)
        m = (length_m, omega_rad_s, drum_tension_n, exit_elevation_rad)
        if self._tension is not None:
            # the tension law: the join's gap, the trim, the lead and the fix's floor are
            # the length law's; the paper's law's filter starts afresh when it next runs
            if ctl.state[S_STARTED]:     # (a filter not started is all zeros)
                ctl.state[:] = 0.0
            ref_m, rate, cmd = self._tension(u, m, *self._tension_args())
            return WinderStep(cmd[0], ref_m, rate, _command(cmd))
        ctl.tension_state[Z_STARTED] = 0.0
        nan = math.nan
        fx, fy, fz = (nan, nan, nan) if fix_m is None else fix_m
        lbar_m, rate, cmd = self._step(u, m, (fx, fy, fz, join_m, join_rate_m_s),
                                       *self._args())
        return WinderStep(cmd[0], lbar_m, rate, _command(cmd))


@njit
def winder_step(uav: tuple[float, ...], measured: tuple[float, ...], fix: tuple[float, ...],
                lbar_p: np.ndarray,
                lbar_s: np.ndarray, law_p: np.ndarray, law_s: np.ndarray,
                trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float
                ) -> tuple[float, float, tuple[float, float, float, float, float, bool]]:
    """:meth:`WinderHost.update` on its records (:class:`StepRecords`): L-bar and its rate
    (:func:`lbar_kernel`, its exit-angle root in ``lbar_s``), the line's weight
    (:func:`weight_estimate`, from the measured exit elevation; the model's weight without
    one), the tension trim's offset (:func:`tension_trim` on that weight, both advanced in
    place), the stop lead (:func:`stop_lead`, on the UAV's position and velocity, bounded
    by :func:`lead_room_m <groundstation.lbar.lead_room_m>` (from the last period's root)
    and held while the measured exit elevation is below the bound's angle), the slack floor
    (:func:`slack_floor`, on the length :func:`floor_length_m` asks at the winder's own
    fix, NaN: none), plus the join's gap moving at its rate, then the torque law
    (:func:`winder_law`, its filter ``law_s`` advanced in place) on L-bar + offset + lead +
    floor + join (the join's gap at most what that asks beyond the measured length,
    written to ``trim_s[TS_JOIN_GAP]``). Returns (the length reference [m], its rate
    [m/s], the WinderCommand's fields)."""
    px, py, pz = uav[U_PX], uav[U_PY], uav[U_PZ]
    vx, vy, vz = uav[U_VX], uav[U_VY], uav[U_VZ]
    length_m, omega_rad_s = measured[M_LENGTH], measured[M_OMEGA]
    drum_tension_n, elevation_rad = measured[M_TENSION], measured[M_ELEVATION]
    a_target, min_slack = lbar_p[LB_A_TARGET], lbar_p[LB_MIN_SLACK]
    lbar_m, rate, a, lbar_s[LS_ROOT] = lbar_kernel(px, py, pz, vx, vy, vz, a_target,
                                                   lbar_p[LB_TAN_MIN], min_slack,
                                                   lbar_s[LS_ROOT])
    w = weight_estimate(trim_p, trim_s, dt_s, lbar_p[LB_W], drum_tension_n, elevation_rad,
                        length_m, pz)
    tension_trim(trim_p, trim_s, dt_s, a, px, py, pz, w, drum_tension_n)
    lbar_m += trim_s[TS_OFFSET]
    rate += trim_s[TS_OFFSET_RATE]
    room = 0.0
    if trim_p[TP_LEAD_ACC] > 0.0:
        room, trim_s[TS_ROOM_ROOT] = lead_room_from(px, py, pz, trim_p[TP_LEAD_TAN_MIN],
                                                    min_slack, trim_s[TS_ROOM_ROOT])
        room -= lbar_m
    # L-bar's least slack is the vehicle's governor's margin, not room to stop in
    stop_lead(trim_p, trim_s, dt_s, px, py, pz, vx, vy, vz, lbar_m - min_slack, room,
              elevation_rad)
    lbar_m += trim_s[TS_LEAD]
    rate += trim_s[TS_LEAD_RATE]
    needed = floor_length_m(fix[F_X], fix[F_Y], fix[F_Z],
                            trim_p[TP_FLOOR_TENSION_RATIO] * a_target, trim_p[TP_FLOOR])
    slack_floor(trim_p, trim_s, dt_s, lbar_m, needed)
    # a join's gap after the floor: it defers what the floor pays out too (on the lumped
    # line the winder's fix, thrown by the line's motion, asked 2 m/s at an in-air start
    # and snapped the line at 92 N); the over-tension pay-out stays the backstop
    lbar_m += trim_s[TS_FLOOR]
    rate += trim_s[TS_FLOOR_RATE]
    # the join's gap defers a pay-out and never winds the line in: a reference falling
    # into it (a first estimate settling lower) takes it, the measured length held
    gap = -fix[F_JOIN]
    join_rate_m_s = fix[F_JOIN_RATE]
    if gap > 0.0 and lbar_m - length_m < gap:
        gap = max(lbar_m - length_m, 0.0)
        join_rate_m_s = -rate if gap > 0.0 else 0.0
    trim_s[TS_JOIN_GAP] = max(gap, 0.0)
    lbar_m -= gap
    rate += join_rate_m_s
    cmd = winder_law(law_p, law_s, dt_s, length_m, omega_rad_s, drum_tension_n, lbar_m,
                     rate)
    return lbar_m, rate, cmd


@njit
def tension_step(uav: tuple[float, ...], measured: tuple[float, ...], lbar_p: np.ndarray,
                 lbar_s: np.ndarray, law_p: np.ndarray, law_s: np.ndarray,
                 trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float
                 ) -> tuple[float, float, tuple[float, float, float, float, float, bool]]:
    """The tension law's winder step on its records (:class:`TensionRecords`), in
    :func:`winder_step`'s place: L-bar and its rate at the UAV's reported position and
    velocity (the rate is the feed-forward; its exit-angle root in ``lbar_s``), the line's
    weight estimate, the set-point (:func:`groundstation.tension_law.tension_setpoint_n`),
    the length bounds (below: the straight distance plus the least slack, or the slack the
    lay-down band lays down, kept until the line has flown or the UAV has left the band and
    then given back at the slack approach's rate (``law_s[Z_LAID]``); above: L-bar or
    the longest line still off the ground, plus ``length_bound_m``), the exit-elevation
    loop's reference (L-bar's least exit angle, at most half the chord's elevation) with
    the measured exit elevation, then
    :func:`groundstation.tension_law.tension_law`. Returns (the length the drum is asked
    to be at: the measured length plus its lag behind the speed set-point, the speed
    set-point [m/s], the WinderCommand's fields)."""
    px, py, pz = uav[U_PX], uav[U_PY], uav[U_PZ]
    vx, vy, vz = uav[U_VX], uav[U_VY], uav[U_VZ]
    length_m, omega_rad_s = measured[M_LENGTH], measured[M_OMEGA]
    drum_tension_n, elevation_rad = measured[M_TENSION], measured[M_ELEVATION]
    min_slack = lbar_p[LB_MIN_SLACK]
    lbar_m, rate, a, lbar_s[LS_ROOT] = lbar_kernel(px, py, pz, vx, vy, vz,
                                                   lbar_p[LB_A_TARGET], lbar_p[LB_TAN_MIN],
                                                   min_slack, lbar_s[LS_ROOT])
    # the drum tension as the tension trim low-passes it (the weight estimate's and the
    # winch's tether fix's input)
    if trim_s[TS_TENSION] == trim_s[TS_TENSION] and trim_p[TP_TRIM_FILTER] > 0.0:
        trim_s[TS_TENSION] += (1.0 - math.exp(-dt_s / trim_p[TP_TRIM_FILTER])) * (
            drum_tension_n - trim_s[TS_TENSION])
    else:
        trim_s[TS_TENSION] = drum_tension_n
    w = weight_estimate(trim_p, trim_s, dt_s, lbar_p[LB_W], drum_tension_n, elevation_rad,
                        length_m, pz)
    h = math.hypot(px, py)
    v = max(pz, 0.0)
    share = lay_down_share(law_p, math.atan(lbar_p[LB_TAN_MIN]), h, v)
    heavy = heavy_scale(law_p, w, lbar_p[LB_W])
    setpoint = tension_setpoint_n(law_p, a, h, v, w, min_slack, share, heavy)
    dist = math.sqrt(px * px + py * py + pz * pz)
    radial = (px * vx + py * vy + pz * vz) / dist if dist > 1e-6 else 0.0
    # no stopping distance in the lower bound: the drum renders to the pull, so the
    # vehicle's governor does not count on the length paid out ahead of it (docs/control.md
    # §8.3); near the vertical, slack held ahead left the line's lower end unloaded, and
    # the dynamic line whipped taut there (the lumped mission: 52.7 N at 18 cm of slack)
    room, trim_s[TS_ROOM_ROOT] = lead_room_from(px, py, pz, trim_p[TP_LEAD_TAN_MIN],
                                                min_slack, trim_s[TS_ROOM_ROOT])
    # the least slack in proportion to the chord's horizontal share (at least 0.4 of it):
    # near the vertical a line with min_slack hangs its lower end unloaded (the load
    # cell reads nothing) and the dynamic line whips taut; the set-point loop, its gain
    # scaled to the stiff line there, holds the lower end at the floor's pull instead
    # (low and far, as the line is laid down, more: at the lay-down share 0 the slack at
    # which the line pulls twice the floor, else the least slack pulls the set-point's cap
    # nearly level at the UAV)
    low_slack = min_slack * max(h / dist, 0.4) if dist > 1e-6 else min_slack
    if share < 1.0:
        low_slack = max(low_slack, (1.0 - share) * string_slack_m(
            w, h, v, 2.0 * law_p[Q_FLOOR]))
    # the slack laid down is kept until the line has flown or the UAV has left the band,
    # then given back at the slack approach's rate: on the take-off the band's share rises
    # with the chord's elevation, and its bound falling back as fast as the distance grew
    # stood the drum while the climb dragged the line lying on the ground into its exit
    # (22-44 N; docs/control.md §8.5)
    laid = law_s[Z_LAID]
    if law_s[Z_LIFTED] > 0.0 or share >= 1.0:
        laid -= dt_s * law_p[Q_APPROACH] * laid
    low_slack = max(low_slack, laid)
    law_s[Z_LAID] = low_slack
    low = dist + low_slack
    law_s[Z_STIFFNESS] = taut_line_stiffness_n_m(law_s[Z_SETPOINT], w, h, v)
    high = max(lbar_m, room) + law_p[Q_BOUND_M]
    trim_s[TS_JOIN_GAP] = 0.0            # no join: the law has no length reference to jump
    # the exit-elevation loop holds L-bar's least exit angle, or half the chord's
    # elevation where that is flatter (a catenary leaves below its chord: the UAV low and
    # far, as L-bar's own rule there)
    # (both times the lay-down share: low and far the line is let down, not held up)
    exit_min = share * min(math.atan(lbar_p[LB_TAN_MIN]), 0.5 * math.atan2(v, h))
    cmd = tension_law(law_p, law_s, dt_s, length_m, omega_rad_s, drum_tension_n, setpoint,
                      rate, low, radial, high, lbar_m, elevation_rad, exit_min, share, heavy)
    return length_m + law_s[Z_LAG], law_s[Z_SPEED], cmd
