"""The paper's Table I on DualLidar-v0: eq.-11 accuracy, ATE, drift and ms/step per estimator.

Run: ``python benchmarks/table1.py [--seed 0] [--frames world sensor] [--tum-dir DIR]
[--plot table1.png] [--feature-density 0]`` (the plot, like the paper's Fig. 8, needs
matplotlib). ``--feature-density`` [features per 10 m of wall] adds door recesses, pillars,
corners and clutter to the two closed areas, placed from the seed
(:mod:`lidar_env.world.feature_worlds`; ``benchmarks/table1_sweep.py`` sweeps it).

Three surroundings as in the paper (section IV.B): a right turn in ``open_cylinders``, a
zigzag in ``hallway`` and in ``closed_to_open``; one seeded episode each, 1 cm range noise,
driven by ``agents.scripted.PurePursuitDriver``. Every estimator runs on the same recorded
scans. Table I's cases without pose-graph are the brown traces of Fig. 8 ("functions 1 and 2
offsets"), i.e. ``pc_offset``; with pose-graph it is ``pc_pg``; ``pc`` (green) has no number
in the paper. ``scan_frame="world"`` is the paper's simplification (scans rotated into world
axes, heading known); ``"sensor"`` is the honest setting where the paper's method cannot see
the car turn.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import estimators
import lidar_env  # registers DualLidar-v0
from agents.scripted import PurePursuitDriver
from estimators.base import SensorSetup
from estimators.evaluation.metrics import evaluate
from estimators.evaluation.tum import write_tum
from lidar_env.world.feature_worlds import FEATURE_WORLDS, feature_world_name

#: (world, trace, {estimator: Table I case and accuracy [%]})
GROUPS = (
    ("open_cylinders", "right_turn", {"pc_offset": (1, 31.25), "pc_pg": (2, 91.10)}),
    ("hallway", "zigzag", {"pc_offset": (3, 60.08), "pc_pg": (4, 60.31)}),
    ("closed_to_open", "zigzag", {"pc_offset": (5, 64.45), "pc_pg": (6, 63.54)}),
)
ESTIMATORS = ("zero", "pc", "pc_offset", "pc_pg")
RANGE_NOISE = 0.01  # [m] the 1 cm of the issue


def record_episode(world: str, trace: str, scan_frame: str, seed: int) -> tuple:
    """Drive one episode; return the env, the observations, their times and the true poses."""
    env = gym.make(
        "DualLidar-v0",
        world=world,
        trace=trace,
        config={"lidars": lidar_env.lidars_with_noise(range_noise_std=RANGE_NOISE),
                "scan_frame": scan_frame},
    )
    driver = PurePursuitDriver()
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    observations, times, poses = [observation], [info["time"]], [info["pose"]]
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        times.append(info["time"])
        poses.append(info["pose"])
        done = terminated or truncated
    return env, observations, np.array(times), np.array(poses)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", nargs="+", default=["world", "sensor"])
    parser.add_argument("--tum-dir", type=Path, help="write truth and estimates as TUM files")
    parser.add_argument("--plot", type=Path, help="save true and estimated paths to this image")
    parser.add_argument("--feature-density", type=float, default=0.0,
                        help="features per 10 m of wall in the closed areas (default 0: bare)")
    args = parser.parse_args()
    paths: dict[tuple[str, str], dict[str, np.ndarray]] = {}
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}; seed {args.seed}, noise {RANGE_NOISE} m, "
          f"{args.feature_density:g} features per 10 m of wall in the closed areas")
    header = (f"{'frame':6s} {'world':15s} {'trace':10s} {'estimator':9s} {'case':>4s} "
              f"{'paper%':>7s} {'acc%':>6s} {'eq11%':>7s} {'ATE m':>7s} {'drift%':>7s} "
              f"{'head°':>6s} {'dist m':>7s} {'ms/step':>8s}")
    print(header)
    for scan_frame in args.frames:
        for world, trace, paper in GROUPS:
            name = (feature_world_name(world, args.feature_density, args.seed)
                    if world in FEATURE_WORLDS else world)
            env, observations, times, truth = record_episode(name, trace, scan_frame, args.seed)
            setup = SensorSetup.from_env(env)
            paths[scan_frame, world] = {"truth": truth}
            if args.tum_dir:
                args.tum_dir.mkdir(parents=True, exist_ok=True)
                write_tum(args.tum_dir / f"{scan_frame}_{world}_truth.tum", times, truth)
            for name in ESTIMATORS:
                estimator = estimators.make(name)
                estimator.reset(setup, truth[0])
                estimator.update(observations[0], times[0])
                start = time.perf_counter()
                for observation, t in zip(observations[1:], times[1:], strict=True):
                    estimator.update(observation, t)
                ms = 1000.0 * (time.perf_counter() - start) / (len(observations) - 1)
                metrics = evaluate(estimator.trajectory, truth)
                paths[scan_frame, world][name] = estimator.trajectory
                case, paper_accuracy = paper.get(name, ("", float("nan")))
                print(f"{scan_frame:6s} {world:15s} {trace:10s} {name:9s} {case!s:>4s} "
                      f"{paper_accuracy:7.2f} {metrics.accuracy_percent:6.2f} "
                      f"{metrics.eq11_error_percent:7.2f} {metrics.ate_rmse_m:7.3f} "
                      f"{metrics.drift_percent:7.2f} {metrics.heading_rmse_deg:6.1f} "
                      f"{metrics.distance_m:7.2f} {ms:8.3f}")
                if args.tum_dir:
                    path = args.tum_dir / f"{scan_frame}_{world}_{name}.tum"
                    write_tum(path, estimator.times, estimator.trajectory)
            env.close()
    if args.plot:
        plot_paths(paths, args.plot)


def plot_paths(paths: dict[tuple[str, str], dict[str, np.ndarray]], path: Path) -> None:
    """One panel per (scan frame, world): the true path and each estimator's, in metres."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = sorted({frame for frame, _ in paths}, reverse=True)
    worlds = [world for world, _, _ in GROUPS]
    figure, axes = plt.subplots(
        len(frames), len(worlds), figsize=(5 * len(worlds), 4.2 * len(frames)), squeeze=False
    )
    for (frame, world), trajectories in paths.items():
        axis = axes[frames.index(frame), worlds.index(world)]
        for name, poses in trajectories.items():
            style = {"color": "black", "linewidth": 2.5} if name == "truth" else {"linewidth": 1.2}
            axis.plot(poses[:, 0], poses[:, 1], label=name, **style)
        axis.set_title(f"{world}, {frame}-frame scans")
        axis.set_aspect("equal", adjustable="datalim")
        axis.set_xlabel("x [m]")
        axis.set_ylabel("y [m]")
    axes[0, 0].legend(loc="best", fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    print(f"saved {path}")


if __name__ == "__main__":
    main()
