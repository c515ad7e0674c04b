"""``tuav-sitl``: command-line entry point."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from tuav_sitl.sweep_keep import DEFAULT_KEEP
from tuavdefs.params import TetherModel
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


def _cmd_run(args: argparse.Namespace) -> int:
    from tuav_sitl.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if args.tether_model is not None:
        scenario = scenario.with_tether_model(args.tether_model)
    if args.duration is not None:
        scenario = scenario.replace(duration_s=args.duration)
    from tuav_sitl.offline import run_scenario
    from tuav_sitl.warmup import compile_if_cold, report_compiles

    out = Path(args.out) if args.out else Path("runs") / scenario.name
    print(f"tuav-sitl run {scenario.name}: {scenario.description}")
    progress = None if args.quiet else sys.stderr
    compile_if_cold(progress)
    stop_reports = report_compiles(progress)
    try:
        result = run_scenario(scenario, out, progress=progress,
                              recording=not args.no_recording)
    finally:
        stop_reports()
    m = result.metrics
    print(f"wrote {out}/timeseries.npz, metrics.json, scenario.toml")
    if not args.no_figures:
        from tuav_sitl.render import draw_run

        drawn = draw_run(out, animation=not args.no_animation,
                         progress=None if args.quiet else sys.stderr)
        print(f"wrote {len(drawn.figures)} figures in {out}/figures")
        if drawn.animation:
            print("wrote " + ", ".join(str(a) for a in drawn.animation))
    if not args.no_recording:
        _report_recording(result.recording, out)
    keys = ["position_rmse_m", "position_max_error_m", "attitude_rmse_rad",
            "tether_length_rmse_m", "min_tether_slack_m", "max_tension_n",
            "motor_saturation_fraction", "settling_time_s", "overshoot_percent",
            "sim_time_s", "wall_time_s", "realtime_factor"]
    for k in keys:
        v = m.get(k)
        print(f"  {k:28s} {v:.6g}" if isinstance(v, float) else f"  {k:28s} {v}")
    return 0


def _report_recording(job, out: Path) -> None:
    """Wait for a run's recording.rrd (written beside the figures) and say where it is."""
    from tuav_sitl.view import INSTALL_HINT

    if job is None:
        print(f"  no recording.rrd: {INSTALL_HINT}")
    elif job.wait():
        print(f"wrote {job.path} (tuav-sitl view {out})")
    else:
        print(f"tuav-sitl: the recording {job.path} could not be written", file=sys.stderr)


def _cmd_view(args: argparse.Namespace) -> int:
    from tuav_sitl.view.open import open_run

    return open_run(Path(args.run_dir), web=args.web, web_port=args.web_port,
                    grpc_port=args.grpc_port)


def _cmd_plot(args: argparse.Namespace) -> int:
    from tuav_sitl.render import draw_run
    from tuav_sitl.run_import import RunImportError, import_up_run, needs_import

    run_dir = Path(args.run_dir)
    if needs_import(run_dir):   # a 'tuav-sitl up' run folder: truth.csv, flight.tlog, ...
        try:
            imported = import_up_run(run_dir)
        except (RunImportError, OSError) as exc:
            print(f"tuav-sitl plot: cannot import the up run {run_dir}: {exc}",
                  file=sys.stderr)
            return 2
        used = ", ".join(imported.metrics["imported_from"])
        print(f"imported the 'tuav-sitl up' run from {used}: wrote "
              + ", ".join(str(p) for p in imported.written))
        for note in imported.notes:
            print(f"  note: {note}")
    if not (run_dir / "timeseries.npz").is_file():
        print(f"tuav-sitl plot: {run_dir} has no timeseries.npz (a 'tuav-sitl run' folder) "
              "nor truth.csv (a 'tuav-sitl up' folder)", file=sys.stderr)
        return 2
    from tuav_sitl.warmup import report_compiles

    stop_reports = report_compiles(None if args.quiet else sys.stderr)
    try:
        drawn = draw_run(run_dir, animation=not args.no_animation,
                         progress=None if args.quiet else sys.stderr)
    finally:
        stop_reports()
    print(f"wrote {len(drawn.figures)} figures in {run_dir}/figures")
    for note in drawn.skipped:
        print(f"  skipped {note}")
    for a in drawn.animation:
        print(f"wrote {a}")
    return 0


