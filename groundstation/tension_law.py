"""The tension-regulating winder law: the drum holds the line's pull at a set-point.

A constant-tension winch as tether and mooring stations run one: a force loop gives the
drum a line-speed set-point (pay out above the set tension, wind in below it), a command
filter limits that set-point's speed and acceleration, and a backstepping speed loop on
the drum, whose inertia changes with the wound length, tracks it. Derivation, Lyapunov
function, proof and where it fails: docs/control.md §8.

Model of the design (the drum as in :mod:`groundstation.winder_control`, the line as a
spring of stiffness kappa between the drum and the line length ``ell`` the UAV's position
asks for at the set tension):

    dL/dt = r_w omega
    I_w(L) d(omega)/dt = tau + r_w T - beta_w omega
    dT/dt = -kappa (r_w omega - d(ell)/dt)

Errors: ``e = T - T*``, ``e_w = omega - v_c / r_w`` with ``v_c`` the filtered line-speed
set-point. Virtual control (a line speed) ``v0 = d(ell)/dt + sigma(T)``,
``sigma = g_T e + g_c max(T - T_ceil, 0)``, between the length bounds. Law:

    tau = -r_w T* + beta_w omega + I_w dv_c/dt / r_w - 1/2 dI_w/dt e_w - k_w e_w

(the measured tension's feed-forward and the backstepping cross term ``+r_w e`` add up to
the set-point's: the drum renders to the line's true pull by itself). Lyapunov function
``V = e^2 / (2 kappa) + 1/2 I_w e_w^2`` [J], with

    dV/dt = -e sigma(T) - k_w e_w^2 - e (v_c - v0)

(the last term is the command filter's lag and the bounds: zero while neither acts).
While a length bound holds the line, the torque's ``T*`` follows the measured tension
(anti-windup); below the slack floor the line is wound in towards L-bar (the slack
floor's recovery; once the line has flown, within L-bar its slack is taken no faster
than the slack approach, the line paid out no faster than the slack pay-out, and the
torque holds the tension the line has). The
exit-elevation loop (:func:`exit_lift`) raises the force loop's
set-point ``T* + dT`` while the guide arm reads the line leaving below L-bar's least exit
angle and the drum follows its speed set-point: the windless catenary's ``T*``
does not keep a line that the wind bows off the ground (docs/control.md §8.4).
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.lbar import expected_drum_tension_n
from tuavdefs.jit import njit

# indices of the packed parameters (WinderController.tension_params)
(Q_R_W, Q_BETA, Q_TAU_MAX, Q_V_MAX, Q_M_BAR, Q_RHO, Q_L_T, Q_R2, Q_I_ROTOR, Q_FILTER,
 Q_SP_FILTER, Q_GAIN, Q_CEIL, Q_CEIL_GAIN, Q_ACC_MAX, Q_CMD_FILTER, Q_K_W, Q_K_BOUND,
 Q_STIFFNESS, Q_FLOOR, Q_SP_MAX, Q_MARGIN, Q_BOUND_M, Q_LAG_S, Q_RECOVER, Q_LIFT_GAIN,
 Q_LIFT_MAX, Q_LIFT_LAG, Q_APPROACH, Q_LAY_HEIGHT, Q_HEAVY_MAX, Q_PAYOUT) = range(32)
N_TENSION_PARAMS = 32
# indices of its state (Z_LIFT: the exit-elevation loop's raise of the set-point [N];
# Z_LAID: the lower length bound's slack laid down and not yet given back [m],
# groundstation.winder_host.tension_step)
(Z_STARTED, Z_TENSION, Z_SETPOINT, Z_SPEED, Z_ACC, Z_LAG, Z_SPEED_RAW, Z_FEEDBACK,
 Z_FF, Z_STIFFNESS, Z_LIFT, Z_LIFTED, Z_LAID) = range(13)
N_TENSION_STATE = 13


#: Time constant [s] of the low-pass on the line speed's feed-forward (dL-bar/dt from the
#: UAV's reported velocity, at the telemetry's 100 Hz).
FF_FILTER_S = 0.03


@njit
def _inertia(p: np.ndarray, length_m: float) -> float:
    """The law's model of the drum inertia at a paid-out length [kg m^2]."""
    m_w = p[Q_M_BAR] + max(p[Q_L_T] - length_m, 0.0) * p[Q_RHO]
    return 0.5 * m_w * p[Q_R2] + p[Q_I_ROTOR]


