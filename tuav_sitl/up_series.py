"""The time series and the metrics of a ``tuav-sitl up`` run, in the offline runner's terms.

:func:`build_series` turns the plant's truth (``truth.csv``, read by
:func:`tuav_sitl.run_import.read_truth`) into every column of
:data:`tuav_sitl.offline.SERIES`, at the truth's instants (SI units, z-up frame, angles in
rad):

- ``t``, ``pos``, ``vel``, ``euler``, ``length``, ``drum_rate``, ``rotor_cmd``: the truth;
- ``lbar``, ``lbar_rate``: the ground station's own L-bar estimator
  (:class:`groundstation.lbar.LBarEstimator` with its default settings, as the
  ground-station process runs it) applied to the true position and velocity;
  ``lbar_fresh`` is 1 (L-bar is computed at every sample);
- ``top_tension``, ``drum_tension``, ``tether_force``, ``regime``, ``lowest``: the
  plant's own tether model (:class:`sitl.tether.Tether`) at the true position and
  paid-out length, i.e. what the plant computed at that instant;
- ``winder_torque``: NaN here; the ground station's ``Set_Input_Torque`` commands
  (:func:`read_can_torque`, from ``can.log``) held between frames (:func:`held`) when the
  import has a CAN log it can time;
- everything the companion keeps to itself (the reference ``ref_pos``/``ref_vel``, the
  attitude commands, thrust and torques, the disturbance estimate, the Lyapunov
  functions, the tether-force estimate) and the wind: NaN. The figures that need them
  are skipped (:func:`tuav_sitl.figures.missing_series`).

Plus ``armed`` (0/1). :func:`compute_up_metrics` gives the figures of merit such a run
supports.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.lbar import LBarEstimator, LBarParams
from sitl.tether import Tether
from tuav_sitl.candump_format import parse_log_line
from tuav_sitl.clock_pairing import ClockMap
from tuav_sitl.offline import GROUND_REGIMES, SERIES
from tuav_sitl.tlog_read import TlogData
from tuavdefs.can_protocol import dbc_path
from tuavdefs.params import SystemParams

__all__ = [
    "FLYING_MARGIN_M",
    "build_series",
    "compute_up_metrics",
    "flying_mask",
    "held",
    "read_can_torque",
]

#: The UAV counts as flying when armed and this far above its resting height (the gear) [m].
FLYING_MARGIN_M = 0.1


def read_can_torque(path: Path, clock: ClockMap) -> tuple[np.ndarray, np.ndarray, int]:
    """The ``Set_Input_Torque`` commands [N m] on an up run's ``can.log`` (candump -L),
    decoded with the project's DBC (any ODrive axis node: the DBC's layout, node 0's id):
    (simulated times [s], torques [N m], frames that could not be timed)."""
    import cantools

    db = cantools.database.load_file(str(dbc_path()), strict=True)
    msg = db.get_message_by_name("Set_Input_Torque")
    cmd_id = msg.frame_id & 0x1F
    walls: list[float] = []
    torques: list[float] = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                frame = parse_log_line(line)
            except ValueError:
                continue
            arb = frame.arbitration_id
            # axis nodes are 0..0x2F; the winch sensors sit on 0x30 (tuavdefs.can_protocol)
            if frame.is_remote or arb & 0x1F != cmd_id or arb >> 5 >= 0x30 \
                    or len(frame.data) < msg.length:
                continue
            walls.append(frame.timestamp)
            torques.append(float(msg.decode(bytes(frame.data))["Input_Torque"]))
    t = clock.sim(np.array(walls, dtype=float))
    ok = np.isfinite(t)
    return t[ok], np.array(torques, dtype=float)[ok], int((~ok).sum())


def held(t: np.ndarray, t_events: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` at the instants ``t_events`` [s] held until the next one, sampled at the
    instants ``t`` [s] (NaN before the first); in the units of ``values``."""
    out = np.full(len(t), np.nan)
    if len(t_events) == 0:
        return out
    order = np.argsort(t_events, kind="stable")
    te, v = t_events[order], values[order]
    idx = np.searchsorted(te, t + 1e-9, side="right") - 1
    ok = idx >= 0
    out[ok] = v[idx[ok]]
    return out