def _cmd_results(args: argparse.Namespace) -> int:
    from tuav_sitl.results import checkout_results_path, write_results

    out = Path(args.out) if args.out is not None else checkout_results_path()
    if out is None:
        print("tuav-sitl results: give --out FILE: this package is installed, not run from "
              "a source checkout, so it has no docs/results.md to write", file=sys.stderr)
        return 2
    out, runs = out.resolve(), Path(args.runs).resolve()
    print(f"tuav-sitl results: writing {out} (figures in {out.parent / 'figures'}), the run "
          f"folders in {runs}")
    if args.sweeps:
        from tuav_sitl.results import run_sweeps

        run_sweeps(runs, figures=not args.no_figures)
    from tuav_sitl.warmup import compile_if_cold

    progress = None if args.quiet else sys.stderr
    compile_if_cold(progress)   # here, not in each pool process
    metrics = write_results(out, runs, figures=not args.no_figures, progress=progress)
    print(f"wrote {out} from {len(metrics)} runs in {runs}")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from tuav_sitl.sweep import load_sweep, run_sweep
    from tuav_sitl.sweep_summary import summary_text

    sweep, scenario = load_sweep(args.sweep)
    if args.runs is not None:
        if args.runs < 1:
            raise ParameterError("--runs", f"must be >= 1, got {args.runs}")
        sweep = sweep.replace(runs=args.runs)
    if args.workers is not None and args.workers < 1:
        raise ParameterError("--workers", f"must be >= 1, got {args.workers}")
    if args.keep < 0:
        raise ParameterError("--keep", f"must be >= 0, got {args.keep}")
    out = Path(args.out) if args.out else Path("sweeps") / sweep.name
    where = args.scheduler or f"a LocalCluster of {args.workers or 'one worker per core'}"
    print(f"tuav-sitl sweep {sweep.name}: {sweep.runs} runs of {scenario.name} on {where}")
    rows, summary = run_sweep(sweep, scenario, out, scheduler=args.scheduler,
                           workers=args.workers,
                           progress=None if args.quiet else sys.stderr)
    print(summary_text(summary))
    print(f"wrote {out}/runs.csv, runs.json, summary.json, summary.md")
    if not args.no_figures:
        from tuav_sitl.sweep_figures import make_sweep_figures

        figs = make_sweep_figures(sweep, rows, out)
        print("wrote " + ", ".join(str(f) for f in figs))
    if args.keep:
        from tuav_sitl.sweep_keep import keep_runs

        for folder in keep_runs(sweep, scenario, rows, out, args.keep):
            print(f"kept a failed run: {folder} (tuav-sitl view {folder})")
    return 0


def _cmd_candump(args: argparse.Namespace) -> int:
    from tuav_sitl.candump import run_candump

    return run_candump(args)


def _cmd_up(args: argparse.Namespace) -> int:
    from tuav_sitl.up import run_up

    return run_up(args)