@njit
def gain_scale(p: np.ndarray, stiffness_n_m: float) -> float:
    """The set-point loop's gain over ``g_T`` for a line of stiffness ``stiffness_n_m``
    [N/m] (0: unknown): 1 up to the stiffness the gain is designed for
    (``line_stiffness_n_m``), ``kappa_0 / kappa`` above it, so that ``g_T kappa``, the
    loop's bandwidth, stays below the filters' (docs/control.md §8.3)."""
    if stiffness_n_m > p[Q_STIFFNESS]:
        return p[Q_STIFFNESS] / stiffness_n_m
    return 1.0


@njit
def taut_line_stiffness_n_m(tension_n: float, w_n_m: float, h_m: float, v_m: float) -> float:
    """dT/dL [N/m] of a taut, shallow-sag line at fixed ends holding ``tension_n`` [N] at
    the winder, spanning ``h_m`` across and ``v_m`` up, weighing ``w_n_m`` [N/m]: a
    string under the load ``q = w h / d`` across its chord ``d`` at tension ``T`` has
    the slack ``q^2 d^3 / (24 T^2)``, so ``dT/dL = 12 T^3 / (q^2 d^3)``, with ``T`` the
    geometric mean of the exit's tension and the top's (the exit's plus the weight
    ``w v``): within 15 % of MoorPy's catenary where the line is stiff (tens of N/m and
    more), within 40 % where it sags (tests/test_tension_law.py); 0 where there is no
    chord."""
    d = math.hypot(h_m, v_m)
    q = w_n_m * h_m / d if d > 0.0 else 0.0
    if q <= 0.0 or tension_n <= 0.0:
        return 0.0
    t = math.sqrt(tension_n * (tension_n + w_n_m * v_m))
    return 12.0 * t * t * t / (q * q * d * d * d)


@njit
def tension_speed(p: np.ndarray, tension_n: float, setpoint_n: float,
                  ff_rate_m_s: float, scale: float = 1.0, heavy: float = 1.0) -> float:
    """The force loops' line speed [m/s] (positive paying out): the feed-forward
    ``ff_rate_m_s`` plus ``sigma(T)`` (the set-point loop, its gain ``g_T`` times
    ``scale``, and the snap ceiling's steeper pay-out above ``T_ceil`` times ``heavy``,
    :func:`heavy_scale`)."""
    sigma = scale * p[Q_GAIN] * (tension_n - setpoint_n)
    over = tension_n - heavy * p[Q_CEIL]
    if over > 0.0:
        sigma += p[Q_CEIL_GAIN] * over
    return ff_rate_m_s + sigma


@njit
def heavy_scale(p: np.ndarray, w_n_m: float, w_model_n_m: float) -> float:
    """How much the set-point's cap and the snap ceiling are raised [1] for a line
    weighing ``w_n_m`` [N/m] (the weight estimate) against the model's ``w_model_n_m``:
    their ratio, at least 1 and at most ``p[Q_HEAVY_MAX]``. A line k times as heavy hangs
    the same shape at k times the tension, so the caps set for the model's line would
    hold a heavier one on the ground (docs/control.md §8.4)."""
    if not (w_n_m > 0.0 and w_model_n_m > 0.0):
        return 1.0
    return min(max(w_n_m / w_model_n_m, 1.0), max(p[Q_HEAVY_MAX], 1.0))


