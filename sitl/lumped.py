"""The tether as a dynamic body: lumped masses joined by elastic segments, in the air.

The line runs from the UAV's attachment point B (the top, moving with the UAV) down to the
winder's exit A (the origin, fixed). Its unstretched length is the paid-out length
``L = r_w * theta`` of the drum. It is cut into segments of the nominal length ``l_s``
(``TetherParams.segment_length_m``) from the top; the last one, at the exit, takes the rest,
``l_e = L - n l_s``, and grows and shrinks as the drum turns. Between the segments sit ``n``
free nodes, numbered from the top (node 0 below B, node n-1 above A), each carrying half of
the mass of the two segments beside it; the half segments at the ends belong to B (the UAV
carries its weight and drag) and to A (the ground carries it).

Each segment pulls with ``T = EA e + BA de/dt`` while stretched (strain ``e > 0``) and not
at all when slack (no compression stiffness, and never a push). Each node feels gravity,
the air drag of its share of line in the local wind (normal and tangential coefficients on
the diameter, MoorDyn's convention), and, below the ground (z < 0), a spring-damper
reaction with Coulomb friction smoothed below a sliding speed. The node above the exit
gains the mass paid out, with the momentum it brings.

Nodes are added and removed at the exit between steps (``manage_nodes``): a new node when
``l_e > SPLIT l_s``, one merged into its neighbour when ``l_e < MERGE l_s``, both conserving
the line's mass and momentum and keeping the exit segment's strain and strain rate. The
equations, the integrator (classical RK4 on the coupled UAV and line, sub-stepped within the
plant's step only where the line's stability limit, :func:`stable_step_s`, asks for it) and
what is neglected are in docs/model.md.

The line's state is a float array (:func:`line_state_size`): ``ls[0]`` the number of free
nodes ``n``, then for node k its position (x, y, z) [m] and velocity [m/s] at
``ls[1 + 6k : 7 + 6k]`` (inertial, z up, origin at the exit), and last (``ls[-1]``) the exit
segment's allowance [m] (:func:`manage_nodes`). The parameters are the plant's packed
array (``sitl.kernel``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from sitl._jit import njit
from sitl.wind import WP_STEADY, profile_factor

#: The exit segment is split when longer than this many nominal segments, ...
SPLIT = 2.0
#: ... and merged into the next one when shorter than this (the shortest segment sets the
#: line's fastest axial mode, hence the step: see :func:`stable_step_s`).
MERGE = 0.8
#: The sub-step is at most this fraction of the stability limit :func:`stable_step_s`.
STEP_SAFETY = 0.8

# packed-parameter indices this module reads (filled by sitl.kernel.pack_params)
(L_G, L_RHO, L_EA, L_BA, L_LS, L_DIAM, L_CDN, L_CDT, L_RHO_AIR, L_KG, L_CG, L_MUG, L_VG,
 L_HMAX, L_MAXN, L_INV_LS, L_INV_M, L_CN, L_CT) = range(19)
N_LINE_PARAMS = 19


def rk4_gain(z: complex | np.ndarray) -> np.ndarray:
    """|R(z)| of classical RK4 for the test equation y' = s y, z = h s."""
    return np.abs(1.0 + z + z * z / 2.0 + z ** 3 / 6.0 + z ** 4 / 24.0)


