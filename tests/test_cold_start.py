"""The first flight after an install: ``tuav-sitl up`` on an empty numba cache says that it
compiles, compiles every kernel the processes can call before its banner (its warm-up, the
manifest of tuavdefs/kernel_signatures.py), and no process compiles anything after it said
it was ready while the README's pymavlink snippet flies (numba's compile events, which
each process logs after its ready point: tuavdefs.jit.watch_compiles). One flight, in a
private network namespace (tests/netns/cold_start_session.py)."""

import pytest
from netns_util import netns_available, run_session

from tuavdefs import jit

pytestmark = [
    pytest.mark.skipif(not jit.JIT, reason="numba absent or TUAV_NO_JIT=1"),
    pytest.mark.skipif(not netns_available(), reason="needs a private network namespace"),
]

PROCESSES = ("plant", "companion", "groundstation")


@pytest.fixture(scope="module")
def cold(tmp_path_factory) -> dict:
    return run_session("tests.netns.cold_start_session",
                       str(tmp_path_factory.mktemp("cold-start")), timeout_s=900)


def _logs(out: dict) -> str:
    return "".join(f"\n--- {name}\n{text[-2000:]}" for name, text in out["logs"].items())


def test_up_says_it_compiles_and_compiles_before_its_banner(cold):
    err = cold["up_stderr"]
    assert "Ctrl-C stops all three" in cold["banner"], err + _logs(cold)
    assert "compiling the numba kernels" in err, err
    assert "compiling: plant" in err and "failed" not in err and "stale" not in err, err
    assert cold["cache_files"] > 0      # the processes' cache was the empty folder
    # the warm-up left nothing for the processes to compile before they were ready
    for name in PROCESSES:
        assert "compiling the numba kernels" not in cold["logs"][name], _logs(cold)


def test_no_kernel_compiles_after_the_processes_are_ready(cold):
    snippet = cold["snippet"]
    assert snippet["rc"] == 0, snippet["stdout"] + snippet["stderr"] + _logs(cold)
    assert "tether paid out" in snippet["stdout"]
    late = [line for name in PROCESSES for line in cold["logs"][name].splitlines()
            if jit.LATE_COMPILE in line]
    assert late == [], "\n".join(late)
