"""The compiled core of the truth model: the state derivative and its RK4 step.

Scalar Python that numba compiles (``sitl._jit.njit``); it *is* the model — ``sitl.plant.rhs``
and ``sitl.winder.WinderModel`` call into it — so there is one implementation of the
equations in docs/model.md. Parameters arrive packed in a float array (indices below,
filled by :func:`pack_params`); the tether solver's warm start is a 2-element array the
kernel updates in place.
"""

from __future__ import annotations

import math

import numpy as np

from sitl._jit import njit
from sitl.catenary import _solve
from sitl.lumped import line_params, line_rhs, node_count
from tuavdefs.airframe import ROTOR_LAYOUT
from tuavdefs.params import SystemParams, TetherModel

# indices of the packed parameter array
(P_G, P_M, P_IXX, P_IYY, P_IZZ, P_KF, P_KM, P_D, P_TAU_M, P_DRAG_X, P_DRAG_Y, P_DRAG_Z,
 P_ROT_DAMP, P_GEAR, P_MU, P_W, P_EA, P_RW, P_THETA_MIN, P_THETA_MAX, P_M_BAR, P_RHO,
 P_LT, P_RADII_SQ, P_I_ROTOR, P_BETA, P_TAU_MAX, P_OMEGA_MAX, P_KV, P_BRAKE, P_HALF_RHO_AIR,
 P_CDA_X, P_CDA_Y, P_CDA_Z, P_ATT_X, P_ATT_Y, P_ATT_Z, P_LUMPED, P_CONTACT_X, P_CONTACT_Y,
 P_CONTACT_Z) = range(41)
N_PARAMS = 41

# the tether's auxiliary array ("warm"): the catenary's warm start (H, V), and the lumped
# line's pull on the UAV (x, y, z) [N], drum tension [N], top tension [N] and pull on the
# exit (x, y, z) [N] at the current state, which the read-outs (the state derivative for
# the sensors) use, with its lowest node's height [m] and the nodes on the ground
W_H, W_V, W_FX, W_FY, W_FZ, W_DRUM, W_TOP, W_EX, W_EY, W_EZ, W_LOWEST, W_GROUNDED = range(12)
N_WARM = 12

#: Heights within this of the gear height count as touching the ground [m].
GROUND_EPS_M = 1e-6
#: Horizontal speeds below this count as stopped for static friction [m/s].
STICK_SPEED_M_S = 1e-3
#: Time constant with which the landing gear brings body rates on the ground to the
#: levelling rate [s].
GEAR_RATE_DAMPING_S = 0.02
#: Time constant with which a vehicle resting on its gear returns to level [s]: four times
#: the rates' (critically damped); it rotates back, at body rates its gyroscope sees.
GEAR_LEVEL_S = 4.0 * GEAR_RATE_DAMPING_S
#: Drum rates below this [rad/s] count as stopped for the brake and the hard stops.
STOPPED_RAD_S = 1e-6
#: Relative Newton step at which the tether solve stops inside the kernel.
TETHER_TOL = 1e-8

_SX = (ROTOR_LAYOUT[0][0], ROTOR_LAYOUT[1][0], ROTOR_LAYOUT[2][0], ROTOR_LAYOUT[3][0])
_SY = (ROTOR_LAYOUT[0][1], ROTOR_LAYOUT[1][1], ROTOR_LAYOUT[2][1], ROTOR_LAYOUT[3][1])
_SPIN = (ROTOR_LAYOUT[0][2], ROTOR_LAYOUT[1][2], ROTOR_LAYOUT[2][2], ROTOR_LAYOUT[3][2])


