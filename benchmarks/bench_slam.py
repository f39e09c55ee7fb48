"""Graph SLAM (``slam``) against its own front end, on real logs and in simulation.

* ACES: Kümmerle relations (all 1,279 and the local ones), front end vs ``slam`` from the
  same run (``slam.odometry_trajectory`` is the front end's own output), with the real-time
  factor of the whole pipeline on one core.
* Intel: relations from ``intel-corrected.log.gz`` (PSEUDO ground truth: another SLAM's poses).
* Simulation: ``DualLidar-v0`` ``loop`` and ``out_and_back`` traces in every built-in world,
  seeds 0 and 1, driven by the scripted pure-pursuit driver: end-point error and ATE of the
  front end and of ``slam``, the ATE floor the front end's motion between keyframes leaves,
  how many of the keyframes that revisit a place got a loop edge, and (``--closure-draws``)
  the ATE ratio the same graph reaches on average with exact loop edges if the front end's
  keyframe steps erred independently: what loop closure can do on that drive at best.

    python benchmarks/bench_slam.py                    # everything (~5 min on one core)
    python benchmarks/bench_slam.py --parts aces sim   # a subset
    python benchmarks/bench_slam.py --parts sim --traces loop --seeds 0 --closure-draws 100
    python benchmarks/bench_slam.py --parts sim --seeds 0 1 2 3 4   # 40 runs: is slam never worse?
    python benchmarks/bench_slam.py --parts sim --noise 0.03   # a noisier Lidar
    python benchmarks/bench_slam.py --parts aces --set min_overlap_separation=10.0   # loops only
    python benchmarks/bench_slam.py --limit 2000       # first 2000 scans of each log
    python benchmarks/bench_slam.py --parts aces sim --render docs/   # + map pictures

Published ACES figures (mean translational error, all relations): scan matching 0.173 m,
graph mapping 0.044 m, Cartographer 0.0375 m / 0.373 deg.
"""

from __future__ import annotations

import argparse
import ast
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimators import make
from estimators.datasets.carmen import load_log
from estimators.datasets.real_log import (
    LogRun,
    pseudo_truth_relations,
    run_on_log,
    score_relations,
)
from estimators.evaluation.relations import load_relations, relation_errors
from estimators.paths import SHARED_DATA
from estimators.slam.graph_slam import GraphSlam
from estimators.slam.pose_graph import PoseGraph
from estimators.slam.solver import optimize
from lidar_env import lidars_with_noise
from lidar_env.core.se2 import compose, relative

DATA = SHARED_DATA / "radish"
WORLDS = ("open_cylinders", "hallway", "closed_to_open", "random")


def _runs(slam: GraphSlam, run: LogRun) -> dict[str, LogRun]:
    """The front end's and the smoothed trajectory of one ``slam`` run."""
    return {
        f"{slam.frontend} (front end)": LogRun(run.times, slam.odometry_trajectory,
                                               run.seconds_per_scan),
        "slam": run,
    }


def _unreachable(slam: GraphSlam) -> int:
    """Verified matches refused by the reachability gate (``loop_gate``)."""
    return sum("unreachable" in result.reason for _, _, result in slam.loop_attempts)


def bench_aces(limit: int | None, params: dict[str, Any], render: Path | None) -> None:
    log = load_log(DATA / "aces.clf.bz2")
    relations = load_relations(DATA / "aces.relations")
    slam = make("slam", **params)
    assert isinstance(slam, GraphSlam)
    run = run_on_log(slam, log, limit=limit)
    print(f"ACES ({len(run.times)} scans), Kümmerle relations; published all: scan matching "
          "0.173 m, graph mapping 0.044 m, Cartographer 0.0375 m / 0.373 deg")
    for name, each in _runs(slam, run).items():
        scores = score_relations(each, relations)
        print(f"  {name:28s} local: {scores['local']}")
        print(f"  {'':28s} all:   {scores['all']}")
    print(f"  slam: {1e3 * run.seconds_per_scan:.2f} ms/scan, {run.realtime_factor:.1f}x real "
          f"time (front end included); {len(slam.keyframes)} keyframes, {slam.n_loops} loop "
          f"edges kept, {len(slam.dropped_loops)} dropped, {len(slam.loop_attempts)} verified, "
          f"{_unreachable(slam)} matches refused as unreachable from the graph's estimate")
    if render is not None:
        slam.render(render / "slam_aces.png")
        slam.save_g2o(render / "slam_aces.g2o")


