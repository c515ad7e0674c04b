"""Running a command in a private network namespace with only loopback (multicast enabled),
so that python-can's udp_multicast bus and every socket stay on this host: joining a
multicast group sends IGMP by the default route, which must not leave the machine. The
same helper the benchmarks use (``benchmarks/netns.py``)."""

import sys

from benchmarks.netns import SETUP, run_in_netns
from benchmarks.netns import netns_available as _unavailable_because

__all__ = ["PYTHON", "SETUP", "netns_available", "run_in_netns"]


def netns_available() -> bool:
    """Root, unshare and ip are here (CI runs as root), or we are inside one already."""
    return _unavailable_because() is None


PYTHON = sys.executable
