"""The three-process stack in lockstep, timed and profiled: ``python -m benchmarks.stack``.

Starts the plant, the ground station and the companion as ``tuav-sitl up --speedup max``
does (lockstep, the winder on a udp_multicast CAN bus, the component link between companion
and winch) and flies one flight (:class:`Flight`):

- :func:`mission_flight` (the benchmark's): the UAV rests on its gear at (2, 0, 0) m; once
  the companion has connected to the plant, ``examples/fly_mission.py`` connects to the
  companion's MAVLink TCP endpoint and flies its scripted mission (GUIDED, arm, take-off
  to 10 m, a loiter-turns circle and three waypoints in AUTO, land, disarm: about 86 s of
  simulated time; ``--short`` for a 2 m hop). When the script exits, the plant is stopped
  with SIGTERM and prints its summary.
- :func:`goto_flight` (the real-time runs): the UAV starts in hover trim and the companion
  flies to a goal; the plant stops at ``--duration``.

It reports simulated seconds per wall second from the plant's own summary and each
process's CPU time (the mission client's too). With ``--profile`` every process runs under
cProfile (``python -m benchmarks.profiled FILE -m ...``, which is ``python -m cProfile -o
FILE -m ...`` profiling only from the flight's start, signalled when the companion has
connected (the client: when it has connected to the vehicle), to its end; each process
exits normally: the client when its mission is over, the plant on SIGTERM or at
``--duration``, the companion when the plant closes the link, the ground station on
SIGTERM), and the profiles are aggregated by category (:data:`CATEGORIES`).

The CAN bus is IPv4 multicast: run this inside a private network namespace, as ``python -m
benchmarks`` does (``unshare --net``, see :func:`tuav_sitl.netns.run_in_netns`), so that no
datagram and no IGMP report leaves the host. Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from tuav_sitl.realtime import (
    BACKGROUND,
    LOCKSTEP_SPIN_US,
    NICENESS,
    PRIORITIES,
    cpu_split,
    set_affinity,
    set_background,
    set_nice,
    set_priority,
)
from tuav_sitl.up import (
    RECORDER_INTERVAL_S,
    SIM_LINK_DEFAULT,
    TELEMETRY_BATCH_S,
    plant_listen_args,
)
from tuavdefs.simlink import SIM_HOST_DEFAULT, format_sim_address

ROOT = Path(__file__).resolve().parents[1]

#: How long a process may take to say it is ready [s].
READY_TIMEOUT_S = 60.0
#: Where the stack starts (hover trim) and where the default flight goes [m], z-up frame.
START_M = (4.0, 0.0, 10.0)
GOAL_M = (8.0, 3.0, 14.0)

#: Categories of the profiles' self time: (name, predicate on (file, function name)).
#: Numba's compiled entry points appear as built-ins named after their kernel.
_PHYSICS_KERNELS = ("advance_kernel", "_truth_kernel", "tether_forces_kernel", "rhs_kernel",
                    "wind_kernel")
_CONTROL_KERNELS = ("flight_step", "winder_step")


def _category(file: str, func: str) -> str:
    """The category of a profiled function (its file and name)."""
    f = file.replace("\\", "/")
    if file == "~":   # a built-in
        if "_dynfunc._Closure" in func:   # a compiled kernel called directly
            if any(f" {k} " in func for k in _PHYSICS_KERNELS):
                return "physics"
            if any(f" {k} " in func for k in _CONTROL_KERNELS):
                return "control"
            return "other"
        if ("_socket.socket" in func or "select." in func or "'select'" in func
                or "poll" in func or "epoll" in func or "sleep" in func):
            return "sockets"
        return "other"
    if ("/pymavlink/" in f or "/tuavdefs/simlink/" in f
            or f.endswith(("tuavdefs/component_link.py", "companion/simlink_client.py",
                           "companion/component_server.py", "companion/mavlink_server.py",
                           "companion/mavlink_io.py", "companion/autopilot.py",
                           "companion/telemetry.py", "companion/commands.py",
                           "companion/mission_items.py", "companion/mission_protocol.py",
                           "companion/param_protocol.py", "groundstation/winch_link.py",
                           "sitl/simlink_server.py", "tuavdefs/frames.py"))):
        return "MAVLink"
    if "/can/" in f or "/cantools/" in f or "tuavdefs/can_protocol/" in f or f.endswith((
            "tuavdefs/canbus.py", "sitl/odrive_axis.py",
            "sitl/winder_node.py")):
        return "CAN"
    if "/sitl/" in f and not f.endswith(("sitl/__main__.py", "sitl/plant_loop.py",
                                         "sitl/truth_log.py")):
        return "physics"
    if f.endswith(("companion/flight_controller.py", "companion/position.py",
                   "companion/attitude.py", "companion/actuators.py",
                   "companion/tether_model.py", "companion/planner.py",
                   "companion/reference.py", "companion/legs.py",
                   "companion/navigation.py", "companion/plan.py",
                   "companion/governor.py", "groundstation/winder_host.py",
                   "groundstation/lbar.py", "groundstation/winder_control.py",
                   "groundstation/winch.py", "tuavdefs/airframe.py")):
        return "control"
    if "/companion/modes/" in f:
        return "control"
    if f.endswith(("socket.py", "selectors.py")):
        return "sockets"
    return "other"


#: The categories in report order.
CATEGORIES = ("physics", "control", "MAVLink", "CAN", "sockets", "other")
#: The processes, in start order.
PROCESSES = ("plant", "groundstation", "companion")


def profile_shares(path: Path) -> dict[str, float]:
    """Shares [0..1] of a cProfile file's total self time by category."""
    stats = pstats.Stats(str(path))
    by_cat = dict.fromkeys(CATEGORIES, 0.0)
    for (file, _line, func), stat in stats.stats.items():  # type: ignore[attr-defined]
        by_cat[_category(file, func)] += stat[2]
    total = sum(by_cat.values()) or 1.0
    return {k: v / total for k, v in by_cat.items()}