@njit
def exit_lift(p: np.ndarray, s: np.ndarray, dt_s: float, elevation_rad: float,
              exit_min_rad: float, lag_m: float = 0.0) -> None:
    """One step of the exit-elevation loop (docs/control.md §8.4): the raise of the
    set-point ``s[Z_LIFT]`` [N] integrates the guide arm's elevation ``elevation_rad``
    [rad] below ``exit_min_rad`` [rad] at ``lift_gain`` N/(s rad), the error bounded to
    +-``exit_min_rad`` (a steep line gives the raise back no faster than a flat one
    takes it), the raise within [0, ``lift_max``]; held without a reading (NaN: the
    line pulls nothing at the exit) or without a reference (``exit_min_rad`` 0). It
    rises only while the drum follows its speed set-point, within ``lift_lag`` of it
    (``lag_m`` [m], the drum's low-passed lag, ``s[Z_LAG]``: 0 following): a raise
    integrated while the drum cannot act (a snag) is the cascade's windup, and winds the
    line in hard once the drum follows (a stall released on the way in: 1.9x its steady
    pull; the tension's own lag behind the raised set-point is no such sign: a line on
    the ground pulls little more as it is wound in, until it lifts). It is armed
    once the arm has read the line leaving at twice ``exit_min_rad`` (``s[Z_LIFTED]``):
    a line that has not yet lifted off the ground (the take-off) is not one the wind
    bows down."""
    if elevation_rad == elevation_rad and elevation_rad >= 2.0 * exit_min_rad:
        s[Z_LIFTED] = 1.0
    if elevation_rad == elevation_rad and exit_min_rad > 0.0 and s[Z_LIFTED] > 0.0:
        err = min(max(exit_min_rad - elevation_rad, -exit_min_rad), exit_min_rad)
        if err > 0.0 and abs(lag_m) > p[Q_LIFT_LAG]:
            return
        s[Z_LIFT] = min(max(s[Z_LIFT] + dt_s * p[Q_LIFT_GAIN] * err, 0.0), p[Q_LIFT_MAX])