def pack_params(params: SystemParams) -> np.ndarray:
    """The parameters as the kernel reads them."""
    v, t, w, env = params.vehicle, params.tether, params.winder, params.environment
    p = np.zeros(N_PARAMS)
    p[P_G] = env.gravity_m_s2
    p[P_M] = v.mass_kg
    p[P_IXX], p[P_IYY], p[P_IZZ] = v.inertia_diag
    p[P_KF] = v.rotor_thrust_coeff
    p[P_KM] = v.rotor_torque_coeff
    p[P_D] = v.arm_length_m / math.sqrt(2.0)
    p[P_TAU_M] = v.motor_time_constant_s
    p[P_DRAG_X], p[P_DRAG_Y], p[P_DRAG_Z] = v.drag_coeff_n_s_m
    p[P_ROT_DAMP] = v.rotational_damping_n_m_s_rad
    p[P_GEAR] = v.gear_height_m
    p[P_MU] = v.ground_friction_coeff
    p[P_W] = t.weight_per_length_n_m(env.gravity_m_s2)
    p[P_EA] = t.axial_stiffness_n
    p[P_RW] = w.drum_radius_m
    p[P_THETA_MIN] = w.min_paid_out_m / w.drum_radius_m
    p[P_THETA_MAX] = t.total_length_m / w.drum_radius_m
    p[P_M_BAR] = w.drum_mass_kg
    p[P_RHO] = t.linear_density_kg_m
    p[P_LT] = t.total_length_m
    p[P_RADII_SQ] = w.drum_radius_m ** 2 + w.drum_inner_radius_m ** 2
    p[P_I_ROTOR] = w.rotor_inertia_kg_m2
    p[P_BETA] = w.viscous_friction_n_m_s_rad
    p[P_TAU_MAX] = w.motor_torque_limit_n_m
    p[P_OMEGA_MAX] = w.motor_speed_limit_rad_s
    p[P_KV] = w.speed_limit_gain_n_m_s_rad
    p[P_BRAKE] = w.brake_torque_n_m
    p[P_HALF_RHO_AIR] = 0.5 * env.air_density_kg_m3
    p[P_CDA_X], p[P_CDA_Y], p[P_CDA_Z] = v.drag_area_m2
    p[P_ATT_X], p[P_ATT_Y], p[P_ATT_Z] = v.tether_attachment_m
    p[P_LUMPED] = 1.0 if t.kind == TetherModel.LUMPED else 0.0
    return p


def pack_line_params(params: SystemParams) -> np.ndarray:
    """The lumped line's parameters as :mod:`sitl.lumped` reads them."""
    t, env = params.tether, params.environment
    return line_params(env.gravity_m_s2, t.linear_density_kg_m, t.axial_stiffness_n,
                       t.axial_damping_n_s, t.segment_length_m, t.diameter_m,
                       t.normal_drag_coeff, t.tangential_drag_coeff, env.air_density_kg_m3,
                       t.ground_stiffness_n_m2, t.ground_damping_n_s_m2,
                       t.ground_friction_coeff, t.ground_friction_speed_m_s,
                       max_line_nodes(params))


def max_line_nodes(params: SystemParams) -> int:
    """The most free nodes the lumped line can have (the whole drum paid out)."""
    t = params.tether
    return node_count(t.total_length_m, t.segment_length_m) + 1


@njit
def drum_inertia(p: np.ndarray, length_m: float) -> float:
    """Drum, spooled tether and motor rotor inertia for a paid-out length [kg m^2]."""
    spooled = p[P_LT] - length_m
    if spooled < 0.0:
        spooled = 0.0
    return 0.5 * (p[P_M_BAR] + spooled * p[P_RHO]) * p[P_RADII_SQ] + p[P_I_ROTOR]


@njit
def motor_torque(p: np.ndarray, command_n_m: float, omega_rad_s: float,
                 enabled: bool) -> float:
    """Torque the winder motor applies [N m]: zero when disabled or NaN, clamped to the
    limit, cut back near the speed limit (|tau| <= k_v (omega_max -+ omega))."""
    if not enabled or command_n_m != command_n_m:
        return 0.0
    lim = p[P_TAU_MAX]
    tau = min(max(command_n_m, -lim), lim)
    kv, wmax = p[P_KV], p[P_OMEGA_MAX]
    tau = min(tau, kv * (wmax - omega_rad_s))
    return max(tau, kv * (-wmax - omega_rad_s))


@njit
def drum_acceleration(p: np.ndarray, theta: float, omega: float, motor_torque_n_m: float,
                      drum_tension_n: float, braked: bool) -> float:
    """d(omega)/dt of the drum [rad/s^2] (brake, friction, hard stops)."""
    inertia = drum_inertia(p, p[P_RW] * theta)
    driving = motor_torque_n_m + p[P_RW] * drum_tension_n
    tau = driving - p[P_BETA] * omega
    if braked:
        hold = p[P_BRAKE]
        if abs(omega) <= STOPPED_RAD_S:
            if abs(driving) <= hold:
                return 0.0  # static friction of the brake holds the drum
            tau -= hold if driving > 0 else -hold
        else:
            tau -= hold if omega > 0 else -hold
    acc = tau / inertia
    if theta <= p[P_THETA_MIN] and omega <= STOPPED_RAD_S and acc < 0.0:
        return 0.0
    if theta >= p[P_THETA_MAX] and omega >= -STOPPED_RAD_S and acc > 0.0:
        return 0.0
    return acc