@dataclass(frozen=True)
class Flight:
    """What a run of the stack flies.

    ``start_m``: where the plant starts the UAV [m], z-up frame (in hover trim, or resting
    on its gear if the height is 0); ``companion_args``: the companion's extra arguments;
    ``client``: if not empty, the command line (after the Python interpreter) of a MAVLink
    client started once the companion has connected, ``{port}`` standing for the companion's
    MAVLink TCP port; the flight ends when it exits (the plant is then stopped). Without a
    client the plant stops at the run's duration. ``client_ready``: text the client prints
    when it has connected to the vehicle (its profile starts there)."""

    name: str
    start_m: tuple[float, float, float]
    companion_args: tuple[str, ...] = ()
    client: tuple[str, ...] = ()
    client_ready: str = ""


def goto_flight(goal_m: Sequence[float] = GOAL_M) -> Flight:
    """From hover trim at :data:`START_M`, the companion flies to ``goal_m`` [m] and holds
    (``--goto``); the real-time runs fly this, for a fixed duration."""
    return Flight("goto", START_M, ("--goto", *map(str, goal_m)))


#: Where the mission flight starts [m]: on the ground, resting on the gear.
MISSION_START_M = (2.0, 0.0, 0.0)
#: The scripted mission: the example pymavlink script, relative to the repository root.
MISSION_SCRIPT = "examples/fly_mission.py"
#: The mission client's own time limit [s] of wall time.
MISSION_TIMEOUT_S = 900.0


def mission_flight(short: bool = False) -> Flight:
    """The benchmark's flight: from the ground, ``examples/fly_mission.py`` flies its
    scripted mission over the companion's MAVLink TCP endpoint (``short``: its ``--short``
    hop, take-off to 2 m, one waypoint, land). The companion listens on any free TCP port
    and pushes no UDP."""
    return Flight("mission", MISSION_START_M, ("--gcs-tcp", "0", "--gcs-udp", "none"),
                  (MISSION_SCRIPT, "--connect", "tcp:127.0.0.1:{port}", "--timeout",
                   str(MISSION_TIMEOUT_S), *(("--short",) if short else ())),
                  client_ready="connected to system")


