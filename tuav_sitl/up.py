"""``tuav-sitl up``: the plant, the companion and the ground station as three OS processes.

Starts them in order (plant, ground station, companion), waits until each says it is
ready, prints a banner, and supervises them (a fourth, `tuav-sitl candump`, records the
bus to ``can.log`` in candump's log format): Ctrl-C or SIGTERM stops all three within a few
seconds and leaves none behind; if one exits, the others are stopped and the exit code says
which failed. Each run gets a folder with every process's log, the plant's truth series and
the parameters used.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import TextIO

from tuavdefs import component_link as cl
from tuavdefs import simlink as sl
from tuavdefs.canbus import DEFAULT_GROUP, resolve_spec
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import load_toml, to_dict

#: How long a process may take to say it is ready [s].
READY_TIMEOUT_S = 60.0
#: How long a process gets to exit after SIGTERM before it is killed [s].
STOP_GRACE_S = 2.0


class UpError(RuntimeError):
    """A problem starting the stack, said in one line."""


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _can_spec(spec: str, instance: int) -> str:
    """The bus spec for this instance: its own multicast group or vcan interface."""
    interface, channel = resolve_spec(spec)
    if interface == "udp_multicast" and channel == DEFAULT_GROUP and instance:
        base, last = DEFAULT_GROUP.rsplit(".", 1)
        return f"udp_multicast:{base}.{int(last) + instance}"
    return f"{interface}:{channel}"


class Stack:
    """The three processes and their logs."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = run_dir
        self.procs: dict[str, subprocess.Popen] = {}
        self.recorders: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, TextIO] = {}

    def start(self, name: str, args: list[str], ready_text: str) -> None:
        """Start ``python -m ...`` and wait until its log shows ``ready_text``."""
        log_path = self.run_dir / f"{name}.log"
        log = open(log_path, "w")  # noqa: SIM115 - kept open for the process's life
        self.logs[name] = log
        proc = subprocess.Popen([sys.executable, *args], stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        self.procs[name] = proc
        deadline = time.monotonic() + READY_TIMEOUT_S
        while time.monotonic() < deadline:
            if ready_text in log_path.read_text():
                return
            if proc.poll() is not None:
                raise UpError(f"{name} exited while starting (code {proc.returncode}): "
                              f"{_last_line(log_path)}")
            time.sleep(0.05)
        raise UpError(f"{name} did not become ready within {READY_TIMEOUT_S:.0f} s")

    def start_recorder(self, name: str, args: list[str]) -> None:
        """Start a process that needs no readiness check (its output goes to its log)."""
        log = open(self.run_dir / f"{name}.log", "w")  # noqa: SIM115
        self.logs[name] = log
        self.recorders[name] = subprocess.Popen([sys.executable, *args], stdout=log,
                                                stderr=subprocess.STDOUT,
                                                start_new_session=True)

    def first_exit(self) -> tuple[str, int] | None:
        """(name, exit code) of a process that has exited, if any."""
        for name, proc in self.procs.items():
            code = proc.poll()
            if code is not None:
                return name, code
        return None

    def stop(self) -> None:
        """SIGTERM to all, then SIGKILL to whatever is left after the grace time."""
        everyone = [*self.procs.values(), *self.recorders.values()]
        for proc in everyone:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE_S
        for proc in everyone:
            try:
                proc.wait(timeout=max(deadline - time.monotonic(), 0.01))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)
        for log in self.logs.values():
            log.close()