@njit
def drum_projection(p: np.ndarray, theta: float, omega: float, omega_before: float,
                    braked: bool) -> tuple[float, float]:
    """The drum's (angle [rad], rate [rad/s]) after an integration step, projected onto
    its constraints: the brake's sticking when the rate crossed zero during the step
    (``omega_before`` the rate before it), and the hard stops."""
    if braked and omega_before != 0.0 and (omega > 0.0) != (omega_before > 0.0):
        omega = 0.0
    if theta < p[P_THETA_MIN]:
        theta = p[P_THETA_MIN]
        omega = 0.0 if omega < 0.0 else omega      # max(omega, 0.0)
    elif theta > p[P_THETA_MAX]:
        theta = p[P_THETA_MAX]
        omega = 0.0 if omega > 0.0 else omega      # min(omega, 0.0)
    return theta, omega


@njit
def tether_pull(p: np.ndarray, px: float, py: float, pz: float, length: float,
                warm: np.ndarray) -> tuple[float, float, float, float]:
    """(force on the UAV x, y, z [N], drum tension [N]) of the elastic catenary; updates
    the warm start ``warm`` = (H, V)."""
    span = math.hypot(px, py)
    height = pz if pz > 0.0 else 0.0
    H, V, HA, VA, lbot, reg, it, low, was_warm, ok = _solve(
        span, height, length, p[P_EA], p[P_W], warm[0], warm[1], TETHER_TOL)
    if ok:
        warm[0] = H
        warm[1] = V
    ux = px / span if span > 0.0 else 0.0
    uy = py / span if span > 0.0 else 0.0
    return -H * ux, -H * uy, -V, math.hypot(HA, VA)


