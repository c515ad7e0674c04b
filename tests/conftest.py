"""The suite's CPU account: with ``TUAV_TEST_CPU=<file>`` set, every test's CPU time (its
setup, call and teardown: the pytest process's own and its waited-for children's, from
``resource.getrusage``) is written to ``<file>`` as a table, the heaviest first; off by
default. On a shared machine wall time is noise; CPU seconds are what a test costs.

A module-scoped fixture's work is counted in the test whose setup built it (and its
teardown in the module's last test). A child process's CPU is counted when it is waited
for: one left running past its test is counted in the test that reaps it.

A run on several workers (``-n 2``, the suite's default) first compiles the numba kernels
the cache lacks, once, before the workers start (:func:`tuav_sitl.warmup.compile_if_cold`,
as ``up`` and ``run`` do): on a fresh clone the workers would otherwise each compile the
kernels their first tests call, the same ones at once. Its CPU is the table's
``(session warm-up)`` row. The tests of a cold cache use caches of their own."""

from __future__ import annotations

import os
import resource
import sys
import time
from pathlib import Path

import pytest

CPU_ENV = "TUAV_TEST_CPU"
_HEADER = "cpu_s\tself_s\tchildren_s\twall_s\tworker\ttest"


def _cpu_s() -> tuple[float, float]:
    """(this process's, its waited-for children's) user + system CPU [s]."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def _table_path(config: pytest.Config) -> Path | None:
    value = os.environ.get(CPU_ENV, "")
    return Path(value) if value else None


def _line(cpu: tuple[float, float], wall_s: float, worker: str, name: str) -> str:
    own, kids = cpu
    return f"{own + kids:.2f}\t{own:.2f}\t{kids:.2f}\t{wall_s:.2f}\t{worker}\t{name}\n"


def _append(path: Path, line: str) -> None:
    # one short write with O_APPEND per line: the workers' lines do not interleave
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, line.encode())
    finally:
        os.close(fd)


#: The modules that take longest, the longest first (on a quiet host's two workers: the
#: first three one to two minutes of wall time, the rest of these 30 s to a minute each).
#: The suite's workers take a whole module at a time, in the collection's order
#: (pyproject's ``--dist loadscope --no-loadscope-reorder``): these first, so that no long
#: one is left to start last while the other worker runs out of work; what follows them
#: (the collection's order) takes under half a minute a module, but for
#: tests/test_groundstation_process.py (45 s, mostly waiting on its real-time sessions,
#: whose rate and length checks a start beside the cold compile and the first-contact
#: flights starved: left in the collection's order).
LONGEST_FIRST = ("test_cold_start.py", "test_first_contact.py", "test_up.py",
                 "test_estimator.py", "test_scenarios.py", "test_sim_params.py",
                 "test_fault_failsafes.py", "test_e2e.py", "test_signing.py", "test_view.py",
                 "test_view_live.py", "test_benchmarks.py", "test_sweep.py",
                 "test_rogue_can.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The modules of :data:`LONGEST_FIRST` first, in its order; the rest as collected."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))   # a stable sort


def pytest_configure(config: pytest.Config) -> None:
    """On the controller (or a run without xdist): start an empty table; with workers to
    come, compile what the numba cache lacks first."""
    if hasattr(config, "workerinput"):
        return
    path = _table_path(config)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("")
    if not getattr(config.option, "numprocesses", None) or config.option.collectonly:
        return
    own0, kids0 = _cpu_s()
    t0 = time.perf_counter()
    from tuav_sitl.warmup import compile_if_cold

    compile_if_cold(sys.stderr)
    own1, kids1 = _cpu_s()
    if path is not None:
        _append(path, _line((own1 - own0, kids1 - kids0), time.perf_counter() - t0, "-",
                            "(session warm-up)"))


@pytest.hookimpl(hookwrapper=True)
def pytest_collection(session: pytest.Session):
    """Collection with the test modules' assertion rewriting cached (``__pycache__``, git
    ignores it) even where ``PYTHONDONTWRITEBYTECODE`` is set: pytest rewrites every test
    module in every worker, about 11 CPU-s each, before the first test can start; from
    the cache it only loads them. Bytecode writing is as it was again after collection."""
    before = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        yield
    finally:
        sys.dont_write_bytecode = before


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """Around one test's setup, call and teardown: its CPU, one line appended."""
    path = _table_path(item.config)
    if path is None:
        yield
        return
    own0, kids0 = _cpu_s()
    t0 = time.perf_counter()
    yield
    own1, kids1 = _cpu_s()
    wall = time.perf_counter() - t0
    worker = getattr(item.config, "workerinput", {}).get("workerid", "-")
    _append(path, _line((own1 - own0, kids1 - kids0), wall, worker, item.nodeid))


def pytest_sessionfinish(session: pytest.Session) -> None:
    """On the controller: the lines sorted (heaviest first) under a header, the sums last."""
    path = _table_path(session.config)
    if path is None or hasattr(session.config, "workerinput") or not path.exists():
        return
    rows = [ln.split("\t") for ln in path.read_text().splitlines() if ln.strip()]
    rows.sort(key=lambda r: -float(r[0]))
    modules: dict[str, float] = {}
    for r in rows:
        module = r[5].split("::", 1)[0]
        modules[module] = modules.get(module, 0.0) + float(r[0])
    total = sum(modules.values())
    out = [_HEADER, *("\t".join(r) for r in rows), "",
           "# per module: cpu_s\tmodule",
           *(f"# {cpu:.2f}\t{m}" for m, cpu in sorted(modules.items(), key=lambda kv: -kv[1])),
           f"# total cpu_s {total:.2f} over {len(rows)} tests"]
    path.write_text("\n".join(out) + "\n")


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    """Where the table went, and the sum."""
    path = _table_path(config)
    if path is not None and path.exists():
        last = path.read_text().rstrip().splitlines()[-1:]
        terminalreporter.write_line(f"CPU per test ({CPU_ENV}): {path}; {' '.join(last)}")
