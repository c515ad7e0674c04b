"""The first flight after an install: ``tuav-sitl up`` on an empty numba cache says that it
compiles, compiles every kernel the processes can call before its banner (its warm-up, the
manifest of tuavdefs/kernel_signatures.py), and no process compiles anything after it said
it was ready while the README's pymavlink snippet flies (numba's compile events, which
each process logs after its ready point: tuavdefs.jit.watch_compiles). One flight, in a
private network namespace (tests/netns/cold_start_session.py).

``tuav-sitl run`` goes through the same warm-up (tuav_sitl/warmup.py): on a copy of the
cache that flight filled, with a kernel of each half of the warm-up taken out (as after a
change to a kernel), the run says it compiles, the two warm-up processes compile, the run
proper compiles nothing, and the next run says nothing of compiling. The whole manifest is
compiled from empty once, by ``up``, for both."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from netns_util import netns_available, run_session

from tuavdefs import jit

pytestmark = [
    pytest.mark.skipif(not jit.JIT, reason="numba absent or TUAV_NO_JIT=1"),
    pytest.mark.skipif(not netns_available(), reason="needs a private network namespace"),
]

PROCESSES = ("plant", "companion", "groundstation")
ROOT = Path(__file__).resolve().parents[1]
#: A kernel of each half of the warm-up (the plant's, the controllers'), taken out of the
#: cache for the run (``module.function``).
TAKEN_OUT = ("sitl.kernel.attachment_point", "companion.ekf.baro.fuse_baro_kernel")


@pytest.fixture(scope="module")
def cold(tmp_path_factory) -> dict:
    base = tmp_path_factory.mktemp("cold-start")
    # (a hang's bound: the cold compile outlasted 900 s on two cores loaded 30 times over)
    out = run_session("tests.netns.cold_start_session", str(base), timeout_s=1800)
    return {**out, "cache_dir": base / "numba-cache"}     # the session's NUMBA_CACHE_DIR


def _logs(out: dict) -> str:
    return "".join(f"\n--- {name}\n{text[-2000:]}" for name, text in out["logs"].items())


def test_up_says_it_compiles_and_compiles_before_its_banner(cold):
    err = cold["up_stderr"]
    assert "Ctrl-C stops all three" in cold["banner"], err + _logs(cold)
    assert "compiling the numba kernels" in err, err
    assert "compiling: plant" in err and "failed" not in err and "stale" not in err, err
    assert cold["cache_files"] > 0      # the processes' cache was the empty folder
    # the warm-up left nothing for the processes to compile before they were ready
    for name in PROCESSES:
        assert "compiling the numba kernels" not in cold["logs"][name], _logs(cold)


def test_no_kernel_compiles_after_the_processes_are_ready(cold):
    snippet = cold["snippet"]
    assert snippet["rc"] == 0, snippet["stdout"] + snippet["stderr"] + _logs(cold)
    assert "tether paid out" in snippet["stdout"]
    late = [line for name in PROCESSES for line in cold["logs"][name].splitlines()
            if jit.LATE_COMPILE in line]
    assert late == [], "\n".join(late)


def _run(out: Path, cache: Path) -> subprocess.CompletedProcess[str]:
    """``tuav-sitl run setpoint`` for 4 s without figures, on the numba cache ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("TUAV_NO_JIT", None)
    env.pop("TUAV_JIT_INTERPRET", None)
    return subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "setpoint", "--duration",
                           "4", "--out", str(out), "--no-figures"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=900)


def test_a_run_missing_kernels_has_the_warm_up_compile_them_and_loads_them(cold,
                                                                         tmp_path):
    cache = tmp_path / "cache"
    shutil.copytree(cold["cache_dir"], cache)
    for name in TAKEN_OUT:      # numba's files of the kernel: module.function-line.*
        module, function = name.rsplit(".", 1)
        files = list(cache.rglob(f"{module.rsplit('.', 1)[-1]}.{function}-*.nb[ic]"))
        assert files, name
        for f in files:
            f.unlink()
    res = _run(tmp_path / "run", cache)
    assert res.returncode == 0, res.stderr
    err = res.stderr
    assert "compiling the numba kernels" in err
    counts = re.findall(r"compiling: plant (\d+)( done)?, controllers (\d+)( done)?", err)
    assert counts and counts[-1][1] == " done" and counts[-1][3] == " done", err
    assert int(counts[-1][0]) > 0 and int(counts[-1][2]) > 0
    assert "failed" not in err, err
    # the run proper compiled nothing: every kernel it called was in the cache
    assert "compiled " not in err, err
    # and the next run says nothing about compiling
    again = _run(tmp_path / "again", cache)
    assert again.returncode == 0 and "compil" not in again.stderr, again.stderr