def bench_intel(limit: int | None, params: dict[str, Any]) -> None:
    log = load_log(DATA / "intel.clf.bz2")
    windows = (None, 5.0, 60.0, 300.0)  # [s]: local accuracy, then drift over long spans
    reference = pseudo_truth_relations(load_log(DATA / "intel-corrected.log.gz"), windows)
    slam = make("slam", **params)
    assert isinstance(slam, GraphSlam)
    run = run_on_log(slam, log, clock="logger", limit=limit)
    print(f"Intel ({len(run.times)} scans) vs intel-corrected.log.gz (PSEUDO ground truth); "
          "published all (true relations): scan matching 0.220 m, Cartographer 0.0229 m")
    for name, each in _runs(slam, run).items():
        for label, rel in reference.items():
            inside = rel.select((rel.t1 >= each.times[0]) & (rel.t2 <= each.times[-1] + 0.01))
            # the corrected log prints 6 significant digits: 10 ms covers its rounding
            summary = relation_errors(each.times, each.poses, inside, tolerance=0.01).summary()
            print(f"  {name:28s} {label:12s} {summary}")
    print(f"  slam: {1e3 * run.seconds_per_scan:.2f} ms/scan, {run.realtime_factor:.1f}x real "
          f"time; {slam.n_loops} loop edges kept, {len(slam.dropped_loops)} dropped")


