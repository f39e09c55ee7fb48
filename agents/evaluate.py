"""Score drivers on trace seeds: success rate, cross-track error, end-point error, time.

    python -m agents.evaluate --episodes 50 --drivers scripted sb3
    python -m agents.evaluate --episodes 10 --pose-sources true lidar_odometry slam
    python -m agents.evaluate --pose-sources lidar_odometry \
        --pose-params '{"lidar_odometry": {"sideslip_sigma": 6e-4}}'
    python -m agents.evaluate --moving-obstacles 10 --worlds open_cylinders random
    python -m agents.evaluate --drivers sb3 --sb3-model runs/ppo_driver.zip
    python -m agents.evaluate --moving-obstacles 10 --mover-model waypoints --worlds random

An episode succeeds when the car reaches the trace's end without touching an obstacle and
before the time limit. Each (world, trace, episode) uses reset seed ``base_seed + episode``;
``random`` worlds are drawn from that seed, so with a ``base_seed`` other than the training
one (training evaluates on seeds >= 10000 of its own stream) they are unseen worlds. With a
pose source other than ``true`` the driver steers by an estimator's poses
(:mod:`agents.pose_source`); the scores always use the env's ground truth. With
``--moving-obstacles M`` every episode has M pedestrians (``config["moving_obstacles"]``, drawn
from the same reset seed, so every driver meets the same crowd), walking by
``--mover-model`` (``config["mover_model"]``: "yielding", the default, keep clear of where
the car stands; "waypoints" ignore it and walk into a standing car); the closest a mover's
edge came to the car's centre is reported so that a success among movers is seen to mean
something.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.driver import DRIVERS, Driver, make_driver
from estimators.arguments import MAX_SEED, non_negative_int, positive_int, seed
from lidar_env.movers import MOVER_MODELS
from lidar_env.routes import TRACE_NAMES
from lidar_env.world import WORLD_NAMES

BUILT_IN_WORLDS = ("open_cylinders", "hallway", "closed_to_open")
TRACE_SEEDS = ("straight", "right_turn", "zigzag")
#: The leaderboard's paper groups G1-G3 as (world, trace).
PAPER_GROUPS = (("open_cylinders", "right_turn"), ("hallway", "zigzag"),
                ("closed_to_open", "zigzag"))


@dataclass(frozen=True)
class Episode:
    """One driven episode, scored against the env's ground truth."""

    success: bool  # reached the trace's end without a collision, in time
    cross_track_error: float  # [m] mean |cross-track error| of the true pose over all steps
    end_point_error: float  # [m] |estimated - true| position at the last action (0 on truth)
    time: float  # [s] episode duration
    collided: bool
    closest_mover: float = float("inf")  # [m] least distance car centre - mover edge (inf: none)


@dataclass(frozen=True)
class DrivingScore:
    """Aggregate of several episodes of one driver on one (world, trace)."""

    episodes: int
    success_rate: float  # [-] fraction of episodes finished without collision
    cross_track_error: float  # [m] mean |cross-track error| over all steps
    end_point_error: float  # [m] mean over episodes of the final position estimate's error
    time_to_finish: float  # [s] mean over successful episodes (nan if none)
    collisions: int
    closest_mover: float = float("inf")  # [m] median over episodes of the closest approach


def drive_episode(env: gym.Env, driver: Driver, seed: int) -> Episode:
    """Drive one episode of ``env`` (reset with ``seed``) with ``driver``."""
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    errors = []
    closest = _closest_mover(info)
    terminated = truncated = False
    while not (terminated or truncated):
        acted_at = info["pose"]  # the true pose of the scans the driver acts on
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        errors.append(abs(info["cross_track_error"]))
        closest = min(closest, _closest_mover(info))
    estimate = getattr(driver, "last_estimate", None)
    end_error = 0.0 if estimate is None else float(np.hypot(*(estimate[:2] - acted_at[:2])))
    collided = bool(info["collision"])
    return Episode(terminated and not collided, float(np.mean(errors)), end_error,
                   float(info["time"]), collided, closest)


def _closest_mover(info: dict[str, Any]) -> float:
    """[m] distance from the car's centre to the nearest mover's edge (inf without movers)."""
    movers = np.asarray(info["moving_obstacles"], np.float64).reshape(-1, 5)
    if not len(movers):
        return float("inf")
    gaps = np.hypot(*(movers[:, :2] - info["pose"][:2]).T) - movers[:, 4]
    return float(gaps.min())


def evaluate(
    driver: Driver, world: str, trace: str, episodes: int, base_seed: int = 1_000_000,
    moving_obstacles: int = 0, mover_model: str = "yielding",
) -> DrivingScore:
    """Score ``driver`` over ``episodes`` seeded episodes of ``world`` and ``trace`` with
    ``moving_obstacles`` pedestrians walking by ``mover_model``."""
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"moving_obstacles": moving_obstacles, "mover_model": mover_model})
    runs = [drive_episode(env, driver, base_seed + k) for k in range(episodes)]
    env.close()
    success = np.array([r.success for r in runs])
    times = np.array([r.time for r in runs])
    return DrivingScore(
        episodes=episodes,
        success_rate=float(success.mean()),
        cross_track_error=float(np.mean([r.cross_track_error for r in runs])),
        end_point_error=float(np.mean([r.end_point_error for r in runs])),
        time_to_finish=float(times[success].mean()) if success.any() else float("nan"),
        collisions=int(sum(r.collided for r in runs)),
        closest_mover=float(np.median([r.closest_mover for r in runs])),
    )