@njit
def tension_law(p: np.ndarray, s: np.ndarray, dt_s: float, length_m: float,
                omega_rad_s: float, tension_n: float, setpoint_n: float,
                ff_rate_m_s: float, low_m: float, low_rate_m_s: float, high_m: float,
                recover_m: float, elevation_rad: float = math.nan,
                exit_min_rad: float = 0.0, share: float = 1.0, heavy: float = 1.0
                ) -> tuple[float, float, float, float, float, bool]:
    """One step of the tension law (module docstring) on the packed parameters ``p``,
    its state ``s`` advanced in place: the load cell's ``tension_n`` [N] low-passed; the
    set-point ``setpoint_n`` [N] raised by the exit-elevation loop (:func:`exit_lift`:
    the guide arm's ``elevation_rad`` [rad], NaN: no reading, held at ``exit_min_rad``
    [rad] or above, the raise times ``share``, :func:`lay_down_share`) and low-passed;
    the force loops' speed bounded by the length bounds ``low_m`` (moving at
    ``low_rate_m_s``) and ``high_m`` [m] and by the ceiling (times ``heavy``,
    :func:`heavy_scale`);
    a slack line (below the floor) wound in towards ``recover_m`` [m] (NaN: none) at up to
    the recovery speed (once the line has flown, ``s[Z_LIFTED]``: within it no faster than
    the slack approach and paid out no faster than the slack pay-out, both towards
    ``low_m``, the torque on the measured tension),
    the speed set-point filtered with its acceleration limit, then the backstepping
    torque. Returns the fields of a :class:`~groundstation.winder_control.WinderCommand`
    (torque [N m], tension error [N] in the length error's place, e_w [rad/s], the drum
    rate set-point [rad/s], V [J], saturated)."""
    r = p[Q_R_W]
    v_max = p[Q_V_MAX]
    if not s[Z_STARTED]:
        s[Z_STARTED] = 1.0
        s[Z_TENSION] = tension_n
        s[Z_SETPOINT] = setpoint_n
        s[Z_SPEED] = min(max(r * omega_rad_s, -v_max), v_max)
        s[Z_ACC] = 0.0
        s[Z_LAG] = 0.0
        s[Z_FF] = ff_rate_m_s
        s[Z_FEEDBACK] = s[Z_SPEED] - ff_rate_m_s
        s[Z_LIFT] = 0.0
        s[Z_LIFTED] = 0.0
        s[Z_LAID] = 0.0
    if p[Q_FILTER] > 0.0:
        s[Z_TENSION] += (1.0 - math.exp(-dt_s / p[Q_FILTER])) * (tension_n - s[Z_TENSION])
    else:
        s[Z_TENSION] = tension_n
    t_f, t_sp = s[Z_TENSION], s[Z_SETPOINT]
    # the guide arm follows a line that pulls: below the slack floor (now, or on the
    # average) its reading is the arm's, not the line's (the lumped line's first segment
    # slack: 0 rad at 0.05 N)
    if min(t_f, tension_n) < p[Q_FLOOR]:
        elevation_rad = math.nan
    exit_lift(p, s, dt_s, elevation_rad, exit_min_rad, s[Z_LAG])
    # the raise enters the force loop's set-point, not the torque's: the drum renders from
    # the line's own set-point, and tracks the speed the raise asks
    ceil = heavy * p[Q_CEIL]
    v0 = tension_speed(p, t_f, min(t_sp + share * s[Z_LIFT], max(ceil, t_sp)),
                       ff_rate_m_s, gain_scale(p, s[Z_STIFFNESS]), heavy)
    k_b = p[Q_K_BOUND]
    # the slack floor's recovery: a line pulling less than the floor says nothing of how
    # much of it hangs slack; the length the UAV's position asks does, and is wound in
    # towards at up to the recovery speed, blended in as the tension falls below the floor
    # (once the line has flown, within L-bar the force loop's wind-in on at most the slack
    # approach's rate towards the lower bound: a line that pulls nothing at the exit yet is
    # no longer than L-bar may be held up by the wind, its lowest segment loose over the
    # winder, and the force loop's wind-in snapped it straight: 115 N; and no pay-out beyond
    # the slack pay-out's rate towards it, nor any while the UAV comes in: line paid out
    # into a line that pulls nothing at the exit piles up in its loose lowest segment, and
    # the node above it, dragged out by the line above, caught it taut: 53 N at 0.75 m of
    # it; and the torque holds the tension the line has. Not before it has flown: on the
    # take-off the set-point's torque pulls the line on the ground straight, which the
    # winder's tether fix counts on)
    slack = (p[Q_FLOOR] - t_f) / p[Q_FLOOR]
    recovering = 0.0
    if slack > 0.0 and p[Q_RECOVER] > 0.0 and recover_m == recover_m:
        if s[Z_LIFTED] > 0.0 and length_m <= recover_m:
            v_rec = max(v0, low_rate_m_s - p[Q_APPROACH] * (length_m - low_m))
            v_rec = min(v_rec, max(low_rate_m_s - p[Q_PAYOUT] * (length_m - low_m), 0.0))
            recovering = min(slack, 1.0)
            v0 += recovering * (v_rec - v0)
        else:
            v_rec = ff_rate_m_s - min(k_b * max(length_m - recover_m, 0.0), p[Q_RECOVER])
            if v_rec < v0:
                v0 += min(slack, 1.0) * (v_rec - v0)
            if s[Z_LIFTED] > 0.0:
                recovering = min(slack, 1.0)
    # command filter: the force loops' part first order (the load cell's noise, the
    # dynamic line's waves), the feed-forward (the UAV's reported motion: smooth) on a
    # light low-pass
    s[Z_FEEDBACK] += (1.0 - math.exp(-dt_s / p[Q_CMD_FILTER])) * (
        v0 - ff_rate_m_s - s[Z_FEEDBACK])
    s[Z_FF] += (1.0 - math.exp(-dt_s / FF_FILTER_S)) * (ff_rate_m_s - s[Z_FF])
    v = s[Z_FF] + s[Z_FEEDBACK]
    # the length bounds, on the encoder's length and the reported position (clean: not
    # filtered): never shorter than low_m (a length loop takes over there), never longer
    # than high_m; the snap ceiling beats both
    free = v
    v = max(v, low_rate_m_s - k_b * (length_m - low_m))
    v = min(v, ff_rate_m_s + k_b * (high_m - length_m))
    if t_f > ceil:
        v = max(v, free)
    # anti-windup: while a bound holds the line, the tension the torque holds is the one
    # the line has (else the set-point's torque drives the drum against its speed loop);
    # free again, the set-point returns on its own filter
    if v != free:
        s[Z_SETPOINT] += (1.0 - math.exp(-dt_s / max(p[Q_FILTER], dt_s))) * (
            t_f - s[Z_SETPOINT])
    else:
        s[Z_SETPOINT] += (1.0 - math.exp(-dt_s / p[Q_SP_FILTER])) * (
            setpoint_n - s[Z_SETPOINT])
    t_sp = s[Z_SETPOINT]
    # (the set-point's torque against a line that pulls nothing winds the drum in
    # r_w^2 (T* - T) / k_w faster than its speed set-point)
    t_tau = t_sp + recovering * (t_f - t_sp)
    saturated = False
    if abs(v) > v_max:
        v = math.copysign(v_max, v)
        saturated = True
    s[Z_SPEED_RAW] = v
    # the sum acceleration limited
    acc = (v - s[Z_SPEED]) / dt_s
    a_max = p[Q_ACC_MAX]
    if abs(acc) > a_max:
        acc = math.copysign(a_max, acc)
        saturated = True
    s[Z_ACC] = acc
    s[Z_SPEED] += acc * dt_s
    v_c = s[Z_SPEED]
    alpha = v_c / r
    alpha_dot = acc / r
    e_w = omega_rad_s - alpha
    inertia = _inertia(p, length_m)
    inertia_dot = -0.5 * p[Q_RHO] * p[Q_R2] * r * omega_rad_s
    tau = (-r * t_tau + p[Q_BETA] * omega_rad_s + inertia * alpha_dot
           - 0.5 * inertia_dot * e_w - p[Q_K_W] * e_w)
    tau_max = p[Q_TAU_MAX]
    tau_limited = min(max(tau, -tau_max), tau_max)
    # how far the drum is behind the speed it is asked (a snag: the winch's stuck check)
    # (a drum winding in faster than asked is not behind: it renders to a line that pulls
    # less than the set-point, and is no snag)
    lag_rate = v_c - r * omega_rad_s
    if v_c <= 0.0:
        lag_rate = min(lag_rate, 0.0)
    s[Z_LAG] += dt_s * (lag_rate - s[Z_LAG] / p[Q_LAG_S])
    e = t_f - t_sp
    lyap = 0.5 * e * e / p[Q_STIFFNESS] + 0.5 * inertia * e_w * e_w
    return tau_limited, e, e_w, alpha, lyap, saturated or tau_limited != tau


