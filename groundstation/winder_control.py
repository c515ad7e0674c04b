"""Backstepping winder-torque control: track the desired tether length L-bar (the paper's
law), or hold the line's tension (``law = "tension"``: :mod:`groundstation.tension_law`).

Model (docs/control.md §4), drum angle positive paying out, L = r_w theta:

    dL/dt = r_w omega
    I_w(L) d(omega)/dt = tau + r_w T_drum - beta_w omega
    I_w(L) = 1/2 (m_w_bar + (L_T - L) rho)(r_w^2 + r_i^2) + I_rotor

Errors and virtual control:  e_L = L - L_c,  alpha = (dL_c/dt - k_L e_L) / r_w,
                             e_w = omega - alpha.
Law:  tau = -r_w T_drum + beta_w omega + I_w d(alpha)/dt - 1/2 dI_w/dt e_w
            - k_w e_w - c r_w e_L
Lyapunov function:  V = 1/2 c e_L^2 + 1/2 I_w e_w^2,  dV/dt = -c k_L e_L^2 - k_w e_w^2.

``T_drum`` is the tension the winch's load cell measures (feed-forward); ``L_c`` follows
L-bar with the analytic rate from the UAV's velocity, and its second derivative comes
from a first-order filter on that rate (command-filtered backstepping). The torque is
limited to the motor's, and alpha to the speed limit.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from groundstation import tension_law as tl
from tuavdefs.jit import JIT, njit
from tuavdefs.params import TetherParams, WinderParams
from tuavdefs.paramspec import Params, quantity


class WinderLaw(enum.Enum):
    """Which law the winder runs while it follows the UAV (RELAXED in flight)."""

    PAPER = "paper"         #: track L-bar's length (docs/control.md §4)
    TENSION = "tension"     #: hold the line's tension (docs/control.md §8)

    @property
    def holds_ground_tension_in_climb(self) -> bool:
        """Whether a take-off low and far goes on under the winch's ground pre-tension
        (:class:`groundstation.winch_ground.GroundPretension`): L-bar's length law asks
        there for a nearly straight line, which only an exact position keeps off taut;
        the tension law lays the line down there itself (its lay-down band), and the
        pre-tension's loop, its drum standing while the climb dragged the line over the
        ground, snapped it (docs/control.md §8.5)."""
        return self is WinderLaw.PAPER


@dataclass(frozen=True)
class WinderControlParams(Params):
    """Gains and limits of the winder torque laws."""

    law: str = quantity(
        "tension", "1", "the law that follows the UAV: the tension-regulating law (the "
        "default, docs/control.md §8) or the paper's length law (its experiments)",
        choices=tuple(m.value for m in WinderLaw))
    rate_hz: float = quantity(100.0, "Hz", "control rate (the encoder frames' rate)", gt=0)
    k_length_1_s: float = quantity(6.0, "1/s", "length error gain k_L", gt=0)
    k_rate_n_m_s: float = quantity(0.6, "N*m*s/rad", "drum-rate error gain k_w", gt=0)
    length_stiffness_n_m: float = quantity(
        20.0, "N/m", "weight c of the length error in the Lyapunov function", gt=0)
    rate_filter_s: float = quantity(
        0.05, "s", "time constant of the filter that differentiates dL-bar/dt", gt=0)
    speed_margin: float = quantity(
        0.9, "1", "share of the motor's speed limit the law may ask for", gt=0, le=1)
    torque_margin: float = quantity(
        1.0, "1", "share of the motor's torque limit the law may ask for", gt=0, le=1)
    tension_floor_n: float = quantity(
        1.0, "N", "tension law: the slack floor, the least tension set-point (a line "
        "held at it is off the ground at the exit)", gt=0)
    tension_setpoint_max_n: float = quantity(
        8.0, "N", "tension law: the most the set-point may ask (near the vertical L-bar's "
        "catenary asks for tens of newtons; the length bound holds the line there)", gt=0)
    tension_heavy_max: float = quantity(
        2.0, "1", "tension law: the set-point's cap and the snap ceiling follow the line's "
        "weight estimate above the model's weight (the same shape hangs at proportionally "
        "more tension), up to this many times (1: never; docs/control.md §8.4)", ge=1)
    tension_margin: float = quantity(
        1.2, "1", "tension law: the set-point over the exit tension of L-bar's catenary "
        "(which leaves the winder at min_exit_angle_rad at least)", ge=1)
    tension_ceiling_n: float = quantity(
        12.0, "N", "tension law: the snap ceiling: above it the drum pays out at "
        "tension_ceiling_gain_m_s_n more per newton, whatever the length bounds say", gt=0)
    tension_gain_m_s_n: float = quantity(
        0.15, "m/(s*N)", "tension law: line speed per newton off the set-point (g_T)", gt=0)
    tension_ceiling_gain_m_s_n: float = quantity(
        0.5, "m/(s*N)", "tension law: line speed per newton above the ceiling (g_c)", ge=0)
    tension_filter_s: float = quantity(
        0.1, "s", "tension law: time constant of its low-pass on the load cell (the "
        "dynamic line's axial waves; 0: none)", ge=0)
    tension_setpoint_filter_s: float = quantity(
        0.5, "s", "tension law: time constant of the low-pass on the set-point (it moves "
        "with the reported position)", gt=0)
    line_acc_max_m_s2: float = quantity(
        10.0, "m/s^2", "tension law: the line speed set-point's acceleration limit: above "
        "the feed-forward's 9.4 m/s^2 for a vehicle accelerating at 8 m/s^2 (at 8 it cut "
        "it and the line snapped at the step's end, docs/control.md §8.2), below what the "
        "drum's torque gives on the full drum against the snap ceiling (12.75 m/s^2), so "
        "that the speed loop keeps a fifth of the torque (at 12 it did not, and two lines "
        "were pulled 0.5 and 2.9 mm past straight: an unhealthy filter's landing, a "
        "consumer receiver's start)", gt=0)
    speed_filter_s: float = quantity(
        0.3, "s", "tension law: time constant of the command filter on the line speed "
        "set-point's feedback part (faster, its derivative's feed-forward shook the drum "
        "and the dynamic line at 8 Hz)", gt=0)
    k_speed_n_m_s: float = quantity(
        0.15, "N*m*s/rad", "tension law: drum-rate error gain k_w of its speed loop (low: "
        "the drum renders to a snap before the force loop sees it)", gt=0)
    slack_recovery_m_s: float = quantity(
        1.0, "m/s", "tension law: below the slack floor the line is wound in towards L-bar "
        "at up to this speed beyond the feed-forward (0: only the force loop's)", ge=0)
    slack_approach_gain_1_s: float = quantity(
        0.15, "1/s", "tension law: below the slack floor and within L-bar, once the line has "
        "flown, its slack above the lower length bound is taken in at most this fast "
        "(relative to the UAV's radial speed): a line that pulls nothing at the exit may be "
        "held up by the wind, and its slack is all that keeps it from a snap", gt=0)
    slack_payout_gain_1_s: float = quantity(
        2.0, "1/s", "tension law: below the slack floor and within L-bar, once the line has "
        "flown, the line is paid out no faster than the lower length bound moves less this "
        "gain times the slack above it, and not at all while that is negative: line paid "
        "out into a line that pulls nothing at the exit piles up in its lowest part, which "
        "is caught taut (docs/control.md §8.2)", gt=0)
    lay_down_height_m: float = quantity(
        1.5, "m", "tension law: low and far (the chord under twice L-bar's least exit "
        "angle) and below twice this height the line is laid down towards the ground, "
        "fully at this height and that angle (the landing's last metres; 0: never)",
        ge=0)
    length_bound_gain_1_s: float = quantity(
        4.0, "1/s", "tension law: the length bounds' loop gain", gt=0)
    length_bound_m: float = quantity(
        3.0, "m", "tension law: the most line beyond L-bar (or the longest line off the "
        "ground) it pays out", gt=0)
    exit_lift_gain_n_s_rad: float = quantity(
        20.0, "N/(s*rad)", "tension law: the exit-elevation loop: how fast the set-point "
        "rises per radian the guide arm's elevation is below L-bar's least exit angle (and "
        "falls, above it, as fast at most as it rises at a flat exit; 0: off; docs/"
        "control.md §8.4)", ge=0)
    exit_lift_max_n: float = quantity(
        6.0, "N", "tension law: the most the exit-elevation loop raises the set-point (the "
        "snap ceiling caps the sum)", ge=0)
    exit_lift_lag_m: float = quantity(
        0.1, "m", "tension law: the exit-elevation loop raises the set-point only while the "
        "drum is at most this far behind its speed set-point (low-passed over 0.5 s: the "
        "cascade's anti-windup, a snagged drum; docs/control.md §8.4)", gt=0)
    line_stiffness_n_m: float = quantity(
        10.0, "N/m", "tension law: the line's stiffness kappa its Lyapunov function is "
        "reported with, and the stiffest line the set-point loop's gain is designed for "
        "(stiffer, near the vertical, the gain falls as kappa_0 / kappa)", gt=0)


class WinderCommand(NamedTuple):
    """Output of one winder control step."""

    torque_n_m: float
    e_length_m: float
    e_rate_rad_s: float
    rate_cmd_rad_s: float
    lyapunov: float
    saturated: bool


#: Time constant [s] of the leak on the tension law's record of how far the drum lags its
#: speed set-point (what the winch's stuck check reads as the reference's lead).
LAG_TIME_S = 0.5

# indices of the packed parameters (WinderController._pack) and of the filter's state
(P_K_L, P_K_W, P_C, P_RATE_FILTER, P_R_W, P_BETA, P_TAU_MAX, P_OMEGA_MAX, P_M_BAR, P_RHO,
 P_L_T, P_R2, P_I_ROTOR) = range(13)
S_STARTED, S_RATE, S_ACC = 0, 1, 2


class WinderController:
    """The winder's backstepping torque law (a controller-side model of the drum).

    The gains and the drum model are packed for the compiled law (:func:`winder_law`),
    again whenever one of the attributes they come from is replaced.
    """

    def __init__(self, gains: WinderControlParams, winder: WinderParams,
                 tether: TetherParams) -> None:
        self.g = gains
        self.r_w = winder.drum_radius_m
        self.beta = winder.viscous_friction_n_m_s_rad
        self.tau_max = gains.torque_margin * winder.motor_torque_limit_n_m
        self.omega_max = gains.speed_margin * winder.motor_speed_limit_rad_s
        self._m_bar = winder.drum_mass_kg
        self._rho = tether.linear_density_kg_m
        self._lt = tether.total_length_m
        self._r2 = winder.drum_radius_m ** 2 + winder.drum_inner_radius_m ** 2
        self._i_rotor = winder.rotor_inertia_kg_m2
        self._pack()
        # the reference filter: started?, filtered dL_c/dt, its derivative d2L_c/dt2
        self.state = np.zeros(3)
        #: the law that follows the UAV
        self.law = WinderLaw(gains.law)
        #: the tension law's state (groundstation.tension_law: started?, filtered tension
        #: [N], filtered set-point [N], line speed set-point [m/s], its rate [m/s^2], the
        #: drum's lag behind it [m], the set-point before its filter [m/s])
        self.tension_state = np.zeros(tl.N_TENSION_STATE)
        if JIT:  # load (or compile) the law's machine code now, not at the first update
            winder_law(self._p, self.state.copy(), 0.01, 10.0, 0.0, 1.0, 10.0, 0.0)

    def _sources(self) -> tuple[Any, ...]:
        return (self.g, self.r_w, self.beta, self.tau_max, self.omega_max, self._m_bar,
                self._rho, self._lt, self._r2, self._i_rotor)

    def _pack(self) -> None:
        g = self.g
        self._p = np.array([
            g.k_length_1_s, g.k_rate_n_m_s, g.length_stiffness_n_m, g.rate_filter_s,
            self.r_w, self.beta, self.tau_max, self.omega_max, self._m_bar, self._rho,
            self._lt, self._r2, self._i_rotor], dtype=float)
        self._packed_from = self._sources()
        self._tension_from: tuple[Any, ...] | None = None

    def tension_params(self) -> np.ndarray:
        """The tension law's gains and drum model packed for
        :func:`groundstation.tension_law.tension_law`."""
        self.params()
        if self._tension_from is not self._packed_from:
            g = self.g
            q = np.zeros(tl.N_TENSION_PARAMS)
            q[tl.Q_R_W], q[tl.Q_BETA], q[tl.Q_TAU_MAX] = self.r_w, self.beta, self.tau_max
            q[tl.Q_V_MAX] = self.omega_max * self.r_w
            q[tl.Q_M_BAR], q[tl.Q_RHO], q[tl.Q_L_T] = self._m_bar, self._rho, self._lt
            q[tl.Q_R2], q[tl.Q_I_ROTOR] = self._r2, self._i_rotor
            q[tl.Q_FILTER], q[tl.Q_SP_FILTER] = g.tension_filter_s, g.tension_setpoint_filter_s
            q[tl.Q_GAIN], q[tl.Q_CEIL] = g.tension_gain_m_s_n, g.tension_ceiling_n
            q[tl.Q_CEIL_GAIN], q[tl.Q_ACC_MAX] = g.tension_ceiling_gain_m_s_n, g.line_acc_max_m_s2
            q[tl.Q_CMD_FILTER], q[tl.Q_K_W] = g.speed_filter_s, g.k_speed_n_m_s
            q[tl.Q_K_BOUND], q[tl.Q_STIFFNESS] = g.length_bound_gain_1_s, g.line_stiffness_n_m
            q[tl.Q_FLOOR], q[tl.Q_SP_MAX] = g.tension_floor_n, g.tension_setpoint_max_n
            q[tl.Q_MARGIN], q[tl.Q_BOUND_M] = g.tension_margin, g.length_bound_m
            q[tl.Q_LAG_S] = LAG_TIME_S
            q[tl.Q_RECOVER] = g.slack_recovery_m_s
            q[tl.Q_LIFT_GAIN], q[tl.Q_LIFT_MAX] = g.exit_lift_gain_n_s_rad, g.exit_lift_max_n
            q[tl.Q_LIFT_LAG] = g.exit_lift_lag_m
            q[tl.Q_APPROACH] = g.slack_approach_gain_1_s
            q[tl.Q_PAYOUT] = g.slack_payout_gain_1_s
            q[tl.Q_LAY_HEIGHT] = g.lay_down_height_m
            q[tl.Q_HEAVY_MAX] = g.tension_heavy_max
            self._q = q
            self._tension_from = self._packed_from
        return self._q

    def params(self) -> np.ndarray:
        """The gains and drum model packed for :func:`winder_law`."""
        f = self._packed_from
        if (self.g is not f[0] or self.r_w is not f[1] or self.beta is not f[2]
                or self.tau_max is not f[3] or self.omega_max is not f[4]
                or self._m_bar is not f[5] or self._rho is not f[6] or self._lt is not f[7]
                or self._r2 is not f[8] or self._i_rotor is not f[9]):
            self._pack()
        return self._p

    def inertia_kg_m2(self, length_m: float) -> float:
        """The law's model of the drum inertia at a paid-out length [kg m^2]."""
        return drum_inertia_model(self.params(), length_m)

    def reset(self) -> None:
        """Forget the reference filter and the tension law's state."""
        self.state[:] = 0.0
        self.tension_state[:] = 0.0

    def update_tension(self, dt_s: float, length_m: float, omega_rad_s: float,
                       tension_n: float, setpoint_n: float, ff_rate_m_s: float,
                       low_m: float, low_rate_m_s: float, high_m: float,
                       recover_m: float = math.nan, elevation_rad: float = math.nan,
                       exit_min_rad: float = 0.0) -> WinderCommand:
        """Torque request [N m] of the tension law (:func:`groundstation.tension_law.
        tension_law`) for the measured length [m], drum rate [rad/s] and tension [N], the
        set-point [N], the line speed's feed-forward [m/s] and the length bounds [m]
        (the lower moving at ``low_rate_m_s``), the length a slack line is wound in towards
        [m] (NaN: none), the guide arm's exit elevation [rad] (NaN: none) and the least
        the exit-elevation loop holds it at [rad] (0: the loop off); the length law's
        filter is forgotten."""
        self.state[:] = 0.0
        return WinderCommand(*tl.tension_law(
            self.tension_params(), self.tension_state, dt_s, length_m, omega_rad_s,
            tension_n, setpoint_n, ff_rate_m_s, low_m, low_rate_m_s, high_m, recover_m,
            elevation_rad, exit_min_rad))

    def update(self, dt_s: float, length_m: float, omega_rad_s: float, drum_tension_n: float,
               ref_length_m: float, ref_rate_m_s: float) -> WinderCommand:
        """Torque request [N m] of the length law for the measured length, drum rate and
        tension (the tension law, not running meanwhile, starts afresh when it next runs)."""
        self.tension_state[tl.Z_STARTED] = 0.0
        return WinderCommand(*winder_law(self.params(), self.state, dt_s, length_m,
                                         omega_rad_s, drum_tension_n, ref_length_m,
                                         ref_rate_m_s))


