"""Compiling the numba kernels of a cold cache, two halves at once, with progress.

On the first run after an install (or after a change to a kernel) every kernel compiles
before the first control period, one after the other in one process. :func:`warm_up` instead
starts two processes that each fly the scenario for a few control periods, one with the
plant's kernels compiled and the controllers' interpreted, the other the reverse
(``TUAV_JIT_INTERPRET``, :mod:`tuavdefs.jit`); each writes what it compiled to numba's
cache, and the run proper then loads it all. The shared ``tuavdefs`` kernels compile in
both. Each finished compilation is reported on the progress stream.

:func:`needs_warm_up` decides, from the cache's index, whether the kernels every run calls
are already there; a kernel that only some scenarios call and that is still cold compiles
in the run itself, reported by :func:`report_compiles`.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import TextIO

from tuav_sitl.scenario import ScenarioParams

__all__ = ["HALVES", "compile_if_cold", "needs_warm_up", "report_compiles", "warm_up"]

#: The two warm-up processes: the packages each leaves interpreted (so compiles the rest).
HALVES: tuple[tuple[str, str], ...] = (
    ("the plant's kernels", "companion,groundstation"),
    ("the controllers' kernels", "sitl"),
)
#: Simulated time each warm-up process flies [s]: enough control periods for every
#: kernel of a run's first seconds to be called once.
_WARM_UP_S = 0.2
#: A warm-up process that takes longer than this is abandoned [s].
_TIMEOUT_S = 600.0


def _sentinels() -> list[object]:
    """The kernels every offline run calls (plant step, flight control, winder law)."""
    from companion.flight_controller import flight_step
    from groundstation.winder_host import winder_step
    from sitl.plant import advance_kernel
    from sitl.tether import tether_forces_kernel

    return [advance_kernel, tether_forces_kernel, flight_step, winder_step]


def needs_warm_up() -> bool:
    """Whether numba is on and one of the kernels every run calls is not in the cache."""
    from tuavdefs.jit import JIT, is_cached

    return JIT and not all(is_cached(k) for k in _sentinels())


def report_compiles(stream: TextIO | None):
    """Report on ``stream`` each kernel this process compiles (``compiling: NAME, 3.1 s``);
    returns the function that stops it."""
    from tuavdefs.jit import on_compile

    if stream is None:
        return lambda: None

    def show(name: str, seconds: float) -> None:
        stream.write(f"compiled {name} ({seconds:.1f} s; cached for the next runs)\n")
        stream.flush()

    return on_compile(show)


_CHILD = """
import pickle, sys
from tuavdefs.jit import on_compile
from tuav_sitl.offline import run_scenario
on_compile(lambda name, s: print(f"{name} {s:.2f}", flush=True))
with open(sys.argv[1], "rb") as f:
    run_scenario(pickle.load(f), None, progress=None)
"""


def warm_up(scenario: ScenarioParams, stream: TextIO | None) -> float:
    """Compile the kernels ``scenario`` calls, in two processes at once (:data:`HALVES`),
    into numba's cache; progress on ``stream``. Returns the wall time [s]. A warm-up
    process that fails only costs its time: the run compiles what is missing itself."""
    start = time.perf_counter()
    short = scenario.replace(duration_s=_WARM_UP_S, metrics_after_s=0.0)
    root = Path(__file__).resolve().parents[1]
    lock = threading.Lock()
    counts = {label: 0 for label, _ in HALVES}
    finished: dict[str, bool] = {}

    def line(note: str) -> None:
        if stream is None:
            return
        parts = [f"{label.split()[1].rstrip('s').rstrip(chr(39))} {counts[label]}"
                 + (" done" if label in finished else "") for label, _ in HALVES]
        stream.write(f"\rcompiling: {', '.join(parts)}, {time.perf_counter() - start:5.1f} s"
                     f"  {note[:24]:24s}")
        stream.flush()

    with tempfile.TemporaryDirectory(prefix="tuav-warmup-") as tmp:
        scenario_file = Path(tmp) / "scenario.pickle"
        scenario_file.write_bytes(pickle.dumps(short))
        procs = []
        for label, interpreted in HALVES:
            env = dict(os.environ, TUAV_JIT_INTERPRET=interpreted)
            env["PYTHONPATH"] = os.pathsep.join(
                p for p in (str(root), env.get("PYTHONPATH", "")) if p)
            err = open(Path(tmp) / f"{len(procs)}.err", "w+")  # noqa: SIM115 - closed below
            procs.append((label, subprocess.Popen(
                [sys.executable, "-c", _CHILD, str(scenario_file)], env=env, text=True,
                stdout=subprocess.PIPE, stderr=err), err))

        def follow(label: str, proc: subprocess.Popen[str]) -> None:
            assert proc.stdout is not None
            for out in proc.stdout:
                with lock:
                    counts[label] += 1
                    line(out.split()[0].rsplit(".", 1)[-1] if out.strip() else "")
            proc.wait()
            with lock:
                finished[label] = proc.returncode == 0
                line("")

        threads = [threading.Thread(target=follow, args=(label, proc), daemon=True)
                   for label, proc, _ in procs]
        for t in threads:
            t.start()
        with lock:
            line("")
        for (_, proc, _), t in zip(procs, threads, strict=True):
            t.join(_TIMEOUT_S)
            if t.is_alive():
                proc.kill()
                t.join()
        notes = []
        for label, _, err in procs:
            err.seek(0)
            if not finished.get(label):
                last = err.read().strip().splitlines()[-1:] or ["killed"]
                notes.append(f"  the warm-up of {label} failed (the run compiles them "
                             f"itself): {last[0][:200]}\n")
            err.close()
    wall = time.perf_counter() - start
    if stream is not None:
        stream.write("\n" + "".join(notes))
        stream.flush()
    return wall


def compile_if_cold(scenario: ScenarioParams, stream: TextIO | None) -> bool:
    """If :func:`needs_warm_up`: say so on ``stream`` and :func:`warm_up` for ``scenario``.
    Returns whether it did."""
    if not needs_warm_up():
        return False
    if stream is not None:
        stream.write("compiling the numba kernels (the first run after an install or a "
                     "change to a kernel; cached for the next runs), the plant's and the "
                     "controllers' at once\n")
        stream.flush()
    warm_up(scenario, stream)
    return True
