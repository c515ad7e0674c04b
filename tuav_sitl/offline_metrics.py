"""The offline run's figures of merit (docs/results.md defines them): tracking, tether and
saturation figures, the estimate's errors, settling and overshoot, and the Lyapunov
functions' report (docs/control.md §5), from the run's series (:data:`tuav_sitl.offline_log.
SERIES`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from sitl.catenary import CatenaryRegime
from tuav_sitl.scenario import ScenarioParams
from tuavdefs.frames import wrap_pi

#: Tether regimes in which part of the tether lies on the ground.
GROUND_REGIMES = (int(CatenaryRegime.TOUCHDOWN), int(CatenaryRegime.SLACK),
                  int(CatenaryRegime.FLAT))
#: Distance to the goal within which a set-point run counts as settled [m].
SETTLE_BAND_M = 0.05
#: Height above the gear's below which the vehicle counts as on the ground (the metrics'
#: saturation counts in the air only) [m].
GEAR_MARGIN_M = 0.02


def compute_metrics(sc: ScenarioParams, s: dict[str, np.ndarray],
                    reference: Any, wall_s: float) -> dict[str, Any]:
    """The run's figures of merit (see docs/results.md for their definitions)."""
    t = s["t"]
    # tracking counts while flying a reference (a mission's time on the ground has none)
    flying = np.isfinite(s["ref_pos"]).all(axis=1)
    win = (t >= sc.metrics_after_s) & flying
    pos_err = np.linalg.norm(s["pos"] - s["ref_pos"], axis=1)
    e_att = s["euler"] - s["att_cmd"]
    e_att[:, 2] = (e_att[:, 2] + np.pi) % (2 * np.pi) - np.pi
    att_err = np.linalg.norm(e_att, axis=1)
    # L-bar is computed at the winder's rate and held between updates: compare the length
    # with it only at the instants it was computed
    fresh = s["lbar_fresh"].astype(bool)
    len_err = (s["length"] - s["lbar"])[fresh]
    len_win = win[fresh]
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    rotor = s["rotor_cmd"]
    rotor_sat = (rotor <= 1e-9).any(axis=1) | (rotor >= 1 - 1e-9).any(axis=1)
    motor_sat = rotor_sat | s["mixer_sat"].astype(bool)
    # saturation counts in the air: a vehicle down on its gear with the rotors at their
    # minimum (landed, the land detector not yet done) is not short of control
    airborne = flying & (s["pos"][:, 2] > sc.plant.vehicle.gear_height_m + GEAR_MARGIN_M)
    m: dict[str, Any] = {
        "scenario": sc.name,
        "position_rmse_m": _rms(pos_err[win]),
        "position_max_error_m": _max(pos_err[win]),
        "attitude_rmse_rad": _rms(att_err[win]),
        "tether_length_rmse_m": _rms(len_err[len_win]),
        "tether_length_max_error_m": _max(np.abs(len_err[len_win])),
        "min_tether_slack_m": float(slack.min()),
        "max_tension_n": float(s["top_tension"].max()),
        "max_drum_tension_n": float(s["drum_tension"].max()),
        "tether_ground_contact_fraction": float(np.isin(s["regime"], GROUND_REGIMES).mean()),
        "motor_saturation_fraction": (float(motor_sat[airborne].mean()) if airborne.any()
                                      else 0.0),
        "position_loop_saturation_fraction": (
            float(s["pos_sat"].astype(bool)[airborne].mean()) if airborne.any() else 0.0),
        "settling_time_s": None,
        "overshoot_percent": None,
        "metrics_after_s": sc.metrics_after_s,
        "sim_time_s": float(t[-1]),
        "wall_time_s": round(wall_s, 3),
        "realtime_factor": round(float(t[-1]) / wall_s, 2) if wall_s > 0 else None,
    }
    m["estimator"] = sc.estimator.kind
    est = np.isfinite(s["est_pos"]).all(axis=1) & (t >= sc.metrics_after_s)
    if est.any():
        denied = any(f.kind == "gnss_loss" and f.start_s <= 0.0 and f.end_s >= sc.duration_s
                     for f in sc.faults)
        m["gnss"] = "none" if denied else sc.sensors.gnss
        e_att_est = s["est_euler"][est] - s["euler"][est]
        e_att_est[:, 2] = (e_att_est[:, 2] + np.pi) % (2 * np.pi) - np.pi
        m["estimate_position_rmse_m"] = _rms(np.linalg.norm(
            s["est_pos"][est] - s["pos"][est], axis=1))
        m["estimate_velocity_rmse_m_s"] = _rms(np.linalg.norm(
            s["est_vel"][est] - s["vel"][est], axis=1))
        m["estimate_attitude_rmse_rad"] = _rms(np.linalg.norm(e_att_est, axis=1))
    loss = np.zeros(len(t), dtype=bool)
    for f in sc.faults:
        if f.kind == "gnss_loss":
            loss |= (t >= f.start_s) & (t < f.end_s)
    if (loss & flying).any():
        # while the GNSS is lost (in flight): the truth off its reference and the estimate
        # off the truth, horizontally
        lf = loss & flying
        m["gnss_loss_horizontal_error_max_m"] = float(np.hypot(
            *(s["pos"][lf, :2] - s["ref_pos"][lf, :2]).T).max())
        lfe = lf & np.isfinite(s["est_pos"]).all(axis=1)
        if lfe.any():
            m["gnss_loss_estimate_horizontal_error_max_m"] = float(np.hypot(
                *(s["est_pos"][lfe, :2] - s["pos"][lfe, :2]).T).max())
    if (reference is not None and sc.trajectory.kind in ("setpoint", "step")
            and reference.goal is not None):
        goal = np.array(reference.goal)
        start = np.array(sc.initial.position_m)
        dist_goal = np.linalg.norm(s["pos"] - goal, axis=1)
        outside = np.nonzero(dist_goal > SETTLE_BAND_M)[0]
        if len(outside) == 0:
            m["settling_time_s"] = 0.0
        elif outside[-1] + 1 < len(t):
            m["settling_time_s"] = float(t[outside[-1] + 1] - sc.trajectory.start_s)
        still = reference.traj.end_s if sc.trajectory.kind == "setpoint" else 0.0
        m["lyapunov"] = lyapunov_report(s, still)
        span = np.linalg.norm(goal - start)
        if span > 0:
            along = (s["pos"] - goal) @ ((goal - start) / span)
            m["overshoot_percent"] = float(max(along.max(), 0.0) / span * 100.0)
    return m


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")


