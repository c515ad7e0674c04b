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
import dataclasses
import datetime as _dt
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, TextIO

from tuav_sitl.locations import Home, parse_home
from tuavdefs import component_link as cl
from tuavdefs import params as tp
from tuavdefs import signing as sg
from tuavdefs import simlink as sl
from tuavdefs.canbus import DEFAULT_GROUP, resolve_spec
from tuavdefs.gcs import (
    GCS_TCP_PORT_DEFAULT,
    INSTANCE_PORT_STEP,
    UDP_API_PORT_DEFAULT,
    UDP_GCS_PORT_DEFAULT,
)
from tuavdefs.params import SystemParams, TetherParams, VehicleParams, WinderParams
from tuavdefs.paramspec import ParameterError, load_toml, to_dict

if TYPE_CHECKING:
    from groundstation.station_params import GroundStationParams

#: The plant's GNSS receivers (sitl.sensors.GnssPreset's values) and what the companion may
#: fly on (companion.ekf.ESTIMATOR_KINDS), spelled out so that the command line
#: parses without importing the packages (a test checks they agree).
GNSS_PRESETS = ("rtk", "gnss")
ESTIMATOR_KINDS = ("ekf", "truth")

#: How long a process may take to say it is ready [s].
READY_TIMEOUT_S = 60.0
#: How long a process gets to exit after SIGTERM before it is killed [s].
STOP_GRACE_S = 2.0
#: The bus recorder's wait between bursts of frames [s]: the frames keep their receive
#: times; its socket holds about half a second of the bus at 20x real time.
RECORDER_INTERVAL_S = 0.01
#: In lockstep faster than real time, the companion writes a TCP ground station what it
#: did not ask for (telemetry, broadcasts) at most this often [s of wall time]; replies
#: go at once.
TELEMETRY_BATCH_S = 0.01


class UpError(RuntimeError):
    """A problem starting the stack, said in one line."""


