"""``tuav-sitl run`` as a user first meets it, in fresh interpreters: every phase shows its
progress on stderr (and ``--quiet`` shows none); on a cold numba cache the run says it is
compiling, the two warm-up processes compile the plant's and the controllers' kernels, and
the run proper then finds every kernel it calls in the cache (it compiles none itself)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tuavdefs import jit

ROOT = Path(__file__).resolve().parents[1]


def _run(out: Path, *extra: str, env: dict[str, str] | None = None
         ) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "setpoint", "--duration",
                           "4", "--out", str(out), *extra], cwd=ROOT,
                          env=env or dict(os.environ), capture_output=True, text=True,
                          timeout=900)


def test_run_shows_the_drawing_progress_and_quiet_shows_nothing(tmp_path):
    res = _run(tmp_path / "a")
    assert res.returncode == 0, res.stderr
    line = res.stderr.rsplit("\r", 1)[-1]
    assert re.search(r"drawing: figures 9/9, animation frames (\d+)/\1,", line), res.stderr
    assert "wrote 9 figures" in res.stdout and "animation.gif" in res.stdout
    quiet = _run(tmp_path / "b", "--quiet")
    assert quiet.returncode == 0, quiet.stderr
    assert "drawing" not in quiet.stderr and "[" not in quiet.stderr
    assert sorted(p.name for p in (tmp_path / "b" / "figures").iterdir()) == sorted(
        p.name for p in (tmp_path / "a" / "figures").iterdir())


@pytest.mark.skipif(not jit.JIT, reason="numba absent or TUAV_NO_JIT=1")
def test_a_cold_cache_is_compiled_by_the_warm_up_and_the_run_loads_it(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("TUAV_NO_JIT", None)
    res = _run(tmp_path / "cold", "--no-figures", env=env)
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
    again = _run(tmp_path / "warm", "--no-figures", env=env)
    assert again.returncode == 0 and "compil" not in again.stderr, again.stderr