@functools.lru_cache(maxsize=64)
def stable_step_s(rho_kg_m: float, ea_n: float, ba_n_s: float, segment_m: float,
                  kg: float, cg: float, mu: float, g: float, v_slip: float) -> float:
    """The largest RK4 step [s] stable for the line's fastest node (a pure function of its
    arguments, remembered: every plant built, the catenary's too, packs it, and a sweep
    builds hundreds with the same line).

    That node sits between a nominal segment and the shortest exit segment
    (``MERGE l_s``). Its stiffness rate bounds every axial mode (Gershgorin):
    ``kappa <= 2 EA (1/l_s + 1/(MERGE l_s)) / m``, m its mass; the segments' damping is
    stiffness-proportional (``BA/l = (BA/EA) EA/l``), so a mode of stiffness rate kappa has
    ``s^2 + (BA/EA kappa + c_g/rho + mu g/v_c) s + kappa + k_g/rho = 0`` (the ground's
    spring and damper and the friction's slope added where the line lies). Both roots of
    every kappa up to the bound must keep ``|R(h s)| <= 1``; this returns the smallest such
    h over them."""
    shortest = MERGE * segment_m
    m_node = rho_kg_m * 0.5 * (segment_m + shortest)
    kappa_max = 2.0 * (ea_n / segment_m + ea_n / shortest) / m_node
    beta = ba_n_s / ea_n
    extra_c = cg / rho_kg_m + mu * g / v_slip
    extra_k = kg / rho_kg_m
    best = math.inf
    for ground in (False, True):
        kappa = kappa_max * np.linspace(1.0 / 64.0, 1.0, 64)
        c = beta * kappa + (extra_c if ground else 0.0)
        k = kappa + (extra_k if ground else 0.0)
        disc = np.sqrt((c * c - 4.0 * k).astype(complex))
        for s in ((-c + disc) / 2.0, (-c - disc) / 2.0):
            mag = np.abs(s)
            # walk out along each root's ray to where |R| first exceeds 1
            frac = np.linspace(0.0, 3.0, 3001)[1:]
            gain = rk4_gain(frac[None, :] * (s / mag)[:, None])
            over = gain > 1.0 + 1e-12
            first = np.where(over.any(axis=1), over.argmax(axis=1), frac.size - 1)
            best = min(best, float(np.min(frac[first] / mag)))
    return best


def substeps(dt_s: float, lp: np.ndarray) -> int:
    """RK4 sub-steps of the coupled UAV and line per plant step of ``dt_s`` [s]: the fewest
    whose length is within ``STEP_SAFETY`` of the line's stability limit."""
    return max(1, math.ceil(dt_s / (STEP_SAFETY * lp[L_HMAX]) - 1e-9))


def line_params(g: float, rho_kg_m: float, ea_n: float, ba_n_s: float, segment_m: float,
                diameter_m: float, cdn: float, cdt: float, rho_air: float, kg: float,
                cg: float, mu: float, v_slip: float, max_nodes: int) -> np.ndarray:
    """The line's packed parameters, with the largest stable step [s]
    (:func:`stable_step_s`) and the constants the state derivative uses."""
    lp = np.zeros(N_LINE_PARAMS)
    lp[:13] = (g, rho_kg_m, ea_n, ba_n_s, segment_m, diameter_m, cdn, cdt, rho_air, kg, cg,
               mu, v_slip)
    lp[L_HMAX] = stable_step_s(rho_kg_m, ea_n, ba_n_s, segment_m, kg, cg, mu, g, v_slip)
    lp[L_MAXN] = max_nodes
    lp[L_INV_LS] = 1.0 / segment_m
    lp[L_INV_M] = 1.0 / (rho_kg_m * segment_m)
    lp[L_CN] = 0.5 * rho_air * diameter_m * cdn
    lp[L_CT] = 0.5 * rho_air * diameter_m * cdt * math.pi
    return lp


def node_count(length_m: float, segment_m: float) -> int:
    """Free nodes of a freshly laid line of ``length_m`` [m]: the exit segment between
    ``MERGE`` and ``MERGE + 1`` nominal ones (no node, one segment, for a line that
    short)."""
    return max(0, math.floor(length_m / segment_m - MERGE))


@njit
def _drag(cn: float, ct: float, share: float, qx: float, qy: float, qz: float, rx: float,
          ry: float, rz: float) -> tuple[float, float, float]:
    """Air drag [N] on ``share`` [m] of line along the unit tangent ``q`` in the air
    velocity ``r`` relative to it [m/s]; ``cn`` = ½ rho_air d C_dn and ``ct`` =
    ½ rho_air pi d C_dt [kg/m^2]."""
    along = rx * qx + ry * qy + rz * qz
    tx, ty, tz = along * qx, along * qy, along * qz
    nx, ny, nz = rx - tx, ry - ty, rz - tz
    kn = cn * share * math.sqrt(nx * nx + ny * ny + nz * nz)
    kt = ct * share * abs(along)
    return kn * nx + kt * tx, kn * ny + kt * ty, kn * nz + kt * tz


