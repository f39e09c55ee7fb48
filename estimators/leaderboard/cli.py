"""The leaderboard: every registered estimator on the paper's scenarios, Table I and Fig. 8.

``duallidar leaderboard`` (also ``duallidar-leaderboard`` or ``python -m estimators.leaderboard``)
records each scenario of
the matrix once into the experiment database (:mod:`estimators.leaderboard.database`), replays
it through every estimator (:mod:`estimators.leaderboard.runner`), scores it
(:mod:`estimators.evaluation.metrics`) and writes

* ``leaderboard.md`` / ``leaderboard.csv``: estimators ranked by mean ATE over all simulated
  scenarios (eq. 11 ignores direction, so it cannot rank alone), with eq.-11 accuracy, heading
  RMSE, drift, ms/step, the scores of the map the estimator's poses yield (occupied-cell IoU,
  precision and recall at 10 cm cells and one cell of tolerance; cylinder recall and centre
  error where the world has cylinders; :func:`estimators.leaderboard.recording.score_map`), one
  column per scenario group and the real-log relation error;
* ``results.csv``: one row per estimator and scenario;
* ``table1.md`` / ``table1.csv``: the paper's Table I, our figures beside the printed ones, in
  two columns: *world-aligned* scans, the paper's own setting (its phase correlation estimates
  translation only, and its simulation hands it scans in world axes, so rotations never enter
  its images: the group scenarios are recorded a second time with ``scan_frame="world"`` and
  replayed through the paper's three estimators only, those of them ``--estimators`` selects,
  always driven by the scripted driver, outside the ranking), and the
  leaderboard's *sensor-frame* scans, where the paper's method cannot see the car turn;
* ``fig8_lidar_image.png`` (an eq.-5 Lidar image) and ``fig8_traces.png`` (per group, the true
  trace and every estimator's trace over the world map);
* ``maps.png``: the true map next to the occupancy maps built at the poses of the best-ranked
  estimator and of the paper's (``pc_pg``), in the first group with cylinders;
* ``failures.txt`` when an estimator raised (the others still run). An estimator that needs
  more Lidars than a log has (``pc_offset``, ``pc_pg`` on the one-laser ACES log:
  :attr:`estimators.base.Estimator.min_lidars`) is not run there and shows "n/a (needs 2
  Lidars)"; that is no failure.

The real-log column is the first 1,000 scans of the Radish ACES log when it is there, or the
user's own CARMEN log or ROS bag (``--real-log``, :mod:`estimators.leaderboard.real_logs`).
Re-running with the same database skips everything already stored.

Cost grows as scenarios x steps x estimators. The default matrix (5 groups x 2 seeds, the
paper's full traces and the hallway out-and-back: 3,638 steps, plus the first 1,000 ACES scans)
costs, in CPU time, about 20 ms per step for all ten estimators together (``pc_fusion`` 4.8 ms,
``slam`` 2.9 ms, the rest 0-2.6 ms), about 5 ms per step for the map scores of all ten (the grid
and the obstacle tracker on every scan) and 3 s for the per-scenario map truths; Table I's
world-aligned copies of the six group scenarios add 2,108 steps through the three paper
estimators. About 126 CPU-seconds in all: 66 s on two free cores. The summary line prints the
workers' time per stage and their CPU time, so a slow run can be told apart from a busy machine.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from agents.driver import DRIVERS
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.file_names import safe_file_name
from estimators.leaderboard.headline import annotate_rows, board_markdown
from estimators.leaderboard.matrix import (
    DEFAULT_NOISE,
    DEFAULT_SEEDS,
    MOVER_GROUPS,
    PAPER_DRIVER,
    PAPER_ESTIMATORS,
    Group,
    build_groups,
    side_scenarios,
    table_one_scenarios,
)
from estimators.leaderboard.publish import draw_all, publish_report, terminal_summary
from estimators.leaderboard.real_logs import RealLog, add_real_log_arguments, real_logs_from
from estimators.leaderboard.records import Scenario, TraceRecord, package_version
from estimators.leaderboard.runner import (
    RunCancelled,
    RunInterrupted,
    RunSummary,
    SideRun,
    run_matrix,
)
from estimators.leaderboard.schema import DatabaseError
from estimators.leaderboard.table_one import table_one, table_one_markdown
from estimators.leaderboard.tables import (
    RANK_KEYS,
    current_records,
    map_ceiling_note,
    rank_table,
    write_csv,
)
from estimators.leaderboard.tasks import STAGES, EstimatorSpec
from estimators.leaderboard.warmup import marker_path, warm_up
from estimators.leaderboard.workers import process_pool
from estimators.paths import SHARED_DATA
from estimators.registry import names
from lidar_env import lidars_with_noise
from lidar_env.core import DualLidarError

DATA_DIR = SHARED_DATA / "radish"
#: Scans of the ACES log replayed by default: the first ~2 minutes of the 7,374, enough for a
#: few hundred ground-truth relations while keeping the default run within a minute.
DEFAULT_REAL_SCANS = 1000


class OutputDirectoryError(OSError):
    """The output directory cannot be created or written."""


def _parser(prog: str = "duallidar leaderboard") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Rank every registered estimator on recorded DualLidar-v0 scenarios, "
                    "reproduce the paper's Table I and draw its Fig. 8.",
    )
    parser.add_argument("--worlds", nargs="+", metavar="WORLD",
                        help="worlds to run (default: the paper's groups plus the straight "
                        "and out-and-back hallway drives)")
    parser.add_argument("--traces", nargs="+", metavar="TRACE",
                        help="trace seeds, crossed with --worlds (default: the paper's pairs)")
    parser.add_argument("--moving-obstacles", action="store_true",
                        help="also run the paper's groups with pedestrians walking through "
                        "them, scoring the moving-obstacle tracker too")
    parser.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS),
                        help="env seeds per scenario (default: %(default)s)")
    parser.add_argument("--driver", choices=sorted(DRIVERS), default="scripted",
                        help="who drives the recorded scenarios (default: %(default)s)")
    parser.add_argument("--estimators", nargs="+", metavar="NAME",
                        help="estimators to rank (default: every registered one)")
    parser.add_argument("--noise", type=float, default=DEFAULT_NOISE,
                        help="range noise std [m] (default: %(default)s, as in Table I)")
    parser.add_argument("--db", type=Path, default=None,
                        help="experiment database (default: OUT/experiments.sqlite)")
    parser.add_argument("--out", type=Path, default=Path("leaderboard"),
                        help="output directory (default: %(default)s)")
    parser.add_argument("--workers", type=int, default=2,
                        help="worker processes, parallel over scenarios; 1 = this process "
                             "(default: %(default)s)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the scenarios on this Dask scheduler (e.g. tcp://host:8786) "
                             "instead of local worker processes; needs dask.distributed")
    parser.add_argument("--rank-by", choices=sorted(RANK_KEYS), default="ate",
                        help="metric that orders the table (default: %(default)s)")
    parser.add_argument("--tum", action="store_true",
                        help="also write every trace of the run and its ground truth as TUM "
                             "files (OUT/tum/), for evo")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_real_log_arguments(parser)
    return parser


def _check_names(parser: argparse.ArgumentParser, kind: str, given: Sequence[str],
                 valid: Sequence[str]) -> None:
    for name in given:
        if name not in valid:
            parser.error(f"unknown {kind} {name!r}: expected one of {', '.join(valid)}")


def check_output_dir(out: Path) -> None:
    """Create ``out`` if needed and prove it writable, before any work is done."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as error:
        raise OutputDirectoryError(
            f"output directory {out} is not writable ({error.strerror}); "
            "choose another --out"
        ) from error


