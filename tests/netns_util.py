"""Running a command in a private network namespace with only loopback (multicast enabled),
so that python-can's udp_multicast bus and every socket stay on this host: joining a
multicast group sends IGMP by the default route, which must not leave the machine. The
same helper the benchmarks use (``tuav_sitl/netns.py``)."""

import json
import sys
from pathlib import Path

from tuav_sitl.netns import SETUP, run_in_netns
from tuav_sitl.netns import netns_available as _unavailable_because

__all__ = ["PYTHON", "SETUP", "netns_available", "run_in_netns", "run_session"]

ROOT = Path(__file__).resolve().parents[1]


def netns_available() -> bool:
    """Root, unshare and ip are here (CI runs as root), or we are inside one already."""
    return _unavailable_because() is None


PYTHON = sys.executable


def run_session(module: str, *args: str, timeout_s: float) -> dict:
    """Run ``python -m module args`` (a driver under tests/netns/) from the repository root
    in a private network namespace; it must succeed and print one JSON line last: that."""
    res = run_in_netns([PYTHON, "-m", module, *args], timeout_s=timeout_s, cwd=str(ROOT))
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])
