"""What an offline run records, into arrays allocated before it starts.

:class:`SeriesLog`: one row of :data:`SERIES` per control period, packed as doubles into a
(rows, columns) array sized for the whole run (a row past its end is dropped), split into
the run's columns at the end. :class:`LineNodesLog`: the lumped tether's nodes at
:data:`LINE_NODES_RATE_HZ`, float32, into a (frames, points, 3) array sized the same way.
:class:`TetherFixLog`: the winch's tether fixes as the vehicle received them (and, under
the name ``gnss_fix``, the GNSS receiver's fixes).
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from tuavdefs.frames import quat_rows_to_euler

if TYPE_CHECKING:
    from companion.ekf import NavFilter
    from companion.onboard import OnboardOutputs
    from sitl.plant import Plant, TetherForces

#: How often a run with the lumped tether records its nodes (``line_t``, ``line_nodes``):
#: the animation's default frame rate [Hz].
LINE_NODES_RATE_HZ = 15.0
#: The time series logged at every control step, in the order of a row: (name, width),
#: width 0 for a scalar.
SERIES: tuple[tuple[str, int], ...] = (
    ("t", 0), ("pos", 3), ("vel", 3), ("ref_pos", 3), ("ref_vel", 3), ("euler", 3),
    ("att_cmd", 3), ("att_des", 3), ("rates", 3), ("thrust", 0), ("torque", 3),
    ("rotor_cmd", 4), ("mixer_sat", 0), ("pos_sat", 0), ("d_hat", 3), ("v_pos", 0),
    ("v_att", 0), ("v_win", 0), ("v_pos_raw", 0), ("v_att_raw", 0), ("length", 0),
    ("lbar", 0), ("lbar_rate", 0), ("lbar_fresh", 0), ("drum_rate", 0),
    ("winder_torque", 0), ("drum_tension", 0), ("top_tension", 0), ("regime", 0),
    ("lowest", 0), ("wind", 3), ("tether_force", 3), ("tether_force_est", 3),
    ("est_pos", 3), ("est_vel", 3), ("est_euler", 3), ("est_pos_sigma", 3))

#: A row as :meth:`SeriesLog.record` packs it: :data:`SERIES`' columns in the order their
#: sources give them (the plant's whole state first, as its list comes), with the two
#: attitudes as quaternions and the drum's angle for the paid-out length (:meth:`SeriesLog.
#: arrays` turns them into ``euler``, ``est_euler`` and ``length`` once, at the end).
_ROW: tuple[tuple[str, int], ...] = (
    ("t", 0), ("pos", 3), ("vel", 3), ("quat", 4), ("rates", 3), ("rotor_speeds", 4),
    ("drum_angle", 0), ("drum_rate", 0), ("ref_pos", 3), ("ref_vel", 3),
    ("att_cmd", 3), ("att_des", 3), ("thrust", 0), ("torque", 3), ("rotor_cmd", 4),
    ("mixer_sat", 0), ("pos_sat", 0), ("d_hat", 3), ("v_pos", 0), ("v_att", 0),
    ("v_pos_raw", 0), ("v_att_raw", 0), ("tether_force_est", 3), ("v_win", 0),
    ("lbar", 0), ("lbar_rate", 0), ("lbar_fresh", 0), ("winder_torque", 0),
    ("drum_tension", 0), ("top_tension", 0), ("regime", 0), ("lowest", 0), ("wind", 3),
    ("tether_force", 3), ("est_pos", 3), ("est_vel", 3), ("est_quat", 4),
    ("est_pos_sigma", 3))
#: The flight controller's diagnostics logged for a control period without flight (on the
#: ground): att_cmd and att_des; thrust and torque; then mixer_sat, pos_sat, d_hat, v_pos,
#: v_att, v_pos_raw, v_att_raw and tether_force_est.
_GROUND_ATTITUDE = (math.nan,) * 6
_GROUND_WRENCH = (math.nan,) * 4
_GROUND_REST = (0.0, 0.0) + (math.nan,) * 10
#: The estimate's columns (est_pos, est_vel, est_quat, est_pos_sigma) without one.
_NO_ESTIMATE = (math.nan,) * 13
_NAN3 = (math.nan,) * 3


class WinderReadout(NamedTuple):
    """What the log takes from the ground station's last winder period."""

    lyapunov: float
    """The torque law's Lyapunov function (NaN before its first command)."""
    lbar_m: float
    """L-bar, the length reference [m]."""
    lbar_rate_m_s: float
    """Its rate [m/s]."""
    torque_n_m: float
    """The torque the axis applies [N m]."""


