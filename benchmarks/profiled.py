"""``python -m benchmarks.profiled OUT -m MODULE [ARGS...]``: ``python -m cProfile -o OUT -m
MODULE ARGS...``, profiling only the part of the run between SIGUSR1 and SIGUSR2 (or the
end), so that a process's start-up and its wait for the others are left out.

The stack benchmark (:mod:`benchmarks.stack`) runs each process under it and signals them
when the flight begins and ends. The profile is written when the module returns or exits
(SystemExit), as cProfile's own command line does.
"""

from __future__ import annotations

import cProfile
import runpy
import signal
import sys


def main() -> int:
    """Run the module named after ``-m`` as ``__main__``; write the profile to OUT."""
    if len(sys.argv) < 4 or sys.argv[2] != "-m":
        print(__doc__, file=sys.stderr)
        return 2
    out, module, args = sys.argv[1], sys.argv[3], sys.argv[4:]
    prof = cProfile.Profile()
    signal.signal(signal.SIGUSR1, lambda *_: prof.enable())
    signal.signal(signal.SIGUSR2, lambda *_: prof.disable())
    sys.argv = [module, *args]
    code = 0
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        prof.disable()
        prof.dump_stats(out)
    return code


if __name__ == "__main__":
    sys.exit(main())
