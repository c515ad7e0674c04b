"""``python -m benchmarks.profiled OUT -m MODULE [ARGS...]`` (or ``OUT SCRIPT.py
[ARGS...]``): ``python -m cProfile -o OUT -m MODULE ARGS...``, profiling only the part of
the run between SIGUSR1 and SIGUSR2 (or the end), so that a process's start-up and its wait
for the others are left out.

The stack benchmark (:mod:`benchmarks.stack`) runs each process under it (and the mission
client, a script) and signals them when the flight begins and ends. The profile is written
when the module or script returns or exits (SystemExit), as cProfile's own command line
does.
"""

from __future__ import annotations

import cProfile
import runpy
import signal
import sys


def main() -> int:
    """Run the module named after ``-m``, or the script, as ``__main__``; write the profile
    to OUT."""
    if len(sys.argv) >= 4 and sys.argv[2] == "-m":
        out, target, args, is_module = sys.argv[1], sys.argv[3], sys.argv[4:], True
    elif len(sys.argv) >= 3 and sys.argv[2] != "-m":
        out, target, args, is_module = sys.argv[1], sys.argv[2], sys.argv[3:], False
    else:
        print(__doc__, file=sys.stderr)
        return 2
    prof = cProfile.Profile()
    signal.signal(signal.SIGUSR1, lambda *_: prof.enable())
    signal.signal(signal.SIGUSR2, lambda *_: prof.disable())
    sys.argv = [target, *args]
    code = 0
    try:
        if is_module:
            runpy.run_module(target, run_name="__main__", alter_sys=True)
        else:
            runpy.run_path(target, run_name="__main__")
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        prof.disable()
        prof.dump_stats(out)
    return code


if __name__ == "__main__":
    sys.exit(main())
