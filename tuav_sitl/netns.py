"""Running a command in a private network namespace with only loopback (multicast
enabled), so that the udp_multicast CAN bus and every socket stay on this host: joining a
multicast group sends IGMP by the default route, which must not leave the machine. Needs
root (``unshare --net``); inside a namespace already (``NETNS_RUN_INSIDE=1``) it runs the
command as it is.

The one copy of this helper: ``tuav-sitl bench`` (:mod:`benchmarks`) runs the process
benchmarks through it, and the test suite its sessions (``tests/netns_util.py``)."""

from __future__ import annotations

import os
import shutil
import subprocess

#: Loopback up, multicast on it, and the multicast route through it; then the command.
SETUP = ("ip link set lo up && ip link set lo multicast on && "
         "ip route add 224.0.0.0/4 dev lo && exec \"$@\"")


def netns_available() -> str | None:
    """None when a private namespace can be made (or we are in one), else why not."""
    if os.environ.get("NETNS_RUN_INSIDE") == "1":
        return None
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "needs root for a private network namespace (unshare --net)"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs unshare and ip (util-linux, iproute2) for a private network namespace"
    return None


def run_in_netns(args: list[str], timeout_s: float, cwd: str) -> subprocess.CompletedProcess:
    """Run ``args`` in a fresh network namespace (``NETNS_RUN_INSIDE=1`` in its
    environment), from the directory ``cwd``, for at most ``timeout_s`` [s] of wall time
    (then :class:`subprocess.TimeoutExpired`); returns the completed process, its output
    captured as text."""
    if os.environ.get("NETNS_RUN_INSIDE") == "1":
        cmd = args
    else:
        cmd = ["unshare", "--net", "--", "sh", "-c", SETUP, "netns", *args]
    env = dict(os.environ, NETNS_RUN_INSIDE="1")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout_s)
