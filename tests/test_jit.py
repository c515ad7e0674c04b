"""The compile cache of tuavdefs.jit: a kernel is recompiled when a kernel it calls in
another module changes, and its key is the same in every process (else nothing would ever
be served from the cache)."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tuavdefs import jit

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not jit.JIT, reason="numba absent or TUAV_NO_JIT=1")

CALLEE = """
from tuavdefs.jit import njit
GAIN = {gain}
@njit
def scaled(x):
    return GAIN * x
"""
CALLER = """
from tuavdefs.jit import njit
from callee import scaled
@njit
def caller(x):
    return scaled(x) + 1.0
"""
RUN = """
import sys
sys.path[:0] = [{root!r}, {here!r}]
from caller import caller
print(caller(2.0), sum(caller.stats.cache_hits.values()))
"""


def _run(here: Path) -> tuple[float, int]:
    env = dict(os.environ)
    env.pop("TUAV_NO_JIT", None)
    res = subprocess.run([sys.executable, "-c", RUN.format(root=str(ROOT), here=str(here))],
                         capture_output=True, text=True, timeout=300, check=True, env=env)
    value, hits = res.stdout.split()
    return float(value), int(hits)


def test_a_kernel_follows_a_change_in_another_module(tmp_path):
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    (tmp_path / "caller.py").write_text(textwrap.dedent(CALLER))
    assert _run(tmp_path) == (5.0, 0)     # compiled
    assert _run(tmp_path) == (5.0, 1)     # served from the cache
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=3.0)))
    assert _run(tmp_path) == (7.0, 0)     # plain numba would serve the stale 5.0 here
    assert _run(tmp_path) == (7.0, 1)


DIGEST = """
from tuavdefs.jit import dependency_digest
from companion.flight_controller import flight_step
from sitl.plant import _rk4_step
print(dependency_digest(flight_step), dependency_digest(_rk4_step))
"""


def test_the_dependency_digest_is_the_same_in_every_process():
    outs = set()
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        res = subprocess.run([sys.executable, "-c", DIGEST], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=300, check=True)
        outs.add(res.stdout.strip())
    assert len(outs) == 1


REPORT = """
import json, sys
sys.path[:0] = [{root!r}, {here!r}]
from tuavdefs import jit
from callee import scaled
before = jit.is_cached(scaled)
names = []
jit.on_compile(lambda name, seconds: names.append(name))
value = scaled(2.0)
print(json.dumps([jit.JIT, before, jit.is_cached(scaled), names, value]))
"""


def _report(here: Path, **env_extra: str) -> list:
    env = dict(os.environ, **env_extra)
    env.pop("TUAV_NO_JIT", None)
    res = subprocess.run([sys.executable, "-c", REPORT.format(root=str(ROOT), here=str(here))],
                         capture_output=True, text=True, timeout=300, check=True, env=env)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_is_cached_and_on_compile_tell_a_compile_from_a_cache_load(tmp_path):
    """A cold kernel: not cached, its compilation reported; in the next process it loads
    from the cache (is_cached before the call) and nothing is reported. A change to the
    source makes it cold again."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    assert _report(tmp_path) == [True, False, True, ["callee.scaled"], 4.0]
    assert _report(tmp_path) == [True, True, True, [], 4.0]
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=3.0)))
    assert _report(tmp_path) == [True, False, True, ["callee.scaled"], 6.0]


def test_an_interpreted_package_stays_python_and_jit_says_so(tmp_path):
    """TUAV_JIT_INTERPRET=callee: the kernel is the plain function (nothing to compile,
    nothing cached) and JIT is False, so no caller counts on machine code."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    assert _report(tmp_path, TUAV_JIT_INTERPRET="callee") == [False, True, True, [], 4.0]
    assert not (tmp_path / "__pycache__").is_dir() or not any(
        p.suffix == ".nbi" for p in (tmp_path / "__pycache__").iterdir())


# --- the manifest of the argument types kernels are called with, and loading it ----------

def test_every_entry_of_the_manifest_is_a_kernel_with_its_argument_count():
    """Each name of tuavdefs/kernel_signatures.py is a kernel made by njit (in a module
    that imports), each signature parses back to the text it was written as and has as
    many types as the function has parameters."""
    import inspect

    entries = jit.manifest()
    assert {name.partition(".")[0] for name in entries} >= {"sitl", "companion",
                                                           "groundstation"}
    for name, sigs in entries.items():
        kernel = jit.find_kernel(name)
        assert kernel is not None, f"{name}: no such kernel (python -m tuav_sitl.kernel_manifest)"
        params = inspect.signature(kernel.py_func).parameters
        assert sigs, name
        for texts in sigs:
            assert len(texts) == len(params), (name, texts)
            assert jit.signature_text(jit.parse_signature(texts)) == texts


#: The declared entry points: (module, kernel, its Signature's name).
DECLARED = (("companion.flight_controller", "flight_step", "STEP_SIGNATURE"),
            ("companion.flight_controller", "flight_commands", "STEP_SIGNATURE"),
            ("sitl.plant", "advance_kernel", "ADVANCE_SIGNATURE"),
            ("sitl.plant", "_truth_kernel", "TRUTH_SIGNATURE"),
            ("sitl.plant", "specific_force_kernel", "SPECIFIC_FORCE_SIGNATURE"),
            ("sitl.tether", "tether_forces_kernel", "SOLVE_SIGNATURE"),
            ("sitl.batch", "batch_kernel", "BATCH_SIGNATURE"),
            ("sitl.sensors", "channel_step", "CHANNEL_STEP_SIGNATURE"))


def test_each_declared_signature_is_the_manifests_entry_as_written():
    """A kernel's declared signature (tuavdefs.jit.Signature) is written in the manifest's
    own spelling (it reads back to the same texts), has a type for each parameter, and is
    the manifest's entry for that kernel: what load_kernels makes machine code before a
    process is ready is what its entry point asks for."""
    import importlib
    import inspect

    entries = jit.manifest()
    for module, kernel_name, sig_name in DECLARED:
        mod = importlib.import_module(module)
        kernel, sig = getattr(mod, kernel_name), getattr(mod, sig_name)
        assert isinstance(sig, jit.Signature)
        assert len(sig) == len(inspect.signature(kernel.py_func).parameters), kernel_name
        assert jit.signature_text(sig.types()) == tuple(sig), kernel_name
        assert tuple(sig) in entries.get(f"{module}.{kernel_name}", ()), (
            f"{module}.{kernel_name}: python -m tuav_sitl.kernel_manifest")


def test_type_texts_read_back_as_the_types():
    import numpy as np
    from numba.core.typing.typeof import Purpose, typeof

    ro = np.zeros(3)
    ro.flags.writeable = False
    for value in (1.0, 3, True, np.float32(1.0), np.zeros(4), np.zeros((2, 3)),
                  np.zeros((4, 3))[:, 0], np.zeros((2, 3)).T, np.zeros(2, np.uint8), ro,
                  (1.0, 2.0), (1.0, np.zeros(3), False)):
        ty = typeof(value, Purpose.argument)
        assert jit.parse_type(jit.type_text(ty)) == ty
    assert jit.type_text(typeof(np.zeros((2, 3)), Purpose.argument)) == "float64[:, ::1]"


CALLER_OF_TWO = """
from tuavdefs.jit import njit
from callee import scaled
@njit
def caller(x):
    return scaled(x) + scaled(2 * x)