@njit
def line_rhs(ls: np.ndarray, dls: np.ndarray, lp: np.ndarray, bx: float, by: float,
             bz: float, bvx: float, bvy: float, bvz: float, length: float,
             length_rate: float, node_wind: np.ndarray, top_wind: np.ndarray
             ) -> tuple[float, float, float, float, float, float, float, float]:
    """The line's state derivative into ``dls`` (positions' and velocities' rates of the
    ``ls[0]`` nodes) for the top B at ``b`` [m] moving at ``bv`` [m/s], ``length`` [m] paid
    out at ``length_rate`` [m/s], the air velocity at each node ``node_wind`` ((n, 3) [m/s])
    and at B ``top_wind``. Returns the force of the line on B (x, y, z) [N] (the top
    segment's pull, its half's weight and drag), the tension at the exit (what the drum
    feels) [N], the top segment's tension [N] and the line's pull on the exit (x, y, z)
    [N].

    One pass from the top: segment j joins its upper end (B for j = 0, else node j-1) and
    its lower end (node j, the exit for j = n); its pull ``t_j`` on the lower end is
    ``(EA e + BA de/dt) u/|u|`` while that is a tension (e > 0 and the sum > 0), else 0.
    Node j-1 is finished as soon as segment j is known: ``t_(j-1) - t_j``, its weight, its
    drag on the tangent from the node above to the node below (MoorDyn's), the ground."""
    n = int(ls[0])
    g, rho, ea, ba, ls_m = lp[L_G], lp[L_RHO], lp[L_EA], lp[L_BA], lp[L_LS]
    inv_ls, inv_m, cn, ct = lp[L_INV_LS], lp[L_INV_M], lp[L_CN], lp[L_CT]
    exit_len = length - n * ls_m
    inv_exit = 1.0 / (exit_len - ls[ls.shape[0] - 1])   # the allowance: manage_nodes
    # the upper end of the current segment and the point above it
    ux, uy, uz, uvx, uvy, uvz = bx, by, bz, bvx, bvy, bvz
    ax, ay, az = bx, by, bz
    ptx = pty = ptz = 0.0          # the pull of the segment above on its lower end
    top_fx = top_fy = top_fz = top_t = 0.0
    for j in range(n + 1):
        if j < n:
            o = 1 + 6 * j
            dx_, dy_, dz_ = ls[o], ls[o + 1], ls[o + 2]
            dvx, dvy, dvz = ls[o + 3], ls[o + 4], ls[o + 5]
            inv_l0 = inv_ls
            l0r = 0.0
        else:
            dx_ = dy_ = dz_ = dvx = dvy = dvz = 0.0
            inv_l0 = inv_exit
            l0r = length_rate
        sx, sy, sz = ux - dx_, uy - dy_, uz - dz_
        d = math.sqrt(sx * sx + sy * sy + sz * sz)
        strain = d * inv_l0 - 1.0
        tx = ty = tz = t = 0.0
        if strain > 0.0:
            rate = inv_l0 * ((sx * (uvx - dvx) + sy * (uvy - dvy) + sz * (uvz - dvz)) / d
                             - d * l0r * inv_l0)
            t = ea * strain + ba * rate
            if t > 0.0:
                k = t / d
                tx, ty, tz = k * sx, k * sy, k * sz
            else:
                t = 0.0
        if j == 0:
            # the top: the segment's pull, its upper half's weight and drag
            top_t = t
            half = 0.5 * (ls_m if n > 0 else exit_len)
            top_fx, top_fy, top_fz = -tx, -ty, -tz - rho * half * g
            if d > 0.0:
                inv_d = 1.0 / d
                fx, fy, fz = _drag(cn, ct, half, sx * inv_d, sy * inv_d, sz * inv_d,
                                   top_wind[0] - bvx, top_wind[1] - bvy, top_wind[2] - bvz)
                top_fx += fx
                top_fy += fy
                top_fz += fz
        else:
            # node j-1, the segment's upper end
            k = j - 1
            o = 1 + 6 * k
            if j < n:
                share = ls_m
                im = inv_m
            else:
                share = 0.5 * (ls_m + exit_len)
                im = 1.0 / (rho * share)
            fx = ptx - tx
            fy = pty - ty
            fz = ptz - tz - rho * share * g
            qx, qy, qz = ax - dx_, ay - dy_, az - dz_
            q2 = qx * qx + qy * qy + qz * qz
            if q2 > 0.0:
                iq = 1.0 / math.sqrt(q2)
                wx_, wy_, wz_ = _drag(cn, ct, share, qx * iq, qy * iq, qz * iq,
                                      node_wind[k, 0] - uvx, node_wind[k, 1] - uvy,
                                      node_wind[k, 2] - uvz)
                fx += wx_
                fy += wy_
                fz += wz_
            if uz < 0.0:
                nrm = share * (-lp[L_KG] * uz - lp[L_CG] * uvz)
                if nrm > 0.0:
                    fz += nrm
                    sl = math.sqrt(uvx * uvx + uvy * uvy)
                    if sl > 0.0:
                        vslip = lp[L_VG]
                        f = lp[L_MUG] * nrm * (sl / vslip if sl < vslip else 1.0) / sl
                        fx -= f * uvx
                        fy -= f * uvy
            if j == n and length_rate > 0.0:
                # line paid out enters this node's share at the exit's speed along the
                # exit segment: d(m v)/dt = F + dm/dt v_in
                dm = 0.5 * rho * length_rate
                if d > 0.0:
                    c = length_rate / d
                    fx += dm * (c * sx - uvx)
                    fy += dm * (c * sy - uvy)
                    fz += dm * (c * sz - uvz)
                else:
                    fx -= dm * uvx
                    fy -= dm * uvy
                    fz -= dm * uvz
            dls[o], dls[o + 1], dls[o + 2] = uvx, uvy, uvz
            dls[o + 3], dls[o + 4], dls[o + 5] = fx * im, fy * im, fz * im
            ax, ay, az = ux, uy, uz
        ptx, pty, ptz = tx, ty, tz
        ux, uy, uz, uvx, uvy, uvz = dx_, dy_, dz_, dvx, dvy, dvz
    # the exit: the last segment's pull, less its lower half's weight, which the ground
    # carries where the line does not lift it
    vz = ptz - rho * 0.5 * exit_len * g
    if vz < 0.0:
        vz = 0.0
    drum = math.sqrt(ptx * ptx + pty * pty + vz * vz)
    return top_fx, top_fy, top_fz, drum, top_t, ptx, pty, vz


