"""Compiling the numba kernels of a cold cache, two halves at once, with progress.

On the first run after an install (or after a change to a kernel) every kernel would
compile when first called, one after the other in one process (and, in ``tuav-sitl up``'s
processes, inside a real-time loop). :func:`warm_up` instead starts two processes that
each compile the kernels of the manifest (:mod:`tuavdefs.kernel_signatures`: every
kernel the processes call from Python, with the argument types they call it with) for its
half of the packages, the plant's in one and the controllers' in the other, with the other
half's kernels interpreted (``TUAV_JIT_INTERPRET``, :mod:`tuavdefs.jit`); each writes what
it compiled to numba's cache, and the processes then load it all before they say they are
ready (:func:`tuavdefs.jit.load_kernels`). The shared ``tuavdefs`` kernels compile in the
controllers' half (and wherever the other half's kernels call them). Each finished
compilation is reported on the progress stream.

:func:`needs_warm_up` decides, from the cache's index, whether every kernel of the
manifest is there for each of its argument types; a kernel that a run calls with types the
manifest lacks compiles in the run itself, reported by :func:`report_compiles`.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import TextIO

__all__ = ["HALVES", "compile_if_cold", "needs_warm_up", "report_compiles", "warm_up"]

#: The two warm-up processes: a label, the packages each leaves interpreted, and those
#: whose kernels of the manifest it compiles.
HALVES: tuple[tuple[str, str, str], ...] = (
    ("the plant's kernels", "companion,groundstation", "sitl"),
    ("the controllers' kernels", "sitl", "companion,groundstation,tuavdefs"),
)
#: A warm-up process that finishes no compilation for this long is abandoned [s] (one
#: kernel takes seconds, a minute on a machine loaded twenty times over).
_SILENT_S = 300.0


def needs_warm_up() -> bool:
    """Whether numba is on and a kernel of the manifest is not in the cache for one of the
    argument types it lists."""
    from tuavdefs.jit import JIT, missing_from_cache

    return JIT and bool(missing_from_cache())


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
import sys
from tuavdefs.jit import load_kernels, on_compile
on_compile(lambda name, s: print(f"{name} {s:.2f}", flush=True))
report = load_kernels(sys.argv[1].split(","))
for failure in report.failures:
    print(failure, file=sys.stderr)
"""


def warm_up(stream: TextIO | None) -> float:
    """Compile the manifest's kernels into numba's cache in two processes at once
    (:data:`HALVES`); progress on ``stream``. Returns the wall time [s]. A warm-up process
    that fails only costs its time: the processes compile what is missing themselves."""
    start = time.perf_counter()
    root = Path(__file__).resolve().parents[1]
    lock = threading.Lock()
    counts = {label: 0 for label, _, _ in HALVES}
    finished: dict[str, bool] = {}

    def line(note: str) -> None:
        if stream is None:
            return
        parts = [f"{label.split()[1].rstrip('s').rstrip(chr(39))} {counts[label]}"
                 + (" done" if label in finished else "") for label, _, _ in HALVES]
        stream.write(f"\rcompiling: {', '.join(parts)}, {time.perf_counter() - start:5.1f} s"
                     f"  {note[:24]:24s}")
        stream.flush()

    with tempfile.TemporaryDirectory(prefix="tuav-warmup-") as tmp:
        procs = []
        for label, interpreted, packages in HALVES:
            env = dict(os.environ, TUAV_JIT_INTERPRET=interpreted)
            env["PYTHONPATH"] = os.pathsep.join(
                p for p in (str(root), env.get("PYTHONPATH", "")) if p)
            err = open(Path(tmp) / f"{len(procs)}.err", "w+")  # noqa: SIM115 - closed below
            procs.append((label, subprocess.Popen(
                [sys.executable, "-c", _CHILD, packages], env=env, text=True,
                stdout=subprocess.PIPE, stderr=err), err))

        heard = {label: time.monotonic() for label, _, _ in procs}

        def follow(label: str, proc: subprocess.Popen[str]) -> None:
            assert proc.stdout is not None
            for out in proc.stdout:
                heard[label] = time.monotonic()
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
        try:
            for (label, proc, _), t in zip(procs, threads, strict=True):
                while t.is_alive():
                    t.join(1.0)
                    if t.is_alive() and time.monotonic() - heard[label] > _SILENT_S:
                        proc.kill()     # stuck: the processes compile what is missing
        finally:    # (stopped by Ctrl-C: no warm-up process is left behind)
            for _, proc, _ in procs:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        notes = []
        for label, _, err in procs:
            err.seek(0)
            said = err.read().strip().splitlines()
            if not finished.get(label):
                last = said[-1:] or ["killed"]
                notes.append(f"  the warm-up of {label} failed (the run compiles them "
                             f"itself): {last[0][:200]}\n")
            elif said:      # entries of the manifest that no longer fit their kernel
                notes.append(f"  the warm-up of {label}: {len(said)} stale entries of "
                             f"tuavdefs/kernel_signatures.py, e.g. {said[0][:200]}\n")
            err.close()
    wall = time.perf_counter() - start
    if stream is not None:
        stream.write("\n" + "".join(notes))
        stream.flush()
    return wall


def compile_if_cold(stream: TextIO | None) -> bool:
    """If :func:`needs_warm_up`: say so on ``stream`` and :func:`warm_up`. Returns whether
    it did."""
    if not needs_warm_up():
        return False
    if stream is not None:
        stream.write("compiling the numba kernels (the first run after an install or a "
                     "change to a kernel; cached for the next runs), the plant's and the "
                     "controllers' at once\n")
        stream.flush()
    warm_up(stream)
    return True
