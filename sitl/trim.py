"""Hover trim: the state and rotor commands that hold the UAV still at a point.

Used to start open-loop demonstrations and simulations from equilibrium. It reads the
plant's own tether model (this is the truth side), and the airframe's mixer only to express
the trim thrust as rotor commands.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sitl.plant import QUAT, ROTORS, VEL, PlantInputs, PlantModel, initial_state, rhs
from sitl.wind import WindModel, profile_factor
from tuavdefs.airframe import Mixer
from tuavdefs.params import SystemParams, TetherModel


def thrust_aligned_quaternion(direction: Sequence[float], yaw_rad: float = 0.0
                              ) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) whose body +z points along ``direction`` and whose body
    x axis is as close as possible to the heading ``yaw_rad`` (z-up convention)."""
    z_b = np.asarray(direction, float)
    z_b = z_b / np.linalg.norm(z_b)
    heading = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    y_b = np.cross(z_b, heading)
    y_b /= np.linalg.norm(y_b)
    x_b = np.cross(y_b, z_b)
    r = np.column_stack([x_b, y_b, z_b])
    return _matrix_to_quat(r)


def _matrix_to_quat(r: np.ndarray) -> tuple[float, float, float, float]:
    tr = float(np.trace(r))
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (r[j, i] + r[i, j]) / s
        v[k] = (r[k, i] + r[i, k]) / s
        q = ((r[k, j] - r[j, k]) / s, *v)
    n = math.sqrt(sum(c * c for c in q))
    sign = 1.0 if q[0] >= 0 else -1.0
    return tuple(sign * c / n for c in q)  # type: ignore[return-value]


def hover_trim(params: SystemParams, position_m: Sequence[float], tether_length_m: float,
               yaw_rad: float = 0.0) -> tuple[np.ndarray, PlantInputs]:
    """State and inputs that hold the UAV at ``position_m`` with ``tether_length_m`` paid
    out (drum braked): thrust balances weight, the tether's pull and the steady wind's drag
    at that height (the drag's dependence on the attitude by a few fixed-point passes),
    rotors at speed."""
    if params.tether.model != TetherModel.CATENARY.value:
        # the line's pull at rest is the catenary's (a lumped line is then laid out and
        # relaxed to its own static shape: within 1 % of it, tests/test_lumped.py); and
        # the drag's passes below read the acceleration from the plant's right-hand side,
        # in which a lumped line's pull is the one its nodes hold, none before they are
        # laid: that took the tether's pull for thrust to spare (a 15 m hover in a 3 m/s
        # wind trimmed 7 N short, and fell)
        params = params.replace(tether=params.tether.replace(
            model=TetherModel.CATENARY.value))
    model = PlantModel(params)
    tf = model.tether.forces(*position_m, tether_length_m)
    m = params.vehicle.mass_kg
    need = np.array([0.0, 0.0, m * params.environment.gravity_m_s2])
    need -= np.asarray(tf.on_uav_n)
    wind_model = WindModel(params.wind, 1e-3)
    wind = np.asarray(wind_model.steady_m_s) * profile_factor(wind_model.packed,
                                                              float(position_m[2]))
    x = initial_state(model, position_m=position_m, tether_length_m=tether_length_m)
    mixer = Mixer(params.vehicle)
    for _ in range(4):
        mix = mixer.mix(float(np.linalg.norm(need)), (0.0, 0.0, 0.0))
        if mix.saturated:
            raise ValueError("the rotors cannot hold the UAV there: thrust needed "
                             f"{np.linalg.norm(need):.1f} N")
        u = PlantInputs(rotor_commands=mix.commands, armed=True)
        x[QUAT] = thrust_aligned_quaternion(need, yaw_rad)
        x[ROTORS] = model.rotor_setpoints(u)
        if not np.any(wind):
            break
        # what is left of the acceleration (the drag) is thrust still to be found
        need = need - m * rhs(0.0, x, u, model, tuple(wind))[VEL]
    return x, u