@njit
def line_wind(ls: np.ndarray, wp: np.ndarray, wind: np.ndarray, out: np.ndarray) -> None:
    """The air velocity at every node [m/s] into ``out`` ((n, 3)): the mean wind at the
    node's height (the wind's packed parameters ``wp``, :func:`sitl.wind.profile_factor`)
    plus the part the same everywhere (turbulence and gusts, ``wind[3:6]`` of
    :func:`sitl.wind.wind_kernel`)."""
    uniform = (wind[3], wind[4], wind[5])
    n = int(ls[0])
    sx, sy, sz = wp[WP_STEADY], wp[WP_STEADY + 1], wp[WP_STEADY + 2]
    calm = sx == 0.0 and sy == 0.0 and sz == 0.0
    for k in range(n):
        f = 0.0 if calm else profile_factor(wp, ls[3 + 6 * k])
        out[k, 0] = f * sx + uniform[0]
        out[k, 1] = f * sy + uniform[1]
        out[k, 2] = f * sz + uniform[2]


def line_state_size(max_nodes: int) -> int:
    """Floats of a line state holding up to ``max_nodes`` free nodes: the count, the nodes,
    then the exit segment's allowance's change over the last plant step (``ls[-2]``) and
    last the allowance (``ls[-1]``, :func:`manage_nodes`)."""
    return 3 + 6 * max_nodes


