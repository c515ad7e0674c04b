"""The three-process stack in lockstep, timed and profiled: ``python -m benchmarks.stack``.

Starts the plant, the ground station and the companion as ``tuav-sitl up --speedup max``
does (lockstep, the winder on a udp_multicast CAN bus, the component link between companion
and winch), flies one flight (:func:`goto_flight`: the companion flies to a goal, until the
scripted MAVLink mission replaces it), and reports simulated seconds per wall second from
the plant's own summary and each process's CPU time. With ``--profile`` every process runs
under cProfile (``python -m benchmarks.profiled FILE -m ...``, which is ``python -m
cProfile -o FILE -m ...`` profiling only from the flight's start, signalled when the
companion has connected, to its end; each process exits normally: the plant at
``--duration``, the companion when the plant closes the link, the ground station on
SIGTERM), and the profiles are aggregated by category (:data:`CATEGORIES`).

The CAN bus is IPv4 multicast: run this inside a private network namespace, as ``python -m
benchmarks`` does (``unshare --net``, see :func:`benchmarks.netns.run_in_netns`), so that no
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
    if "/pymavlink/" in f or f.endswith(("tuavdefs/simlink.py", "tuavdefs/component_link.py",
                                         "companion/simlink_client.py",
                                         "companion/component_server.py",
                                         "companion/mavlink_server.py",
                                         "companion/mavlink_io.py", "companion/autopilot.py",
                                         "companion/mission_protocol.py",
                                         "companion/param_protocol.py",
                                         "groundstation/winch_link.py",
                                         "sitl/simlink_server.py", "tuavdefs/frames.py")):
        return "MAVLink"
    if "/can/" in f or "/cantools/" in f or f.endswith((
            "tuavdefs/canbus.py", "tuavdefs/can_protocol.py", "sitl/odrive_axis.py",
            "sitl/winder_node.py")):
        return "CAN"
    if "/sitl/" in f and not f.endswith("sitl/__main__.py"):
        return "physics"
    if f.endswith(("companion/flight_controller.py", "companion/position.py",
                   "companion/attitude.py", "companion/actuators.py",
                   "companion/tether_model.py", "companion/trajectory.py",
                   "companion/navigation.py", "groundstation/winder_host.py",
                   "groundstation/lbar.py", "groundstation/winder_control.py",
                   "groundstation/winch.py", "tuavdefs/airframe.py")):
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


def goto_flight(goal_m: Sequence[float] = GOAL_M) -> list[str]:
    """The companion's arguments for the benchmark's flight: fly to ``goal_m`` [m] and
    hold. The one function to replace by a scripted MAVLink mission."""
    return ["--goto", *map(str, goal_m)]


@dataclass
class ProcessResult:
    """One process of a run: exit code, CPU time [s] (user + system) from the companion's
    connection to its end, its log's text and, when profiled, its profile's shares by
    category."""

    exit_code: int
    cpu_s: float
    log: str
    shares: dict[str, float] = field(default_factory=dict)


@dataclass
class StackResult:
    """A run of the stack: simulated [s] and wall [s] time from the plant's summary, and
    the processes'."""

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