def _max(x: np.ndarray) -> float:
    """The largest of ``x``; NaN for none (a run that never flew a reference)."""
    return float(x.max()) if len(x) else float("nan")



#: A subsystem's reference counts as constant once its rate stays below these.
ATTITUDE_REF_STILL_RAD_S = 1e-3
LENGTH_REF_STILL_M_S = 1e-3
#: Below these values a Lyapunov function is under what a 250 Hz sampled loop on a 1 kHz
#: plant resolves (position errors ~0.3 mm, attitude ~1e-4 rad, length ~30 um).
LYAPUNOV_FLOORS = {"v_pos": 1e-7, "v_att": 1e-8, "v_win": 1e-8}


def still_from(t: np.ndarray, x: np.ndarray, tol: float) -> float | None:
    """First time after which ``x``'s rate stays at or below ``tol`` (None if never)."""
    rate = np.abs(np.gradient(x, t, axis=0))
    if rate.ndim > 1:
        rate = rate.max(axis=1)
    moving = np.nonzero(rate > tol)[0]
    if len(moving) == 0:
        return float(t[0])
    if moving[-1] + 1 >= len(t):
        return None
    return float(t[moving[-1] + 1])


def lyapunov_increases(t: np.ndarray, v: np.ndarray, from_s: float, floor: float = 0.0
                       ) -> int:
    """How many times ``v`` rises after ``from_s`` while above ``floor``: zero for a
    Lyapunov function once its reference is constant."""
    sel = t >= from_s
    vv = v[sel]
    d = np.diff(vv)
    return int(np.sum((d > 0.0) & (vv[:-1] > floor)))


def above_floor_s(t: np.ndarray, v: np.ndarray, from_s: float, floor: float) -> float:
    """How long after ``from_s`` [s] ``v`` stays above ``floor`` before it first reaches
    it: the span a count of rises above the floor covers (0 if it starts at the floor)."""
    sel = t >= from_s
    tt, vv = t[sel], v[sel]
    if not len(vv) or not vv[0] > floor:
        return 0.0
    below = np.nonzero(~(vv > floor))[0]
    end = tt[below[0]] if len(below) else tt[-1]
    return float(end - tt[0])


#: The Lyapunov functions of the raw (uncompensated) errors, beside the compensated ones.
RAW_LYAPUNOV = {"v_pos": "v_pos_raw", "v_att": "v_att_raw"}


def lyapunov_report(s: dict[str, np.ndarray], position_ref_still_s: float
                    ) -> dict[str, dict[str, Any]]:
    """For each subsystem, from when its reference is constant (docs/control.md §5): its
    Lyapunov function's value then and its floor (:data:`LYAPUNOV_FLOORS`), how long it
    stays above the floor (``above_floor_s``: what the count covers; 0 means the count is
    no evidence), how often it rose above the floor and at all; for the position and
    attitude loops the same of the raw errors' function (``raw_*``).

    Position: the position reference is constant. Attitude: the filtered attitude command
    is still. Winder: L-bar is still.
    """
    t = s["t"]
    starts = {
        "v_pos": position_ref_still_s,
        "v_att": still_from(t, s["att_cmd"], ATTITUDE_REF_STILL_RAD_S),
        "v_win": still_from(t, s["lbar"], LENGTH_REF_STILL_M_S),
    }
    out: dict[str, dict[str, Any]] = {}
    for name, t0 in starts.items():
        floor = LYAPUNOV_FLOORS[name]
        if t0 is not None and t0 >= t[-1]:
            t0 = None   # the run ended before the reference settled
        if t0 is None:
            out[name] = {"from_s": None, "value_then": None, "floor": floor,
                         "above_floor_s": None, "increases": None, "increases_any": None}
            continue
        i0 = int(np.searchsorted(t, t0))
        v = s[name]
        r: dict[str, Any] = {
            "from_s": round(t0, 3), "value_then": float(v[i0]), "floor": floor,
            "above_floor_s": round(above_floor_s(t, v, t0, floor), 3),
            "increases": lyapunov_increases(t, v, t0, floor),
            "increases_any": lyapunov_increases(t, v, t0, 0.0)}
        raw = RAW_LYAPUNOV.get(name)
        if raw is not None:
            vr = s[raw]
            r |= {"raw_value_then": float(vr[i0]),
                  "raw_above_floor_s": round(above_floor_s(t, vr, t0, floor), 3),
                  "raw_increases": lyapunov_increases(t, vr, t0, floor)}
        out[name] = r
    return out


def yaw_error(a: float, b: float) -> float:
    """Wrapped difference of two headings [rad]."""
    return wrap_pi(a - b)