@dataclass
class ProcessResult:
    """One process of a run: exit code, CPU time [s] (user + system) from the companion's
    connection to its end, its log's text and, when profiled, its profile's shares by
    category; when traced, its system calls and wake-ups."""

    exit_code: int
    cpu_s: float
    log: str
    shares: dict[str, float] = field(default_factory=dict)
    #: with ``syscalls``: system calls by name from the flight's start to its end (``perf
    #: trace -s``), and the voluntary context switches (wake-ups after a wait) meanwhile
    syscalls: dict[str, int] = field(default_factory=dict)
    wakeups: int = 0


@dataclass
class StackResult:
    """A run of the stack: the flight's name, simulated [s] and wall [s] time from the
    plant's summary, and the processes' (with the mission client's, ``"client"``, if the
    flight has one)."""

    flight: str
    sim_s: float
    wall_s: float
    processes: dict[str, ProcessResult]

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("nan")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_ready(proc: subprocess.Popen, log: Path, text: str) -> None:
    end = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < end:
        if text in log.read_text():
            return
        if proc.poll() is not None:
            raise RuntimeError(f"{log.stem} exited while starting: {log.read_text()[-500:]}")
        time.sleep(0.02)
    raise RuntimeError(f"{log.stem} did not become ready")


def _cpu_s(pid: int) -> float:
    """User + system CPU time [s] a running process has used so far (0 if unknown)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return 0.0


def _reap(proc: subprocess.Popen, timeout_s: float) -> tuple[int, float]:
    """Wait for ``proc`` (at most ``timeout_s`` [s], then SIGKILL); returns (exit code, CPU
    time [s])."""
    end = time.monotonic() + timeout_s
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            code = os.waitstatus_to_exitcode(status)
            proc.returncode = code
            return code, usage.ru_utime + usage.ru_stime
        if time.monotonic() > end:
            proc.kill()
            end = time.monotonic() + 10.0
        time.sleep(0.01)


def _wakeups(pid: int) -> int:
    """Voluntary context switches of a running process so far (each a wait that blocked:
    one wake-up), summed over its threads (0 if unknown)."""
    total = 0
    try:
        for task in Path(f"/proc/{pid}/task").iterdir():
            for line in (task / "status").read_text().splitlines():
                if line.startswith("voluntary_ctxt_switches:"):
                    total += int(line.split()[1])
    except (OSError, ValueError):
        return 0
    return total


_SYSCALL_ROW = re.compile(r"^\s+([a-z_0-9]+)\s+(\d+)\s+\d+\s+[\d.]+")


def _trace(pid: int, out: Path) -> subprocess.Popen:
    """``perf trace -s`` of process ``pid`` to ``out`` until it gets SIGINT."""
    return subprocess.Popen(["perf", "trace", "-s", "-o", str(out), "-p", str(pid)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _end_trace(proc: subprocess.Popen, out: Path) -> dict[str, int]:
    """Stop a :func:`_trace` and read its summary: calls by system call, all threads."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(30.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    calls: dict[str, int] = {}
    if out.is_file():
        for line in out.read_text().splitlines():
            m = _SYSCALL_ROW.match(line)
            if m:
                calls[m.group(1)] = calls.get(m.group(1), 0) + int(m.group(2))
    return calls


