"""Real-log benchmark: Lidar-only estimators on ACES (Kümmerle relations) and Intel
(SLAM-corrected poses as pseudo ground truth), with ms/scan and the real-time factor.

    python benchmarks/bench_real_logs.py                      # icp and lidar_odometry, full logs
    python benchmarks/bench_real_logs.py --limit 1500 --estimators lidar_odometry
    python benchmarks/bench_real_logs.py --estimators lidar_odometry --set reject_dynamic=true
    python benchmarks/bench_real_logs.py --estimators lidar_odometry --set moving_filter.radius=0.4

No estimator reads odometry. ``icp`` (scan-to-previous-scan PL-ICP from a constant-velocity
guess) is the reference every ratio is measured against, in the same run on the same machine.
ms/scan is CPU time (``time.process_time``) per scan, the real-time factor the log's median
scan interval over it. Intel's logger clock runs backwards 631 times, which the estimators
refuse: they are fed the stamps made to run forward
(``estimators.datasets.real_log.forward_clock``: a stamp that jumps back is moved 1 us past its
predecessor) and scored on the logged ones.
``--set NAME=VALUE`` (a number, ``true``/``false``) passes parameters to every estimator but
the reference; a dotted NAME sets one key of a mapping parameter (``moving_filter.radius=0.4``;
``frontend_params.moving_filter.radius=0.4`` for ``slam``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from typing import Any

from bench_layouts import parameter

from estimators import make
from estimators.datasets.carmen import CarmenLog, load_log
from estimators.datasets.real_log import (
    LogRun,
    forward_clock,
    pseudo_truth_relations,
    run_on_log,
    score_relations,
)
from estimators.evaluation.relations import load_relations, relation_errors
from estimators.paths import SHARED_DATA

DATA = SHARED_DATA / "radish"
REFERENCE = "icp"
#: Published mean translational errors, ACES, all relations (SOURCE.md in the data folder).
PUBLISHED_ACES = (
    "Kümmerle 2009 scan matching 0.173 m; graph mapping 0.044 m; "
    "Cartographer (Hess 2016) 0.0375 m / 0.373 deg (all relations, with loop closure); "
    "PL-ICP given wheel odometry 0.036 m / 0.32 deg (local)"
)
#: Intel pseudo ground-truth poses come from SLAM with a few cm of error of their own.
INTEL_WINDOWS: tuple[float | None, ...] = (None, 1.0, 5.0)


def estimator_params(settings: list[tuple[str, object]]) -> dict[str, Any]:
    """``--set`` pairs as keyword parameters, a dotted name as nested mappings:
    ``[("moving_filter.radius", 0.4)]`` -> ``{"moving_filter": {"radius": 0.4}}``."""
    params: dict[str, Any] = {}
    for name, value in settings:
        *outer, last = keys = name.split(".")
        if not all(keys):
            raise argparse.ArgumentTypeError(f"--set {name}: expected NAME or NAME.KEY, "
                                             "with no empty part")
        group = params
        for key in outer:
            group = group.setdefault(key, {})
            if not isinstance(group, dict):
                break
        if not isinstance(group, dict) or isinstance(group.get(last), dict):
            raise argparse.ArgumentTypeError(f"--set {name}: expected each NAME set either "
                                             "to a value or key by key, not both")
        group[last] = value
    return params


def _line(name: str, label: str, summary: object, run: LogRun) -> str:
    return (
        f"  {name:15s} {label:12s} {summary}  "
        f"{1e3 * run.seconds_per_scan:6.2f} ms/scan CPU, {run.realtime_factor:6.1f}x real time"
    )


def _cpu_run(name: str, log: CarmenLog, clock: str, limit: int | None,
             params: dict[str, object]) -> LogRun:
    """``run_on_log`` with the CPU time per scan in place of its wall time; ``params`` go to
    every estimator but the reference."""
    start = time.process_time()
    run = run_on_log(make(name, **({} if name == REFERENCE else params)), log, clock=clock,
                     limit=limit)
    return dataclasses.replace(run, seconds_per_scan=(time.process_time() - start)
                               / max(len(run.times), 1))


def _forward(log: CarmenLog) -> CarmenLog:
    """The log with its logger stamps made to run forward (see the module docstring)."""
    stamps = forward_clock(log.scan_times("logger"))
    return dataclasses.replace(log, scans=[dataclasses.replace(scan, logger_timestamp=t)
                                           for scan, t in zip(log.scans, stamps, strict=True)])


def bench_aces(names: list[str], limit: int | None, params: dict[str, object]) -> None:
    log = load_log(DATA / "aces.clf.bz2")
    relations = load_relations(DATA / "aces.relations")
    print(f"ACES ({len(log.scans) if limit is None else limit} scans), Kümmerle relations:")
    print(f"  published: {PUBLISHED_ACES}")
    reference_ms = None
    for name in names:
        run = _cpu_run(name, log, "ipc", limit, params)
        scores = score_relations(run, relations)
        for subset in ("local", "all"):
            print(_line(name, f"{subset}:", scores[subset], run))
        reference_ms = run.seconds_per_scan if name == REFERENCE else reference_ms
        if reference_ms is not None and name != REFERENCE:
            print(f"  {name}: {run.seconds_per_scan / reference_ms:.2f}x the time of {REFERENCE}")


def bench_intel(names: list[str], limit: int | None, params: dict[str, object]) -> None:
    log = load_log(DATA / "intel.clf.bz2")
    reference = pseudo_truth_relations(load_log(DATA / "intel-corrected.log.gz"), INTEL_WINDOWS)
    print(
        f"Intel ({len(log.scans) if limit is None else limit} scans) vs intel-corrected.log.gz "
        "(PSEUDO ground truth: SLAM output, keyframes ~0.6 m apart):"
    )
    forward = _forward(log)
    logged = log.scan_times("logger")
    for name in names:
        run = _cpu_run(name, forward, "logger", limit, params)
        run = dataclasses.replace(run, times=logged[: len(run.times)])
        for label, relations in reference.items():
            inside = relations.select(
                (relations.t1 >= run.times[0]) & (relations.t2 <= run.times[-1] + 0.01)
            )
            # The corrected log prints 6 significant digits: 10 ms covers its rounding.
            summary = relation_errors(run.times, run.poses, inside, tolerance=0.01).summary()
            print(_line(name, f"{label}:", summary, run))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--estimators", nargs="+", default=[REFERENCE, "lidar_odometry"])
    parser.add_argument("--limit", type=int, default=None, help="first N scans of each log")
    parser.add_argument("--logs", nargs="+", default=["aces", "intel"], choices=["aces", "intel"])
    parser.add_argument("--set", type=parameter, nargs="+", default=[], metavar="NAME=VALUE",
                        help="estimator parameters over their defaults (not for the reference)")
    args = parser.parse_args()
    try:
        params = estimator_params(args.set)
    except argparse.ArgumentTypeError as error:
        parser.error(str(error))
    if params:
        print(f"parameters of every estimator but {REFERENCE}: {params}")
    if not DATA.is_dir():
        raise SystemExit(f"real logs not found: expected them in {DATA}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"python {platform.python_version()}")
    if "aces" in args.logs:
        bench_aces(args.estimators, args.limit, params)
    if "intel" in args.logs:
        bench_intel(args.estimators, args.limit, params)


if __name__ == "__main__":
    main()
