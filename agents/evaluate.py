"""Score drivers on trace seeds: success rate, cross-track error, end-point error, time.

    python -m agents.evaluate --episodes 50 --drivers scripted sb3
    python -m agents.evaluate --episodes 10 --pose-sources true lidar_odometry slam

An episode succeeds when the car reaches the trace's end without touching an obstacle and
before the time limit. Each (world, trace, episode) uses reset seed ``base_seed + episode``;
``random`` worlds are drawn from that seed, so with a ``base_seed`` other than the training
one (training evaluates on seeds >= 10000 of its own stream) they are unseen worlds. With a
pose source other than ``true`` the driver steers by an estimator's poses
(:mod:`agents.pose_source`); the scores always use the env's ground truth.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.driver import DRIVERS, Driver, make_driver

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


@dataclass(frozen=True)
class DrivingScore:
    """Aggregate of several episodes of one driver on one (world, trace)."""

    episodes: int
    success_rate: float  # [-] fraction of episodes finished without collision
    cross_track_error: float  # [m] mean |cross-track error| over all steps
    end_point_error: float  # [m] mean over episodes of the final position estimate's error
    time_to_finish: float  # [s] mean over successful episodes (nan if none)
    collisions: int


def drive_episode(env: gym.Env, driver: Driver, seed: int) -> Episode:
    """Drive one episode of ``env`` (reset with ``seed``) with ``driver``."""
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    errors = []
    terminated = truncated = False
    while not (terminated or truncated):
        acted_at = info["pose"]  # the true pose of the scans the driver acts on
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        errors.append(abs(info["cross_track_error"]))
    estimate = getattr(driver, "last_estimate", None)
    end_error = 0.0 if estimate is None else float(np.hypot(*(estimate[:2] - acted_at[:2])))
    collided = bool(info["collision"])
    return Episode(terminated and not collided, float(np.mean(errors)), end_error,
                   float(info["time"]), collided)


def evaluate(
    driver: Driver, world: str, trace: str, episodes: int, base_seed: int = 1_000_000
) -> DrivingScore:
    """Score ``driver`` over ``episodes`` seeded episodes of ``world`` and ``trace``."""
    env = gym.make("DualLidar-v0", world=world, trace=trace)
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
    )


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drivers", nargs="+", default=list(DRIVERS), choices=list(DRIVERS))
    parser.add_argument("--pose-sources", nargs="+", default=["true"],
                        help="true (the env's pose) and/or estimator names to steer by")
    parser.add_argument("--worlds", nargs="+", default=[*BUILT_IN_WORLDS, "random"])
    parser.add_argument("--traces", nargs="+", default=list(TRACE_SEEDS))
    parser.add_argument("--paper-groups", action="store_true",
                        help="drive only the paper groups G1-G3 instead of worlds x traces")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--base-seed", type=int, default=1_000_000)
    args = parser.parse_args(argv)
    print("| driver | pose | world | trace | success | cross-track [m] | end-point [m] | "
          "time [s] | collisions |")
    print("|---|---|---|---|---|---|---|---|---|")
    pairs = PAPER_GROUPS if args.paper_groups else [
        (world, trace) for world in args.worlds for trace in args.traces]
    for name in args.drivers:
        for source in args.pose_sources:
            driver = make_driver(name, pose_source=source)
            for world, trace in pairs:
                s = evaluate(driver, world, trace, args.episodes, args.base_seed)
                print(
                    f"| {name} | {source} | {world} | {trace} | {100 * s.success_rate:.0f}% | "
                    f"{s.cross_track_error:.3f} | {s.end_point_error:.3f} | "
                    f"{s.time_to_finish:.1f} | {s.collisions} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
