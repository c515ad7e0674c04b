"""The benchmarks are not tests; this runs each once in a tiny configuration so they keep
working."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_benchmarks_run_quick():
    res = subprocess.run([sys.executable, "-m", "benchmarks", "--quick"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    for row in ("tether solve, cold", "tether solve, warm-started", "plant step at 1000 Hz",
                "offline closed loop (circle)", "share: plant physics"):
        assert row in res.stdout, row
    assert "faster than MoorPy" in res.stdout