def _cmd_bench(args: argparse.Namespace) -> int:
    """``tuav-sitl bench``: ``python -m benchmarks`` (a package installed with this one)."""
    from benchmarks.__main__ import main as bench_main

    return bench_main([*(["--quick"] if args.quick else []),
                       *(["--no-processes"] if args.no_processes else [])])


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

    from tuav_sitl.scenario import shipped_scenarios

    run = sub.add_parser(
        "run", help="run an experiment offline (plant and controllers in one process)",
        description="Run a scenario with the plant, the onboard controllers and the winder "
                    "controller in one process, as fast as the machine allows; write the time "
                    "series, metrics.json, the figures and an animation. Shipped scenarios: "
                    + ", ".join(sorted(shipped_scenarios())) + ".")
    run.add_argument("scenario", help="a shipped scenario name or a scenario TOML file")
    run.add_argument("--out", default=None, help="output folder (default runs/NAME)")
    run.add_argument("--duration", type=float, default=None,
                     help="override the scenario's simulated time [s]")
    run.add_argument("--tether-model", default=None,
                     choices=tuple(m.value for m in TetherModel),
                     help="the plant's truth line, lumped or catenary (default: the "
                          "scenario's, [tether] model; lumped where it names none)")
    run.add_argument("--no-figures", action="store_true", help="skip figures and animation")
    run.add_argument("--no-animation", action="store_true", help="skip the animation")
    run.add_argument("--no-recording", action="store_true",
                     help="skip recording.rrd (the Rerun recording 'tuav-sitl view' opens)")
    run.add_argument("--quiet", action="store_true",
                     help="no progress (simulation, figures, animation frames)")
    run.set_defaults(func=_cmd_run)

    plot = sub.add_parser(
        "plot", help="draw the figures and animation of a run folder",
        description="Draw the figures and the animation of a run folder of 'tuav-sitl run', "
                    "or of 'tuav-sitl up': its truth.csv, params.toml, flight.tlog and "
                    "can.log are first imported into timeseries.npz, metrics.json and "
                    "scenario.toml (figures that need data the run does not have are "
                    "skipped with a note).")
    plot.add_argument("run_dir", help="a folder written by 'tuav-sitl run' or 'tuav-sitl up'")
    plot.add_argument("--no-animation", action="store_true", help="skip the animation")
    plot.add_argument("--quiet", action="store_true", help="no progress")
    plot.set_defaults(func=_cmd_plot)

    view = sub.add_parser(
        "view", help="open a run folder's recording.rrd in Rerun's viewer",
        description="Open the recording of a run folder (recording.rrd, written by "
                    "'tuav-sitl run', 'tuav-sitl up' and the runs a sweep keeps) in Rerun's "
                    "native viewer, or with --web serve Rerun's web viewer on a localhost "
                    "URL it prints (until Ctrl-C). A 'tuav-sitl run' folder without one "
                    "gets it written first. Needs the optional extra 'view' (rerun-sdk).")
    view.add_argument("run_dir", help="a run folder (or a .rrd file)")
    view.add_argument("--web", action="store_true",
                      help="serve the web viewer on http://127.0.0.1:PORT instead")
    view.add_argument("--web-port", type=int, default=9090,
                      help="the web viewer's HTTP port (with --web; default 9090)")
    view.add_argument("--grpc-port", type=int, default=9876,
                      help="the port the recording is served on to the viewer (default 9876)")
    view.set_defaults(func=_cmd_view)

    from tuav_sitl.results import checkout_results_path

    checkout = checkout_results_path()
    res = sub.add_parser(
        "results", help="run every shipped experiment and write the results file "
                        "(docs/results.md of the source checkout)",
        description="Run all shipped scenarios in parallel, write their run folders, copy "
                    "the main figures next to the results file and write the metrics table "
                    "against the targets. It says where it writes before it starts.")
    res.add_argument("--out", default=None,
                     help="the Markdown file to write (default: "
                          + (f"{checkout}, the source checkout's, wherever this is run)"
                             if checkout is not None else
                             "none: this package is installed, not run from a source "
                             "checkout; required)"))
    res.add_argument("--runs", default="runs",
                     help="folder for the run folders (default: runs, in the current folder)")
    res.add_argument("--no-figures", action="store_true", help="metrics only")
    res.add_argument("--quiet", action="store_true", help="no progress")
    res.add_argument("--sweeps", action="store_true",
                     help="also run the shipped sweeps (tuav-sitl sweep; long) into "
                          "RUNS/sweeps; without, the summaries found there are included")
    res.set_defaults(func=_cmd_results)

    from tuav_sitl.sweep import shipped_sweeps

    sweep = sub.add_parser(
        "sweep", help="Monte Carlo over a scenario on Dask (drawn truth, wind, sensors)",
        description="Run a sweep file's runs (each an offline run of its scenario with drawn "
                    "plant parameters, wind, sensors and seeds) on Dask distributed; write "
                    "the table of drawn values and metrics (runs.csv as runs finish, "
                    "runs.json) and the summary (failure rate against the targets, "
                    "percentiles, what the failures correlate with). An interrupted sweep "
                    "resumes where it stopped (docs/usage.md#tuav-sitl-sweep). Shipped "
                    "sweeps: " + ", ".join(sorted(shipped_sweeps())) + ".")
    sweep.add_argument("sweep", help="a shipped sweep name or a sweep TOML file")
    sweep.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                       help="an existing Dask cluster's scheduler (default: a LocalCluster)")
    sweep.add_argument("--workers", type=int, default=None,
                       help="the LocalCluster's worker processes (default: one per core)")
    sweep.add_argument("--runs", type=int, default=None, help="override the run count")
    sweep.add_argument("--out", default=None, help="output folder (default sweeps/NAME)")
    sweep.add_argument("--keep", type=int, default=DEFAULT_KEEP, metavar="N",
                       help="fly the N failed runs with the largest position error again "
                            "into OUT/runs/run-INDEX/ as run folders with their "
                            f"recording.rrd (default {DEFAULT_KEEP}; 0: none)")
    sweep.add_argument("--quiet", action="store_true", help="no progress bar")
    sweep.add_argument("--no-figures", action="store_true",
                       help="skip the figures (CDFs, failures against the drawn parameters)")
    sweep.set_defaults(func=_cmd_sweep)

    from tuav_sitl.up import add_arguments

    up = sub.add_parser(
        "up", help="start the plant, companion and ground station as three processes",
        description="Start the three processes, wait until each is ready, print where to "
                    "connect, keep their logs and the truth series in a run folder, and stop "
                    "all of them on Ctrl-C or when one exits.")
    add_arguments(up)
    up.set_defaults(func=_cmd_up)

    from tuav_sitl.candump import add_arguments as candump_arguments

    dump = sub.add_parser("candump", help="print the live winder CAN bus as candump does",
                          description="Print every frame on the winder's bus in can-utils' "
                                      "candump formats (default or -L), line-buffered.")
    candump_arguments(dump)
    dump.set_defaults(func=_cmd_candump)

    bench = sub.add_parser(
        "bench", help="run every benchmark and print one table (python -m benchmarks)",
        description="Run every benchmark (tether solve vs MoorPy, plant step, offline closed "
                    "loop, sweep throughput on Dask, the three processes in lockstep and in "
                    "real time, latencies) and print one table of medians and same-run "
                    "ratios, each goal beside its measurement (docs/performance.md).")
    bench.add_argument("--quick", action="store_true",
                       help="each benchmark once in a tiny configuration")
    bench.add_argument("--no-processes", action="store_true",
                       help="skip the benchmarks of the three processes")
    bench.set_defaults(func=_cmd_bench)
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
