"""A new user's first flight: ``tuav-sitl up`` (real time, its defaults) from an empty
numba cache (``NUMBA_CACHE_DIR`` a fresh folder, for up, its warm-up and the three
processes), then the README's pymavlink snippet 5 s after the banner. Each process logs
every compilation after it said it was ready (``numba compiled after start-up``,
:func:`tuavdefs.jit.watch_compiles`). Run inside a private network namespace; prints one
JSON line: up's output, how long it took to its banner, the snippet's result and the
processes' logs."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.netns.readme_session import python_blocks, run

ROOT = Path(__file__).resolve().parents[2]
#: Wait after the banner before the snippet starts [s] (as the issue's user did).
AFTER_BANNER_S = 5.0


def main() -> int:
    base = Path(sys.argv[1])
    cache = base / "numba-cache"
    cache.mkdir(parents=True)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("TUAV_NO_JIT", None)
    env.pop("TUAV_JIT_INTERPRET", None)
    logdir = base / "up"
    err_path = base / "up.stderr"
    start = time.monotonic()
    with open(err_path, "w") as err:
        p = subprocess.Popen([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                              "--logdir", str(logdir)], cwd=ROOT, env=env, text=True,
                             stdout=subprocess.PIPE, stderr=err)
        banner: list[str] = []
        assert p.stdout is not None
        for line in p.stdout:
            banner.append(line)
            if "Ctrl-C stops all three" in line:
                break
        banner_s = time.monotonic() - start
        out: dict = {"banner": "".join(banner), "banner_s": banner_s}
        if p.poll() is None:
            time.sleep(AFTER_BANNER_S)
            out["snippet"] = run(python_blocks()[0], base / "pymavlink_snippet.py", 300)
            p.send_signal(signal.SIGINT)
        try:
            p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            p.communicate()
    out["up_rc"] = p.returncode
    # what a terminal shows of it: each line as its last carriage return left it
    out["up_stderr"] = "\n".join(line.rsplit("\r", 1)[-1]
                                 for line in err_path.read_text().split("\n"))
    out["logs"] = {f.stem: f.read_text(errors="replace")
                   for f in sorted(logdir.glob("up-*/*.log")) if f.name != "can.log"}
    out["cache_files"] = sum(1 for _ in cache.rglob("*.nbi"))
    out["total_s"] = time.monotonic() - start
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
