"""Estimators, maps and trackers among moving obstacles, against the same drive
without them.

    python benchmarks/bench_movers_estimators.py               # the three paper groups, seed 0
    python benchmarks/bench_movers_estimators.py --seeds 0 1
    python benchmarks/bench_movers_estimators.py --mover-model waypoints --without-filter
    python benchmarks/bench_movers_estimators.py --seeds 0 1 --oracle   # + movers' returns deleted

Each paper group (G1 ``open_cylinders`` + ``right_turn`` with 10 pedestrians, G2 ``hallway`` +
``zigzag`` with 5, G3 ``closed_to_open`` + ``zigzag`` with 5) is driven by the scripted driver
twice with the same seed: without movers and with them (``--mover-model``, default the
env's: "yielding" pedestrians keep clear of where the car stands, "waypoints" ones ignore it).
A mover the driver (which ignores the scans) walks into ends the episode, so both drives are
scored over the steps they share. Per
drive: eq.-11 accuracy and ATE of ``lidar_odometry`` and ``slam`` as registered (their
moving-point filter on, also on the static drive; with ``--without-filter``
``reject_dynamic=False``, to see what the filter buys); the
occupancy map's IoU and the static cylinders' precision at the ``lidar_odometry`` poses
(against the static world); and the moving-obstacle tracker
(:func:`estimators.leaderboard.recording.score_movers`: a
:class:`estimators.mapping.motion_tracking.MotionTracker` on those poses) scored by
:class:`estimators.evaluation.mover_scores.MoverScore` against ``info["moving_obstacles"]``:
recall of visible movers within 5 m, position and velocity error, identity switches,
moving-label precision.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.driver import make_driver
from estimators import make
from estimators.base import SensorSetup
from estimators.evaluation.metrics import evaluate
from estimators.leaderboard.recording import (
    map_reference,
    score_map,
    score_movers,
    world_geometry,
)
from estimators.leaderboard.records import SensorDataset
from lidar_env.config import EnvConfig
from lidar_env.movers import MOVER_MODELS

GROUPS = (("open_cylinders", "right_turn", 10), ("hallway", "zigzag", 5),
          ("closed_to_open", "zigzag", 5))
ESTIMATORS = ("lidar_odometry", "slam")
#: The columns after the estimators': the map's, then the tracker's.
MAP_COLUMNS = ("map IoU", "cylinder prec.", "mover recall", "pos. err [m]", "vel. err [m/s]",
               "id sw.", "moving prec.")
#: The moving-point filter off, for each (``slam`` passes it to its front end).
UNFILTERED = {"lidar_odometry": {"reject_dynamic": False},
              "slam": {"frontend_params": {"reject_dynamic": False}}}


def drive(world: str, trace: str, seed: int, movers: int, model: str
          ) -> tuple[SensorDataset, list[Any]]:
    """The scripted drive's sensor dataset and the true movers (M, 5) at every observation,
    among ``movers`` pedestrians walking by mover model ``model``."""
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"moving_obstacles": movers, "mover_model": model})
    driver = make_driver("scripted")
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    observations, infos, done = [observation], [info], False
    while not done:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        infos.append(info)
        done = terminated or truncated
    setup = SensorSetup.from_env(env)
    dataset = SensorDataset(
        setup=setup, times=np.array([i["time"] for i in infos]),
        scans={key: np.stack([o[key] for o in observations]).astype(np.float32)
               for key in setup.keys},
        poses=np.array([i["pose"] for i in infos]),
        lidar_poses=np.array([i["lidar_poses"] for i in infos]),
        world=world_geometry(env.unwrapped.world))
    env.close()
    return dataset, [i["moving_obstacles"] for i in infos]


def prefix(dataset: SensorDataset, n: int) -> SensorDataset:
    """The first ``n`` steps of ``dataset``."""
    return dataclasses.replace(
        dataset, times=dataset.times[:n], poses=dataset.poses[:n],
        lidar_poses=dataset.lidar_poses[:n],
        scans={key: scan[:n] for key, scan in dataset.scans.items()})


def without_mover_returns(dataset: SensorDataset, movers: list[Any],
                          tolerance: float = 0.04) -> SensorDataset:
    """``dataset`` with every return that lies within ``tolerance`` [m] of a true mover's
    circle read as no return (``max_range``): the scans a perfect moving-point filter would
    leave, which still lack what the movers hid (an oracle; it reads the truth)."""
    scans = {}
    for k, key in enumerate(dataset.setup.keys):
        sensor = dataset.setup.sensors[k]
        cleaned = dataset.scans[key].copy()
        for i, (lidar_pose, circles) in enumerate(zip(dataset.lidar_poses[:, k], movers,
                                                      strict=False)):
            ranges = cleaned[i].astype(np.float64)
            bearings = lidar_pose[2] + sensor.beam_angles
            x = lidar_pose[0] + ranges * np.cos(bearings)
            y = lidar_pose[1] + ranges * np.sin(bearings)
            gaps = np.hypot(x[:, None] - circles[None, :, 0],
                            y[:, None] - circles[None, :, 1]) - circles[None, :, 4]
            cleaned[i, (gaps.min(axis=1, initial=np.inf) < tolerance)
                    & (ranges < sensor.max_range)] = sensor.max_range
        scans[key] = cleaned
    return dataclasses.replace(dataset, scans=scans)


def run(name: str, dataset: SensorDataset, params: dict[str, Any]) -> np.ndarray:
    """The trajectory (N, 3) of estimator ``name`` with ``params``, started at the true first
    pose."""
    estimator = make(name, **params)
    estimator.reset(dataset.setup, dataset.poses[0])
    for step, observation in enumerate(dataset.observations()):
        estimator.update(observation, float(dataset.times[step]))
    return estimator.trajectory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--mover-model", choices=MOVER_MODELS, default=EnvConfig.mover_model,
                        help="how the pedestrians walk (default %(default)s)")
    parser.add_argument("--without-filter", action="store_true",
                        help="the estimators with their moving-point filter off")
    parser.add_argument("--oracle", action="store_true",
                        help="also each drive with movers with their returns deleted "
                             "(the truth's), the estimators' own filter off")
    args = parser.parse_args()
    params = {name: UNFILTERED[name] if args.without_filter else {} for name in ESTIMATORS}
    print("| group | seed | movers | steps | " + " | ".join(
        f"{n} acc [%] | {n} ATE [m]" for n in ESTIMATORS) + " | " + " | ".join(MAP_COLUMNS)
          + " |")
    print("|---" * (4 + 2 * len(ESTIMATORS) + len(MAP_COLUMNS)) + "|")
    for world, trace, count in GROUPS:
        for seed in args.seeds:
            with_movers, movers = drive(world, trace, seed, count, args.mover_model)
            without, _ = drive(world, trace, seed, 0, args.mover_model)
            n = min(len(with_movers), len(without))
            runs: list[tuple[SensorDataset, Any]] = [(prefix(without, n), 0),
                                                      (prefix(with_movers, n), count)]
            if args.oracle:
                runs.append((without_mover_returns(runs[1][0], movers[:n]), f"{count} oracle"))
            for dataset, m in runs:
                cells = []
                if isinstance(m, str):  # the oracle: the truth's filter instead of theirs
                    for name in ESTIMATORS:
                        metrics = evaluate(run(name, dataset, UNFILTERED[name]), dataset.poses)
                        cells += [f"{metrics.accuracy_percent:.2f}", f"{metrics.ate_rmse_m:.4f}"]
                    print(f"| {world}/{trace} | {seed} | {m} | {n} | " + " | ".join(cells)
                          + " | -" * len(MAP_COLUMNS) + " |", flush=True)
                    continue
                trajectories = {name: run(name, dataset, params[name]) for name in ESTIMATORS}
                for name in ESTIMATORS:
                    metrics = evaluate(trajectories[name], dataset.poses)
                    cells += [f"{metrics.accuracy_percent:.2f}", f"{metrics.ate_rmse_m:.4f}"]
                poses = trajectories["lidar_odometry"]
                reference = map_reference(dataset)
                assert reference is not None
                maps = score_map(reference, poses, dataset)
                cells += [f"{maps['map_iou']:.3f}",
                          f"{maps.get('cylinder_precision', float('nan')):.3f}"]
                if m:
                    s = score_movers(dataset, poses, np.stack(movers[:n]))
                    cells += [f"{s['mover_recall']:.3f}", f"{s['mover_position_error_m']:.3f}",
                              f"{s['mover_velocity_error_mps']:.3f}",
                              f"{s['mover_id_switches']:.0f}",
                              f"{s['moving_label_precision']:.3f}"]
                else:
                    cells += ["-"] * 5
                print(f"| {world}/{trace} | {seed} | {m} | {n} | " + " | ".join(cells) + " |",
                      flush=True)


if __name__ == "__main__":
    main()