def build_driver(name: str, pose_source: str = "true", sb3_model: Path | None = None,
                 pose_params: Mapping[str, Any] | None = None,
                 trust_model: bool = False) -> Driver:
    """``make_driver(name, pose_source, pose_params)``, or for ``sb3`` with ``sb3_model`` that
    model (unpickled only with ``trust_model``: :class:`agents.sb3_driver.SB3Driver`)."""
    if name != "sb3" or sb3_model is None:
        return make_driver(name, pose_source=pose_source, pose_params=pose_params)
    from agents.sb3_driver import SB3Driver

    driver: Driver = SB3Driver(sb3_model, trust_model=trust_model)
    if pose_source == "true":
        return driver
    from agents.pose_source import EstimatedPoseDriver, check_pose_source

    return EstimatedPoseDriver(driver, check_pose_source(pose_source), pose_params)


def pose_params_by_source(text: str) -> dict[str, dict[str, Any]]:
    """``--pose-params``: a JSON object of pose source -> that estimator's parameters."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"expected JSON, {error}") from error
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise argparse.ArgumentTypeError(
            f"expected an object of pose source -> parameters, e.g. "
            f'{{"lidar_odometry": {{"sideslip_sigma": 6e-4}}}}, got {text!r}')
    return value


def build_parser(prog: str = "python -m agents.evaluate") -> argparse.ArgumentParser:
    """The command line's parser (``duallidar drive`` is the same command)."""
    from estimators.registry import names

    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--drivers", nargs="+", default=list(DRIVERS), choices=list(DRIVERS),
                        metavar="DRIVER", help=f"drivers to score, of: {', '.join(DRIVERS)}")
    parser.add_argument("--pose-sources", nargs="+", default=["true"], metavar="SOURCE",
                        help="where the drivers take the car's pose from: true (the env's "
                             f"pose) and/or estimators, of: {', '.join(names())}")
    parser.add_argument("--worlds", nargs="+", default=[*BUILT_IN_WORLDS, "random"],
                        metavar="WORLD", help=f"worlds, of: {', '.join(WORLD_NAMES)}")
    parser.add_argument("--traces", nargs="+", default=list(TRACE_SEEDS), metavar="TRACE",
                        help=f"trace seeds, of: {', '.join(TRACE_NAMES)}")
    parser.add_argument("--paper-groups", action="store_true",
                        help="drive only the paper groups G1-G3 instead of worlds x traces")
    parser.add_argument("--episodes", type=positive_int, default=50,
                        help="episodes per driver, pose source, world and trace")
    parser.add_argument("--base-seed", type=seed, default=1_000_000,
                        help="reset seed of the first episode; episode k uses base seed + k")
    parser.add_argument("--moving-obstacles", type=non_negative_int, default=0,
                        help="pedestrians per episode (config moving_obstacles)")
    parser.add_argument("--mover-model", choices=MOVER_MODELS, default="yielding",
                        help="how the pedestrians walk (config mover_model)")
    parser.add_argument("--sb3-model", type=Path, default=None,
                        help="the sb3 driver's model .zip; None: the shipped one")
    parser.add_argument("--trust-model", action="store_true",
                        help="load --sb3-model with PPO.load, unpickling its settings (only "
                             "for a model you made; without it the weights alone are read)")
    parser.add_argument("--pose-params", type=pose_params_by_source, default={},
                        help="JSON: pose source -> its estimator's parameters, e.g. "
                             '\'{"lidar_odometry": {"sideslip_sigma": 6e-4}}\'')
    return parser


def check_arguments(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse, naming the option, what the parser's types cannot see alone."""
    from estimators.registry import names

    for option, given, valid in (("--worlds", args.worlds, WORLD_NAMES),
                                 ("--traces", args.traces, TRACE_NAMES),
                                 ("--pose-sources", args.pose_sources, ("true", *names()))):
        for name in given:
            if name.partition("?")[0] not in valid:
                parser.error(f"{option}: unknown name {name!r}: expected one of "
                             f"{', '.join(valid)}")
    if args.base_seed + args.episodes - 1 > MAX_SEED:
        parser.error(f"--base-seed: expected base seed + episodes - 1 <= {MAX_SEED}, got "
                     f"{args.base_seed} + {args.episodes} - 1")
    if args.sb3_model is not None and not args.sb3_model.is_file():
        parser.error(f"--sb3-model: no such file {args.sb3_model}")


def main(argv: Sequence[str] | None = None, prog: str = "python -m agents.evaluate") -> int:
    """Score the drivers and print one table row per combination; returns the exit status
    (2 for bad input)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    check_arguments(parser, args)
    unknown = sorted(set(args.pose_params) - (set(args.pose_sources) - {"true"}))
    if unknown:
        parser.error(f"--pose-params: {', '.join(unknown)} is not an estimator "
                     f"among --pose-sources ({', '.join(args.pose_sources)})")
    print("| driver | pose | world | trace | movers | success | cross-track [m] | end-point [m] | "
          "time [s] | collisions | closest mover [m] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    movers = (f"{args.moving_obstacles} {args.mover_model}" if args.moving_obstacles
              else "0")
    pairs = PAPER_GROUPS if args.paper_groups else [
        (world, trace) for world in args.worlds for trace in args.traces]
    for name in args.drivers:
        for source in args.pose_sources:
            driver = build_driver(name, source, args.sb3_model,
                                  args.pose_params.get(source), args.trust_model)
            for world, trace in pairs:
                s = evaluate(driver, world, trace, args.episodes, args.base_seed,
                             args.moving_obstacles, args.mover_model)
                print(
                    f"| {name} | {source} | {world} | {trace} | {movers} | "
                    f"{100 * s.success_rate:.0f}% | {s.cross_track_error:.3f} | "
                    f"{s.end_point_error:.3f} | {s.time_to_finish:.1f} | {s.collisions} | "
                    f"{s.closest_mover:.2f} |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
