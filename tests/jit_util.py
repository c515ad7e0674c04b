"""Running a script twice in fresh interpreters, with the compiled kernels and with
``TUAV_NO_JIT=1`` (the same code interpreted), for the tests that compare the two."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_script(script: str, no_jit: bool, timeout_s: float) -> dict:
    """Run ``script`` (which prints one JSON line last) with or without numba; its JSON."""
    env = dict(os.environ)
    env.pop("TUAV_NO_JIT", None)
    if no_jit:
        env["TUAV_NO_JIT"] = "1"
    res = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=timeout_s, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])
