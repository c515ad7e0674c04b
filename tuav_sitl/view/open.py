"""``tuav-sitl view RUN``: a run folder's recording in Rerun's native viewer, or served to
its web viewer on a localhost URL (``--web``).

The recording is ``RUN/recording.rrd``; a ``tuav-sitl run`` folder without one (written
before rerun-sdk was installed) gets it written from ``timeseries.npz`` first, and a
``tuav-sitl up`` folder without one is first imported as ``tuav-sitl plot`` imports it.
The viewers are Rerun's own CLI (``rerun FILE``, ``rerun --serve-web FILE``), run with
rerun's analytics off.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from urllib.parse import quote

from tuav_sitl.view import RECORDING_NAME, ViewUnavailableError, rerun_module


def has_display() -> bool:
    """Whether a native window can be opened: not Linux/BSD, or an X11/Wayland display."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def web_viewer_url(web_port: int, grpc_url: str) -> str:
    """The URL that opens the web viewer on ``web_port`` connected to ``grpc_url``."""
    return f"http://127.0.0.1:{web_port}/?url={quote(grpc_url, safe='')}"


def grpc_proxy_url(grpc_port: int) -> str:
    """The viewer's URL of a gRPC server on 127.0.0.1:``grpc_port``."""
    return f"rerun+http://127.0.0.1:{grpc_port}/proxy"


def rerun_cli() -> str:
    """The path of the ``rerun`` executable rerun-sdk ships."""
    import rerun_cli as pkg

    name = "rerun.exe" if sys.platform.startswith("win") else "rerun"
    bundled = Path(pkg.__file__).parent / "Rerun.app" / "Contents" / "MacOS" / "Rerun"
    return str(bundled if bundled.exists() else Path(pkg.__file__).parent / name)


class RecordingMissingError(RuntimeError):
    """The folder has no recording and nothing to make one from."""


def recording_of(run: Path) -> Path:
    """The recording of ``run`` (a run folder or a ``.rrd`` file), written first for a
    run folder that has none."""
    if run.is_file():
        return run
    rrd = run / RECORDING_NAME
    if rrd.is_file():
        return rrd
    from tuav_sitl.run_import import import_up_run, needs_import
    from tuav_sitl.view.recording import write_run_recording

    if needs_import(run):
        import_up_run(run)
    if not (run / "timeseries.npz").is_file():
        raise RecordingMissingError(f"{run} has no {RECORDING_NAME}, nor a run's timeseries.npz "
                               "or truth.csv to write one from")
    print(f"tuav-sitl view: writing {rrd}", flush=True)
    return write_run_recording(run)


def serve_web_args(rrd: Path, web_port: int, grpc_port: int) -> list[str]:
    """The ``rerun`` command serving ``rrd`` to the web viewer, on localhost only."""
    return [rerun_cli(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
            "--web-viewer-port", str(web_port), str(rrd)]


def _interrupt(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def open_run(run: Path, web: bool = False, web_port: int = 9090,
             grpc_port: int = 9876) -> int:
    """Open ``run``'s recording (native viewer, or ``web``: serve the web viewer and print
    its URL, until Ctrl-C); returns the exit code."""
    try:
        rerun_module()   # installed, analytics off
        rrd = recording_of(run)
    except (ViewUnavailableError, RecordingMissingError, OSError) as exc:
        print(f"tuav-sitl view: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:   # an import of an up folder that cannot be read
        print(f"tuav-sitl view: cannot make a recording of {run}: {exc}", file=sys.stderr)
        return 2
    if not web and not has_display():
        print("tuav-sitl view: no display (DISPLAY/WAYLAND_DISPLAY unset): serving the web "
              "viewer instead", flush=True)
        web = True
    if web:
        args = serve_web_args(rrd, web_port, grpc_port)
        print(f"tuav-sitl view: {rrd} in Rerun's web viewer: "
              f"{web_viewer_url(web_port, grpc_proxy_url(grpc_port))}  (Ctrl-C stops)",
              flush=True)
    else:
        args = [rerun_cli(), str(rrd)]
        print(f"tuav-sitl view: opening {rrd} in Rerun's viewer", flush=True)
    signal.signal(signal.SIGTERM, _interrupt)
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    try:
        _, err = proc.communicate()
    except KeyboardInterrupt:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        return 0
    if proc.returncode not in (0, -signal.SIGINT, -signal.SIGTERM, 130):
        tail = [ln for ln in (err or "").splitlines() if ln.strip()][-1:]
        print(f"tuav-sitl view: rerun exited with code {proc.returncode}"
              + (f": {tail[0]}" if tail else ""), file=sys.stderr)
        return 1
    return 0
