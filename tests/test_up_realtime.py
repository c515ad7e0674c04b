"""``tuav-sitl up``'s scheduling in real time (tuav_sitl/up.py: ``_real_time``) on real
processes: the bus recorder at idle priority with or without ``--no-rt-priority``, the
plant, the companion and the ground station at SCHED_FIFO where permitted (root here, as
in CI), and left at normal scheduling with ``--no-rt-priority``."""

from __future__ import annotations

import os
import subprocess
import sys
import types

import pytest

from tuav_sitl.realtime import RT_PRIORITY
from tuav_sitl.up import _real_time

NAMES = ("plant", "companion", "groundstation")


@pytest.fixture
def stack():
    """Four sleeping processes standing for the three and the bus recorder."""
    procs = {name: subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
             for name in (*NAMES, "candump")}
    yield types.SimpleNamespace(procs={n: procs[n] for n in NAMES},
                                recorders={"candump": procs["candump"]})
    for p in procs.values():
        p.kill()
        p.wait()


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root here")
def test_real_time_gives_the_three_sched_fifo_and_the_recorder_idle(stack):
    assert _real_time(stack, True) == f"SCHED_FIFO priority {RT_PRIORITY}"
    for p in stack.procs.values():
        assert os.sched_getscheduler(p.pid) == os.SCHED_FIFO
        assert os.sched_getparam(p.pid).sched_priority == RT_PRIORITY
    assert os.sched_getscheduler(stack.recorders["candump"].pid) == os.SCHED_IDLE


def test_no_rt_priority_leaves_the_three_and_idles_the_recorder(stack):
    assert _real_time(stack, False).startswith("normal (--no-rt-priority")
    for p in stack.procs.values():
        assert os.sched_getscheduler(p.pid) == os.SCHED_OTHER
    assert os.sched_getscheduler(stack.recorders["candump"].pid) == os.SCHED_IDLE
