"""An open-loop run of the truth model from hover trim, printed as a table."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import TextIO

from sitl.plant import Plant
from sitl.trim import hover_trim
from tuavdefs.params import GustParams, SystemParams


def default_tether_length_m(position_m: Sequence[float]) -> float:
    """A comfortable slack length for a demo: 15 % longer than the straight line [m]."""
    return 1.15 * math.dist(position_m, (0.0, 0.0, 0.0))


def run_open_loop_demo(params: SystemParams, duration_s: float, print_every_s: float,
                       position_m: Sequence[float], out: TextIO) -> Plant:
    """Hold the hover-trim commands for ``duration_s`` and print the state.

    Unless the parameters already bring gusts, a 2 m/s easterly (1 - cos) gust at 1 s
    disturbs the equilibrium, so the open-loop drift shows within the run.
    """
    length = default_tether_length_m(position_m)
    if not params.wind.gusts:
        gust = GustParams(start_s=1.0, duration_s=1.5, amplitude_m_s=(2.0, 0.0, 0.0))
        params = params.replace(wind=params.wind.replace(gusts=(gust,)))
    x, u = hover_trim(params, position_m, length)
    plant = Plant(params, state=x)
    tf = plant.tether_forces()
    out.write(f"tuav-sitl demo: open loop from hover trim at {tuple(position_m)} m, "
              f"{length:.2f} m of tether (regime {tf.info.regime.name}), "
              f"pull on the UAV {tuple(round(f, 2) for f in tf.on_uav_n)} N\n")
    out.write("rotor commands held at " + ", ".join(f"{c:.4f}" for c in u.rotor_commands)
              + "; no controller is running.\n")
    for g in params.wind.gusts:
        out.write(f"gust of {g.amplitude_m_s} m/s from t = {g.start_s} s for {g.duration_s} s: "
                  "the open-loop equilibrium is unstable and drifts away after it.\n")
    header = (f"{'t [s]':>6} {'x [m]':>8} {'y [m]':>8} {'z [m]':>8} {'roll':>7} {'pitch':>7} "
              f"{'yaw':>7} {'L [m]':>7} {'T_top [N]':>9} {'T_drum [N]':>10}")
    out.write(header + "\n")
    steps = round(duration_s / plant.dt_s)
    every = max(1, round(print_every_s / plant.dt_s))
    wall = time.perf_counter()
    for k in range(steps + 1):
        if k % every == 0:
            p = plant.position_m
            r, pi, ya = (math.degrees(a) for a in plant.euler_rad)
            tf = plant.tether_forces()
            out.write(f"{plant.t_s:6.2f} {p[0]:8.3f} {p[1]:8.3f} {p[2]:8.3f} {r:7.2f} "
                      f"{pi:7.2f} {ya:7.2f} {plant.tether_length_m:7.3f} "
                      f"{tf.top_tension_n:9.3f} {tf.drum_tension_n:10.3f}\n")
        if k < steps:
            plant.step(u)
    wall = time.perf_counter() - wall
    out.write(f"simulated {duration_s:.1f} s in {wall:.2f} s of wall time "
              f"({duration_s / wall:.1f}x real time, RK4 at {1 / plant.dt_s:.0f} Hz)\n")
    return plant