def hold_speed(s: np.ndarray, speed_m_s: float) -> None:
    """Anti-windup for a drum that cannot follow (a snag: the winch's stuck check): the
    law's state ``s`` with its speed set-point, that set-point's feedback part and its lag
    restarted from the drum's measured line speed ``speed_m_s`` [m/s]; the tension's and
    the set-point's filters run on (else the set-point runs on to the law's speed limit,
    and a drum released with it pays out a metre of slack at once)."""
    if s[Z_STARTED]:
        s[Z_SPEED] = speed_m_s
        s[Z_FEEDBACK] = speed_m_s - s[Z_FF]
        s[Z_ACC] = 0.0
        s[Z_LAG] = 0.0


@njit
def slack_tension_n(w_n_m: float, h_m: float, v_m: float, slack_m: float) -> float:
    """The exit tension [N] at which a taut, shallow-sag line spanning ``h_m`` across and
    ``v_m`` up, weighing ``w_n_m`` [N/m], has ``slack_m`` [m] of slack (the string of
    :func:`taut_line_stiffness_n_m`: the geometric mean ``T_m`` of its exit's and top's
    tension has ``q^2 d^3 / (24 T_m^2)`` of slack); inf where nothing hangs across."""
    d = math.hypot(h_m, v_m)
    q = w_n_m * h_m / d if d > 0.0 else 0.0
    if q <= 0.0 or slack_m <= 0.0:
        return math.inf
    tm2 = q * q * d * d * d / (24.0 * slack_m)
    wv = w_n_m * v_m
    return 0.5 * (math.sqrt(wv * wv + 4.0 * tm2) - wv)


