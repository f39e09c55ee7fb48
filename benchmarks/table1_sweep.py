"""Table I against feature density: the paper's method and ours in the closed areas, from bare
walls to walls as rich in edges as the open area.

Run: ``python -m benchmarks.table1_sweep [--densities 0 0.5 1 2 4 8] [--seeds 0 1 2]
[--workers 2] [--db leaderboard/table1_sweep.sqlite] [--figure docs/table1_sweep.png]``
(the figure needs matplotlib; an SVG is written beside the PNG).

The paper's closed (``hallway``, narrow-broad-narrow) and closed-to-open (``closed_to_open``)
areas, driven along the paper's zigzag, with door recesses, pillars, corners and clutter at each
feature density [features per 10 m of wall] (:mod:`lidar_env.world.feature_worlds`); each seed draws
both the range noise (1 cm) and the features' placement (``feature_seed`` = the env seed). Every
scenario is recorded once, world-aligned (the paper's setting) and sensor-frame, into an
experiment database and replayed through ``pc``, ``pc_offset``, ``pc_pg`` and ``lidar_odometry``
by the leaderboard's runner (a re-run resumes; the stored version carries the source digest).

Prints the mean ± std eq.-11 accuracy per (area, frame, estimator, density) and the density at
which each of the paper's estimators first reaches its Table I figure (linear between the
densities swept; "not reached" when it never does). The figure has one panel per area and frame,
one line per estimator with a ± 1 std band over the seeds, and the paper's Table I values as
horizontal marks.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.matrix import DEFAULT_NOISE, PAPER_DRIVER, TABLE_I, TABLE_I_FRAMES
from estimators.leaderboard.records import Scenario, TraceRecord, package_version
from estimators.leaderboard.runner import SideRun, run_matrix
from estimators.leaderboard.tables import current_records
from estimators.leaderboard.tasks import EstimatorSpec
from lidar_env import lidars_with_noise
from lidar_env.world.feature_worlds import feature_world_name

#: The two closed areas of Table I (the open area has its features already).
AREAS: tuple[str, ...] = ("hallway", "closed_to_open")
TRACE = "zigzag"
DENSITIES: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)
SEEDS: tuple[int, ...] = (0, 1, 2)
ESTIMATORS: tuple[str, ...] = ("pc", "pc_offset", "pc_pg", "lidar_odometry")
COLOURS = {"pc": "tab:green", "pc_offset": "tab:brown", "pc_pg": "tab:blue",
           "lidar_odometry": "tab:red"}
#: The paper's method, whose closed-area figure sets the density of the leaderboard's column.
PAPER_METHOD = "pc_pg"


def sweep_scenarios(densities: Sequence[float], seeds: Sequence[int],
                    areas: Sequence[str] = AREAS) -> list[Scenario]:
    """Every (area, density, seed, scan frame) scenario; the features are placed from the seed."""
    return [Scenario(feature_world_name(area, density, seed), TRACE, seed,
                     {"lidars": lidars_with_noise(range_noise_std=DEFAULT_NOISE),
                      "scan_frame": frame}, PAPER_DRIVER)
            for area in areas for density in densities for seed in seeds
            for frame in TABLE_I_FRAMES]


def summarise(scenarios: Sequence[Scenario], densities: Sequence[float],
              records: Mapping[tuple[Scenario, str], TraceRecord],
              areas: Sequence[str] = AREAS) -> list[dict[str, Any]]:
    """One row per (area, frame, estimator, density): mean and std [%] of the eq.-11 accuracy
    over the seeds that ran, their number, and the mean ATE [m]."""
    rows = []
    for area in areas:
        for frame in TABLE_I_FRAMES:
            for estimator in ESTIMATORS:
                for density in densities:
                    names = {feature_world_name(area, density, s.seed) for s in scenarios}
                    runs = [records[(s, estimator)].metrics for s in scenarios
                            if s.world in names and s.config["scan_frame"] == frame
                            and (s, estimator) in records]
                    accuracy = [m["accuracy_percent"] for m in runs]
                    rows.append({
                        "area": area, "frame": frame, "estimator": estimator,
                        "density": float(density), "seeds": len(runs),
                        "accuracy_mean": float(np.mean(accuracy)) if runs else math.nan,
                        "accuracy_std": float(np.std(accuracy)) if runs else math.nan,
                        "ate_m": float(np.mean([m["ate_rmse_m"] for m in runs]))
                        if runs else math.nan,
                    })
    return rows


def crossing(densities: Sequence[float], values: Sequence[float], target: float) -> float:
    """The lowest density [features per 10 m] at which ``values`` reach ``target``, linear
    between neighbouring densities; NaN when they never do (no extrapolation)."""
    points = [(d, v) for d, v in zip(densities, values, strict=True) if math.isfinite(v)]
    for i, (density, value) in enumerate(points):
        if value >= target:
            if i == 0:
                return density
            (d0, v0) = points[i - 1]
            return d0 + (target - v0) / (value - v0) * (density - d0)
    return math.nan


def paper_targets(area: str) -> dict[str, float]:
    """{estimator: the paper's Table I accuracy [%]} in ``area``'s cases."""
    return {case.estimator: case.paper_accuracy for case in TABLE_I if case.world == area}


def crossings(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (area, frame, paper estimator): the density where the paper's figure is reached."""
    found = []
    for area in AREAS:
        for frame in TABLE_I_FRAMES:
            for estimator, target in paper_targets(area).items():
                line = [r for r in rows if (r["area"], r["frame"], r["estimator"])
                        == (area, frame, estimator)]
                if not line:
                    continue
                density = crossing([r["density"] for r in line],
                                   [r["accuracy_mean"] for r in line], target)
                found.append({"area": area, "frame": frame, "estimator": estimator,
                              "paper_percent": target, "density": density})
    return found


def print_table(rows: Sequence[dict[str, Any]], densities: Sequence[float]) -> None:
    """The sweep as text: one line per (area, frame, estimator), one column per density."""
    print(f"{'area':15s} {'frame':14s} {'estimator':15s} "
          + " ".join(f"{f'd={d:g}':>13s}" for d in densities))
    for area in AREAS:
        for frame, title in TABLE_I_FRAMES.items():
            for estimator in ESTIMATORS:
                line = [r for r in rows if (r["area"], r["frame"], r["estimator"])
                        == (area, frame, estimator)]
                cells = [f"{r['accuracy_mean']:6.1f}±{r['accuracy_std']:5.1f}"
                         if r["seeds"] else f"{'n/a':>12s}" for r in line]
                if line:
                    print(f"{area:15s} {title:14s} {estimator:15s} " + " ".join(
                        f"{c:>13s}" for c in cells))


def draw(rows: Sequence[dict[str, Any]], path: Path) -> list[Path]:
    """Accuracy vs density, one panel per (frame, area), bands of ± 1 std; PNG and SVG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = list(TABLE_I_FRAMES)
    figure, axes = plt.subplots(len(frames), len(AREAS), figsize=(12, 8.5), sharex=True,
                                sharey=True, squeeze=False)
    for i, frame in enumerate(frames):
        for j, area in enumerate(AREAS):
            axis = axes[i, j]
            for estimator in ESTIMATORS:
                line = [r for r in rows if (r["area"], r["frame"], r["estimator"])
                        == (area, frame, estimator) and r["seeds"]]
                if not line:
                    continue
                x = np.array([r["density"] for r in line])
                mean = np.array([r["accuracy_mean"] for r in line])
                std = np.array([r["accuracy_std"] for r in line])
                colour = COLOURS[estimator]
                axis.plot(x, mean, "o-", color=colour, label=estimator, linewidth=1.6)
                axis.fill_between(x, mean - std, np.minimum(mean + std, 100.0), color=colour,
                                  alpha=0.18, linewidth=0)
            for estimator, target in paper_targets(area).items():
                axis.axhline(target, color=COLOURS[estimator], linestyle="--", linewidth=1.0,
                             label=f"paper Table I, {estimator}")
            axis.set_title(f"{area} + {TRACE}, {TABLE_I_FRAMES[frame]} scans")
            axis.set_ylim(-3, 103)
            axis.grid(alpha=0.3)
            if i == len(frames) - 1:
                axis.set_xlabel("feature density [features per 10 m of wall]")
            if j == 0:
                axis.set_ylabel("eq.-11 accuracy [%]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="center left", bbox_to_anchor=(0.83, 0.5), fontsize=9)
    figure.tight_layout(rect=(0, 0, 0.82, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    written = [path, path.with_suffix(".svg")]
    for target in written:
        figure.savefig(target, dpi=150)
    plt.close(figure)
    return written


def run(db_path: Path, scenarios: Sequence[Scenario], workers: int
        ) -> dict[tuple[Scenario, str], TraceRecord]:
    """Record and replay what the database lacks (no map scores); the current records."""
    specs = tuple(EstimatorSpec(name) for name in ESTIMATORS)
    db_path.parent.mkdir(parents=True, exist_ok=True)
    with ExperimentDatabase(db_path) as db:
        executor = ProcessPoolExecutor(workers) if workers > 1 else None
        try:
            summary = run_matrix(db, (), (), specs, executor,
                                 side_runs=[SideRun(tuple(scenarios), specs)])
        finally:
            if executor is not None:
                executor.shutdown(cancel_futures=True)
        print(f"{summary.recorded} scenarios recorded, {summary.traces} traces new, "
              f"{summary.skipped} already stored; workers' CPU time {summary.cpu_seconds:.0f} s")
        for stage, error in summary.failures.items():
            print(f"failed: {stage}: {error.splitlines()[-1] if error else ''}", file=sys.stderr)
        return current_records(db.traces(poses=False), specs, package_version())


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--densities", type=float, nargs="+", default=list(DENSITIES),
                        help="feature densities [features per 10 m of wall]")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--db", type=Path, default=Path("leaderboard/table1_sweep.sqlite"))
    parser.add_argument("--figure", type=Path, default=Path("docs/table1_sweep.png"))
    args = parser.parse_args(argv)
    densities = sorted(set(args.densities))
    scenarios = sweep_scenarios(densities, args.seeds)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}; {len(scenarios)} scenarios "
          f"({len(AREAS)} areas x {len(densities)} densities x {len(args.seeds)} seeds x "
          f"{len(TABLE_I_FRAMES)} frames), {len(ESTIMATORS)} estimators, {args.workers} workers")
    start = time.perf_counter()
    records = run(args.db, scenarios, args.workers)
    rows = summarise(scenarios, densities, records)
    print(f"swept in {time.perf_counter() - start:.0f} s; eq.-11 accuracy [%], mean ± std over "
          f"seeds {', '.join(map(str, args.seeds))}:")
    print_table(rows, densities)
    print("density [features per 10 m of wall] where the paper's Table I figure is reached:")
    for found in crossings(rows):
        where = (f"{found['density']:.2f}" if math.isfinite(found["density"])
                 else f"not reached up to {densities[-1]:g}")
        marker = "  <- the paper's method, closed area" if (
            found["estimator"], found["area"], found["frame"]) == (
            PAPER_METHOD, AREAS[0], "world") else ""
        print(f"  {found['area']:15s} {TABLE_I_FRAMES[found['frame']]:14s} "
              f"{found['estimator']:10s} paper {found['paper_percent']:.2f} %: {where}{marker}")
    try:
        for path in draw(rows, args.figure):
            print(f"saved {path}")
    except ImportError as error:
        print(f"note: figure skipped ({error}); install matplotlib")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
