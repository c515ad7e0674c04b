"""The compile cache of tuavdefs.jit: a kernel is recompiled when a kernel it calls in
another module changes, and its key is the same in every process (else nothing would ever
be served from the cache)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tuavdefs import jit

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not jit.JIT, reason="numba absent or TUAV_NO_JIT=1")

CALLEE = """
from tuavdefs.jit import njit
GAIN = {gain}
@njit
def scaled(x):
    return GAIN * x
"""
CALLER = """
from tuavdefs.jit import njit
from callee import scaled
@njit
def caller(x):
    return scaled(x) + 1.0
"""
RUN = """
import sys
sys.path[:0] = [{root!r}, {here!r}]
from caller import caller
print(caller(2.0), sum(caller.stats.cache_hits.values()))
"""


def _run(here: Path) -> tuple[float, int]:
    env = dict(os.environ)
    env.pop("TUAV_NO_JIT", None)
    res = subprocess.run([sys.executable, "-c", RUN.format(root=str(ROOT), here=str(here))],
                         capture_output=True, text=True, timeout=300, check=True, env=env)
    value, hits = res.stdout.split()
    return float(value), int(hits)


def test_a_kernel_follows_a_change_in_another_module(tmp_path):
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    (tmp_path / "caller.py").write_text(textwrap.dedent(CALLER))
    assert _run(tmp_path) == (5.0, 0)     # compiled
    assert _run(tmp_path) == (5.0, 1)     # served from the cache
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=3.0)))
    assert _run(tmp_path) == (7.0, 0)     # plain numba would serve the stale 5.0 here
    assert _run(tmp_path) == (7.0, 1)


DIGEST = """
from tuavdefs.jit import dependency_digest
from companion.flight_controller import flight_step
from sitl.plant import _rk4_step
print(dependency_digest(flight_step), dependency_digest(_rk4_step))
"""


def test_the_dependency_digest_is_the_same_in_every_process():
    outs = set()
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        res = subprocess.run([sys.executable, "-c", DIGEST], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=300, check=True)
        outs.add(res.stdout.strip())
    assert len(outs) == 1


REPORT = """
import json, sys
sys.path[:0] = [{root!r}, {here!r}]
from tuavdefs import jit
from callee import scaled
before = jit.is_cached(scaled)
names = []
jit.on_compile(lambda name, seconds: names.append(name))
value = scaled(2.0)
print(json.dumps([jit.JIT, before, jit.is_cached(scaled), names, value]))
"""


def _report(here: Path, **env_extra: str) -> list:
    import json

    env = dict(os.environ, **env_extra)
    env.pop("TUAV_NO_JIT", None)
    res = subprocess.run([sys.executable, "-c", REPORT.format(root=str(ROOT), here=str(here))],
                         capture_output=True, text=True, timeout=300, check=True, env=env)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_is_cached_and_on_compile_tell_a_compile_from_a_cache_load(tmp_path):
    """A cold kernel: not cached, its compilation reported; in the next process it loads
    from the cache (is_cached before the call) and nothing is reported. A change to the
    source makes it cold again."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    assert _report(tmp_path) == [True, False, True, ["callee.scaled"], 4.0]
    assert _report(tmp_path) == [True, True, True, [], 4.0]
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=3.0)))
    assert _report(tmp_path) == [True, False, True, ["callee.scaled"], 6.0]


def test_an_interpreted_package_stays_python_and_jit_says_so(tmp_path):
    """TUAV_JIT_INTERPRET=callee: the kernel is the plain function (nothing to compile,
    nothing cached) and JIT is False, so no caller counts on machine code."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    assert _report(tmp_path, TUAV_JIT_INTERPRET="callee") == [False, True, True, [], 4.0]
    assert not (tmp_path / "__pycache__").is_dir() or not any(
        p.suffix == ".nbi" for p in (tmp_path / "__pycache__").iterdir())