def build_series(truth: dict[str, np.ndarray], params: SystemParams,
                 lbar_params: LBarParams | None = None) -> dict[str, np.ndarray]:
    """The offline runner's columns (:data:`tuav_sitl.offline.SERIES`) from the truth:
    the truth itself, L-bar from the ground station's estimator, the tether's forces from
    the plant's model; NaN for what an up run does not record. Plus ``armed``."""
    t = truth["t_s"]
    n = len(t)
    s: dict[str, np.ndarray] = {name: np.full((n,) if w == 0 else (n, w), np.nan)
                                for name, w in SERIES}
    s["t"] = t.copy()
    s["pos"] = np.column_stack((truth["x_m"], truth["y_m"], truth["z_m"]))
    s["vel"] = np.column_stack((truth["vx_m_s"], truth["vy_m_s"], truth["vz_m_s"]))
    s["euler"] = np.column_stack((truth["roll_rad"], truth["pitch_rad"], truth["yaw_rad"]))
    s["length"] = truth["tether_length_m"].copy()
    s["drum_rate"] = truth["drum_rate_rad_s"].copy()
    s["rotor_cmd"] = np.column_stack([truth[f"rotor{i}"] for i in range(1, 5)])
    s["armed"] = truth["armed"].copy()
    g = params.environment.gravity_m_s2
    est = LBarEstimator(lbar_params or LBarParams(), params.tether.weight_per_length_n_m(g))
    tether = Tether(params.tether, g)
    pos, vel, length = s["pos"], s["vel"], s["length"]
    for i in range(n):
        p = (float(pos[i, 0]), float(pos[i, 1]), float(pos[i, 2]))
        lb = est.estimate(p, (float(vel[i, 0]), float(vel[i, 1]), float(vel[i, 2])))
        s["lbar"][i], s["lbar_rate"][i] = lb.length_m, lb.rate_m_s
        try:
            f = tether.forces(p[0], p[1], max(p[2], 0.0), float(length[i]))
        except (ValueError, RuntimeError):
            tether.reset_warm_start()
            continue
        s["top_tension"][i], s["drum_tension"][i] = f.top_tension_n, f.drum_tension_n
        s["tether_force"][i] = f.on_uav_n
        s["regime"][i] = int(f.info.regime)
        s["lowest"][i] = f.info.lowest_point_height_m
    s["lbar_fresh"] = np.ones(n)
    return s


def flying_mask(s: dict[str, np.ndarray], gear_height_m: float) -> np.ndarray:
    """Samples at which the UAV flies: armed and more than :data:`FLYING_MARGIN_M` above
    its resting height."""
    return (s["armed"] > 0.5) & (s["pos"][:, 2] > gear_height_m + FLYING_MARGIN_M)


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def compute_up_metrics(s: dict[str, np.ndarray], params: SystemParams,
                       tlog: TlogData | None, name: str) -> dict[str, Any]:
    """What an up run supports of the offline runner's figures of merit, and its own:

    ``sim_time_s`` (last truth instant), ``flight_time_s`` (time flying: armed and above
    the gear, see :func:`flying_mask`), ``armed_time_s``,
    ``max_tether_slack_violation_m`` (max of straight-line distance minus paid-out
    length: positive if the tether was ever stretched beyond its unstretched length),
    ``min_tether_slack_m`` (its negative, as the offline runner defines it),
    ``tether_length_rmse_m`` and ``tether_length_max_error_m`` (L - L-bar while flying),
    ``max_tension_n``, ``max_drum_tension_n``, ``tether_ground_contact_fraction`` (the
    plant's tether model), ``max_winder_torque_n_m`` (CAN), ``waypoints_reached``
    (``MISSION_ITEM_REACHED``: mission sequence number and simulated time; null if the tlog
    has none). Tracking metrics need the reference, which an up run does not log: null.
    """
    t = s["t"]
    dt = np.diff(t)
    fly = flying_mask(s, params.vehicle.gear_height_m)
    armed = s["armed"] > 0.5
    dist = np.linalg.norm(s["pos"], axis=1)
    err = (s["length"] - s["lbar"])[fly]
    top, drum, regime = s["top_tension"], s["drum_tension"], s["regime"]
    solved = np.isfinite(regime)
    torque = s["winder_torque"]
    m: dict[str, Any] = {
        "scenario": name,
        "source": "tuav-sitl up",
        "sim_time_s": float(t[-1]),
        "samples": len(t),
        "flight_time_s": float(dt[fly[:-1]].sum()),
        "armed_time_s": float(dt[armed[:-1]].sum()),
        "max_tether_slack_violation_m": float(np.max(dist - s["length"])),
        "min_tether_slack_m": float(np.min(s["length"] - dist)),
        "tether_length_rmse_m": float(np.sqrt(np.mean(err ** 2))) if len(err) else None,
        "tether_length_max_error_m": float(np.max(np.abs(err))) if len(err) else None,
        "max_tension_n": _finite_or_none(np.max(top[solved])) if solved.any() else None,
        "max_drum_tension_n": _finite_or_none(np.max(drum[solved])) if solved.any() else None,
        "tether_ground_contact_fraction": (float(np.isin(regime[solved], GROUND_REGIMES)
                                                 .mean()) if solved.any() else None),
        "max_winder_torque_n_m": (float(np.nanmax(np.abs(torque)))
                                  if np.isfinite(torque).any() else None),
        "position_rmse_m": None,
        "position_max_error_m": None,
        "attitude_rmse_rad": None,
        "waypoints_reached": None,
    }
    if tlog is not None and tlog.reached:
        m["waypoints_reached"] = [
            {"index": seq, "t_s": round(ts, 3) if math.isfinite(ts) else None}
            for seq, ts in tlog.reached]
    return m