@njit
def manage_nodes(ls: np.ndarray, lp: np.ndarray, length: float, length_rate: float,
                 decay: float, top: np.ndarray) -> int:
    """Adds or removes the node at the exit so that the exit segment stays between
    ``MERGE`` and ``SPLIT`` nominal lengths, conserving mass and momentum (a new node on the
    exit segment's chord where the two parts keep its strain; on a slack segment, below the
    chord in its vertical plane where both parts are at rest length, as the line hangs
    there, and not below the ground; moving across the chord as
    the line there, interpolated towards the exit at rest, and along it so that both parts
    keep the segment's strain rate, the line at the exit leaving at the drum's speed: with
    the drum still the free nodes' momentum is the same after; a removed node and its
    neighbour become one node at their mean velocity, the half segment of line that joins
    the exit's share taking its momentum at that velocity into the exit).

    A removed node leaves the exit segment's chord shorter than the path it replaces (the
    line bent there), by up to millimetres: as much as the segment's whole stretch at
    working tension. So that this does not drop the tension to nothing for the moment the
    line takes to straighten, the exit segment keeps its strain: its elastic length is
    ``l_e - a``, the allowance ``a`` (``ls[-1]``, [m]) that difference, which then fades as
    a critically damped second-order decay, from rest, with ``decay`` (< 1) = exp(-dt/tau)
    for the call's step dt (once a plant step; ``ls[-2]`` its last change): the fade lets
    out line at the exit at a rate that starts from zero, where a first-order fade (tension
    down by EA a / (l_e tau) per second at once: 1.6 N/ms) made a step that set the drum
    and the line ringing; and its strain rate, the survivor's
    velocity along the new chord set for it (``length_rate`` [m/s] the drum's): else the
    drum, reeling in at the line's speed along the old segment, stretches the new one at
    once (a bend of 20 degrees took the tension from 5 to 44 N in 25 ms). ``top`` is the
    top B's position and velocity (6 floats), the upper end of a line without free nodes.
    Returns the change in the number of nodes."""
    ls_m = lp[L_LS]
    maxn = int(lp[L_MAXN])
    last = ls.shape[0] - 1
    a, b = ls[last], ls[last - 1]
    if a != 0.0 or b != 0.0:
        # a'' = -2 a'/tau - a/tau^2, exactly over the step, in b = a' dt and w = dt/tau
        w = -math.log(decay) if decay > 0.0 else 0.0
        c = b + w * a
        ls[last] = decay * (a + c)
        ls[last - 1] = decay * (b - w * c)
    n0 = int(ls[0])
    n = n0
    while True:
        exit_len = length - n * ls_m
        allowance = ls[last]
        if exit_len > SPLIT * ls_m and n < maxn:
            # the node above the exit keeps its place and velocity; the new one divides
            # the chord as the elastic lengths ls_m and exit_len - ls_m - allowance
            l0 = exit_len - allowance
            f = (l0 - ls_m) / l0
            if n > 0:       # the node above: node n-1, else (the first free node) the top
                o = 1 + 6 * (n - 1)
                px, py, pz, vx, vy, vz = (ls[o], ls[o + 1], ls[o + 2], ls[o + 3],
                                          ls[o + 4], ls[o + 5])
            else:
                px, py, pz, vx, vy, vz = top[0], top[1], top[2], top[3], top[4], top[5]
            o = 1 + 6 * n
            ls[o], ls[o + 1], ls[o + 2] = f * px, f * py, f * pz
            d = math.sqrt(px * px + py * py + pz * pz)
            if 0.0 < d < l0:
                # a slack segment hangs: its new node goes where both parts are at their
                # rest lengths, below the chord in its vertical plane (on the chord it
                # would fall free until the line caught it: a snap no real line has)
                la = l0 - ls_m
                x = (la * la - ls_m * ls_m + d * d) / (2.0 * d)
                y = math.sqrt(max(la * la - x * x, 0.0))
                ux, uy, uz = px / d, py / d, pz / d
                nx, ny, nz = uz * ux, uz * uy, uz * uz - 1.0
                nn = math.sqrt(nx * nx + ny * ny + nz * nz)
                if nn < 1e-9:   # a vertical chord: any horizontal side
                    nx, ny, nz, nn = 1.0, 0.0, 0.0, 1.0
                ls[o] = x * ux + y * nx / nn
                ls[o + 1] = x * uy + y * ny / nn
                ls[o + 2] = max(x * uz + y * nz / nn, 0.0)   # not below the ground
            if d > 0.0:
                # across the chord: interpolated towards the exit at rest; along it: what
                # keeps both parts at the segment's strain rate (line paid out leaves the
                # exit at the drum's speed)
                ux, uy, uz = px / d, py / d, pz / d
                along = ux * vx + uy * vy + uz * vz
                strain = d / l0 - 1.0
                strain_rate = along / l0 - d * length_rate / (l0 * l0)
                rate = (l0 - ls_m) * strain_rate + (1.0 + strain) * length_rate
                ls[o + 3] = f * (vx - along * ux) + rate * ux
                ls[o + 4] = f * (vy - along * uy) + rate * uy
                ls[o + 5] = f * (vz - along * uz) + rate * uz
            else:
                ls[o + 3], ls[o + 4], ls[o + 5] = f * vx, f * vy, f * vz
            n += 1
        elif exit_len < MERGE * ls_m and n > 0:
            # node n-1 goes; node n-2 (if any), whose share becomes ls_m + exit_len/2,
            # moves at the two nodes' mean velocity; the exit's share takes the other
            # ls_m/2 of line and the momentum it carries at that velocity (line reeled in
            # arrives at the exit moving with it)
            o = 1 + 6 * (n - 1)
            x, y, z = ls[o], ls[o + 1], ls[o + 2]
            d = math.sqrt(x * x + y * y + z * z)
            l0 = exit_len - allowance
            strain = d / l0 - 1.0
            strain_rate = 0.0
            if d > 0.0:
                strain_rate = ((x * ls[o + 3] + y * ls[o + 4] + z * ls[o + 5]) / (d * l0)
                               - d * length_rate / (l0 * l0))
            chord = 0.0
            if n > 1:
                o = 1 + 6 * (n - 2)
                m_keep = ls_m
                m_gone = 0.5 * (ls_m + exit_len)
                m_both = m_keep + m_gone
                for i in range(3, 6):
                    ls[o + i] = (m_keep * ls[o + i] + m_gone * ls[o + 6 + i]) / m_both
                x, y, z = ls[o], ls[o + 1], ls[o + 2]
                chord = math.sqrt(x * x + y * y + z * z)
            allowance = 0.0
            if strain > 0.0 and n > 1 and chord > 0.0:
                allowance = exit_len + ls_m - chord / (1.0 + strain)
                if allowance < 0.0:
                    allowance = 0.0
                elif allowance > 0.5 * (exit_len + ls_m):
                    allowance = 0.5 * (exit_len + ls_m)
                # the chord's rate that keeps the strain rate
                l0 = exit_len + ls_m - allowance
                rate = l0 * strain_rate + chord * length_rate / l0
                ux, uy, uz = x / chord, y / chord, z / chord
                along = ux * ls[o + 3] + uy * ls[o + 4] + uz * ls[o + 5]
                ls[o + 3] += (rate - along) * ux
                ls[o + 4] += (rate - along) * uy
                ls[o + 5] += (rate - along) * uz
            ls[last] = allowance
            ls[last - 1] = 0.0
            n -= 1
        else:
            break
        ls[0] = n
    return n - n0


