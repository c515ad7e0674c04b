"""The plant's lumped line (sitl/lumped.py) held still and settled in a steady uniform wind:
the truth the line-shape model and the tether fix are checked against
(tests/test_line_shape.py, tests/test_tether_fix.py)."""

from __future__ import annotations

import functools
import math

import numpy as np

from sitl.kernel import max_line_nodes, pack_line_params
from sitl.lumped import L_CN, L_CT, _drag, lay_line, line_state_size, relax
from sitl.tether import Tether
from tuavdefs.params import SystemParams, TetherParams

G = 9.81


def exit_reading(f: np.ndarray) -> tuple[float, float, float]:
    """(tension [N], azimuth, elevation [rad]) of a tension vector at the exit."""
    return (float(np.linalg.norm(f)), math.atan2(f[1], f[0]),
            math.atan2(f[2], math.hypot(f[0], f[1])))


@functools.cache
def settled_exit(top: tuple[float, float, float], length_m: float,
                 wind: tuple[float, float], density_factor: float = 1.0,
                 drag_factor: float = 1.0
                 ) -> tuple[float, float, float, float, tuple[float, float, float]]:
    """(tension [N], azimuth, elevation [rad] at the exit, the lowest node's height [m],
    the line's pull on the top [N]: the top segment's, its upper half's weight and drag) of
    the plant's lumped line (60 segments on 60 m; its linear density and drag coefficients
    ``density_factor`` and ``drag_factor`` times the defaults) held at ``top`` with
    ``length_m`` paid out, settled by dynamic relaxation (12 s) in the uniform steady
    ``wind`` [m/s].

    The plant's pull on the exit is its exit segment's pull less the weight of the
    segment's lower half (which the ground carries), not less that half's drag: the line's
    tension at the exit, what an arm at the fairlead reads, is taken here with that drag
    too (in 12 m/s it turns the reading by up to 0.05 rad on the plant's 0.8-1.8 m exit
    segment)."""
    tp = TetherParams()
    tp = tp.replace(total_length_m=60.0, segments=60,
                    linear_density_kg_m=tp.linear_density_kg_m * density_factor,
                    normal_drag_coeff=tp.normal_drag_coeff * drag_factor,
                    tangential_drag_coeff=tp.tangential_drag_coeff * drag_factor)
    params = SystemParams().replace(tether=tp)
    lp = pack_line_params(params)
    n = max_line_nodes(params)
    state = np.zeros(line_state_size(n))
    scratch = np.zeros((5, state.size))
    node_wind = np.zeros((n, 3))
    node_wind[:, :2] = wind
    top_wind = np.zeros(6)
    top_wind[:2] = wind
    cat = Tether(params.tether, G)
    cat.forces(*top, length_m)
    lay_line(state, lp, cat.shape(*top, length_m, 2001), length_m)
    out = relax(state, scratch, lp, 2e-4, 60000, np.array([*top, 0.0, 0.0, 0.0]), length_m,
                node_wind, top_wind, 0.998)
    nodes = int(state[0])
    low = np.array(state[1 + 6 * (nodes - 1): 4 + 6 * (nodes - 1)]) if nodes else np.array(top)
    chord = low / np.linalg.norm(low)
    half = 0.5 * (length_m - nodes * tp.total_length_m / tp.segments)
    drag = _drag(lp[L_CN], lp[L_CT], half, *chord, *wind, 0.0)
    lowest = min((state[3 + 6 * k] for k in range(nodes)), default=top[2])
    return (*exit_reading(np.array(out[5:8]) + np.array(drag)), float(lowest),
            (float(out[0]), float(out[1]), float(out[2])))
