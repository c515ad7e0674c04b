"""``tuav-sitl``: command-line entry point."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from tuavdefs.paramspec import ParameterError


def _load_system(args: argparse.Namespace):
    from tuavdefs.params import SystemParams
    from tuavdefs.paramspec import load_toml

    if args.params is None:
        return SystemParams()
    return load_toml(SystemParams, Path(args.params))


def _cmd_demo(args: argparse.Namespace) -> int:
    params = _load_system(args)
    from sitl.demo import run_open_loop_demo

    run_open_loop_demo(params, duration_s=args.duration, print_every_s=args.every,
                       position_m=tuple(args.position), out=sys.stdout)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``tuav-sitl``."""
    parser = argparse.ArgumentParser(
        prog="tuav-sitl",
        description="Software-in-the-loop simulator of a tethered quadrotor and its winder.")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser(
        "demo", help="open-loop run of the truth model from hover trim, printing the state",
        description="Start the UAV in hover trim on its tether (thrust balancing weight and "
                    "the catenary's pull, drum braked), then hold the trim commands open-loop "
                    "and print the state as the unstable equilibrium drifts away.")
    demo.add_argument("--duration", type=float, default=5.0, help="simulated seconds [s]")
    demo.add_argument("--every", type=float, default=0.5, help="print period [s]")
    demo.add_argument("--position", type=float, nargs=3, default=(5.0, 5.0, 20.0),
                      metavar=("X", "Y", "Z"), help="trim position, z-up frame [m]")
    demo.add_argument("--params", default=None,
                      help="TOML file with [environment] [vehicle] [tether] [winder] [wind]")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``tuav-sitl`` with ``argv``; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except ParameterError as exc:
        print(f"tuav-sitl: bad parameter: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
