"""``tuav-sitl run`` as a user first meets it, in fresh interpreters: every phase shows its
progress on stderr (and ``--quiet`` shows none). (On a cold numba cache: the warm-up's
compiling, which ``up`` shares, tests/test_cold_start.py.)"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "setpoint", "--duration",
                           "4", "--out", str(out), *extra], cwd=ROOT, capture_output=True,
                          text=True, timeout=900)


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
