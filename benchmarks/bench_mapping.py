"""Occupancy mapping: update time per step, and map scores with true (or estimated) poses.

Run: ``python benchmarks/bench_mapping.py [--estimators pc lidar_odometry] [--figures DIR]
[--aces]`` (about 15 s without estimators).

1. Speed: the map update of one step (both 360-beam scans, 5 cm cells over the whole
   40 m x 40 m ``open_cylinders`` world) on the scans of a scripted drive, against a plain
   numpy mapper measured in the same run (every beam sampled every half cell, ``np.unique``
   per step to update each cell once). Target: <= 2 ms per step on one core.
2. Quality: in every built-in world, driven along the paper's trace by the pure-pursuit
   driver, the map built at the true poses is scored against ``world.to_image`` on the visible
   occupied cells at one-cell tolerance (target IoU >= 0.9), and the tracked cylinders against
   ``world.circles`` (target recall >= 95 %, error <= 5 cm). With ``--estimators`` the same
   scores follow for the map built at each estimator's poses.
3. With ``--aces --figures DIR``: the maps of the real ACES log (Radish) at each estimator's
   poses next to the map at the SLAM poses of ``aces-corrected`` (pseudo truth), as a PNG, with
   each map's return agreement (``estimators.map_scoring.return_agreement``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

from estimators.real_log import SHARED_DATA

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # the target is for one core

import gymnasium as gym  # noqa: E402
import numba  # noqa: E402
import numpy as np  # noqa: E402

import lidar_env  # noqa: E402, F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver  # noqa: E402
from estimators import SensorSetup, make  # noqa: E402
from estimators.map_scoring import (  # noqa: E402
    evaluate_run_map,
    map_truth,
    return_agreement,
    save_map_figure,
)
from estimators.occupancy import (  # noqa: E402
    OccupancyGrid,
    bounds_around,
    from_estimator_run,
    logit,
    sensor_poses,
)

WORLDS = ("open_cylinders", "hallway", "closed_to_open")
RESOLUTION = 0.05  # [m]


def drive(world: str, seed: int) -> tuple[gym.Env, list[dict], np.ndarray, np.ndarray]:
    """The observations, true car poses and times [s] of one scripted drive along the paper's
    trace."""
    env = gym.make("DualLidar-v0", world=world)
    observation, info = env.reset(seed=seed)
    driver = PurePursuitDriver()
    driver.reset(env)
    observations, poses, times = [observation], [info["pose"]], [info["time"]]
    while True:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        poses.append(info["pose"])
        times.append(info["time"])
        if terminated or truncated:
            return env, observations, np.array(poses), np.array(times)


def numpy_update(
    grid: OccupancyGrid, ranges: np.ndarray, angles: np.ndarray, poses: np.ndarray,
    max_range: float,
) -> None:
    """The reference: sample every beam each half cell, update each touched cell once."""
    directions = poses[:, 2:3] + angles
    lengths = np.minimum(ranges, max_range)
    samples = np.arange(0.0, max_range, grid.resolution / 2)
    along = np.where(samples[None, None, :] < lengths[..., None] - grid.free_margin,
                     samples, np.nan)
    points = np.stack([poses[:, 0:1, None] + along * np.cos(directions)[..., None],
                       poses[:, 1:2, None] + along * np.sin(directions)[..., None]], axis=-1)
    rows, cols = grid.shape

    def cell_ids(xy: np.ndarray) -> np.ndarray:
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        cell = np.floor(grid.to_grid_coordinates(xy)).astype(np.int64)
        inside = (cell[:, 0] >= 0) & (cell[:, 0] < cols) & (cell[:, 1] >= 0) & (cell[:, 1] < rows)
        return np.unique(cell[inside, 1] * cols + cell[inside, 0])

    hit = ranges < max_range
    ends = np.stack([poses[:, 0:1] + lengths * np.cos(directions),
                     poses[:, 1:2] + lengths * np.sin(directions)], axis=-1)[hit]
    hits = cell_ids(ends)
    free = np.setdiff1d(cell_ids(points.reshape(-1, 2)), hits)
    flat = grid.log_odds.reshape(-1)
    flat[free] = np.maximum(flat[free] + logit(grid.p_miss), logit(grid.p_min))
    flat[hits] = np.minimum(flat[hits] + logit(grid.p_hit), logit(grid.p_max))


def time_updates(
    update, world_bounds, scans: np.ndarray, poses: np.ndarray, setup: SensorSetup, repeats: int
) -> float:
    """Mean seconds per step of ``update(grid, ranges, angles, sensor_poses, max_range)``."""
    best = np.inf
    for _ in range(repeats):
        grid = OccupancyGrid(world_bounds, RESOLUTION)
        start = time.perf_counter()
        for ranges, pose in zip(scans, poses, strict=True):
            update(grid, ranges, setup.beam_angles, pose, setup.max_range)
        best = min(best, (time.perf_counter() - start) / len(scans))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--estimators", nargs="*", default=[],
                        help="also score the maps built at these estimators' poses")
    parser.add_argument("--seed", type=int, default=0, help="env reset seed (range noise)")
    parser.add_argument("--figures", type=Path, default=None,
                        help="save the true world next to each map as DIR/maps_<world>.png")
    parser.add_argument("--aces", action="store_true",
                        help="with --figures: also map the real ACES log at the --estimators' "
                             "poses next to its SLAM (pseudo truth) map, DIR/maps_aces.png")
    args = parser.parse_args()
    if args.aces and args.figures is None:
        parser.error("--aces needs --figures DIR")

    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}, "
          f"{os.cpu_count()} cpus, python {platform.python_version()}, numba {numba.__version__}, "
          f"numpy {np.__version__}")
    runs = {world: drive(world, args.seed) for world in WORLDS}

    env, observations, truth, _ = runs["open_cylinders"]
    setup = SensorSetup.from_env(env)
    scans = np.array([[o[key] for key in setup.keys] for o in observations], dtype=np.float64)
    poses = sensor_poses(truth, setup)
    bounds = env.unwrapped.world.bounds

    def numba_update(grid, ranges, angles, pose, max_range):
        grid.integrate(ranges, angles, pose, max_range)

    time_updates(numba_update, bounds, scans[:2], poses[:2], setup, 1)  # compile / load cache
    ours = time_updates(numba_update, bounds, scans, poses, setup, 3)
    reference = time_updates(numpy_update, bounds, scans[:50], poses[:50], setup, 1)
    rows, cols = OccupancyGrid(bounds, RESOLUTION).shape
    print(f"\nmap update, {len(scans)} steps of 2 x {scans.shape[2]} beams, {RESOLUTION} m cells, "
          f"{rows} x {cols} grid:")
    print(f"  OccupancyGrid.integrate (numba, exact traversal): {ours * 1e3:7.3f} ms per step "
          f"(target <= 2 ms)")
    print(f"  numpy half-cell sampling reference:               {reference * 1e3:7.3f} ms per step")
    print(f"  speed-up: {reference / ours:.1f}x")

    print("\nmap scores at one-cell tolerance on the visible occupied cells; cylinders:")
    header = f"  {'world':15s} {'poses':14s} {'IoU':>6s} {'prec':>6s} {'recall':>6s}  cylinders"
    print(header)
    for world, (env, observations, truth, times) in runs.items():
        setup = SensorSetup.from_env(env)
        trajectories = {"true": truth}
        for name in args.estimators:
            estimator = make(name)
            estimator.reset(setup, truth[0])
            for observation, t in zip(observations, times, strict=True):
                estimator.update(observation, t)
            trajectories[name] = estimator.trajectory
        true_map = map_truth(env.unwrapped.world, truth, setup, RESOLUTION)
        panels = {"true world": true_map.image}
        for name, trajectory in trajectories.items():
            result = evaluate_run_map(true_map, trajectory, observations, setup)
            panels[f"map at {name} poses (IoU {result.map_scores.iou:.2f})"] = result.grid
            m, c = result.map_scores, result.cylinder_scores
            cylinders = ("-" if c is None else
                         f"recall {c.recall:.0%} ({c.n_matched}/{c.n_true}), mean error "
                         f"{c.mean_error * 100:.1f} cm, max {c.max_error * 100:.1f} cm, "
                         f"precision {c.precision:.0%}")
            print(f"  {world:15s} {name:14s} {m.iou:6.3f} {m.precision:6.3f} {m.recall:6.3f}  "
                  f"{cylinders}")
        if args.figures is not None:
            args.figures.mkdir(parents=True, exist_ok=True)
            path = save_map_figure(args.figures / f"maps_{world}.png", panels, true_map.bounds,
                                   trajectories, title=f"{world}, {RESOLUTION} m cells")
            print(f"  -> {path}")

    if args.aces:
        print(f"  -> {map_aces(args.estimators, args.figures / 'maps_aces.png')}")


def map_aces(estimators: list[str], path: Path) -> Path:
    """Maps of the whole ACES log at 0.1 m: at the SLAM poses of ``aces-corrected`` (pseudo
    truth, its keyframes only) and at each estimator's poses, each in its own first-pose frame."""
    from estimators.carmen import load_log
    from estimators.real_log import run_on_log, setup_from_log
    from lidar_env.se2 import relative

    radish = SHARED_DATA / "radish"
    if not radish.is_dir():
        raise FileNotFoundError(f"expected the Radish logs in {radish}")
    panels = {}
    for name, log_file in [("SLAM (aces-corrected)", "aces-corrected.log.gz"),
                           *((name, "aces.clf.bz2") for name in estimators)]:
        log = load_log(radish / log_file)
        setup = setup_from_log(log)
        if log_file == "aces.clf.bz2":
            start = time.perf_counter()
            try:
                poses = run_on_log(make(name), log).poses
            except ValueError as error:  # e.g. an estimator that needs two Lidars
                print(f"  aces {name}: skipped ({error})")
                continue
            print(f"  aces {name}: {len(poses)} scans in {time.perf_counter() - start:.0f} s")
        else:
            poses = relative(log.logged_poses()[0], log.logged_poses())
        observations = [{setup.keys[0]: scan.ranges} for scan in log.scans]
        grid = from_estimator_run(poses, observations, setup, resolution=0.1,
                                  bounds=bounds_around(poses[:, :2], 8.0))
        agreement = return_agreement(grid, poses, observations, setup)
        print(f"  aces {name}: return agreement {agreement:.3f} at one-cell tolerance")
        panels[f"{name} (agreement {agreement:.2f})"] = grid
    return save_map_figure(path, panels, title="ACES (Radish), whole log, 0.1 m cells")


if __name__ == "__main__":
    main()