@njit
def string_slack_m(w_n_m: float, h_m: float, v_m: float, tension_n: float) -> float:
    """The slack [m] of the taut, shallow-sag line of :func:`slack_tension_n` pulling
    ``tension_n`` [N] at its exit (that function's inverse: its top pulls ``w v`` more, and
    ``q^2 d^3 / (24 T_m^2)`` with ``T_m^2`` the product of the two); 0 where nothing hangs
    across."""
    d = math.hypot(h_m, v_m)
    q = w_n_m * h_m / d if d > 0.0 else 0.0
    tm2 = tension_n * (tension_n + w_n_m * v_m)
    if q <= 0.0 or tm2 <= 0.0:
        return 0.0
    return q * q * d * d * d / (24.0 * tm2)


@njit
def lay_down_share(p: np.ndarray, exit_min_rad: float, h_m: float, v_m: float) -> float:
    """How much of the suspending set-point the station asks [0, 1] with the UAV ``h_m``
    [m] across and ``v_m`` [m] up: 1 less the product of two lay-down shares, each
    linear from 1 to 0 between twice its bound and the bound: the chord's elevation
    below twice L-bar's least exit angle ``exit_min_rad`` [rad] (low and far, the
    catenary that leaves the winder at that angle is nearly straight and its pull nearly
    level at the UAV: 8 N, a 0.23 rad lean, landing 8.5 m out at 1.5 m up) and the height
    below twice ``lay_down_height_m`` (``p[Q_LAY_HEIGHT]``: the landing's last metres; in
    flight above it the line is held off the ground whatever it costs, up to the cap).
    There the station lays the line down, as it lies before a take-off."""
    if exit_min_rad <= 0.0:
        return 1.0
    v = max(v_m, 0.0)
    low_angle = 1.0 - min(max(math.atan2(v, h_m) / exit_min_rad - 1.0, 0.0), 1.0)
    z_lay = p[Q_LAY_HEIGHT]
    low_height = 1.0 - min(max(v / z_lay - 1.0, 0.0), 1.0) if z_lay > 0.0 else 0.0
    return 1.0 - low_angle * low_height


@njit
def tension_setpoint_n(p: np.ndarray, a_m: float, h_m: float, v_m: float,
                       w_n_m: float, min_slack_m: float, share: float = 1.0,
                       heavy: float = 1.0) -> float:
    """The tension set-point [N]: the exit tension of L-bar's catenary (parameter ``a_m``
    [m], spanning ``h_m`` across and ``v_m`` up, weighing ``w_n_m`` [N/m]) times the
    margin, at most the tension at which the line keeps ``min_slack_m`` [m] of slack
    (:func:`slack_tension_n`: near the vertical L-bar's catenary asks tens of newtons of
    a nearly straight line), between the slack floor and the set-point's cap times
    ``heavy`` (:func:`heavy_scale`; the floor where that catenary is degenerate: the UAV
    above the winder, or low and far), the part above the floor times ``share``
    (:func:`lay_down_share`)."""
    t_hat = expected_drum_tension_n(a_m, h_m, v_m, w_n_m)
    if not math.isfinite(t_hat):
        return p[Q_FLOOR]
    t_sp = min(p[Q_MARGIN] * t_hat, slack_tension_n(w_n_m, h_m, v_m, min_slack_m))
    t_sp = min(max(t_sp, p[Q_FLOOR]), heavy * p[Q_SP_MAX])
    return p[Q_FLOOR] + share * (t_sp - p[Q_FLOOR])