@njit
def rhs_kernel(x: np.ndarray, p: np.ndarray, setpoints: np.ndarray, winder_cmd_n_m: float,
               winder_enabled: bool, wind: np.ndarray, warm: np.ndarray) -> np.ndarray:
    """dx/dt of the 19-state plant (layout in sitl/plant.py); for the lumped line, with the
    pull ``warm`` holds."""
    dx = np.empty(19)
    rhs_into(dx, x, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    return dx


@njit
def attachment_point(x: np.ndarray, p: np.ndarray) -> tuple[float, float, float,
                                                            float, float, float]:
    """The tether's attachment point B on the UAV at the state ``x``: position [m] and
    velocity [m/s], inertial (p + R r_a, v + R (omega x r_a))."""
    ax, ay, az = p[P_ATT_X], p[P_ATT_Y], p[P_ATT_Z]
    if ax == 0.0 and ay == 0.0 and az == 0.0:
        return x[0], x[1], x[2], x[3], x[4], x[5]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    wx, wy, wz = x[10], x[11], x[12]
    cx, cy, cz = wy * az - wz * ay, wz * ax - wx * az, wx * ay - wy * ax
    r00 = 1 - 2 * (qy * qy + qz * qz)
    r01 = 2 * (qx * qy - qw * qz)
    r02 = 2 * (qx * qz + qw * qy)
    r10 = 2 * (qx * qy + qw * qz)
    r11 = 1 - 2 * (qx * qx + qz * qz)
    r12 = 2 * (qy * qz - qw * qx)
    r20 = 2 * (qx * qz - qw * qy)
    r21 = 2 * (qy * qz + qw * qx)
    r22 = 1 - 2 * (qx * qx + qy * qy)
    return (x[0] + r00 * ax + r01 * ay + r02 * az, x[1] + r10 * ax + r11 * ay + r12 * az,
            x[2] + r20 * ax + r21 * ay + r22 * az, x[3] + r00 * cx + r01 * cy + r02 * cz,
            x[4] + r10 * cx + r11 * cy + r12 * cz, x[5] + r20 * cx + r21 * cy + r22 * cz)


@njit
def rhs_into(dx: np.ndarray, x: np.ndarray, p: np.ndarray, setpoints: np.ndarray,
             winder_cmd_n_m: float, winder_enabled: bool, wind: np.ndarray,
             warm: np.ndarray) -> None:
    """:func:`rhs_kernel` written into ``dx`` (19 floats, every one set). The tether's pull:
    the catenary's at the attachment point (warm-started from ``warm``), or, for the lumped
    line, the pull ``warm`` holds for the current state."""
    if p[P_LUMPED] != 0.0:
        fux, fuy, fuz, drum = warm[W_FX], warm[W_FY], warm[W_FZ], warm[W_DRUM]
    else:
        bx, by, bz, _, _, _ = attachment_point(x, p)
        fux, fuy, fuz, drum = tether_pull(p, bx, by, bz, p[P_RW] * x[17], warm)
    uav_rhs_into(dx, x, p, setpoints, winder_cmd_n_m, winder_enabled, wind, fux, fuy, fuz,
                 drum)


@njit
def uav_rhs_into(dx: np.ndarray, x: np.ndarray, p: np.ndarray, setpoints: np.ndarray,
                 winder_cmd_n_m: float, winder_enabled: bool, wind: np.ndarray,
                 fux: float, fuy: float, fuz: float, drum_tension: float) -> None:
    """dx/dt of the 19 states into ``dx`` given the tether's pull on the attachment point
    (x, y, z) [N] and the tension at the drum [N]."""
    pz = x[2]
    vx, vy, vz = x[3], x[4], x[5]
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    wx, wy, wz = x[10], x[11], x[12]
    theta, omega_d = x[17], x[18]
    kf, d = p[P_KF], p[P_D]
    ratio = p[P_KM] / kf
    thrust = 0.0
    tau_x = 0.0
    tau_y = 0.0
    tau_z = 0.0
    for i in range(4):
        ti = kf * x[13 + i] * x[13 + i]
        thrust += ti
        tau_x += _SY[i] * d * ti
        tau_y -= _SX[i] * d * ti
        tau_z -= _SPIN[i] * ratio * ti
    # rotation matrix body -> inertial
    r00 = 1 - 2 * (qy * qy + qz * qz)
    r01 = 2 * (qx * qy - qw * qz)
    r02 = 2 * (qx * qz + qw * qy)
    r10 = 2 * (qx * qy + qw * qz)
    r11 = 1 - 2 * (qx * qx + qz * qz)
    r12 = 2 * (qy * qz - qw * qx)
    r20 = 2 * (qx * qz - qw * qy)
    r21 = 2 * (qy * qz + qw * qx)
    r22 = 1 - 2 * (qx * qx + qy * qy)
    # drag against the air-relative velocity, in body axes: linear (rotor drag) plus
    # quadratic (the airframe's C_d A)
    ax_, ay_, az_ = vx - wind[0], vy - wind[1], vz - wind[2]
    abx = r00 * ax_ + r10 * ay_ + r20 * az_
    aby = r01 * ax_ + r11 * ay_ + r21 * az_
    abz = r02 * ax_ + r12 * ay_ + r22 * az_
    q = p[P_HALF_RHO_AIR] * math.sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_)
    dbx = -(p[P_DRAG_X] + q * p[P_CDA_X]) * abx
    dby = -(p[P_DRAG_Y] + q * p[P_CDA_Y]) * aby
    dbz = -(p[P_DRAG_Z] + q * p[P_CDA_Z]) * abz
    # the tether's moment about the centre of mass, body axes: r_a x (R^T F)
    fbx = r00 * fux + r10 * fuy + r20 * fuz
    fby = r01 * fux + r11 * fuy + r21 * fuz
    fbz = r02 * fux + r12 * fuy + r22 * fuz
    rax, ray, raz = p[P_ATT_X], p[P_ATT_Y], p[P_ATT_Z]
    tau_x += ray * fbz - raz * fby
    tau_y += raz * fbx - rax * fbz
    tau_z += rax * fby - ray * fbx
    m = p[P_M]
    fx = thrust * r02 + r00 * dbx + r01 * dby + r02 * dbz + fux
    fy = thrust * r12 + r10 * dbx + r11 * dby + r12 * dbz + fuy
    fz = thrust * r22 + r20 * dbx + r21 * dby + r22 * dbz + fuz - m * p[P_G]
    # ground contact: a constraint force, and Coulomb friction on the gear
    landed = pz <= p[P_GEAR] + GROUND_EPS_M and vz <= 0.0 and fz <= 0.0
    if landed:
        limit = p[P_MU] * (-fz)
        fz = 0.0
        speed = math.hypot(vx, vy)
        if speed < STICK_SPEED_M_S:
            f = math.hypot(fx, fy)
            if f <= limit:
                fx = 0.0
                fy = 0.0
            else:
                k = (f - limit) / f
                fx *= k
                fy *= k
        else:
            fx -= limit * vx / speed
            fy -= limit * vy / speed
    dx[0], dx[1], dx[2] = vx, vy, vz
    dx[3], dx[4], dx[5] = fx / m, fy / m, fz / m
    # rotational dynamics: J domega = tau - c omega - omega x J omega
    ixx, iyy, izz = p[P_IXX], p[P_IYY], p[P_IZZ]
    if landed:
        # the gear rotates a tilted vehicle back to level about the horizontal axis b3 x e3
        # (b3 the body's z axis, R e3): the rates toward (b3 x e3) / GEAR_LEVEL_S in body
        # axes, yaw held
        lx = (r00 * r12 - r10 * r02) / GEAR_LEVEL_S
        ly = (r01 * r12 - r11 * r02) / GEAR_LEVEL_S
        dx[10] = (lx - wx) / GEAR_RATE_DAMPING_S
        dx[11] = (ly - wy) / GEAR_RATE_DAMPING_S
        dx[12] = -wz / GEAR_RATE_DAMPING_S
    else:
        c = p[P_ROT_DAMP]
        dx[10] = (tau_x - c * wx - (wy * izz * wz - wz * iyy * wy)) / ixx
        dx[11] = (tau_y - c * wy - (wz * ixx * wx - wx * izz * wz)) / iyy
        dx[12] = (tau_z - c * wz - (wx * iyy * wy - wy * ixx * wx)) / izz
    # quaternion kinematics dq/dt = q (0, omega) / 2
    dx[6] = 0.5 * (-qx * wx - qy * wy - qz * wz)
    dx[7] = 0.5 * (qw * wx + qy * wz - qz * wy)
    dx[8] = 0.5 * (qw * wy + qz * wx - qx * wz)
    dx[9] = 0.5 * (qw * wz + qx * wy - qy * wx)
    # rotor lag
    for i in range(4):
        dx[13 + i] = (setpoints[i] - x[13 + i]) / p[P_TAU_M]
    # winder
    tau_m = motor_torque(p, winder_cmd_n_m, omega_d, winder_enabled)
    dx[18] = drum_acceleration(p, theta, omega_d, tau_m, drum_tension, not winder_enabled)
    dtheta = omega_d
    if (theta <= p[P_THETA_MIN] and omega_d < 0.0) or (theta >= p[P_THETA_MAX]
                                                        and omega_d > 0.0):
        dtheta = 0.0
    dx[17] = dtheta