#: Whether this system has Linux's abstract namespace of Unix-domain socket names.
ABSTRACT_UNIX = sys.platform.startswith("linux") and hasattr(socket, "AF_UNIX")
#: The simulator link by default: a Unix-domain socket where names need no file (Linux).
SIM_LINK_DEFAULT = "unix" if ABSTRACT_UNIX else "tcp"


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _abstract_name_free(name: str) -> bool:
    """Whether no socket holds the abstract Unix-domain name ``@NAME`` (binding one and
    closing it leaves nothing behind: abstract names have no file)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        try:
            s.bind(sl.unix_sockaddr(name))
        except OSError:
            return False
    return True


def sim_address(kind: str, instance: int) -> tuple[str, int] | str:
    """The simulator link of an instance: the abstract Unix-domain name
    ``@tuav-sitl-sim-I`` (``kind`` "unix"), or (127.0.0.1, 4560 + 10 I) ("tcp")."""
    if kind == "unix":
        return f"@tuav-sitl-sim-{instance}"
    return (sl.SIM_HOST_DEFAULT, ports_for(instance).sim)


def plant_listen_args(sim: tuple[str, int] | str) -> list[str]:
    """The plant's options to listen on the simulator link ``sim`` (a Unix-domain path or
    name, or (host, port))."""
    return ["--socket", sim] if isinstance(sim, str) else ["--port", str(sim[1])]


def _can_spec(spec: str, instance: int) -> str:
    """The bus spec for this instance: its own multicast group or vcan interface."""
    interface, channel = resolve_spec(spec)
    if interface == "udp_multicast" and channel == DEFAULT_GROUP and instance:
        base, last = DEFAULT_GROUP.rsplit(".", 1)
        return f"udp_multicast:{base}.{int(last) + instance}"
    return f"{interface}:{channel}"


class DiskWatch:
    """Says once on stderr when the run folder's disk is full (every log there ends, each
    process says which, the stack flies on), and again if it fills after having room."""

    #: Free space below which the disk counts as full [bytes].
    FULL_BYTES = 64 * 1024
    #: Wall time between two looks [s].
    EVERY_S = 1.0

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = run_dir
        self.full = False
        self._next = 0.0

    def check(self) -> None:
        """Look at the disk if it is time to."""
        now = time.monotonic()
        if now < self._next:
            return
        self._next = now + self.EVERY_S
        try:
            free = shutil.disk_usage(self.run_dir).free
        except OSError:
            return
        full = free < self.FULL_BYTES
        if full and not self.full:
            print(f"tuav-sitl up: the disk of {self.run_dir} is full ({free} bytes free): "
                  "the run's logs end there; the stack flies on", file=sys.stderr,
                  flush=True)
        self.full = full


class Stack:
    """The three processes and their logs."""

    def __init__(self, run_dir: Path, echo: bool = False) -> None:
        self.run_dir = run_dir
        self.echo = echo
        self._echoed: dict[str, int] = {}
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
        # its frames go to the file it is given; its log keeps what it says on stderr
        self.recorders[name] = subprocess.Popen([sys.executable, *args],
                                                stdout=subprocess.DEVNULL, stderr=log,
                                                start_new_session=True)

    def echo_new(self) -> None:
        """With ``echo``, print the lines the processes logged since the last call."""
        if not self.echo:
            return
        for name in [*self.procs, *self.recorders]:
            path = self.run_dir / f"{name}.log"
            try:
                with open(path) as f:
                    f.seek(self._echoed.get(name, 0))
                    text = f.read()
                    self._echoed[name] = f.tell()
            except OSError:
                continue
            for line in text.splitlines():
                print(f"[{name}] {line}", flush=True)

    def first_exit(self) -> tuple[str, int] | None:
        """(name, exit code) of a process that has exited, if any: the three, or a
        recorder (which runs until it is stopped: its end is always an error)."""
        for name, proc in (*self.procs.items(), *self.recorders.items()):
            code = proc.poll()
            if code is not None:
                return name, code
        return None

    def wait_exit(self, name: str, timeout_s: float) -> tuple[str, int] | None:
        """(name, exit code) of process ``name`` once it has exited, waiting at most
        ``timeout_s`` [s]; None if it is still running."""
        try:
            return name, self.procs[name].wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def stop(self) -> None:
        """SIGTERM to all, then SIGKILL to whatever is left after the grace time."""
        everyone = [*self.procs.items(), *self.recorders.items()]
        for _, proc in everyone:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE_S
        for name, proc in everyone:
            try:
                proc.wait(timeout=max(deadline - time.monotonic(), 0.01))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)
                print(f"tuav-sitl up: {name} did not stop within {STOP_GRACE_S:g} s: killed",
                      file=sys.stderr, flush=True)
        for log in self.logs.values():
            log.close()


def _last_line(path: Path) -> str:
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    return lines[-1] if lines else "(no output)"


def _home(text: str) -> Home:
    """``--home``: a named location (tuav_sitl/locations.py) or LAT,LON,ALT[,HEADING]."""
    try:
        return parse_home(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--home: {exc}") from None


def _out(text: str) -> tuple[str, int]:
    """``--out udp:HOST:PORT`` (or ``udpout:``, as MAVProxy and sim_vehicle.py write it)."""
    kind, _, rest = text.partition(":")
    host, _, port = rest.rpartition(":")
    if kind not in ("udp", "udpout") or not host or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(
            f"--out takes udp:HOST:PORT (e.g. udp:127.0.0.1:14551), got {text!r}")
    return (host, int(port))


def _wind(text: str) -> tuple[float, float, str]:
    parts = [v.strip() for v in text.split(",")]
    if len(parts) < 2:
        raise argparse.ArgumentTypeError(
            f"--wind needs the direction it blows from: SPEED,FROM_DEG[,TURBULENCE], e.g. "
            f"--wind {parts[0] or 5},270 for {parts[0] or 5} m/s from the west")
    try:
        speed, from_deg = float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            "--wind takes SPEED,FROM_DEG[,TURBULENCE], e.g. 5,270,light") from None
    turb = parts[2] if len(parts) > 2 else "none"
    if turb not in ("none", "light", "moderate", "severe") or speed < 0:
        raise argparse.ArgumentTypeError(
            "--wind: speed >= 0 m/s, turbulence none|light|moderate|severe")
    return (speed, from_deg, turb)


def _speedup(text: str) -> float:
    if text == "max":
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("--speedup takes a number > 0 or 'max'") from None
    if not value > 0:
        raise argparse.ArgumentTypeError("--speedup takes a number > 0 or 'max'")
    return value


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of ``tuav-sitl up``."""
    ap.add_argument("--speedup", type=_speedup, default=1.0, metavar="N|max",
                    help="simulated time per wall time: 1 real time (default), N paced at N x, "
                         "max as fast as the processes allow (all in lockstep but 1)")
    ap.add_argument("--params", default=None, help="whole system parameters TOML (vehicle, "
                    "tether, winder, wind, environment)")
    ap.add_argument("--vehicle", default=None, metavar="FILE", help="vehicle TOML (fields of "
                    "[vehicle] at top level) replacing the default paper vehicle")
    ap.add_argument("--tether", default=None, metavar="FILE", help="tether TOML")
    ap.add_argument("--winder", default=None, metavar="FILE", help="winder TOML")
    ap.add_argument("--ground-params", default=None, metavar="FILE",
                    help="the ground station's parameters TOML: [winder_control] (law = "
                         "paper | tension), [lbar], [winch], as a scenario's tables")
    ap.add_argument("--tether-model", default=tp.DEFAULT_TRUTH_TETHER.value,
                    choices=tuple(m.value for m in tp.TetherModel), help="the plant's truth "
                    "line: lumped (default) or catenary; the controllers model a catenary")
    ap.add_argument("--plant-params", default=None, metavar="FILE",
                    help="the plant's truth where it differs from the controllers' model "
                         "(the parameters above): a system TOML whose fields replace the "
                         "model's, field by field, for the plant only")
    ap.add_argument("--wind", type=_wind, default=None, metavar="SPEED,FROM_DEG[,TURB]",
                    help="steady wind [m/s] blowing from FROM_DEG (compass, 0 = north) with "
                         "Dryden turbulence none|light|moderate|severe, e.g. 5,270,light")
    ap.add_argument("--can", default="auto", metavar="SPEC",
                    help="CAN bus: auto, socketcan:IFACE, udp_multicast[:GROUP]")
    ap.add_argument("--home", type=_home, default=Home(*sl.HOME_DEFAULT),
                    metavar="NAME|LAT,LON,ALT[,HEADING]",
                    help="the winder's global position (ground altitude AMSL) and the "
                         "vehicle's heading at start [deg from north]: a name of "
                         "tuav_sitl/data/locations.txt or ~/.config/tuav-sitl/locations.txt "
                         "(e.g. CMAC), or the numbers")
    ap.add_argument("--position", type=float, nargs=3, default=(2.0, 0.0, 0.0),
                    metavar=("X", "Y", "Z"),
                    help="where the UAV starts [m], z-up frame from the winder: on the "
                         "ground (default 2 m east) or, with Z above the gear, in hover")
    ap.add_argument("--gnss", choices=GNSS_PRESETS, default="rtk",
                    help="the plant's GNSS receiver: rtk (ZED-F9P class, ~2 cm, the default) "
                         "or gnss (M9N/M10 class, 0.5-1 m, wandering); the companion is told "
                         "its latency, as GPS_DELAY_MS would")
    ap.add_argument("--state", choices=ESTIMATOR_KINDS, default="ekf",
                    help="what the companion flies on: its navigation filter's estimate "
                         "(ekf, the default) or the simulator's state (truth, to compare)")
    ap.add_argument("--goto", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="when starting in the air, fly here [m] at once")
    ap.add_argument("--duration", type=float, default=None,
                    help="stop after [s] of simulated time")
    ap.add_argument("--faults", default=None, metavar="FILE",
                    help="faults the plant injects: a TOML file of [[faults]] tables, as a "
                         "scenario's (kind = gnss_loss | wind | motor | winder_motor, "
                         "start_s, end_s in simulated time)")
    ap.add_argument("--parm", default=None, metavar="FILE",
                    help="start the companion with these ground-station parameters (.parm, "
                         "e.g. a previous run's companion.parm or MAVProxy's 'param save')")
    key = ap.add_mutually_exclusive_group()
    key.add_argument("--signing-passphrase", default=None, metavar="WORDS",
                     help="MAVLink 2 signing on from the start, with MAVProxy's key for "
                          "'signing setup WORDS' (SHA-256 of the ASCII text)")
    key.add_argument("--signing-key-file", default=None, metavar="FILE",
                     help="MAVLink 2 signing on from the start with this key (64 "
                          "hexadecimal digits)")
    ap.add_argument("--logdir", default="runs", help="where run folders go")
    ap.add_argument("--log-max-mb", type=float, default=None, metavar="MB",
                    help="end each log of the run (truth.csv, flight.tlog, can.log) when it "
                         "reaches this size [MB]; a full disk ends them too, and the stack "
                         "flies on (docs/usage.md: the logs' volume)")
    ap.add_argument("--out", type=_out, action="append", default=[],
                    metavar="udp:HOST:PORT",
                    help="also push MAVLink by UDP here (repeatable, as MAVProxy's --out)")
    ap.add_argument("-I", "--instance", type=int, default=0,
                    help="offset every port (by 10 per instance) to run stacks side by side")
    ap.add_argument("--sim-link", choices=("unix", "tcp"), default=SIM_LINK_DEFAULT,
                    help="the simulator link between plant and companion: a Unix-domain "
                         "socket named @tuav-sitl-sim-I in Linux's abstract namespace (the "
                         "default on Linux: it costs both ends less per period), or TCP "
                         "127.0.0.1:4560 + 10 I")
    ap.add_argument("--no-rt-priority", action="store_true",
                    help="in real time, leave the processes at normal scheduling (by "
                         "default they get SCHED_FIFO where permitted)")
    ap.add_argument("--no-pin", action="store_true",
                    help="in lockstep, let the processes run on any CPU (by default the "
                         "plant and the companion share one, the others the rest)")
    ap.add_argument("--view", nargs="?", const="auto", choices=("auto", "native", "web"),
                    default=None,
                    help="a live 3-D view in Rerun (the optional extra 'view'): its native "
                         "viewer where there is a display (auto, the default), else or with "
                         "'web' its web viewer on a localhost URL the banner prints; every "
                         "run records recording.rrd in its folder with or without it")
    ap.add_argument("--no-recording", action="store_true",
                    help="no recording.rrd (nor the process that writes it); not with --view")
    out = ap.add_mutually_exclusive_group()
    out.add_argument("--headless", action="store_true",
                     help="print only errors and the log folder (no banner, no status)")
    out.add_argument("--verbose", action="store_true",
                     help="also echo every process's log lines to the terminal")


