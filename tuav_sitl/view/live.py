"""The live view of ``tuav-sitl up``: a process beside the stack that follows what the
processes already write into the run folder and logs it to Rerun.

It reads, as they grow, the plant's truth (``truth.csv``, :mod:`sitl.truth_log`: the
vehicle's pose, the paid-out length, the rotor commands; the tether's tensions and L-bar
computed from them as ``tuav-sitl plot`` imports an up run,
:func:`tuav_sitl.up_series.build_series`; the tether's shape the lumped line's nodes of
``tether_nodes.csv``, or the plant's catenary) and the companion's ``flight.tlog`` (its
estimate in ``LOCAL_POSITION_NED``, with its covariance in ``LOCAL_POSITION_NED_COV``; the
receiver's fix in ``GPS_RAW_INT`` with its accuracy; the winch's tether fix, ``ODOMETRY``,
with its covariance; ``STATUSTEXT``), every :data:`POLL_S`. Nothing in the stack waits for
it: the processes write their files whatever it does, and when it falls behind it takes
what has accumulated in one chunk. Its sinks are always the run folder's
``recording.rrd``, and with ``--viewer native`` Rerun's native viewer (spawned), with
``--viewer web`` a gRPC server on 127.0.0.1 and Rerun's web viewer on a localhost URL.
SIGTERM (or SIGINT) ends it after a last read of both files.

``python -m tuav_sitl.view.live RUN_DIR [--viewer none|native|web] ...``
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tuav_sitl.view import RECORDING_NAME, ViewUnavailableError, rerun_module

#: The truth kept to compare the estimates with [s of simulated time].
TRUTH_KEPT_S = 10.0
#: What the estimates' comparison with the truth logs (the error plots only).
ERROR_PLOT_COLUMNS = ("errors",)
#: How often the files are read [s of wall time]: each read logs what came meanwhile in
#: one call per entity, so the recorder's cost is mostly per read, not per row.
POLL_S = 0.5
#: The tlog's messages the view draws (the others are skipped undecoded): the estimate
#: (LOCAL_POSITION_NED, with its covariance LOCAL_POSITION_NED_COV), the fixes (GPS_RAW_INT,
#: the winch's ODOMETRY), the messages (STATUSTEXT).
TLOG_MESSAGES = ("LOCAL_POSITION_NED", "LOCAL_POSITION_NED_COV", "GPS_RAW_INT", "ODOMETRY",
                 "STATUSTEXT")
#: Truth rows handed to the logger at most at once (a backlog is logged in such chunks).
MAX_CHUNK_ROWS = 2000
#: The STATUSTEXT severities (MAV_SEVERITY) at or below which a message is an error, a
#: warning.
_SEVERITY_ERROR, _SEVERITY_WARNING, _SEVERITY_DEBUG = 3, 4, 7
_MAGIC_V2, _MAGIC_V1 = 0xFD, 0xFE


class LineTail:
    """The complete lines of a growing text file, as they are written (a line still being
    written waits for its end)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._file: Any = None
        self._partial = ""

    def lines(self, max_lines: int | None = None) -> list[str]:
        """The complete lines written since the last call (at most ``max_lines``), without
        their line ends; none while the file does not exist."""
        if self._file is None:
            try:
                self._file = open(self.path)  # noqa: SIM115 - followed for the run's life
            except OSError:
                return []
        out: list[str] = []
        while max_lines is None or len(out) < max_lines:
            line = self._file.readline()
            if not line:
                break
            line = self._partial + line
            if not line.endswith("\n"):
                self._partial = line
                break
            self._partial = ""
            out.append(line.rstrip("\n"))
        return out

    def close(self) -> None:
        """Stop following the file."""
        if self._file is not None:
            self._file.close()


class TruthTail(LineTail):
    """The rows of a growing ``truth.csv`` (:data:`sitl.truth_log.TRUTH_COLUMNS`), read
    line by line as they are completed."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.header: list[str] | None = None

    def read(self, max_rows: int = MAX_CHUNK_ROWS) -> dict[str, np.ndarray] | None:
        """The columns of the complete rows written since the last call (at most
        ``max_rows``; None if there are none yet). Rows that are not numbers, or not as
        many as the header's columns, are skipped."""
        lines = self.lines(max_rows + (self.header is None))
        if self.header is None and lines:
            self.header = lines.pop(0).strip().split(",")
        if not lines or self.header is None:
            return None
        width = len(self.header)
        try:     # the whole chunk converted at once (numpy's parser, not a float() a value)
            data = np.array(",".join(lines).split(","), dtype=float).reshape(-1, width)
        except ValueError:
            data = np.array([row for row in (_floats(line, width) for line in lines)
                             if row is not None], dtype=float).reshape(-1, width)
        if not len(data):
            return None
        return {name: np.ascontiguousarray(data[:, i]) for i, name in enumerate(self.header)}


