"""A fingerprint of every shipped scenario's offline series, for restructuring commits.

``python -m tuav_sitl.series_digest [--seconds S] [--out F] [--compare F] [NAME ...]``
flies each scenario offline for ``S`` simulated seconds (all of it with ``--seconds 0``)
and prints one SHA-256 per scenario over its series (names, dtypes and bytes, in name
order) and its events. A commit that only moves code leaves every digest unchanged;
``--compare`` names the scenarios whose digest moved and exits 1 if any did.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import load_scenario, shipped_scenarios


def scenario_digest(name: str, seconds_s: float) -> str:
    """The SHA-256 (hex) of scenario ``name``'s series and events over ``seconds_s``
    simulated seconds (its whole duration when ``seconds_s`` is 0)."""
    sc = load_scenario(name)
    if seconds_s > 0.0:
        duration_s = min(sc.duration_s, seconds_s)
        sc = sc.replace(duration_s=duration_s,
                        metrics_after_s=min(sc.metrics_after_s, 0.5 * duration_s))
    res = OfflineRunner(sc).run()
    h = hashlib.sha256()
    for key in sorted(res.series):
        arr = np.ascontiguousarray(res.series[key])
        h.update(key.encode())
        h.update(str(arr.dtype).encode())
        h.update(arr.tobytes())
    h.update(repr([tuple(e) for e in res.events]).encode())
    return h.hexdigest()


def main(argv: list[str] | None = None) -> int:
    """Print (and optionally save or compare) the digests; 1 if a compared one moved."""
    ap = argparse.ArgumentParser(prog="python -m tuav_sitl.series_digest",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help="scenarios (default: every shipped one)")
    ap.add_argument("--seconds", type=float, default=20.0,
                    help="simulated seconds per scenario; 0 = its whole duration")
    ap.add_argument("--out", type=Path, help="write the digests to this JSON file")
    ap.add_argument("--compare", type=Path, help="compare with digests saved by --out")
    args = ap.parse_args(argv)
    names = args.names or sorted(shipped_scenarios())
    digests = {}
    for name in names:
        digests[name] = scenario_digest(name, args.seconds)
        print(f"{digests[name]}  {name}", flush=True)
    if args.out:
        args.out.write_text(json.dumps(digests, indent=1) + "\n")
    if args.compare:
        before = json.loads(args.compare.read_text())
        moved = [n for n in names if n in before and before[n] != digests[n]]
        for n in moved:
            print(f"moved: {n}", file=sys.stderr)
        return 1 if moved else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