def _system_params(args: argparse.Namespace) -> SystemParams:
    """The run's parameters: --params, then --vehicle/--tether/--winder, then --wind."""
    params = SystemParams() if args.params is None else load_toml(SystemParams,
                                                                  Path(args.params))
    for name, cls in (("vehicle", VehicleParams), ("tether", TetherParams),
                      ("winder", WinderParams)):
        path = getattr(args, name)
        if path is not None:
            try:
                params = dataclasses.replace(params, **{name: load_toml(cls, Path(path))})
            except ParameterError as exc:
                stem = Path(path).stem
                field = (name + exc.field[len(stem):] if exc.field.startswith(stem + ".")
                         else f"{name}: {exc.field}")
                raise ParameterError(field, exc.reason, source=exc.source, line=exc.line) from None
    if args.wind is not None:
        speed, from_deg, turb = args.wind
        to = math.radians(from_deg + 180.0)   # the air moves towards the opposite bearing
        steady = (speed * math.sin(to), speed * math.cos(to), 0.0)
        params = dataclasses.replace(params, wind=dataclasses.replace(
            params.wind, steady_m_s=steady, turbulence=turb))
    return params


def ground_params(args: argparse.Namespace) -> GroundStationParams:
    """The ground station's parameters: ``--ground-params``, else the defaults."""
    from groundstation.station_params import GroundStationParams

    if args.ground_params is None:
        return GroundStationParams()
    return load_toml(GroundStationParams, Path(args.ground_params))


