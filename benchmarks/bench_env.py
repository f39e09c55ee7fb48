"""Speed of ``DualLidar-v0``: env steps/s and where a step's time goes.

Prints, in one run on this machine:

* env steps/s from ``gymnasium.utils.performance.benchmark_step`` (random actions, resets
  included) on each built-in world, with default noise and noiseless, next to CartPole-v1's
  steps/s measured the same way as a reference for how fast this machine runs gymnasium;
* a per-step breakdown [us] (best of several repeats): action sampling, car motion, the pymunk
  alternative for the car (stepping a body in the space + a shape query) as its reference,
  the exact dual scan, the scan with noise, progress tracking, the info dict, a whole step.

Target (issue 2): >= 20,000 env steps/s without rendering.

Run: ``python benchmarks/bench_env.py [--seconds 2]``
"""

from __future__ import annotations

import argparse
import os
import platform
import timeit
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from gymnasium.utils.performance import benchmark_step

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.lidar import cast_rays
from lidar_env.worlds import WORLD_NAMES

TARGET_STEPS_PER_SECOND = 20_000


def best_microseconds(call: Callable[[], object], number: int = 2000, repeat: int = 5) -> float:
    """Best-of-``repeat`` mean time of ``call`` [us]: the least disturbed by other load."""
    return min(timeit.repeat(call, number=number, repeat=repeat)) / number * 1e6


def pymunk_car_step(env: gym.Env, substeps: int) -> Callable[[], object]:
    """One control step of the car done the pymunk way: velocity-driven substeps + a query."""
    unwrapped = env.unwrapped
    space = unwrapped.space
    body = unwrapped.car.body
    shape = next(iter(body.shapes))
    dt = unwrapped.config.control_dt / substeps

    def step() -> object:
        body.velocity = (0.0, 0.0)
        body.angular_velocity = 0.0
        for _ in range(substeps):
            space.step(dt)
        return space.shape_query(shape)

    return step


def breakdown(world: str) -> dict[str, float]:
    """Per-step cost [us] of each part of ``env.step`` on ``world``."""
    env = gym.make("DualLidar-v0", world=world)
    unwrapped = env.unwrapped
    env.reset(seed=0)
    config = unwrapped.config
    poses = unwrapped._sensor_poses.copy()
    rng = np.random.default_rng(0)
    still = np.zeros(2, dtype=np.float32)
    env.action_space.seed(0)
    return {
        "action_space.sample": best_microseconds(env.action_space.sample),
        "car motion (kernel)": best_microseconds(
            lambda: unwrapped.car.drive(0.0, 0.0, config.control_dt, config.physics_substeps)
        ),
        "car motion (pymunk ref)": best_microseconds(
            pymunk_car_step(env, config.physics_substeps), number=500
        ),
        "dual scan, exact": best_microseconds(
            lambda: cast_rays(unwrapped.world, poses, unwrapped.lidar.beam_angles, config.max_range)
        ),
        "dual scan + noise": best_microseconds(
            lambda: unwrapped.lidar.scan(unwrapped.world, poses, rng)
        ),
        "progress tracking": best_microseconds(unwrapped._progress),
        "info dict": best_microseconds(lambda: unwrapped._info(0.0, 0.0, False)),
        "env.step (unwrapped)": best_microseconds(lambda: unwrapped.step(still)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="duration of each rate [s]")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}, python {platform.python_version()}")
    reference = benchmark_step(gym.make("CartPole-v1"), target_duration=args.seconds, seed=0)
    print(f"reference CartPole-v1: {reference:,.0f} steps/s")
    print(f"{'world':<16}{'steps/s':>10}{'noiseless':>11}{'vs CartPole':>13}{'vs target':>11}")
    for world in (name for name in WORLD_NAMES if name != "random"):
        rate = benchmark_step(gym.make("DualLidar-v0", world=world), args.seconds, seed=0)
        clean = benchmark_step(
            gym.make("DualLidar-v0", world=world, config={"range_noise_std": 0.0}),
            args.seconds, seed=0,
        )
        print(f"{world:<16}{rate:>10,.0f}{clean:>11,.0f}{rate / reference:>13.2f}"
              f"{rate / TARGET_STEPS_PER_SECOND:>11.2f}")
    random_rate = benchmark_step(gym.make("DualLidar-v0", world="random"), args.seconds, seed=0)
    print(f"{'random':<16}{random_rate:>10,.0f}   (a new world at every reset)")
    print("\nper-step breakdown [us], best of 5 (world closed_to_open):")
    parts = breakdown("closed_to_open")
    for name, micros in parts.items():
        print(f"  {name:<26}{micros:>8.2f}")
    ratio = parts["car motion (pymunk ref)"] / parts["car motion (kernel)"]
    print(f"  car kernel is {ratio:.1f}x faster than the pymunk step + query")
    overhead = parts["env.step (unwrapped)"] - parts["dual scan + noise"]
    print(f"  env overhead beyond the scan: {overhead:.2f} us per step")


if __name__ == "__main__":
    main()
