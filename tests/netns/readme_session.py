"""The README's Python snippets (the pymavlink one, MAVSDK's native binding, MAVSDK-Python's
gRPC API ``mavsdk_grpc``), and running one as written: what the sessions that fly them
against ``tuav-sitl up`` share (tests/netns/first_contact_session.py, at every speed-up from
the banner; tests/netns/cold_start_session.py, from an empty numba cache)."""

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def python_blocks() -> list[str]:
    """The README's ```python blocks, in order."""
    return re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


def run(code: str, path: Path, timeout_s: float) -> dict:
    """Run ``code`` as the script ``path``; on a timeout its threads' tracebacks (the
    fault handler's, on SIGABRT) are what it left on stderr."""
    path.write_text(code)
    p = subprocess.Popen([sys.executable, str(path)], cwd=path.parent, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env=dict(os.environ, PYTHONFAULTHANDLER="1"))
    try:
        so, se = p.communicate(timeout=timeout_s)
        return {"rc": p.returncode, "stdout": so, "stderr": se[-3000:]}
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGABRT)
        try:
            so, se = p.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            so, se = p.communicate()
        return {"rc": None, "stdout": so, "stderr": f"timed out after {timeout_s} s\n"
                + se[-6000:]}