@njit
def drum_inertia_model(p: np.ndarray, length_m: float) -> float:
    """:meth:`WinderController.inertia_kg_m2` on the packed parameters ``p``."""
    m_w = p[P_M_BAR] + max(p[P_L_T] - length_m, 0.0) * p[P_RHO]
    return 0.5 * m_w * p[P_R2] + p[P_I_ROTOR]


@njit
def winder_law(p: np.ndarray, s: np.ndarray, dt_s: float, length_m: float,
               omega_rad_s: float, drum_tension_n: float, ref_length_m: float,
               ref_rate_m_s: float) -> tuple[float, float, float, float, float, bool]:
    """One step of :class:`WinderController` (the law of the module docstring) on the packed
    parameters ``p``, advancing the reference filter ``s`` in place; returns the fields of
    a :class:`WinderCommand`."""
    # second derivative of the reference from a first-order filter on its rate
    if not s[S_STARTED]:
        s[S_STARTED], s[S_RATE] = 1.0, ref_rate_m_s
    k = 1.0 - math.exp(-dt_s / p[P_RATE_FILTER])
    new_rate = s[S_RATE] + k * (ref_rate_m_s - s[S_RATE])
    s[S_ACC] = (new_rate - s[S_RATE]) / dt_s
    s[S_RATE] = new_rate
    ref_acc = s[S_ACC]

    r = p[P_R_W]
    k_l = p[P_K_L]
    omega_max = p[P_OMEGA_MAX]
    e_l = length_m - ref_length_m
    alpha = (ref_rate_m_s - k_l * e_l) / r
    alpha_limited = min(max(alpha, -omega_max), omega_max)
    l_dot = r * omega_rad_s
    alpha_dot = (ref_acc - k_l * (l_dot - ref_rate_m_s)) / r
    if alpha_limited != alpha:
        alpha_dot = 0.0
    e_w = omega_rad_s - alpha_limited
    inertia = drum_inertia_model(p, length_m)
    inertia_dot = -0.5 * p[P_RHO] * p[P_R2] * l_dot
    tau = (-r * drum_tension_n + p[P_BETA] * omega_rad_s + inertia * alpha_dot
           - 0.5 * inertia_dot * e_w - p[P_K_W] * e_w
           - p[P_C] * r * e_l)
    tau_max = p[P_TAU_MAX]
    tau_limited = min(max(tau, -tau_max), tau_max)
    lyap = 0.5 * p[P_C] * e_l * e_l + 0.5 * inertia * e_w * e_w
    return (tau_limited, e_l, e_w, alpha_limited, lyap,
            tau_limited != tau or alpha_limited != alpha)