def busy_loads(n: int) -> list[subprocess.Popen]:
    """``n`` processes that spin on a CPU each (the second load of the real-time runs)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def _profiled(work: Path, name: str, profile: bool) -> list[str]:
    """The interpreter arguments that run a process under :mod:`benchmarks.profiled`."""
    return ["-m", "benchmarks.profiled", str(work / f"{name}.prof")] if profile else []


def run_stack(work: Path, duration_s: float | None = None, flight: Flight | None = None,
              profile: bool = False, real_time: bool = False,
              control_rate_hz: float = 250.0, plant_extra: Sequence[str] = (),
              priority: str | None = None,
              on_connected: Callable[[], object] | None = None,
              pin: bool | None = None, recorder: bool = True,
              sim_link: str = SIM_LINK_DEFAULT, syscalls: bool = False,
              spin: bool = False) -> StackResult:
    """Run the three processes in ``work`` (logs, profiles, truth series) and return what
    they did: in lockstep, or paced by the wall clock (``real_time``), at
    ``control_rate_hz`` [Hz] (the companion's gains get the same rate), flying ``flight``
    (default :func:`goto_flight`). The plant stops after ``duration_s`` [s] of simulated
    time without a client, and once the flight's client has exited with one (then without a
    duration). ``priority`` (:data:`tuav_sitl.realtime.PRIORITIES`) is given to the three
    processes when the companion has connected; ``on_connected`` is called then too (the
    flight begins). As ``tuav-sitl up`` runs them: the bus recorder (``tuav-sitl candump
    -L`` to a log) listens too unless ``recorder`` is False, and in lockstep the plant gets
    a CPU of its own, the companion and the ground station (at
    :data:`tuav_sitl.realtime.NICENESS`) share the rest and the recorder runs at idle
    priority beside the plant (:mod:`tuav_sitl.realtime`) unless ``pin`` is False (None: pin
    in lockstep only), and the simulator link is ``sim_link``: "unix" (an abstract
    Unix-domain name of this process's own) or "tcp" (a free port). ``syscalls``: count
    each process's system calls over the flight with ``perf trace -s`` (root; it slows
    every call, so the run's speed is not the benchmark's) and its wake-ups. ``spin``:
    a pinned plant's lockstep waits spin first (``--lockstep-spin-us``
    :data:`tuav_sitl.realtime.LOCKSTEP_SPIN_US`; an experiment, up does not)."""
    flight = flight if flight is not None else goto_flight()
    if (duration_s is None) == (not flight.client):
        raise ValueError("a flight without a client needs a duration; one with a client "
                         "ends with it")
    work.mkdir(parents=True, exist_ok=True)
    comp_port = _free_port()
    sim = (f"@tuav-sitl-bench-{os.getpid()}" if sim_link == "unix"
           else (SIM_HOST_DEFAULT, _free_port()))
    can = "udp_multicast"
    py = sys.executable
    gains: list[str] = []
    if control_rate_hz != 250.0:
        (work / "gains.toml").write_text(f"rate_hz = {float(control_rate_hz)!r}\n")
        gains = ["--gains", str(work / "gains.toml")]
    commands = {
        "plant": ["-m", "sitl", *plant_listen_args(sim), "--can", can, "--position",
                  *map(str, flight.start_m),
                  *(["--duration", str(duration_s)] if duration_s is not None else []),
                  "--control-rate", str(float(control_rate_hz)),
                  "--truth-log", str(work / "truth.csv"),
                  *(["--real-time"] if real_time else []), *plant_extra],
        # in lockstep the winch runs on the plant's time, as up runs it: on a busy host a
        # stalled plant is no lost encoder (the wall clock's 0.1 s would brake the drum)
        "groundstation": ["-m", "groundstation", "--can", can, "--mavlink",
                          f"127.0.0.1:{comp_port}",
                          *([] if real_time else ["--clock", "frames"])],
        "companion": ["-m", "companion", "--sim", format_sim_address(sim),
                      "--component-port", str(comp_port), *gains, *flight.companion_args,
                      *([] if real_time else ["--telemetry-batch", repr(TELEMETRY_BATCH_S)])],
    }
    ready = {"plant": "listening on", "groundstation": "groundstation: CAN",
             "companion": None}
    procs: dict[str, subprocess.Popen] = {}
    logs: dict[str, Path] = {}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    results: dict[str, ProcessResult] = {}
    traced: dict[str, dict[str, int]] = {}
    wake: dict[str, int] = {}
    traces: dict[str, subprocess.Popen] = {}
    pin = (not real_time) if pin is None else pin
    if spin and not pin and not real_time:
        # unpinned (the pinning puts the companion on the plant's CPU, where a spin would
        # only keep it waiting): the plant spins briefly in its lockstep waits
        commands["plant"] += ["--lockstep-spin-us", repr(LOCKSTEP_SPIN_US)]
    try:
        if recorder:
            logs["candump"] = work / "candump.log"
            with open(logs["candump"], "w") as log:
                procs["candump"] = subprocess.Popen(
                    [py, "-m", "tuav_sitl", "candump", "-s", "2", "--can", can, "--interval",
                     repr(RECORDER_INTERVAL_S), "--log", str(work / "can.log")], cwd=ROOT,
                    stdout=log, stderr=subprocess.STDOUT, env=env)
        for name in PROCESSES:
            logs[name] = work / f"{name}.log"
            with open(logs[name], "w") as log:
                procs[name] = subprocess.Popen([py, *_profiled(work, name, profile),
                                                *commands[name]], cwd=ROOT, stdout=log,
                                               stderr=subprocess.STDOUT, env=env)
            if ready[name]:
                _wait_ready(procs[name], logs[name], ready[name])
        # the flight starts when the companion connects: each process's CPU time so far
        # (start-up) is left out of its figure
        _wait_ready(procs["companion"], logs["companion"], "companion: connected")
        start_cpu = {name: _cpu_s(p.pid) for name, p in procs.items()}
        start_wake = {name: _wakeups(p.pid) for name, p in procs.items()}
        traces = ({name: _trace(p.pid, work / f"{name}.syscalls") for name, p in procs.items()}
                  if syscalls else {})
        if priority is not None:
            for name in PROCESSES:
                set_priority(procs[name].pid, priority)
        split = cpu_split() if pin else None
        for name, p in procs.items():
            if split is not None and name in split:
                set_affinity(p.pid, split[name])
            if split is not None and name in BACKGROUND:
                set_background(p.pid)
            if split is not None and name in NICENESS and priority is None:
                set_nice(p.pid, NICENESS[name])
        if profile:   # the flight begins: profile from here (benchmarks.profiled)
            for name in PROCESSES:
                procs[name].send_signal(signal.SIGUSR1)
        if on_connected is not None:
            on_connected()
        if flight.client:
            m = re.search(r"MAVLink on tcp:127\.0\.0\.1:(\d+)", logs["companion"].read_text())
            if m is None:
                raise RuntimeError("the companion has no MAVLink TCP endpoint")
            args = [a.replace("{port}", m.group(1)) for a in flight.client]
            logs["client"] = work / "client.log"
            with open(logs["client"], "w") as log:
                procs["client"] = subprocess.Popen(
                    [py, *_profiled(work, "client", profile), *args], cwd=ROOT, stdout=log,
                    stderr=subprocess.STDOUT, env=dict(env, PYTHONUNBUFFERED="1"))
            # its start-up (imports) is left out of its figure, as the others'
            _wait_ready(procs["client"], logs["client"], flight.client_ready)
            start_cpu["client"] = _cpu_s(procs["client"].pid)
            start_wake["client"] = _wakeups(procs["client"].pid)
            if syscalls:
                traces["client"] = _trace(procs["client"].pid, work / "client.syscalls")
            if profile:
                procs["client"].send_signal(signal.SIGUSR1)
            client_wake = 0
            # its count just before it exits (it is gone once reaped); WNOWAIT: not reaped
            while os.waitid(os.P_PID, procs["client"].pid,
                            os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
                client_wake = _wakeups(procs["client"].pid) or client_wake
                time.sleep(0.05)
            code, cpu = _reap(procs["client"], MISSION_TIMEOUT_S + 60.0)
            results["client"] = ProcessResult(code, cpu - start_cpu["client"], "",
                                              wakeups=client_wake - start_wake["client"])
            # the flight is over: the counts stop here
            wake = {n: _wakeups(p.pid) - start_wake[n] for n, p in procs.items()
                    if n != "client"}
            for n, tr in traces.items():
                calls = _end_trace(tr, work / f"{n}.syscalls")
                if n == "client":
                    results["client"].syscalls = calls
                else:
                    traced[n] = calls
            procs["plant"].send_signal(signal.SIGTERM)   # it prints its summary and exits
            plant_budget_s = 60.0
        else:
            assert duration_s is not None
            plant_budget_s = 60.0 + 50.0 * duration_s
            wake = {}
        code, cpu = _reap(procs["plant"], plant_budget_s)
        if profile and procs["groundstation"].poll() is None:
            procs["groundstation"].send_signal(signal.SIGUSR2)   # the flight is over
        results["plant"] = ProcessResult(code, cpu - start_cpu["plant"], "")
        code, cpu = _reap(procs["companion"], 30.0)
        results["companion"] = ProcessResult(code, cpu - start_cpu["companion"], "")
        procs["groundstation"].send_signal(signal.SIGTERM)
        code, cpu = _reap(procs["groundstation"], 30.0)
        results["groundstation"] = ProcessResult(code, cpu - start_cpu["groundstation"], "")
        if "candump" in procs:
            procs["candump"].send_signal(signal.SIGTERM)
            code, cpu = _reap(procs["candump"], 30.0)
            results["candump"] = ProcessResult(code, cpu - start_cpu["candump"], "")
    finally:
        for p in (*traces.values(), *procs.values()):
            if p.returncode is None and p.poll() is None:
                p.kill()
                p.wait()
    results = {k: results[k] for k in (*PROCESSES, "client", "candump") if k in results}
    for name, r in results.items():
        r.log = logs[name].read_text()
        r.syscalls = traced.get(name, r.syscalls)
        r.wakeups = wake.get(name, r.wakeups)
        if profile and (work / f"{name}.prof").is_file():
            r.shares = profile_shares(work / f"{name}.prof")
    m = re.search(r"([\d.]+) s simulated in ([\d.]+) s", results["plant"].log)
    sim_s, wall_s = (float(m.group(1)), float(m.group(2))) if m else (float("nan"),) * 2
    return StackResult(flight.name, sim_s, wall_s, results)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the stack (inside a private network namespace) and print one JSON line."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.stack", description=__doc__)
    ap.add_argument("work", help="folder for the logs and profiles")
    ap.add_argument("--flight", choices=("mission", "short-mission", "goto"),
                    default="mission", help="the scripted mission (default), its --short "
                    "hop, or --goto from hover trim for --duration")
    ap.add_argument("--duration", type=float, default=None,
                    help="goto: stop the plant after [s] of simulated time (default 10 s)")
    ap.add_argument("--profile", action="store_true", help="run every process under cProfile")
    ap.add_argument("--no-pin", action="store_true",
                    help="let the processes run on any CPU (as up --no-pin)")
    ap.add_argument("--no-recorder", action="store_true",
                    help="without the bus recorder that up runs")
    ap.add_argument("--priority", choices=PRIORITIES, default=None,
                    help="scheduling for the three processes (experiments)")
    ap.add_argument("--sim-link", choices=("unix", "tcp"), default=SIM_LINK_DEFAULT,
                    help="the simulator link, as up --sim-link (default: up's)")
    ap.add_argument("--spin", action="store_true",
                    help="experiment, with --no-pin: the plant's lockstep waits spin first "
                         "(python -m sitl --lockstep-spin-us)")
    ap.add_argument("--syscalls", action="store_true",
                    help="count each process's system calls over the flight (perf trace "
                         "-s, root; slows the run) and print them per control period")
    args = ap.parse_args(argv)
    flight = goto_flight() if args.flight == "goto" else mission_flight(
        args.flight == "short-mission")
    duration = None if flight.client else args.duration or 10.0
    res = run_stack(Path(args.work), duration, flight, profile=args.profile,
                    priority=args.priority, pin=False if args.no_pin else None,
                    recorder=not args.no_recorder, sim_link=args.sim_link,
                    syscalls=args.syscalls, spin=args.spin)
    out = asdict(res)
    out["real_time_factor"] = res.real_time_factor
    print(json.dumps(out))
    periods = res.sim_s * 250.0   # (the mission's control rate)
    print(f"{res.real_time_factor:.2f}x real time, {res.sim_s:.2f} s simulated "
          f"in {res.wall_s:.2f} s", file=sys.stderr)
    for name, r in res.processes.items():
        calls = sum(r.syscalls.values())
        top = ", ".join(f"{k} {v / periods:.2f}" for k, v in
                        sorted(r.syscalls.items(), key=lambda kv: -kv[1])[:6])
        print(f"{name:14s} CPU {r.cpu_s / periods * 1e6:6.1f} us/period, wake-ups "
              f"{r.wakeups / periods:5.2f}/period"
              + (f", syscalls {calls / periods:5.2f}/period ({top})" if r.syscalls else ""),
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