@njit
def line_energy_j(ls: np.ndarray, lp: np.ndarray, bx: float, by: float, bz: float,
                  length: float) -> float:
    """Kinetic, gravitational, elastic and ground-spring energy of the free nodes and
    segments [J] (the top half segment's weight counted at B, the exit's not)."""
    n = int(ls[0])
    g, rho, ea, ls_m, kg = lp[L_G], lp[L_RHO], lp[L_EA], lp[L_LS], lp[L_KG]
    exit_len = length - n * ls_m
    e = 0.0
    ux, uy, uz = bx, by, bz
    for j in range(n + 1):
        if j < n:
            o = 1 + 6 * j
            x, y, z = ls[o], ls[o + 1], ls[o + 2]
            l0 = ls_m
        else:
            x = y = z = 0.0
            l0 = exit_len - ls[ls.shape[0] - 1]
        d = math.sqrt((ux - x) ** 2 + (uy - y) ** 2 + (uz - z) ** 2)
        if d > l0:
            e += 0.5 * ea * (d - l0) ** 2 / l0
        if j == 0:
            e += rho * 0.5 * (ls_m if n > 0 else exit_len) * g * bz
        if j < n:
            share = 0.5 * (ls_m + (ls_m if j < n - 1 else exit_len))
            m = rho * share
            o = 1 + 6 * j
            v2 = ls[o + 3] ** 2 + ls[o + 4] ** 2 + ls[o + 5] ** 2
            e += 0.5 * m * v2 + m * g * z
            if z < 0.0:
                e += 0.5 * kg * share * z * z
        ux, uy, uz = x, y, z
    return e