def _floats(line: str, width: int) -> list[float] | None:
    """The ``width`` numbers of a CSV line, or None."""
    parts = line.strip().split(",")
    if len(parts) != width:
        return None
    try:
        return [float(p) for p in parts]
    except ValueError:
        return None


class NodesTail(LineTail):
    """The lumped line's nodes of a growing ``tether_nodes.csv``
    (:data:`sitl.truth_log.NODES_NAME`: rows ``t_s,n,x0,y0,z0,...``)."""

    def read(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(times [s], nodes (rows, most points, 3) [m], NaN-padded) of the complete rows
        written since the last call; None if there are none."""
        times: list[float] = []
        rows: list[np.ndarray] = []
        for line in self.lines():
            try:
                values = [float(v) for v in line.split(",")]
                n = int(values[1])
                pts = np.array(values[2:2 + 3 * n]).reshape(n, 3)
            except (ValueError, IndexError):
                continue
            times.append(values[0])
            rows.append(pts)
        if not rows:
            return None
        most = max(r.shape[0] for r in rows)
        nodes = np.full((len(rows), most, 3), np.nan)
        for i, r in enumerate(rows):
            nodes[i, :r.shape[0]] = r
        return np.array(times), nodes

    def close(self) -> None:
        """Stop following the file."""
        if self._file is not None:
            self._file.close()


class TlogTail:
    """The messages of a growing ``.tlog`` (each frame after its 8-byte big-endian
    microsecond stamp), decoded by pymavlink as they are completed; with ``wanted``
    (message names) only those are decoded, the others skipped by their header's id."""

    def __init__(self, path: Path, wanted: tuple[str, ...] | None = None) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink

        self.path = path
        self.wanted = (None if wanted is None else
                       frozenset(getattr(mavlink, f"MAVLINK_MSG_ID_{n}") for n in wanted))
        self._file: Any = None
        self._buf = bytearray()
        self._mav = mavlink.MAVLink(None)
        self._mav.robust_parsing = True

    def read(self) -> list[Any]:
        """The messages completed since the last call."""
        if self._file is None:
            try:
                self._file = open(self.path, "rb")  # noqa: SIM115
            except OSError:
                return []
        self._buf += self._file.read()
        out: list[Any] = []
        buf = self._buf
        wanted = self.wanted
        i = 0
        while len(buf) - i >= 8 + 10:
            magic = buf[i + 8]
            if magic == _MAGIC_V2:
                n = 12 + buf[i + 9] + (13 if buf[i + 10] & 0x01 else 0)
                msg_id = buf[i + 15] | buf[i + 16] << 8 | buf[i + 17] << 16
            elif magic == _MAGIC_V1:
                n = 8 + buf[i + 9]
                msg_id = buf[i + 13]
            else:
                i += 1           # lost the framing: look for the next frame
                continue
            if len(buf) - i < 8 + n:
                break
            start = i + 8
            i += 8 + n
            if wanted is not None and msg_id not in wanted:
                continue
            try:
                msg = self._mav.decode(bytearray(buf[start:start + n]))
            except Exception:   # a corrupt frame: skipped as a ground station would
                continue
            if msg is not None:
                out.append(msg)
        del buf[:i]
        return out

    def close(self) -> None:
        """Stop following the file."""
        if self._file is not None:
            self._file.close()


class LiveView:
    """Follows a run folder and logs it (:class:`tuav_sitl.view.recording.SceneLogger`)
    to the recording stream ``rec``. ``params``: the plant's truth parameters (the run's
    ``params.toml``); ``home``: the winder's (latitude deg, longitude deg, altitude m)."""

    def __init__(self, rec: Any, run_dir: Path, params: Any,
                 home: tuple[float, float, float]) -> None:
        from sitl.truth_log import NODES_NAME
        from tuav_sitl.up_series import build_series
        from tuav_sitl.view.recording import SceneLogger
        from tuavdefs.params import TetherModel

        self.params = params
        self.home = home
        self._build_series = build_series   # (imported here: not in the flight's time)
        lumped = params.tether.kind == TetherModel.LUMPED
        self.logger = SceneLogger(rec, params, lumped=lumped,
                                  ground_half_m=_ground_half_m(params))
        self.truth = TruthTail(run_dir / "truth.csv")
        self.nodes = NodesTail(run_dir / NODES_NAME) if lumped else None
        self.tlog = TlogTail(run_dir / "flight.tlog", wanted=TLOG_MESSAGES)
        self.t_s = 0.0            # the latest simulated time seen [s]
        self.rows = 0
        self.vehicle_system = 1
        self._last_stamp: dict[str, int] = {}
        self._recent_texts: list[tuple[int, bytes]] = []
        self._truth_t = np.empty(0)
        self._truth_pos = np.empty((0, 3))
        self._pending_est: list[tuple[float, tuple[float, float, float]]] = []

    def poll(self) -> int:
        """Log what the files hold beyond the last call; returns the truth rows logged."""
        logged = 0
        while True:
            chunk = self.truth.read()
            if chunk is None:
                break
            series = self._build_series(chunk, self.params)
            self.logger.log_series(series)
            self._keep_truth(series["t"], series["pos"])
            self.t_s = float(series["t"][-1])
            logged += len(series["t"])
            if len(series["t"]) < MAX_CHUNK_ROWS:
                break
        self.rows += logged
        if self.nodes is not None:
            nodes = self.nodes.read()
            if nodes is not None:
                self.logger.log_line_nodes(*nodes)
        self._messages(self.tlog.read())
        return logged

    def _messages(self, msgs: list[Any]) -> None:
        from tuav_sitl.view.recording import Entity
        from tuavdefs.component_link import external_position
        from tuavdefs.frames import global_to_local_enu

        est_t: list[float] = []
        est: list[tuple[float, float, float]] = []
        cov_t: list[float] = []
        cov: list[tuple[float, ...]] = []
        fixes: dict[str, tuple[list[float], list[Any], list[Any]]] = {
            Entity.GNSS_FIX: ([], [], []), Entity.TETHER_FIX: ([], [], [])}
        for msg in msgs:
            kind = msg.get_type()
            if msg.get_srcSystem() != self.vehicle_system:
                continue      # what ground stations sent
            boot = getattr(msg, "time_boot_ms", None)
            # the tlog holds a copy of each message for every link it went out on
            stamp = (boot if boot is not None else getattr(msg, "time_usec", None))
            if stamp is not None:
                if stamp <= self._last_stamp.get(kind, -1):
                    continue
                self._last_stamp[kind] = stamp
            if kind == "LOCAL_POSITION_NED" and msg.get_srcComponent() == 1:
                est_t.append(boot * 1e-3)
                est.append((msg.y, msg.x, -msg.z))      # NED to the z-up frame
            elif kind == "LOCAL_POSITION_NED_COV":
                c = msg.covariance     # the diagonal's x, y, z (NED) [m^2]: index 9k - k(k-1)/2
                cov_t.append(msg.time_usec * 1e-6)
                cov.append((msg.y, msg.x, -msg.z, c[9], c[0], c[17]))
            elif kind == "ODOMETRY":   # the winch's tether fix (compid 169)
                fix = external_position(msg)
                if fix is not None:
                    ts, pos, acc = fixes[Entity.TETHER_FIX]
                    ts.append(fix.t_s)
                    pos.append(fix.pos_m)
                    acc.append([fix.cov_m2[i][i] ** 0.5 for i in range(3)])
            elif kind == "GPS_RAW_INT" and msg.fix_type >= 3:
                ts, pos, acc = fixes[Entity.GNSS_FIX]
                ts.append(msg.time_usec * 1e-6 or self.t_s)     # simulated time [us]
                pos.append(global_to_local_enu(msg.lat * 1e-7, msg.lon * 1e-7,
                                               msg.alt * 1e-3, self.home))
                h = getattr(msg, "h_acc", 0) * 1e-3
                v = getattr(msg, "v_acc", 0) * 1e-3
                acc.append((h, h, v))
            elif kind == "STATUSTEXT":
                self._status_text(msg)
            if boot is not None and kind != "STATUSTEXT":
                self.t_s = max(self.t_s, boot * 1e-3)
        if est:
            self.logger.log_series({"t": np.array(est_t), "est_pos": np.array(est)})
            self._pending_est += list(zip(est_t, est, strict=True))
        if cov:
            c = np.array(cov)
            self.logger.log_estimate_ellipsoids(np.array(cov_t), c[:, :3],
                                                np.sqrt(c[:, 3:]))
        self._estimate_errors()
        for path, (ts, pos, acc) in fixes.items():
            if ts:
                self.logger.log_fixes(path, np.array(ts), np.array(pos),
                                      accuracy_m=np.array(acc))

    def _status_text(self, msg: Any) -> None:
        """A STATUSTEXT into the text log (once, though the tlog has it once per link)."""
        from tuav_sitl.view.recording import LogLevel

        key = (msg.get_srcComponent(), bytes(msg.get_payload()))
        if key in self._recent_texts:
            return
        self._recent_texts = [*self._recent_texts[-15:], key]
        sev = int(msg.severity)
        level = (LogLevel.ERROR if sev <= _SEVERITY_ERROR else
                 LogLevel.WARN if sev == _SEVERITY_WARNING else
                 LogLevel.DEBUG if sev >= _SEVERITY_DEBUG else LogLevel.INFO)
        text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode(
            "utf-8", "replace")
        self.logger.log_text(self.t_s, text.rstrip("\x00"), level)

    def _keep_truth(self, t: np.ndarray, pos: np.ndarray) -> None:
        """The truth's last :data:`TRUTH_KEPT_S` seconds, to compare the estimates with."""
        self._truth_t = np.concatenate((self._truth_t, t))
        self._truth_pos = np.concatenate((self._truth_pos, pos))
        keep = self._truth_t >= self._truth_t[-1] - TRUTH_KEPT_S
        self._truth_t, self._truth_pos = self._truth_t[keep], self._truth_pos[keep]

    def _estimate_errors(self) -> None:
        """Estimate minus truth (interpolated) for the estimates the truth has reached;
        the later ones wait for it."""
        if not self._pending_est or len(self._truth_t) < 2:
            return
        t_end = self._truth_t[-1]
        ready = [(t, p) for t, p in self._pending_est if self._truth_t[0] <= t <= t_end]
        self._pending_est = [(t, p) for t, p in self._pending_est if t > t_end]
        if not ready:
            return
        t = np.array([r[0] for r in ready])
        est = np.array([r[1] for r in ready])
        truth = np.column_stack([np.interp(t, self._truth_t, self._truth_pos[:, i])
                                 for i in range(3)])
        self.logger.log_series({"t": t, "est_pos": est, "pos": truth},
                               only=ERROR_PLOT_COLUMNS)

    def close(self) -> None:
        """Stop following the files."""
        self.truth.close()
        self.tlog.close()
        if self.nodes is not None:
            self.nodes.close()


def _ground_half_m(params: Any) -> float:
    """The ground grid's half-width [m]: the tether's longest length, within 10-100 m."""
    return float(min(max(params.tether.total_length_m, 10.0), 100.0))


#: The live viewer's ports of instance 0 (rerun's defaults); each instance adds
#: :data:`tuavdefs.gcs.INSTANCE_PORT_STEP` times its number.
GRPC_PORT_DEFAULT, WEB_PORT_DEFAULT = 9876, 9090
#: How long the live view gets, after the stack has stopped, for its last read [s].
STOP_TIMEOUT_S = 5.0


@dataclass
class LiveProcess:
    """The running live view: its process and the banner's line about it."""

    process: subprocess.Popen
    banner: str
    log: Any


def viewer_kind(view: str | None) -> str:
    """``up --view``'s value as the live view's ``--viewer``: none without the option,
    ``auto`` the native viewer where there is a display, else the web viewer."""
    from tuav_sitl.view.open import has_display

    if view is None:
        return "none"
    if view == "auto":
        return "native" if has_display() else "web"
    return view


def start_live_view(run_dir: Path, view: str | None, instance: int,
                    home: Any) -> LiveProcess:
    """Start the live view of ``up``'s run folder (``view``: ``--view``'s value, None
    without it: the recording only), its log in ``RUN/view.log``."""
    from tuav_sitl.view.open import grpc_proxy_url, web_viewer_url
    from tuavdefs.gcs import INSTANCE_PORT_STEP

    grpc = GRPC_PORT_DEFAULT + INSTANCE_PORT_STEP * instance
    web = WEB_PORT_DEFAULT + INSTANCE_PORT_STEP * instance
    kind = viewer_kind(view)
    log = open(run_dir / "view.log", "w")  # noqa: SIM115 - kept open for the process's life
    proc = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl.view.live", str(run_dir), "--viewer", kind,
         "--grpc-port", str(grpc), "--web-port", str(web),
         "--home", repr(home.lat_deg), repr(home.lon_deg), repr(home.alt_m)],
        stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    rrd = run_dir / RECORDING_NAME
    banner = (f"live view (Rerun's web viewer): {web_viewer_url(web, grpc_proxy_url(grpc))}"
              if kind == "web" else
              f"live view: Rerun's native viewer (recording {rrd})" if kind == "native" else
              f"recording: {rrd} (tuav-sitl view {run_dir}; up --view for a live view)")
    return LiveProcess(proc, banner, log)