def busy_loads(n: int) -> list[subprocess.Popen]:
    """``n`` processes that spin on a CPU each (the second load of the real-time runs)."""
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def run_stack(work: Path, duration_s: float,
              flight: Callable[[], list[str]] = goto_flight, profile: bool = False,
              real_time: bool = False, control_rate_hz: float = 250.0,
              plant_extra: Sequence[str] = (),
              on_connected: Callable[[], object] | None = None) -> StackResult:
    """Run the three processes for ``duration_s`` [s] of simulated time in ``work`` (logs,
    profiles, truth series) and return what they did: in lockstep, or paced by the wall
    clock (``real_time``), at ``control_rate_hz`` [Hz] (the companion's gains get the same
    rate). ``on_connected`` is called when the companion has connected to the plant (the
    flight begins)."""
    work.mkdir(parents=True, exist_ok=True)
    sim_port, comp_port = _free_port(), _free_port()
    can = "udp_multicast"
    py = sys.executable
    gains: list[str] = []
    if control_rate_hz != 250.0:
        (work / "gains.toml").write_text(f"rate_hz = {float(control_rate_hz)!r}\n")
        gains = ["--gains", str(work / "gains.toml")]
    commands = {
        "plant": ["-m", "sitl", "--port", str(sim_port), "--can", can, "--position",
                  *map(str, START_M), "--duration", str(duration_s),
                  "--control-rate", str(float(control_rate_hz)),
                  "--truth-log", str(work / "truth.csv"),
                  *(["--real-time"] if real_time else []), *plant_extra],
        "groundstation": ["-m", "groundstation", "--can", can, "--mavlink",
                          f"127.0.0.1:{comp_port}"],
        "companion": ["-m", "companion", "--sim", f"127.0.0.1:{sim_port}",
                      "--component-port", str(comp_port), *gains, *flight()],
    }
    ready = {"plant": "listening on", "groundstation": "groundstation: CAN",
             "companion": None}
    procs: dict[str, subprocess.Popen] = {}
    logs: dict[str, Path] = {}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    try:
        for name in PROCESSES:
            logs[name] = work / f"{name}.log"
            prof = (["-m", "benchmarks.profiled", str(work / f"{name}.prof")] if profile
                    else [])
            with open(logs[name], "w") as log:
                procs[name] = subprocess.Popen([py, *prof, *commands[name]], cwd=ROOT,
                                               stdout=log, stderr=subprocess.STDOUT, env=env)
            if ready[name]:
                _wait_ready(procs[name], logs[name], ready[name])
        # the flight starts when the companion connects: each process's CPU time so far
        # (start-up) is left out of its figure
        _wait_ready(procs["companion"], logs["companion"], "companion: connected")
        start_cpu = {name: _cpu_s(p.pid) for name, p in procs.items()}
        if profile:   # the flight begins: profile from here (benchmarks.profiled)
            for p in procs.values():
                p.send_signal(signal.SIGUSR1)
        if on_connected is not None:
            on_connected()
        results: dict[str, ProcessResult] = {}
        code, cpu = _reap(procs["plant"], 60.0 + 50.0 * duration_s)
        if profile and procs["groundstation"].poll() is None:
            procs["groundstation"].send_signal(signal.SIGUSR2)   # the flight is over
        results["plant"] = ProcessResult(code, cpu - start_cpu["plant"], "")
        code, cpu = _reap(procs["companion"], 30.0)
        results["companion"] = ProcessResult(code, cpu - start_cpu["companion"], "")
        procs["groundstation"].send_signal(signal.SIGTERM)
        code, cpu = _reap(procs["groundstation"], 30.0)
        results["groundstation"] = ProcessResult(code, cpu - start_cpu["groundstation"], "")
    finally:
        for p in procs.values():
            if p.returncode is None and p.poll() is None:
                p.kill()
                p.wait()
    for name, r in results.items():
        r.log = logs[name].read_text()
        if profile and (work / f"{name}.prof").is_file():
            r.shares = profile_shares(work / f"{name}.prof")
    m = re.search(r"([\d.]+) s simulated in ([\d.]+) s", results["plant"].log)
    sim_s, wall_s = (float(m.group(1)), float(m.group(2))) if m else (float("nan"),) * 2
    return StackResult(sim_s, wall_s, results)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the stack (inside a private network namespace) and print one JSON line."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.stack", description=__doc__)
    ap.add_argument("work", help="folder for the logs and profiles")
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds [s]")
    ap.add_argument("--profile", action="store_true", help="run every process under cProfile")
    args = ap.parse_args(argv)
    res = run_stack(Path(args.work), args.duration, profile=args.profile)
    out = asdict(res)
    out["real_time_factor"] = res.real_time_factor
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