def plant_params(args: argparse.Namespace, model: SystemParams) -> SystemParams:
    """The plant's truth: ``model`` (the controllers' parameters) on the line
    ``--tether-model``, with ``--plant-params``' fields replacing its own, table by table."""
    if model.tether.model != args.tether_model:
        model = dataclasses.replace(model, tether=model.tether.replace(model=args.tether_model))
    if args.plant_params is None:
        return model
    path = Path(args.plant_params)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ParameterError("--plant-params", f"cannot read {path}: {exc}") from None
    merged = to_dict(model)
    for table, fields in data.items():
        if isinstance(fields, dict) and isinstance(merged.get(table), dict):
            merged[table] = {**merged[table], **fields}
        else:
            merged[table] = fields
    return SystemParams.from_dict(merged, prefix=path.stem)


def signing_key(args: argparse.Namespace) -> bytes | None:
    """The signing key ``--signing-passphrase`` or ``--signing-key-file`` gives (None:
    signing off until a ground station sets a key)."""
    if args.signing_passphrase is not None:
        return sg.key_from_passphrase(args.signing_passphrase)
    if args.signing_key_file is not None:
        if not Path(args.signing_key_file).is_file():
            raise sg.SigningError(f"--signing-key-file: no file {args.signing_key_file}")
        key = sg.read_key_file(args.signing_key_file)
        if key is None:
            raise sg.SigningError(f"--signing-key-file: {args.signing_key_file} holds no "
                                  "key (empty or all zeros)")
        return key
    return None


