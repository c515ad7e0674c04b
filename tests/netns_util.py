"""Running a command in a private network namespace with only loopback (multicast enabled),
so that python-can's udp_multicast bus and every socket stay on this host: joining a
multicast group sends IGMP by the default route, which must not leave the machine."""

import os
import shutil
import subprocess
import sys

SETUP = ("ip link set lo up && ip link set lo multicast on && "
         "ip route add 224.0.0.0/4 dev lo && exec \"$@\"")


def netns_available() -> bool:
    """Root, unshare and ip are here (CI runs as root), or we are inside one already."""
    if os.environ.get("NETNS_RUN_INSIDE") == "1":
        return True
    return (hasattr(os, "geteuid") and os.geteuid() == 0 and shutil.which("unshare") is not None
            and shutil.which("ip") is not None)


def run_in_netns(args: list[str], timeout_s: float, cwd: str) -> subprocess.CompletedProcess:
    """Run ``args`` in a fresh network namespace; returns the completed process."""
    if os.environ.get("NETNS_RUN_INSIDE") == "1":
        cmd = args
    else:
        cmd = ["unshare", "--net", "--", "sh", "-c", SETUP, "netns", *args]
    env = dict(os.environ, NETNS_RUN_INSIDE="1")
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout_s)


PYTHON = sys.executable
