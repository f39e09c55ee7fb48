"""``duallidar run RECORDING``: registered estimators on your own log or bag, in one line.

    duallidar run intel.clf.bz2 --truth intel-corrected.log.gz --estimators lidar_odometry slam
    duallidar run drive_bag/ --truth-topic /ground_truth --estimators lidar_odometry icp
    duallidar run aces.clf.bz2 --relations aces.relations --max-scans 1000

Reads the recording and its truth (:mod:`estimators.leaderboard.run_sources`), runs each
estimator over every scan and scores it (:mod:`estimators.leaderboard.single_run`), writes the
TUM trajectories, relation errors, ROS maps, figures, metrics and each estimator's input health
(:mod:`estimators.leaderboard.run_outputs`) and prints one table: the SE(2)-aligned ATE beside
the local relation errors, so an estimator that drifts shows at once, and the skipped and
frozen scans and clock jumps it met, so a faulty sensor shows too.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from estimators.arguments import non_negative_float, positive_float, positive_int
from estimators.registry import names

if TYPE_CHECKING:
    from estimators.leaderboard.run_sources import RunInput

DEFAULT_ESTIMATORS: tuple[str, ...] = ("lidar_odometry",)


def build_parser(prog: str = "duallidar run") -> argparse.ArgumentParser:
    """The ``duallidar run`` parser (every default shown in ``--help``)."""
    from estimators.leaderboard.run_sources import CLOCKS
    from estimators.leaderboard.single_run import DEFAULT_WINDOWS

    parser = argparse.ArgumentParser(
        prog=prog, formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        description="Run registered estimators over a recorded log or bag and score them on "
                    "its ground truth: TUM trajectories for evo, relation errors, the "
                    "SE(2)-aligned ATE, ms per scan, ROS maps and a figure per estimator.")
    parser.add_argument("recording", metavar="RECORDING", type=Path,
                        help="a CARMEN log (.clf/.log, plain, .gz or .bz2), a ROS 1/2 bag (.bag, "
                             ".db3, .mcap or a bag directory) or a leaderboard database "
                             "(.sqlite) holding a recorded simulated drive")
    parser.add_argument("--estimators", nargs="+", metavar="NAME",
                        default=list(DEFAULT_ESTIMATORS),
                        help=f"registered estimators to run, of: {', '.join(names())}")
    parser.add_argument("--out", type=Path, default=Path("run"),
                        help="output directory (one folder per estimator inside)")
    truth = parser.add_argument_group("ground truth (one of them; none: no scores)")
    given = truth.add_mutually_exclusive_group()
    given.add_argument("--truth", type=Path, metavar="FILE",
                       help="true poses: a TUM file (.tum/.txt: t x y z qx qy qz qw) or a "
                            "*-corrected CARMEN log (logger clock)")
    given.add_argument("--truth-topic", metavar="TOPIC",
                       help="a bag's nav_msgs/Odometry or geometry_msgs/PoseStamped topic")
    given.add_argument("--relations", type=Path, metavar="FILE",
                       help="relative true poses, one 't1 t2 x y z roll pitch yaw' per line "
                            "(Kümmerle et al. 2009); no ATE")
    truth.add_argument("--truth-tolerance", type=non_negative_float, metavar="SECONDS",
                       help="largest gap between a truth pose's stamp and its scan's [s]; "
                            "None: half the median scan period")
    truth.add_argument("--windows", nargs="+", type=positive_float, metavar="SECONDS",
                       default=list(DEFAULT_WINDOWS),
                       help="spans [s] of the longer relations between truth poses")
    reading = parser.add_argument_group("reading the recording")
    reading.add_argument("--topics", nargs="+", metavar="TOPIC",
                         help="a bag's LaserScan topics, Lidar 1 first; None: all")
    reading.add_argument("--clock", choices=CLOCKS,
                         help="a CARMEN log's clock; None: logger with --truth, else ipc")
    reading.add_argument("--scenario", metavar="LABEL",
                         help="the drive of a leaderboard database, e.g. hallway/zigzag/s0; "
                              "None: its only one")
    reading.add_argument("--max-scans", type=positive_int, metavar="N",
                         help="run on the first N scans only; None: all")
    output = parser.add_argument_group("output")
    output.add_argument("--map-resolution", type=positive_float, default=0.05, metavar="M",
                        help="cell size of the written maps [m]")
    output.add_argument("--no-figures", action="store_true",
                        help="skip the PNG figures")
    return parser


def _check(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    valid = names()
    for name in args.estimators:
        if name not in valid:
            parser.error(f"--estimators: unknown estimator {name!r}: expected one of "
                         f"{', '.join(valid)}")
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        probe = args.out / ".duallidar-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as error:
        parser.error(f"--out: {args.out} is not a writable directory ({error.strerror})")


def main(argv: Sequence[str] | None = None, prog: str = "duallidar run") -> int:
    """Run ``duallidar run``; returns the exit status (2 for bad input, 1 when an estimator
    failed)."""
    from estimators.leaderboard.run_sources import OptionError, load_run_input
    from lidar_env.core import DualLidarError

    parser = build_parser(prog)
    args = parser.parse_args(argv)
    _check(parser, args)
    start = time.perf_counter()
    print(f"reading {args.recording} ...", flush=True)
    try:
        run_input = load_run_input(
            args.recording, relations=args.relations, truth=args.truth,
            truth_topic=args.truth_topic, topics=args.topics, clock=args.clock,
            truth_tolerance=args.truth_tolerance, max_scans=args.max_scans,
            scenario=args.scenario)
    except OptionError as error:
        parser.error(str(error))
    except (DualLidarError, OSError) as error:
        parser.error(f"RECORDING or its truth: {error}")
    return _run_all(args, run_input, start)


def _run_all(args: argparse.Namespace, run_input: RunInput, start: float) -> int:
    from estimators.leaderboard.run_outputs import (
        ATE_NOTE,
        health_summary,
        metrics_row,
        summary_table,
        write_estimator_files,
        write_metrics,
    )
    from estimators.leaderboard.single_run import not_applicable, run_estimator, score_run

    recording = run_input.recording
    print(f"{run_input.name}: {len(recording)} scans of {recording.setup.n_lidars} Lidar(s); "
          f"truth: {run_input.truth_label}"
          + (f"; {run_input.truth.describe()}" if run_input.truth is not None else ""))
    for note in run_input.notes:
        print(f"note: {note}")
    rows, failed, no_figures = [], [], False
    for index, name in enumerate(args.estimators, start=1):
        if reason := not_applicable(name, run_input):
            rows.append({"estimator": name, "status": f"not run: {reason}"})
            continue
        print(f"[{index}/{len(args.estimators)}] {name}: running over {len(recording)} scans "
              "...", flush=True)
        try:
            run, health = run_estimator(name, run_input)
            scores = score_run(run_input, run, args.windows)
        except Exception as error:  # one estimator's failure does not stop the others
            failed.append(name)
            rows.append({"estimator": name, "status": f"failed: {type(error).__name__}: "
                                                      f"{error}"})
            continue
        files = write_estimator_files(args.out, name, run_input, run, scores,
                                      args.map_resolution, figure=not args.no_figures,
                                      health=health)
        no_figures |= not args.no_figures and "figure" not in files
        rows.append(metrics_row(name, run_input, run, scores, health=health))
        print(f"    {1e3 * run.seconds_per_scan:.2f} ms/scan; health: "
              f"{health_summary(rows[-1])}; files in {files['estimate'].parent}")
    json_path, _ = write_metrics(args.out, run_input, rows)
    scored = run_input.truth is not None or run_input.relations is not None
    windows = [f"{w:g} s" for w in args.windows] if run_input.truth is not None else []
    print()
    print(summary_table(rows, windows))
    if scored and run_input.truth is not None:
        print(ATE_NOTE)
    elif not scored:
        print("no truth given (--truth, --truth-topic or --relations): trajectories, maps and "
              "timing only")
    if no_figures:
        print("note: figures skipped: they need matplotlib (pip install 'duallidar[plots]')")
    print(f"done in {time.perf_counter() - start:.1f} s; metrics in {json_path} and "
          f"{json_path.with_suffix('.csv')}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