@njit
def coupled_rhs_into(dx: np.ndarray, dls: np.ndarray, x: np.ndarray, ls: np.ndarray,
                     p: np.ndarray, lp: np.ndarray, setpoints: np.ndarray,
                     winder_cmd_n_m: float, winder_enabled: bool, wind: np.ndarray,
                     node_wind: np.ndarray, warm: np.ndarray) -> None:
    """The UAV's (``dx``) and the lumped line's (``dls``) state derivatives together: the
    line's top at the attachment point, its pull on the UAV, its exit tension on the drum.
    The forces go into ``warm`` (W_FX .. W_EZ)."""
    bx, by, bz, bvx, bvy, bvz = attachment_point(x, p)
    rw = p[P_RW]
    fx, fy, fz, drum, top, ex, ey, ez = line_rhs(ls, dls, lp, bx, by, bz, bvx, bvy, bvz,
                                                 rw * x[17], rw * x[18], node_wind, wind)
    warm[W_FX], warm[W_FY], warm[W_FZ], warm[W_DRUM], warm[W_TOP] = fx, fy, fz, drum, top
    warm[W_EX], warm[W_EY], warm[W_EZ] = ex, ey, ez
    uav_rhs_into(dx, x, p, setpoints, winder_cmd_n_m, winder_enabled, wind, fx, fy, fz, drum)


