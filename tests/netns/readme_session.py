"""The README's Python snippets run as written against ``tuav-sitl up`` (its default ports:
this runs inside a private network namespace), one fresh stack each: the pymavlink one,
MAVSDK's native binding, MAVSDK-Python's gRPC API (``mavsdk_grpc``). Also the pymavlink
snippet's first lines (to the targets) on ten fresh connections while the winch's
heartbeats arrive too: whom pymavlink then addresses and which mode map it uses. Prints one
JSON line."""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

from tests.netns.up_session import processes_mentioning, up, wait_banner

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


def with_stack(logdir: Path, fn) -> dict:
    """``fn()`` against a fresh ``tuav-sitl up``; its result with up's exit and leftovers."""
    p = up(logdir, "--speedup", "3")
    banner = wait_banner(p)
    try:
        out = fn()
    finally:
        p.send_signal(signal.SIGINT)
        so, se = p.communicate(timeout=60)
    out["banner"] = banner
    out["up_rc"], out["up_stderr"] = p.returncode, se[-2000:]
    out["left"] = processes_mentioning(str(logdir))
    rc = out["rc"] if "rc" in out else out["full"]["rc"]
    if rc != 0:
        # a snippet that failed or hung: what each process said last (a rare hang of the
        # gRPC snippet left nothing else to go on)
        out["logs"] = {f.name: f.read_text(errors="replace")[-1500:]
                       for f in sorted(logdir.glob("up-*/*.log")) if f.name != "can.log"}
    return out


def main() -> int:
    base = Path(sys.argv[1])
    pym, native, grpc = python_blocks()
    head = pym.split("m.target_system, m.target_component = 1, 1\n", 1)[0]
    probe = head + (
        "m.target_system, m.target_component = 1, 1\n"
        "import json\n"
        "print(json.dumps([m.target_system, m.target_component,\n"
        "                  sorted((m.mode_mapping() or {}).items())]))\n")

    def pymavlink_runs() -> dict:
        heads = [run(probe, base / f"head{i}.py", 60) for i in range(10)]
        return {"heads": heads, "full": run(pym, base / "pymavlink_snippet.py", 300)}

    out = {"pymavlink": with_stack(base / "up-pymavlink", pymavlink_runs),
           "native": with_stack(base / "up-native",
                                lambda: run(native, base / "native_snippet.py", 300)),
           "grpc": with_stack(base / "up-grpc",
                              lambda: run(grpc, base / "grpc_snippet.py", 300))}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