"""
RECORD = """
import sys
sys.path[:0] = [{root!r}, {here!r}]
from caller import caller
from callee import scaled
caller(1.5)
scaled(3)
"""


def test_recording_keeps_the_calls_from_python_not_those_from_kernels(tmp_path):
    """TUAV_JIT_RECORD: caller(float64) and scaled(int64) were called from Python;
    scaled(float64) only from inside caller's machine code, which brings it along."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    (tmp_path / "caller.py").write_text(textwrap.dedent(CALLER_OF_TWO))
    env = dict(os.environ, TUAV_JIT_RECORD=str(tmp_path / "rec"),
               NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("TUAV_NO_JIT", None)
    subprocess.run([sys.executable, "-c", RECORD.format(root=str(ROOT), here=str(tmp_path))],
                   env=env, capture_output=True, text=True, timeout=300, check=True)
    (record,) = (tmp_path / "rec").glob("*.json")
    assert json.loads(record.read_text()) == {"callee.scaled": [["int64"]],
                                              "caller.caller": [["float64"]]}


LOAD = """
import json, sys
sys.path[:0] = [{root!r}, {here!r}]
from tuavdefs import jit
report = jit.load_kernels(["callee", "caller"], sys.stdout, "proc", signatures={{
    "caller.caller": [["float64"]], "callee.scaled": [["int64"]],
    "callee.gone": [["float64"]], "callee.scaled_": [["float64", "float64"]]}})
jit.watch_compiles("proc", sys.stdout)
from caller import caller
from callee import scaled
caller(1.5), scaled(3)          # loaded: nothing compiles
scaled(True)                    # a type the manifest lacks: compiles, after start-up
print(json.dumps([report.signatures, report.compiled, len(report.failures)]))
"""


def test_load_kernels_compiles_then_loads_and_late_compiles_are_told(tmp_path):
    """On an empty cache load_kernels compiles the manifest's signatures and says so; in the
    next process it loads them silently; a call with types the manifest lacks compiles
    after watch_compiles and is logged; unknown names and a wrong argument count are
    failures, not errors."""
    (tmp_path / "callee.py").write_text(textwrap.dedent(CALLEE.format(gain=2.0)))
    (tmp_path / "caller.py").write_text(textwrap.dedent(CALLER_OF_TWO))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("TUAV_NO_JIT", None)
    script = LOAD.format(root=str(ROOT), here=str(tmp_path))

    def run() -> list[str]:
        return subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, timeout=300, check=True).stdout.splitlines()

    first = run()
    assert first[0].startswith("proc: compiling the numba kernels missing from the cache")
    assert first[1].startswith("proc: compiled ")
    assert [ln for ln in first if jit.LATE_COMPILE in ln] == [
        ln for ln in first if ln.startswith(f"proc: numba {jit.LATE_COMPILE}: callee.scaled")]
    assert len([ln for ln in first if jit.LATE_COMPILE in ln]) == 1
    assert json.loads(first[-1])[0] == 2 and json.loads(first[-1])[2] == 2
    second = run()      # (the bool call too is in the cache now)
    assert len(second) == 1 and json.loads(second[-1]) == [2, 0, 2], second


#: Scenarios whose flights call every kernel the others do and more (the lumped line in a
#: gust, a mission on the tether fix without GNSS, a hover through a GNSS loss on the
#: drag fusion and the raw tether reading fused tightly).
MANIFEST_SCENARIOS = ("gust-lumped", "mission-gnss-denied", "hover-gnss-loss-windy")


def test_the_manifest_has_every_signature_these_scenarios_call():
    """Flown to their ends with TUAV_JIT_RECORD, these scenarios call no kernel with types
    missing from tuavdefs/kernel_signatures.py (python -m tuav_sitl.kernel_manifest
    regenerates it from all shipped scenarios)."""
    from tuav_sitl import kernel_manifest

    recorded = kernel_manifest.fly(MANIFEST_SCENARIOS)
    assert {n.partition(".")[0] for n in recorded} >= {"sitl", "companion", "groundstation"}
    assert kernel_manifest.missing(recorded, jit.manifest()) == []