def stop_live_view(live: LiveProcess) -> None:
    """End the live view after its last read (SIGTERM, then SIGKILL after
    :data:`STOP_TIMEOUT_S`)."""
    proc = live.process
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)
    live.log.close()


def _idle() -> None:
    """This process (and the threads and viewer it starts after) at idle priority."""
    if hasattr(os, "SCHED_IDLE"):
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))


def main(argv: list[str] | None = None) -> int:
    """Follow a run folder until SIGTERM/SIGINT; returns the exit code."""
    ap = argparse.ArgumentParser(prog="python -m tuav_sitl.view.live", description=__doc__)
    ap.add_argument("run_dir", help="the up run folder to follow")
    ap.add_argument("--viewer", choices=("none", "native", "web"), default="none",
                    help="besides recording.rrd: Rerun's native viewer, or its web viewer")
    ap.add_argument("--grpc-port", type=int, default=9876,
                    help="the gRPC port the viewer connects to")
    ap.add_argument("--web-port", type=int, default=9090, help="the web viewer's port")
    ap.add_argument("--home", type=float, nargs=3, required=True,
                    metavar=("LAT", "LON", "ALT"), help="the winder's global position")
    args = ap.parse_args(argv)
    run_dir = Path(args.run_dir)
    stop = {"now": False}

    def on_signal(_signum: int, _frame: object) -> None:
        stop["now"] = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    _idle()
    try:
        rr = rerun_module()
    except ViewUnavailableError as exc:
        print(f"live view: {exc}", file=sys.stderr, flush=True)
        return 2
    from tuav_sitl.view.open import grpc_proxy_url, web_viewer_url
    from tuav_sitl.view.recording import blueprint, new_stream
    from tuavdefs.params import SystemParams
    from tuavdefs.paramspec import load_toml

    params = load_toml(SystemParams, run_dir / "params.toml")
    rec = new_stream(f"tuav-sitl up {run_dir.name}")
    sinks: list[Any] = [rr.FileSink(str(run_dir / RECORDING_NAME))]
    url = grpc_proxy_url(args.grpc_port)
    if args.viewer == "native":
        rec.spawn(port=args.grpc_port, connect=False, hide_welcome_screen=True)
        sinks.append(rr.GrpcSink(url))
    elif args.viewer == "web":
        sinks.append(rr.GrpcServerSink(bind_ip="127.0.0.1", port=args.grpc_port))
        rr.serve_web_viewer(web_port=args.web_port, open_browser=False, connect_to=url)
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    view = LiveView(rec, run_dir, params, tuple(args.home))
    where = (web_viewer_url(args.web_port, url) if args.viewer == "web" else
             "the native viewer" if args.viewer == "native" else "no viewer")
    print(f"live view: recording {run_dir / RECORDING_NAME}; {where}", flush=True)
    cpu0 = time.process_time()     # (the imports and the viewer's start before it)
    while not stop["now"]:
        view.poll()
        time.sleep(POLL_S)
    time.sleep(POLL_S)            # the processes' last writes
    view.poll()
    view.close()
    rec.flush()
    print(f"live view: {view.rows} truth rows up to {view.t_s:.2f} s recorded; "
          f"{time.process_time() - cpu0:.2f} s of CPU after the start", flush=True)
    if args.viewer == "web":
        with contextlib.suppress(Exception):
            rec.disconnect()
    return 0


if __name__ == "__main__":
    sys.exit(main())
