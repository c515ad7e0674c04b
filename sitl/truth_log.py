"""The plant's truth log: ``truth.csv``, one row every N control periods.

:data:`TRUTH_COLUMNS` names the columns; each row holds their values as floats, each
written as its ``repr`` (so a reader gets the plant's doubles back to the bit). Units are SI
in the inertial frame (z up, origin at the winder's tether exit): time ``t_s`` [s],
position ``x_m, y_m, z_m`` [m], velocity ``vx_m_s, vy_m_s, vz_m_s`` [m/s], the attitude's
Euler angles ``roll_rad, pitch_rad, yaw_rad`` [rad] (body x forward, y left, z up), the
paid-out ``tether_length_m`` [m], the drum's rate ``drum_rate_rad_s`` [rad/s], ``armed``
(1.0 or 0.0), the held rotor commands ``rotor1`` .. ``rotor4`` (normalised, [0, 1]) and
the wind at the UAV ``wind_x_m_s, wind_y_m_s, wind_z_m_s`` [m/s] (the air's velocity: mean,
turbulence and gusts, as the last physics step sampled it).

With the lumped tether (``[tether] model = "lumped"``) and a log that is a file
(:class:`tuavdefs.logfile.LogFile`), the line's nodes are logged beside it, to
``tether_nodes.csv`` in the same folder, every 1/:data:`NODES_RATE_HZ` s of simulated time
(on the logged periods): a row ``t_s,n,x0,y0,z0,...`` of the ``n`` points from the
winder's exit to the attachment point [m, to 0.1 mm] (``n`` changes as nodes are added and
removed at the drum).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Protocol

from sitl.plant import DRUM_RATE, POS, QUAT, VEL
from tuavdefs.frames import quat_to_euler

if TYPE_CHECKING:
    from sitl.simlink_server import SimLinkServer

#: The truth log's columns, in order (units in the module docstring).
TRUTH_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "roll_rad",
                 "pitch_rad", "yaw_rad", "tether_length_m", "drum_rate_rad_s", "armed",
                 "rotor1", "rotor2", "rotor3", "rotor4", "wind_x_m_s", "wind_y_m_s",
                 "wind_z_m_s")
#: A row of the truth log: the columns' values (floats) as their repr.
_ROW = ",".join(["%r"] * len(TRUTH_COLUMNS)) + "\n"
#: The lumped line's nodes beside the truth log: the file's name, its rate [Hz of
#: simulated time].
NODES_NAME = "tether_nodes.csv"
NODES_RATE_HZ = 15.0


class TextSink(Protocol):
    """Where the rows go: a text file, or a :class:`tuavdefs.logfile.LogFile` (which ends
    the log, not the plant, when the disk fills)."""

    def write(self, text: str, /) -> object: ...
    def flush(self) -> object: ...
    def close(self) -> object: ...


class TruthLog:
    """The plant's truth as CSV on ``stream`` (the header written at once), a row every
    ``every_periods`` control periods (at least 1), flushed at least once a wall-clock
    second."""

    def __init__(self, stream: TextSink, every_periods: int) -> None:
        self.stream = stream
        self.every = max(1, every_periods)
        self._count = 0
        self._flushed = time.monotonic()
        stream.write(",".join(TRUTH_COLUMNS) + "\n")
        self._nodes: TextSink | None = None
        self._nodes_next_s = 0.0
        self._nodes_checked = False

    def record(self, server: SimLinkServer) -> None:
        """Called after each control period: the row of the state ``server.plant`` has
        reached and the commands the server holds, if this period is one to log."""
        self._count += 1
        if (self._count - 1) % self.every:
            return
        p = server.plant
        x = p.x.tolist()
        c0, c1, c2, c3 = server.rotor_commands
        # every value a float, each written as its repr
        self.stream.write(_ROW % (float(p.t_s), *x[POS], *x[VEL], *quat_to_euler(x[QUAT]),
                                  float(p.tether_length_m), x[DRUM_RATE],
                                  1.0 if server.armed else 0.0, float(c0), float(c1),
                                  float(c2), float(c3), *p.wind_m_s))
        if not self._nodes_checked:
            self._nodes_checked = True
            self._nodes = self._nodes_log(p.model.lumped)
        if self._nodes is not None and p.t_s >= self._nodes_next_s - 1e-9:
            self._nodes_next_s += 1.0 / NODES_RATE_HZ
            nodes = p.line_nodes_m().ravel().tolist()
            self._nodes.write(f"{float(p.t_s)!r},{len(nodes) // 3}," + ",".join(
                [f"{v:.4f}" for v in nodes]) + "\n")
        now = time.monotonic()
        if now - self._flushed >= 1.0:
            self.stream.flush()
            if self._nodes is not None:
                self._nodes.flush()
            self._flushed = now

    def _nodes_log(self, lumped: bool) -> TextSink | None:
        """The nodes' log beside a truth log that is a file, on the lumped line."""
        from tuavdefs.logfile import LogFile

        if not lumped or not isinstance(self.stream, LogFile):
            return None
        return LogFile(self.stream.path.with_name(NODES_NAME), text=True,
                       max_bytes=self.stream.max_bytes)

    def close(self) -> None:
        """Close the stream (what is buffered is written first)."""
        self.stream.close()
        if self._nodes is not None:
            self._nodes.close()