class Ports(NamedTuple):
    """The ports of one instance."""

    sim: int
    component: int
    gcs_tcp: int
    udp_gcs: int
    udp_api: int


def ports_for(instance: int) -> Ports:
    """ArduPilot's convention: every port moves by 10 per instance; except the API port,
    which moves by 1 as PX4's does (14540 + I), so that it never lands on another
    instance's ground-station port."""
    k = INSTANCE_PORT_STEP * instance
    return Ports(sl.SIM_PORT_DEFAULT + k, cl.COMPONENT_PORT_DEFAULT + k,
                 GCS_TCP_PORT_DEFAULT + k, UDP_GCS_PORT_DEFAULT + k,
                 UDP_API_PORT_DEFAULT + instance)


def run_up(args: argparse.Namespace) -> int:
    """Start, supervise and stop the stack; returns the exit code."""
    from tuav_sitl.view import INSTALL_HINT, available

    if args.view is not None and args.no_recording:
        print("tuav-sitl up: --view records; drop --no-recording", file=sys.stderr)
        return 2
    if args.view is not None and not available():
        print(f"tuav-sitl up: --view: {INSTALL_HINT}", file=sys.stderr)
        return 2
    speedup = args.speedup
    ports = ports_for(args.instance)
    if args.sim_link == "unix" and not ABSTRACT_UNIX:
        print("tuav-sitl up: --sim-link unix needs Linux (abstract socket names); use "
              "--sim-link tcp", file=sys.stderr)
        return 2
    sim = sim_address(args.sim_link, args.instance)
    for port in (*([ports.sim] if args.sim_link == "tcp" else []), ports.component,
                 ports.gcs_tcp):
        if not _port_free(port):
            print(f"tuav-sitl up: port {port} is in use (another stack?); "
                  f"try --instance {args.instance + 1}", file=sys.stderr)
            return 1
    if isinstance(sim, str) and not _abstract_name_free(sim):
        print(f"tuav-sitl up: {sl.format_sim_address(sim)} is in use (another stack?); "
              f"try --instance {args.instance + 1}", file=sys.stderr)
        return 1
    try:
        params = _system_params(args)
        truth = plant_params(args, params)
        ground = ground_params(args)
    except ParameterError as exc:
        print(f"tuav-sitl up: bad parameter: {exc}", file=sys.stderr)
        return 2
    if args.state == "ekf":
        from companion.navigation import air_start_too_low_m
        from sitl.sensors import SensorNoise

        need = air_start_too_low_m(args.position[2], truth.vehicle.gear_height_m,
                                   SensorNoise.preset(args.gnss, 0).gps_epv_m)
        if need is not None:
            print(f"tuav-sitl up: --position: a start in the air with --gnss {args.gnss} "
                  f"needs Z >= {need:.2f} m (the vehicle's first fix decides whether it is "
                  "in the air); start on the ground (Z = 0) or higher", file=sys.stderr)
            return 2
    try:
        key = signing_key(args)
    except sg.SigningError as exc:
        print(f"tuav-sitl up: {exc}", file=sys.stderr)
        return 2
    # the files given are checked before anything is made or started
    parm_text = faults = None
    if args.parm is not None:
        from companion.param_names import check_parm_text

        try:
            parm_text = Path(args.parm).read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            print(f"tuav-sitl up: --parm: {exc}", file=sys.stderr)
            return 2
        problems = check_parm_text(parm_text, args.parm)
        if problems:
            print("".join(f"tuav-sitl up: --parm: {p}\n" for p in problems), end="",
                  file=sys.stderr)
            return 2
    if args.faults is not None:
        from sitl.faults import FaultsFile

        try:
            faults = load_toml(FaultsFile, Path(args.faults))
        except ParameterError as exc:
            print(f"tuav-sitl up: --faults: {exc}", file=sys.stderr)
            return 2
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    run_dir = Path(args.logdir) / f"up-{stamp}-{args.instance}"
    run_dir.mkdir(parents=True, exist_ok=True)
    from tuav_sitl.offline import _to_toml  # the same writer as the offline runner's

    # the plant's truth (params.toml, what `plot` imports) and the controllers' model
    (run_dir / "params.toml").write_text(_to_toml(to_dict(truth)))
    (run_dir / "model.toml").write_text(_to_toml(to_dict(params)))
    (run_dir / "groundstation.toml").write_text(_to_toml(to_dict(ground)))
    if parm_text is not None:
        (run_dir / "companion.parm").write_text(parm_text)
    faults_args: list[str] = []
    if faults is not None:
        (run_dir / "faults.toml").write_text(_to_toml(to_dict(faults)))
        faults_args = ["--faults", str(run_dir / "faults.toml")]
    key_file = run_dir / "signing.key"   # the vehicle's key, set here or by SETUP_SIGNING
    if key is not None:
        fd = os.open(key_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(sg.key_file_text(key))
    can = _can_spec(args.can, args.instance)
    h = args.home
    home = [repr(h.lat_deg), repr(h.lon_deg), repr(h.alt_m)]
    common = ["--params", str(run_dir / "model.toml")]
    from companion.ekf import EstimatorParams
    from sitl.sensors import GNSS_MODELS, GnssPreset

    # what the receiver's datasheet tells the vehicle's designers: its latency (ArduPilot's
    # GPS_DELAY_MS) and how slowly its position error wanders
    receiver = GNSS_MODELS[GnssPreset(args.gnss)]
    estimator = EstimatorParams(kind=args.state, gnss_delay_s=receiver.latency_s,
                                gnss_pos_tau_s=receiver.horizontal.gm_tau_s)
    if args.state == "ekf":
        # the user calibrated the accelerometer before the flight (on the plant's sensors:
        # the preset and seed the plant is started with)
        from sitl.sensors import SensorNoise
        from tuav_sitl.calibration import CALIBRATED_ACCEL_BIAS_SIGMA_M_S2, accel_calibration

        estimator = estimator.replace(
            accel_offsets_m_s2=accel_calibration(SensorNoise.preset(args.gnss, 0),
                                                 (h.lat_deg, h.lon_deg, h.alt_m),
                                                 params.environment.gravity_m_s2),
            accel_bias_sigma_m_s2=CALIBRATED_ACCEL_BIAS_SIGMA_M_S2)
    (run_dir / "estimator.toml").write_text(_to_toml(to_dict(estimator)))
    log_cap = ["--log-max-mb", repr(args.log_max_mb)] if args.log_max_mb else []
    plant_args = ["-m", "sitl", *plant_listen_args(sim), "--can", can, "--home", *home,
                  "--gnss", args.gnss, "--position", *map(str, args.position),
                  *(["--heading", repr(h.heading_deg)] if h.heading_deg is not None else []),
                  "--truth-log", str(run_dir / "truth.csv"), *faults_args,
                  "--params", str(run_dir / "params.toml"), *log_cap]
    if math.isfinite(speedup):
        plant_args += ["--speedup", repr(speedup)]
    if args.duration is not None:
        plant_args += ["--duration", str(args.duration)]
    comp_args = ["-m", "companion", "--sim", sl.format_sim_address(sim), "--component-port",
                 str(ports.component), "--home", *home, "--gcs-tcp", str(ports.gcs_tcp),
                 "--gcs-udp", f"127.0.0.1:{ports.udp_gcs}",
                 "--gcs-udp", f"127.0.0.1:{ports.udp_api}",
                 *[a for host, port in args.out for a in ("--gcs-udp", f"{host}:{port}")],
                 "--tlog", str(run_dir / "flight.tlog"), *log_cap,
                 "--param-file", str(run_dir / "companion.parm"),
                 "--log-dir", str(run_dir / "logs"),
                 "--estimator", str(run_dir / "estimator.toml"),
                 "--signing-key-file", str(key_file), *common]
    if args.goto is not None:
        comp_args += ["--goto", *map(str, args.goto)]
    if speedup != 1.0:
        comp_args += ["--telemetry-batch", repr(TELEMETRY_BATCH_S)]
    gs_args = ["-m", "groundstation", "--can", can, "--mavlink",
               f"127.0.0.1:{ports.component}", "--signing-key-file", str(key_file),
               "--control", str(run_dir / "groundstation.toml"), *common]
    if speedup != 1.0:
        # in lockstep the winch runs on the plant's time: a stall is no lost encoder
        gs_args += ["--clock", "frames"]
    from tuav_sitl.warmup import compile_if_cold

    # a cold numba cache compiled here, said and shown, before the processes load it (a
    # SIGTERM meanwhile stops it as Ctrl-C does)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        compile_if_cold(None if args.headless else sys.stderr)
    except KeyboardInterrupt:
        print(f"tuav-sitl up: stopped while compiling; logs in {run_dir}", file=sys.stderr)
        return 130
    stack = Stack(run_dir, echo=args.verbose)
    stopping = {"signal": None}

    def on_signal(signum: int, _frame: object) -> None:
        stopping["signal"] = signum

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    code = 0
    from tuav_sitl.view.live import start_live_view, stop_live_view

    live = (start_live_view(run_dir, args.view, args.instance, h)
            if available() and not args.no_recording else None)
    try:
        stack.start_recorder("candump", ["-m", "tuav_sitl", "candump", "-s", "2", "--can", can,
                                         "--interval", repr(RECORDER_INTERVAL_S),
                                         "--log", str(run_dir / "can.log"), *log_cap])
        stack.start("plant", plant_args, "listening on")
        stack.start("groundstation", gs_args, "groundstation: CAN")
        stack.start("companion", comp_args, "companion: connected")
        sched = "normal"
        if speedup == 1.0:
            sched = _real_time(stack, not args.no_rt_priority)
        elif speedup != 1.0 and not args.no_pin:
            sched = _pin(stack)
        if not args.headless:
            print(_banner(run_dir, ports, sim, can, args, speedup, sched, key), flush=True)
            if live is not None:
                print(f"  {live.banner}", flush=True)
        disk = DiskWatch(run_dir)
        while stopping["signal"] is None:
            stack.echo_new()
            disk.check()
            ended = stack.first_exit()
            if ended is not None:
                name, rc = ended
                if name != "plant" and name not in stack.recorders and rc == 0:
                    # the plant ending its run (--duration) closes the link, and the
                    # companion may exit first: the plant's own end decides
                    ended = stack.wait_exit("plant", STOP_GRACE_S) or ended
                    name, rc = ended
                if name in stack.recorders:
                    print(f"tuav-sitl up: the bus recorder ({name}) exited with code "
                          f"{rc}: the bus is no longer recorded; stopping",
                          file=sys.stderr)
                    code = 1
                elif name == "plant" and rc == 0:
                    if not args.headless:
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
        if live is not None:
            stop_live_view(live)
    if stopping["signal"] is not None and not args.headless:
        print("tuav-sitl up: stopped", flush=True)
    print(f"tuav-sitl up: logs in {run_dir}", flush=True)
    return code


def _real_time(stack: Stack, fifo: bool) -> str:
    """In real time: the bus recorder at idle priority (it keeps each frame's kernel receive
    time, so it may read late), and with ``fifo`` the plant, the companion and the ground
    station at SCHED_FIFO where permitted: at :data:`tuav_sitl.realtime.RT_PRIORITY`, or
    at the user's rtprio limit (``RLIMIT_RTPRIO``) where that is lower. Returns the
    banner's words for it."""
    import resource

    from tuav_sitl.realtime import BACKGROUND, RT_PRIORITY, set_background, set_real_time

    for name, proc in stack.recorders.items():
        if name in BACKGROUND:
            set_background(proc.pid)    # (where refused it keeps the normal scheduling)
    if not fifo:
        return "normal (--no-rt-priority; the bus recorder at idle priority)"
    pids = [stack.procs[name].pid for name in ("plant", "companion", "groundstation")]
    why = None
    for pid in pids:
        why = set_real_time(pid) or why
    if why is None:
        return f"SCHED_FIFO priority {RT_PRIORITY}"
    limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    if 1 <= limit < RT_PRIORITY and not any([set_real_time(pid, limit) for pid in pids]):
        return f"SCHED_FIFO priority {limit} (the rtprio limit)"
    return f"normal (SCHED_FIFO {why}; jitter may exceed 2 ms under load)"


def _pin(stack: Stack) -> str:
    """In lockstep: the plant and the companion, which take turns, on one CPU, the ground
    station (at a lower priority) and the recorder (at idle priority) on the rest
    (:mod:`tuav_sitl.realtime`); returns the banner's words for it."""
    from tuav_sitl.realtime import (
        BACKGROUND,
        NICENESS,
        cpu_split,
        set_affinity,
        set_background,
        set_nice,
    )

    split = cpu_split()
    if split is None:
        return "normal (one CPU)"
    why = None
    for name, proc in (*stack.procs.items(), *stack.recorders.items()):
        if name in split:
            why = set_affinity(proc.pid, split[name]) or why
        if name in BACKGROUND:
            why = set_background(proc.pid) or why
        if name in NICENESS:
            why = set_nice(proc.pid, NICENESS[name]) or why
    if why is not None:
        return f"normal (CPU affinity: {why})"
    pair = ",".join(map(str, sorted(split["plant"])))
    rest = ",".join(map(str, sorted(split["groundstation"])))
    return (f"plant and companion on CPU {pair}, ground station (nice "
            f"{NICENESS['groundstation']}) and recorder at idle priority on CPU {rest}")


def _banner(run_dir: Path, ports: Ports, sim: tuple[str, int] | str, can: str,
            args: argparse.Namespace, speedup: float, sched: str = "normal",
            key: bytes | None = None) -> str:
    interface, channel = resolve_spec(can)
    watch = (f"candump {channel}   (or: tuav-sitl candump --can {interface}:{channel})"
             if interface == "socketcan" else
             f"tuav-sitl candump --can {interface}:{channel} [--decode | -L]")
    h = args.home
    heading = f", facing {h.heading_deg:g} deg" if h.heading_deg is not None else ""
    outs = "".join(f" and udp:{host}:{port}" for host, port in args.out)
    clock = ("real time" if speedup == 1.0 else
             "lockstep, as fast as possible" if math.isinf(speedup) else
             f"lockstep, paced at {speedup:g}x real time")
    return "\n".join([
        "tuav-sitl up: plant, companion and ground station are running",
        f"  MAVLink (connect a ground station or script): tcp:127.0.0.1:{ports.gcs_tcp}",
        f"    UDP pushed to udp:127.0.0.1:{ports.udp_gcs} (ground stations) and "
        f"udp:127.0.0.1:{ports.udp_api} (APIs){outs}",
        f"    e.g. mavproxy.py --master tcp:127.0.0.1:{ports.gcs_tcp}",
        *([f"    MAVLink 2 signing on: key in {run_dir / 'signing.key'} (MAVProxy: "
           "signing key PASSPHRASE; pymavlink: mav.setup_signing(key))"]
          if key is not None else []),
        f"  simulator link (plant <-> companion): {sl.format_sim_address(sim)}",
        f"  component link (companion <-> winch): tcp:127.0.0.1:{ports.component}",
        f"  winder CAN bus: {interface}:{channel}   watch it: {watch}",
        f"  home: {h.lat_deg:.7f}, {h.lon_deg:.7f}, {h.alt_m:.1f} m AMSL (the winder)"
        f"{heading}",
        f"  clock: {clock}; scheduling: {sched}",
        f"  logs: {run_dir} (flight.tlog, can.log, truth.csv, a log per process)",
        "  Ctrl-C stops all three.",
    ])