def _last_line(path: Path) -> str:
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    return lines[-1] if lines else "(no output)"


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of ``tuav-sitl up``."""
    ap.add_argument("--speedup", default="1", help="1: real time (default); max: lockstep, "
                    "as fast as the processes allow")
    ap.add_argument("--params", default=None, help="system parameters TOML (vehicle, tether, "
                    "winder, wind)")
    ap.add_argument("--can", default="auto", metavar="SPEC",
                    help="CAN bus: auto, socketcan:IFACE, udp_multicast[:GROUP]")
    ap.add_argument("--home", type=float, nargs=3, default=sl.HOME_DEFAULT,
                    metavar=("LAT", "LON", "ALT"), help="the winder's global position")
    ap.add_argument("--position", type=float, nargs=3, default=(4.0, 0.0, 10.0),
                    metavar=("X", "Y", "Z"), help="start in hover here [m], z-up frame")
    ap.add_argument("--goto", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="have the companion fly here [m] (until missions come over MAVLink)")
    ap.add_argument("--duration", type=float, default=None,
                    help="stop after [s] of simulated time")
    ap.add_argument("--logdir", default="runs", help="where run folders go")
    ap.add_argument("--instance", type=int, default=0,
                    help="offset every port (by 10 per instance) to run stacks side by side")


def run_up(args: argparse.Namespace) -> int:
    """Start, supervise and stop the stack; returns the exit code."""
    if args.speedup not in ("1", "max"):
        print("tuav-sitl up: --speedup takes 1 (real time) or max (lockstep) for now",
              file=sys.stderr)
        return 2
    real_time = args.speedup == "1"
    sim_port = sl.SIM_PORT_DEFAULT + 10 * args.instance
    comp_port = cl.COMPONENT_PORT_DEFAULT + 10 * args.instance
    for port in (sim_port, comp_port):
        if not _port_free(port):
            print(f"tuav-sitl up: port {port} is in use (another stack?); "
                  f"try --instance {args.instance + 1}", file=sys.stderr)
            return 1
    params = SystemParams() if args.params is None else load_toml(SystemParams,
                                                                   Path(args.params))
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    run_dir = Path(args.logdir) / f"up-{stamp}-{args.instance}"
    run_dir.mkdir(parents=True, exist_ok=True)
    from tuav_sitl.offline import _to_toml  # the same writer as the offline runner's

    (run_dir / "params.toml").write_text(_to_toml(to_dict(params)))
    can = _can_spec(args.can, args.instance)
    home = [str(v) for v in args.home]
    common = ["--params", str(run_dir / "params.toml")]
    plant_args = ["-m", "sitl", "--port", str(sim_port), "--can", can, "--home", *home,
                  "--position", *map(str, args.position),
                  "--truth-log", str(run_dir / "truth.csv"), *common]
    if real_time:
        plant_args.append("--real-time")
    if args.duration is not None:
        plant_args += ["--duration", str(args.duration)]
    comp_args = ["-m", "companion", "--sim", f"127.0.0.1:{sim_port}", "--component-port",
                 str(comp_port), "--home", *home, *common]
    if args.goto is not None:
        comp_args += ["--goto", *map(str, args.goto)]
    gs_args = ["-m", "groundstation", "--can", can, "--mavlink", f"127.0.0.1:{comp_port}",
               *common]
    stack = Stack(run_dir)
    stopping = {"signal": None}

    def on_signal(signum: int, _frame: object) -> None:
        stopping["signal"] = signum

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    code = 0
    try:
        stack.start_recorder("candump", ["-m", "tuav_sitl", "candump", "-L", "--can", can,
                                         "--log", str(run_dir / "can.log")])
        stack.start("plant", plant_args, "listening on")
        stack.start("groundstation", gs_args, "groundstation: CAN")
        stack.start("companion", comp_args, "companion: connected")
        print(_banner(run_dir, sim_port, comp_port, can, args, real_time), flush=True)
        while stopping["signal"] is None:
            ended = stack.first_exit()
            if ended is not None:
                name, rc = ended
                if name == "plant" and rc == 0:
                    print(f"tuav-sitl up: plant finished: "
                          f"{_last_line(run_dir / 'plant.log')}", flush=True)
                else:
                    print(f"tuav-sitl up: {name} exited with code {rc}: "
                          f"{_last_line(run_dir / f'{name}.log')}", file=sys.stderr)
                    code = 1
                break
            time.sleep(0.1)
    except UpError as exc:
        print(f"tuav-sitl up: {exc}", file=sys.stderr)
        code = 1
    finally:
        stack.stop()
    if stopping["signal"] is not None:
        print("tuav-sitl up: stopped", flush=True)
    print(f"tuav-sitl up: logs in {run_dir}", flush=True)
    return code


def _banner(run_dir: Path, sim_port: int, comp_port: int, can: str,
            args: argparse.Namespace, real_time: bool) -> str:
    interface, channel = resolve_spec(can)
    watch = (f"candump {channel}" if interface == "socketcan" else
             f"python -c \"import can; b=can.Bus(interface='udp_multicast', "
             f"channel='{channel}', hop_limit=0); [print(m) for m in b]\"")
    lat, lon, alt = args.home
    return "\n".join([
        "tuav-sitl up: plant, companion and ground station are running",
        f"  simulator link (plant <-> companion): tcp:127.0.0.1:{sim_port}",
        f"  component link (companion <-> winch): tcp:127.0.0.1:{comp_port}",
        "  ground-station MAVLink endpoints (tcp:5760, udp:14550/14540): not yet built",
        f"  winder CAN bus: {interface}:{channel}   watch it: {watch}",
        f"  home: {lat:.7f}, {lon:.7f}, {alt:.1f} m AMSL (the winder)",
        f"  clock: {'real time' if real_time else 'lockstep, as fast as possible'}",
        f"  logs: {run_dir} (truth.csv, can.log, a log per process)",
        "  Ctrl-C stops all three.",
    ])