def _ate(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Root-mean-square position error [m] (same start pose, so no alignment)."""
    return float(np.sqrt(np.mean(np.sum((estimate[:, :2] - truth[:, :2]) ** 2, axis=1))))


def _revisiting(slam: GraphSlam, keyframe_truth: np.ndarray) -> np.ndarray:
    """Keyframes that revisit a place: at their true poses (K, 3) an older keyframe at least
    ``min_loop_separation`` of path back lies within ``max_search_window`` (the farthest a
    loop match of ``slam`` reaches), so their scans share most walls."""
    path = np.array([k.path_length for k in slam.keyframes])
    revisiting = []
    for k in range(len(path)):
        behind = path[k] - path[:k]
        distance = np.hypot(*(keyframe_truth[:k, :2] - keyframe_truth[k, :2]).T)
        if np.any((behind >= slam.min_loop_separation) & (distance <= slam.max_search_window)):
            revisiting.append(k)
    return np.array(revisiting, dtype=np.int64)


def exact_loop_ratio(graph: PoseGraph, keyframe_truth: np.ndarray, draws: int,
                         rng: np.random.Generator) -> tuple[float, float]:
    """What this graph's loop closures can do for a front end whose keyframe steps err
    independently: the graph's odometry edges are redrawn as the true steps (from
    ``keyframe_truth`` (K, 3)) with Gaussian noise of the covariance their measured errors
    have, its loop edges made exact, and the graph optimised with that covariance (the best
    linear estimator).

    Returns the front end's mean ATE over the mean optimised ATE (the expected ratio) and the
    share of draws whose own ratio is at least 3 (the issue's target)."""
    loops = graph.is_loop
    steps = [relative(keyframe_truth[i], keyframe_truth[j]) for i, j in graph.edges]
    errors = np.array([relative(step, z) for step, z, loop
                       in zip(steps, graph.measurements, loops, strict=True) if not loop])
    covariance = np.cov(errors.T)
    information, factor = np.linalg.inv(covariance), np.linalg.cholesky(covariance)
    exact = np.diag([1e3, 1e3, 1e4]) ** 2  # loop edges good to 1 mm / 0.1 mrad
    front_end, closed = np.zeros(draws), np.zeros(draws)
    for draw in range(draws):
        noisy = PoseGraph()
        noisy.add_node(keyframe_truth[0])
        for (i, j), step, loop in zip(graph.edges, steps, loops, strict=True):
            if loop:
                noisy.add_edge(i, j, step, exact, is_loop=True)
            else:  # odometry edges chain the keyframes in order: j = i + 1
                measured = compose(step, factor @ rng.standard_normal(3))
                noisy.add_node(compose(noisy.poses[i], measured))
                noisy.add_edge(i, j, measured, information)
        front_end[draw] = _ate(noisy.poses, keyframe_truth)
        closed[draw] = _ate(optimize(noisy, max_iterations=50).poses, keyframe_truth)
    return float(front_end.mean() / closed.mean()), float(np.mean(front_end >= 3 * closed))


def bench_sim(params: dict[str, Any], traces: list[str], seeds: list[int], draws: int,
              render: Path | None, noise: float | None = None) -> None:
    import gymnasium as gym

    import lidar_env  # noqa: F401  (registers DualLidar-v0)
    from agents.scripted import PurePursuitDriver
    from estimators import SensorSetup

    print(f"Simulation, traces {', '.join(traces)}, seeds {', '.join(map(str, seeds))}, "
          "scripted driver; targets: end-point error <= 0.05 m, ATE >= 3x lower than the front "
          "end alone. 'floor': ATE with every keyframe at its true pose and the front end's "
          "motion between keyframes (what no keyframe correction removes); revisiting keyframes: "
          "those within max_search_window of an old one at their true poses; CPU ms/step")
    if draws:
        print(f"  'exact loops': expected ATE ratio of this graph with exact loop edges, "
              f"optimised, if the front end's keyframe steps erred independently ({draws} "
              "draws), and the share of draws reaching 3x")
    rng = np.random.default_rng(0)
    gains = []  # front end's ATE / slam's, per run
    for trace in traces:
        for seed in seeds:
            for world in WORLDS:
                config = {} if noise is None else {
                    "lidars": lidars_with_noise(range_noise_std=noise)}
                env = gym.make("DualLidar-v0", world=world, trace=trace, config=config)
                obs, info = env.reset(seed=seed)
                driver = PurePursuitDriver()
                driver.reset(env)
                slam = make("slam", **params)
                assert isinstance(slam, GraphSlam)
                slam.reset(SensorSetup.from_env(env), info["pose"])
                truth, start = [], time.process_time()
                done = False
                while not done:
                    slam.update(obs, info["time"])
                    truth.append(info["pose"])
                    obs, _, terminated, truncated, info = env.step(driver.act(obs, info))
                    done = terminated or truncated
                smoothed = slam.trajectory
                seconds = time.process_time() - start
                truth_arr = np.array(truth)
                odometry = slam.odometry_trajectory
                keyframe_truth = truth_arr[slam.keyframe_scans]
                floor = _ate(slam.anchored_trajectory(keyframe_truth), truth_arr)
                end_fe = float(np.hypot(*(odometry[-1, :2] - truth_arr[-1, :2])))
                end_slam = float(np.hypot(*(smoothed[-1, :2] - truth_arr[-1, :2])))
                ate_fe, ate_slam = _ate(odometry, truth_arr), _ate(smoothed, truth_arr)
                gains.append(ate_fe / max(ate_slam, 1e-9))  # front end's ATE / slam's
                revisiting = _revisiting(slam, keyframe_truth)
                looped = len(np.intersect1d(slam.graph.edges[slam.revisits, 1], revisiting))
                revisits = len(revisiting)
                line = (f"  {trace:12s} s{seed} {world:15s} {len(truth_arr):4d} steps: end "
                        f"error {1e3 * end_fe:6.1f} -> {1e3 * end_slam:4.1f} mm; ATE "
                        f"{1e3 * ate_fe:6.1f} -> {1e3 * ate_slam:5.1f} mm "
                        f"({gains[-1]:4.1f}x), floor {1e3 * floor:4.1f} mm; "
                        f"{slam.n_loops} match edges, loops on {looped} of {revisits} "
                        f"revisiting keyframes; {1e3 * seconds / len(truth_arr):.1f} ms/step")
                if draws and slam.n_loops:
                    ratio, reach = exact_loop_ratio(slam.graph, keyframe_truth, draws, rng)
                    line += f"; exact loops {ratio:.1f}x, {100 * reach:.0f} % >= 3x"
                print(line)
                if render is not None:
                    slam.render(render / f"slam_{world}_{trace}_s{seed}.png", truth_arr)
                env.close()
    # One run's gain is noisy (a few mm either way): the count and the spread over all runs
    # say whether slam is never worse than its front end.
    print(f"  slam's ATE below the front end's in {sum(g > 1 for g in gains)} of {len(gains)} "
          f"runs, at least 3x below in {sum(g >= 3 for g in gains)}; gain: geometric mean "
          f"{np.exp(np.mean(np.log(gains))):.2f}x, worst {min(gains):.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", nargs="+", default=["aces", "intel", "sim"],
                        choices=["aces", "intel", "sim"])
    parser.add_argument("--limit", type=int, default=None, help="first N scans of each log")
    parser.add_argument("--frontend", default="lidar_odometry")
    parser.add_argument("--set", nargs="+", default=[], metavar="NAME=VALUE",
                        help="slam parameters, e.g. min_overlap_separation=10.0 (Python literals)")
    parser.add_argument("--traces", nargs="+", default=["loop", "out_and_back"],
                        choices=["loop", "out_and_back"], help="simulated drives")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1],
                        help="simulation reset seeds")
    parser.add_argument("--noise", type=float, default=None,
                        help="simulated range noise [m], 1 sigma (default: the env's 0.01)")
    parser.add_argument("--closure-draws", type=int, default=0,
                        help="draws of the exact-loop bound per simulated run (0: off)")
    parser.add_argument("--render", type=Path, default=None,
                        help="folder for map pictures (and the ACES graph as g2o)")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"python {platform.python_version()}")
    params: dict[str, Any] = {"frontend": args.frontend}
    for setting in args.set:
        name, sep, value = setting.partition("=")
        if not sep:
            parser.error(f"--set {setting!r}: expected NAME=VALUE")
        try:
            params[name] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            parser.error(f"--set {setting!r}: expected a Python literal value, got {value!r}")
    try:
        make("slam", **params)  # bad settings fail here, before any work
    except (TypeError, ValueError, KeyError) as err:
        parser.error(f"--set: {err}")
    if {"aces", "intel"} & set(args.parts) and not DATA.is_dir():
        raise SystemExit(f"real logs not found: expected them in {DATA}")
    if "aces" in args.parts:
        bench_aces(args.limit, params, args.render)
    if "intel" in args.parts:
        bench_intel(args.limit, params)
    if "sim" in args.parts:
        bench_sim(params, args.traces, args.seeds, args.closure_draws, args.render, args.noise)


if __name__ == "__main__":
    main()