@njit
def line_rk4_prescribed(ls: np.ndarray, scratch: np.ndarray, lp: np.ndarray, h: float,
                        b0: np.ndarray, b1: np.ndarray, b2: np.ndarray, length: float,
                        node_wind: np.ndarray, top_wind: np.ndarray) -> tuple:
    """One RK4 step of ``h`` [s] of the line alone, its top prescribed: ``b0``, ``b1``,
    ``b2`` the top's (position, velocity) (6 floats) at the step's start, middle and end;
    the length fixed. Returns :func:`line_rhs`'s forces at the step's start."""
    n = int(ls[0])
    size = 1 + 6 * n
    k1, k2, k3, k4, xt = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    xt[0] = ls[0]
    last = ls.shape[0] - 1
    xt[last], xt[last - 1] = ls[last], ls[last - 1]   # the allowance, for every stage
    out = line_rhs(ls, k1, lp, b0[0], b0[1], b0[2], b0[3], b0[4], b0[5], length, 0.0,
                   node_wind, top_wind)
    for i in range(1, size):
        xt[i] = ls[i] + 0.5 * h * k1[i]
    line_rhs(xt, k2, lp, b1[0], b1[1], b1[2], b1[3], b1[4], b1[5], length, 0.0,
             node_wind, top_wind)
    for i in range(1, size):
        xt[i] = ls[i] + 0.5 * h * k2[i]
    line_rhs(xt, k3, lp, b1[0], b1[1], b1[2], b1[3], b1[4], b1[5], length, 0.0,
             node_wind, top_wind)
    for i in range(1, size):
        xt[i] = ls[i] + h * k3[i]
    line_rhs(xt, k4, lp, b2[0], b2[1], b2[2], b2[3], b2[4], b2[5], length, 0.0,
             node_wind, top_wind)
    c = h / 6.0
    for i in range(1, size):
        ls[i] = ls[i] + c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    return out


@njit
def relax(ls: np.ndarray, scratch: np.ndarray, lp: np.ndarray, h: float, steps: int,
          top: np.ndarray, length: float, node_wind: np.ndarray, top_wind: np.ndarray,
          keep: float) -> tuple:
    """Dynamic relaxation towards the static shape: ``steps`` RK4 steps of ``h`` [s] with
    the top held at ``top`` (position, zero velocity: 6 floats), each followed by the
    nodes' velocities scaled by ``keep`` (< 1). Returns :func:`line_rhs`'s forces at the
    end."""
    for _ in range(steps):
        line_rk4_prescribed(ls, scratch, lp, h, top, top, top, length, node_wind, top_wind)
        n = int(ls[0])
        for k in range(n):
            o = 1 + 6 * k
            ls[o + 3] *= keep
            ls[o + 4] *= keep
            ls[o + 5] *= keep
    return line_rhs(ls, scratch[0], lp, top[0], top[1], top[2], 0.0, 0.0, 0.0, length, 0.0,
                    node_wind, top_wind)


def lay_line(ls: np.ndarray, lp: np.ndarray, points: np.ndarray, length: float) -> None:
    """The nodes at rest on a drawn shape: ``points`` ((m, 3) [m], from the exit to the top,
    at equal steps of unstretched arc length, e.g. :meth:`sitl.tether.Tether.shape`), each
    node at its arc length (linear interpolation)."""
    ls_m = lp[L_LS]
    n = node_count(length, ls_m)
    if line_state_size(n) > ls.size:
        raise ValueError(f"length {length!r} m needs {n} nodes, more than the line holds")
    m = points.shape[0]
    s = np.linspace(0.0, length, m)
    ls[:] = 0.0
    ls[0] = n
    for k in range(n):
        sk = length - (k + 1) * ls_m           # arc length from the exit
        o = 1 + 6 * k
        for c in range(3):
            ls[o + c] = float(np.interp(sk, s, points[:, c]))