@njit
def coupled_rk4_into(x: np.ndarray, ls: np.ndarray, scratch: np.ndarray,
                     lscratch: np.ndarray, dt: float, p: np.ndarray, lp: np.ndarray,
                     setpoints: np.ndarray, winder_cmd_n_m: float, winder_enabled: bool,
                     wind: np.ndarray, node_wind: np.ndarray, warm: np.ndarray) -> None:
    """One classical RK4 step of ``dt`` [s] of the UAV (``x``, 19 floats) and the lumped
    line (``ls``) together, in place; ``scratch`` (5, 19) and ``lscratch`` (5, len(ls))
    hold the stages. Inputs and winds held."""
    k1, k2, k3, k4, xt = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    m1, m2, m3, m4, lt = lscratch[0], lscratch[1], lscratch[2], lscratch[3], lscratch[4]
    size = 1 + 6 * int(ls[0])
    lt[0] = ls[0]
    # the exit segment's allowance (and its last change) hold over the step: every stage
    # reads it (sitl.lumped.line_rhs), not the stale value the scratch array held
    last = ls.shape[0] - 1
    lt[last], lt[last - 1] = ls[last], ls[last - 1]
    h2 = 0.5 * dt
    coupled_rhs_into(k1, m1, x, ls, p, lp, setpoints, winder_cmd_n_m, winder_enabled, wind,
                     node_wind, warm)
    for i in range(19):
        xt[i] = x[i] + h2 * k1[i]
    for i in range(1, size):
        lt[i] = ls[i] + h2 * m1[i]
    coupled_rhs_into(k2, m2, xt, lt, p, lp, setpoints, winder_cmd_n_m, winder_enabled,
                     wind, node_wind, warm)
    for i in range(19):
        xt[i] = x[i] + h2 * k2[i]
    for i in range(1, size):
        lt[i] = ls[i] + h2 * m2[i]
    coupled_rhs_into(k3, m3, xt, lt, p, lp, setpoints, winder_cmd_n_m, winder_enabled,
                     wind, node_wind, warm)
    for i in range(19):
        xt[i] = x[i] + dt * k3[i]
    for i in range(1, size):
        lt[i] = ls[i] + dt * m3[i]
    coupled_rhs_into(k4, m4, xt, lt, p, lp, setpoints, winder_cmd_n_m, winder_enabled,
                     wind, node_wind, warm)
    c = dt / 6.0
    for i in range(19):
        x[i] = x[i] + c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    for i in range(1, size):
        ls[i] = ls[i] + c * (m1[i] + 2.0 * m2[i] + 2.0 * m3[i] + m4[i])


@njit
def rk4_kernel(x: np.ndarray, dt: float, p: np.ndarray, setpoints: np.ndarray,
               winder_cmd_n_m: float, winder_enabled: bool, wind: np.ndarray,
               warm: np.ndarray) -> np.ndarray:
    """One classical Runge-Kutta step of size ``dt`` [s], inputs and wind held."""
    out = np.empty(19)
    rk4_into(out, np.empty((5, 19)), x, dt, p, setpoints, winder_cmd_n_m, winder_enabled,
             wind, warm)
    return out


@njit
def rk4_into(out: np.ndarray, scratch: np.ndarray, x: np.ndarray, dt: float, p: np.ndarray,
             setpoints: np.ndarray, winder_cmd_n_m: float, winder_enabled: bool,
             wind: np.ndarray, warm: np.ndarray) -> None:
    """:func:`rk4_kernel` written into ``out`` (which may not be ``x``), with a (5, 19)
    ``scratch`` array for the stages: no allocation. The same arithmetic, element by
    element, as the array expressions x + h/2 k1, ..., x + dt/6 (k1 + 2 k2 + 2 k3 + k4)."""
    k1, k2, k3, k4, xt = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    h2 = 0.5 * dt
    rhs_into(k1, x, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    for i in range(19):
        xt[i] = x[i] + h2 * k1[i]
    rhs_into(k2, xt, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    for i in range(19):
        xt[i] = x[i] + h2 * k2[i]
    rhs_into(k3, xt, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    for i in range(19):
        xt[i] = x[i] + dt * k3[i]
    rhs_into(k4, xt, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    c = dt / 6.0
    for i in range(19):
        out[i] = x[i] + c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