class SeriesLog:
    """The run's :data:`SERIES`, ``n`` rows allocated up front; ``drum_radius_m`` turns the
    drum's angle into the paid-out length; ``nav_filter`` the onboard filter whose position
    sigma is logged (None: flying on the truth, no estimate columns)."""

    def __init__(self, n: int, drum_radius_m: float, nav_filter: NavFilter | None) -> None:
        self.n = n
        self.i = 0
        self.width = sum(max(w, 1) for _, w in _ROW)
        self._data = np.empty((n, self.width))
        self._buffer = memoryview(self._data).cast("B")
        packer = struct.Struct(f"{self.width}d")
        self._pack_into = packer.pack_into
        self._row_bytes = packer.size
        self._r_w = drum_radius_m
        self._filter = nav_filter

    def record(self, t_s: float, x: list[float], out: OnboardOutputs, fresh: bool,
               winder: WinderReadout, forces: TetherForces,
               wind_m_s: tuple[float, float, float]) -> None:
        """The row of the control period at ``t_s`` [s]: the plant's state ``x`` (its
        list), the onboard step's outputs, whether the winder computed L-bar in this
        period (``fresh``), the winder's readout, the tether's forces and the wind."""
        i = self.i
        if i >= self.n:
            return
        self.i = i + 1
        state, fs, ref = out.state, out.flight, out.reference
        if fs is not None:
            po, ao = fs.position, fs.attitude
            control = (*ao.attitude_cmd_rad, *po.attitude_rad, po.thrust_n, *ao.torque_n_m,
                       *fs.rotor_commands, fs.mixer_saturated, po.saturated,
                       *po.disturbance_m_s2, po.lyapunov, ao.lyapunov, po.lyapunov_raw,
                       ao.lyapunov_raw, *fs.tether_force_est_n)
        else:
            control = (*_GROUND_ATTITUDE, *_GROUND_WRENCH, *out.rotor_commands,
                       *_GROUND_REST)
        ref_pos, ref_vel = ((ref.pos_m, ref.vel_m_s) if ref is not None
                            else (_NAN3, _NAN3))
        filt = self._filter
        if filt is None or state is None:
            estimate = _NO_ESTIMATE
        else:
            estimate = (*state.pos_m, *state.vel_m_s, *state.quat, *filt.position_sigma_m())
        info = forces.info
        self._pack_into(
            self._buffer, i * self._row_bytes, t_s, *x, *ref_pos, *ref_vel, *control,
            winder.lyapunov, winder.lbar_m, winder.lbar_rate_m_s, fresh, winder.torque_n_m,
            forces.drum_tension_n, forces.top_tension_n, int(info.regime),
            info.lowest_point_height_m, *wind_m_s, *forces.on_uav_n, *estimate)

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns: 1-D arrays for scalars, (rows, width) arrays for vectors."""
        if not self.i:
            return {}
        # one pass over the rows; the columns are views of the result (a vector's
        # (rows, width) view is column-major)
        cols = np.ascontiguousarray(self._data[:self.i].T)
        row: dict[str, np.ndarray] = {}
        j = 0
        for name, w in _ROW:
            row[name] = cols[j] if w == 0 else cols[j:j + w].T
            j += max(w, 1)
        row["euler"] = quat_rows_to_euler(np.ascontiguousarray(row["quat"]))
        row["est_euler"] = quat_rows_to_euler(np.ascontiguousarray(row["est_quat"]))
        row["length"] = self._r_w * row["drum_angle"]
        return {name: row[name] for name, _ in SERIES}


class LineNodesLog:
    """The lumped tether's nodes (exit to attachment point) every 1/:data:`LINE_NODES_RATE_HZ`
    of a run of ``duration_s`` [s], float32, padded with NaN to the ``points`` the line can
    have at most."""

    def __init__(self, duration_s: float, points: int) -> None:
        n = int(duration_s * LINE_NODES_RATE_HZ) + 2
        self._t = np.empty(n)
        self._nodes = np.full((n, points, 3), np.nan, dtype=np.float32)
        self.i = 0
        self._next_s = 0.0

    def record(self, t_s: float, plant: Plant) -> None:
        """The nodes at ``t_s`` [s] when a frame is due."""
        if t_s < self._next_s - 1e-9 or self.i >= len(self._t):
            return
        self._next_s += 1.0 / LINE_NODES_RATE_HZ
        self._t[self.i] = t_s
        plant.line_nodes_into(self._nodes[self.i])
        self.i += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """``line_t`` [s] and ``line_nodes`` [m] (frames, points, 3), none if no frame."""
        if not self.i:
            return {}
        return {"line_t": self._t[:self.i].copy(), "line_nodes": self._nodes[:self.i].copy()}


class TetherFixLog:
    """The winch's tether fixes the vehicle received (at most the winch's
    :data:`tuavdefs.component_link.TETHER_FIX_RATE_HZ`, in a run of ``duration_s`` [s]):
    their sample times [s], positions [m] and standard deviations along x, y, z [m]. With
    ``name`` "gnss_fix", the GNSS receiver's fixes (at most ``rate_hz``) likewise."""

    def __init__(self, duration_s: float, rate_hz: float, name: str = "tether_fix") -> None:
        n = int(duration_s * rate_hz) + 2
        self._rows = np.empty((n, 7))
        self.i = 0
        self.name = name

    def record(self, t_s: float, pos_m: tuple[float, float, float],
               cov_m2: tuple[tuple[float, float, float], ...]) -> None:
        """A fix: its sample time [s], position [m] and covariance [m^2]."""
        if self.i < len(self._rows):
            self._rows[self.i] = (t_s, *pos_m, *(math.sqrt(cov_m2[k][k]) for k in range(3)))
            self.i += 1

    def record_sigma(self, t_s: float, pos_m: tuple[float, float, float],
                     sigma_m: tuple[float, float, float]) -> None:
        """A fix: its time [s], position [m] and standard deviations along x, y, z [m]."""
        if self.i < len(self._rows):
            self._rows[self.i] = (t_s, *pos_m, *sigma_m)
            self.i += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """``NAME_t`` [s], ``NAME_pos`` [m], ``NAME_sigma`` [m] (``NAME``: "tether_fix",
        or the name given); none if no fix came."""
        if not self.i:
            return {}
        r = self._rows[:self.i]
        name = self.name
        return {f"{name}_t": r[:, 0].copy(), f"{name}_pos": r[:, 1:4].copy(),
                f"{name}_sigma": r[:, 4:7].copy()}