def _executor(args: argparse.Namespace) -> Any:
    """A Dask client when ``--scheduler`` is given, else a local process pool (``None`` for
    one worker: run in this process)."""
    if args.scheduler:
        from distributed import Client

        return Client(args.scheduler)
    return process_pool(args.workers) if args.workers > 1 else None


def export_tum_files(db: ExperimentDatabase, records: dict[tuple[Scenario, str], TraceRecord],
                     directory: Path) -> Path:
    """``<scenario>_<estimator>.tum`` per trace and ``<scenario>_truth.tum`` per simulated
    scenario in ``directory``, named by :func:`safe_file_name` (no ``?``, ``&``, ``=`` or
    ``/``); returns it."""
    directory.mkdir(exist_ok=True)
    for (scenario, estimator), record in records.items():
        stem = safe_file_name(scenario.label)
        db.export_tum(record.trace_id, directory / f"{stem}_{estimator}.tum")
        if scenario.kind == "sim" and not (directory / f"{stem}_truth.tum").exists():
            db.export_truth_tum(scenario, directory / f"{stem}_truth.tum")
    return directory


def _progress(total: int, label: str, enabled: bool) -> Any:
    """A bar of scenarios done on stderr, when ``enabled`` and stderr is a terminal (a log file
    gets no carriage-return frames)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit="scenario", disable=None if enabled else True,
                leave=False)


def main(argv: Sequence[str] | None = None, prog: str = "duallidar leaderboard") -> int:
    """Run the leaderboard; returns the exit status (2 for bad input). ``prog`` names the
    command in usage lines (``duallidar-leaderboard`` is the same command)."""
    from lidar_env.routes import TRACE_NAMES
    from lidar_env.world import WORLD_NAMES

    parser = _parser(prog)
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # the report's command line
    _check_names(parser, "world", args.worlds or [], WORLD_NAMES)
    _check_names(parser, "trace", args.traces or [], TRACE_NAMES)
    estimator_names = args.estimators or names()
    _check_names(parser, "estimator", estimator_names, names())
    if not estimator_names:
        parser.error("no estimators are registered")
    if args.workers < 1:
        parser.error(f"--workers: expected an integer >= 1, got {args.workers}")
    if bad_seeds := [seed for seed in args.seeds if not 0 <= seed < 2**32]:
        parser.error(f"--seeds: expected integers in 0 .. 2**32 - 1 (env seeds), got {bad_seeds}")
    if not math.isfinite(args.noise) or args.noise < 0:
        parser.error(f"--noise: expected a range noise std >= 0 [m], got {args.noise}")
    if args.scheduler:
        try:
            import distributed  # noqa: F401
        except ImportError:
            parser.error("--scheduler needs dask.distributed: pip install 'duallidar[distributed]'")
    try:
        args.logs = real_logs_from(args, DATA_DIR, DEFAULT_REAL_SCANS)
    except (DualLidarError, OSError) as error:
        parser.error(str(error))
    start = time.perf_counter()
    try:
        check_output_dir(args.out)
        db = ExperimentDatabase(args.db or args.out / "experiments.sqlite")
    except (OutputDirectoryError, DatabaseError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    try:
        with db:
            groups = build_groups(args.worlds, args.traces)
            groups += list(MOVER_GROUPS) if args.moving_obstacles else []
            return _run(args, db, groups,
                        [EstimatorSpec(name) for name in estimator_names], start)
    except KeyboardInterrupt as error:  # Ctrl-C: one line, not a traceback; 130 = 128 + SIGINT
        print(error if isinstance(error, RunCancelled) else "interrupted; re-run to resume",
              file=sys.stderr)
        return 130
    except DatabaseError as error:  # damaged, edited, locked or full: one line, no traceback
        print(f"error: {error}", file=sys.stderr)
        return 2
    except OSError as error:  # an output file (disk full, quota, removed directory)
        print(f"error: could not write {error.filename or args.out} ({error.strerror or error}); "
              "everything stored in the database is intact: free space or choose another "
              "--out and re-run (stored work is not redone)", file=sys.stderr)
        return 2


def _run_on_executor(args: argparse.Namespace, db: ExperimentDatabase, every: list[Scenario],
                     logs: list[RealLog], specs: list[EstimatorSpec],
                     world_aligned: SideRun) -> RunSummary | None:
    """Run the matrix on the executor ``--workers``/``--scheduler`` ask for (:func:`_executor`:
    the worker pool is created here and shut down after); None if the run was interrupted."""
    executor = _executor(args)
    try:
        if isinstance(executor, ProcessPoolExecutor) and (
            seconds := warm_up(executor, tuple(spec.name for spec in specs),
                               progress=not args.no_progress)
        ):
            print(f"compiled the numba kernels in {seconds:.0f} s (cached: later runs skip it)"
                  if marker_path().exists() else "the kernels did not all compile: each run "
                  "compiles what it uses on first use, and reports any failure itself")
        tasks = len(every) + len(world_aligned.scenarios) + len(logs) * len(specs)
        with _progress(tasks, "scenarios", not args.no_progress) as bar:
            return run_matrix(db, every, logs, specs, executor, side_runs=[world_aligned],
                              on_done=lambda _: bar.update())
    except RunInterrupted as error:
        print(f"error: {error}", file=sys.stderr)
        return None
    finally:
        if isinstance(executor, ProcessPoolExecutor):
            executor.shutdown(cancel_futures=True)
        elif executor is not None:
            executor.close()  # a Dask client: disconnect, the cluster stays up


def _write_tables(args: argparse.Namespace, groups: list[Group],
                  scenarios: dict[str, list[Scenario]], specs: list[EstimatorSpec],
                  records: dict[tuple[Scenario, str], TraceRecord], logs: list[RealLog],
                  table_i_runs: dict[str, Any]) -> tuple[list[Path], list[dict[str, Any]]]:
    """Write the leaderboard (.md, .csv), results.csv and Table I (.md, .csv);
    returns the files written and the ranked rows."""
    real = logs[0].scenario if logs else None
    not_applicable = {spec.name: reason for spec in specs
                      if logs and (reason := spec.not_applicable(logs[0].n_lidars))}
    rows = rank_table(groups, scenarios, specs, records, real, RANK_KEYS[args.rank_by],
                      not_applicable)
    rows = annotate_rows(rows, groups, scenarios, records, RANK_KEYS[args.rank_by])
    out: Path = args.out
    table = board_markdown(rows, groups, logs[0].name.upper() if real else None, args.rank_by)
    table += map_ceiling_note(records)
    case_rows = table_one(table_i_runs, records)
    written = [out / "leaderboard.md", out / "leaderboard.csv", out / "results.csv"]
    (out / "leaderboard.md").write_text(
        f"# duallidar leaderboard (ranked by {args.rank_by}; noise {args.noise} m; seeds "
        f"{', '.join(map(str, args.seeds))})\n\n{table}")
    write_csv(out / "leaderboard.csv", rows)
    write_csv(out / "results.csv", [
        {"estimator": name, "kind": scenario.kind, "world": scenario.world,
         "trace": scenario.trace, "seed": scenario.seed,
         "scan_frame": scenario.config.get("scan_frame", "sensor"), **record.metrics}
        for (scenario, name), record in records.items()
    ])
    if table_i_runs["sensor"]:
        table_i = table_one_markdown(case_rows)
        (out / "table1.md").write_text(
            f"# Table I: eq.-11 accuracy, paper vs ours (noise {args.noise} m; seeds "
            f"{', '.join(map(str, args.seeds))}; driver {args.driver}, world-aligned runs "
            f"{PAPER_DRIVER})\n\n{table_i}")
        write_csv(out / "table1.csv", case_rows)
        written += [out / "table1.md", out / "table1.csv"]
    else:
        print("note: Table I skipped: the run holds none of the paper's world/trace pairs")
    return written, rows


def _run(args: argparse.Namespace, db: ExperimentDatabase, groups: list[Group],
         specs: list[EstimatorSpec], start: float) -> int:
    configs = {g.name: {**dict(g.config), "lidars": lidars_with_noise(
        dict(g.config), range_noise_std=args.noise)} for g in groups}
    scenarios = {g.name: [Scenario(g.world, g.trace, seed, configs[g.name], args.driver)
                          for seed in args.seeds]
                 for g in groups}
    logs = args.logs
    if not logs and not args.no_real:
        print(f"note: real-log results skipped: {DATA_DIR} has no ACES log and relations")
    table_i_runs = table_one_scenarios(groups, scenarios, specs)
    world_aligned = SideRun(
        side_scenarios(table_i_runs),
        tuple(spec for spec in specs if spec.name in PAPER_ESTIMATORS))
    every = [s for group in groups for s in scenarios[group.name]]
    summary = _run_on_executor(args, db, every, logs, specs, world_aligned)
    if summary is None:
        return 1

    reporting = time.perf_counter()
    records = current_records(db.traces(poses=False), specs, package_version())
    out: Path = args.out
    written, rows = _write_tables(args, groups, scenarios, specs, records, logs, table_i_runs)
    try:
        written += draw_all(db, groups, scenarios, records, specs, rows, logs, out,
                            workers=1 if args.scheduler else args.workers)
    except ImportError as error:
        print(f"note: figures skipped ({error}); install the plots extra: "
              "pip install 'duallidar[plots]'")
    written.append(publish_report(out, written, vars(args), args.argv))
    if args.tum:
        written.append(export_tum_files(db, records, out / "tum"))
    print(terminal_summary(out, written))
    failures = summary.failures
    if failures:
        (out / "failures.txt").write_text(
            "".join(f"== {stage}\n{error}\n" for stage, error in failures.items()))
        written.append(out / "failures.txt")
        print(f"note: {len(failures)} estimator runs failed: {', '.join(sorted(failures))}")
    else:  # a failures.txt of an earlier run in this directory no longer holds
        (out / "failures.txt").unlink(missing_ok=True)
    if summary.not_applicable:
        print("note: not applicable, so not run: " + ", ".join(
            f"{stage} ({reason})" for stage, reason in sorted(summary.not_applicable.items())))
    done = summary.recorded, summary.traces
    skipped = summary.skipped
    stages = summary.stage_seconds
    print("worker time: " + ", ".join(f"{stage} {stages[stage]:.1f} s" for stage in STAGES
                                       if stage in stages)
          + f"; workers' CPU time {summary.cpu_seconds:.1f} s; tables and figures "
            f"{time.perf_counter() - reporting:.1f} s")
    side = (f" + {len(world_aligned.estimators)} x {len(world_aligned.scenarios)} world-aligned "
            "for Table I" if world_aligned.scenarios else "")
    print(f"leaderboard: {len(specs)} estimators x {len(every)} scenarios{side}"
          f"{' + ' + str(len(logs)) + ' real log' if logs else ''} in "
          f"{time.perf_counter() - start:.1f} s ({done[0]} recorded, {done[1]} traces new, "
          f"{skipped} already stored); database {db.path}; files in {out}/: "
          f"{', '.join(p.name for p in written)}")
    unrecorded = [stage for stage in failures if stage.endswith(": record")]
    if unrecorded:  # an estimator may legitimately not apply; a scenario must record
        print(f"error: {len(unrecorded)} scenarios could not be recorded (see failures.txt)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
