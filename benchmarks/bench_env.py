"""Speed of ``DualLidar-v0``: env steps/s and where a step's time goes.

Prints, in one run on this machine:

* env steps/s from ``gymnasium.utils.performance.benchmark_step`` (random actions, resets
  included) on each built-in world, with default noise and noiseless, next to CartPole-v1's
  steps/s measured the same way as a reference for how fast this machine runs gymnasium;
* the same loop timed in CPU seconds of this process ("one core"): on a shared machine the
  wall-clock rate also counts the time other processes hold the core, the CPU rate does not;
* a per-step breakdown [us of CPU] (best of several repeats): action sampling, car motion, the
  pymunk alternative for the car (stepping a body in the space + a shape query) as its
  reference, the exact dual scan, the Gaussian draws, the scan with noise, progress tracking,
  the info dict, a whole step, and a step plus its action sample (what ``benchmark_step``
  times).

Target: >= 20,000 env steps/s on one core without rendering.

Run: ``python benchmarks/bench_env.py [--seconds 2]``
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import timeit
from collections.abc import Callable
from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium.utils.performance import benchmark_step

import lidar_env  # registers DualLidar-v0
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.built_in import WORLD_NAMES

TARGET_STEPS_PER_SECOND = 20_000


def best_microseconds(call: Callable[[], object], number: int = 2000, repeat: int = 5) -> float:
    """Best-of-``repeat`` mean CPU time of ``call`` [us]: the least disturbed by other load."""
    times = timeit.repeat(call, number=number, repeat=repeat, timer=time.process_time)
    return min(times) / number * 1e6


def cpu_steps_per_second(env: gym.Env, seconds: float, seed: int) -> float:
    """``benchmark_step``'s loop (random actions, reset at episode end), timed in CPU seconds."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    steps = 0
    start = time.process_time()
    while time.process_time() - start < seconds:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        steps += 1
        if terminated or truncated:
            env.reset()
    return steps / (time.process_time() - start)


def rates(make: Callable[[], gym.Env], seconds: float) -> tuple[float, float]:
    """Steps/s of a fresh env from ``make``: wall clock (``benchmark_step``) and CPU time.

    One step is taken first, so compiling (or loading the numba cache) is not timed.
    """
    env = make()
    env.reset(seed=0)
    env.step(env.action_space.sample())
    return benchmark_step(make(), seconds, seed=0), cpu_steps_per_second(make(), seconds, 0)


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
    """Per-step CPU cost [us] of each part of ``env.step`` on ``world``."""
    env = gym.make("DualLidar-v0", world=world)
    unwrapped = env.unwrapped
    env.reset(seed=0)
    config = unwrapped.config
    lidar = unwrapped.lidar
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
            lambda: cast_rays(unwrapped.world, poses, lidar.beam_angles[0], config.max_range)
        ),
        f"2 x {config.n_beams} Gaussian draws": best_microseconds(
            lambda: rng.standard_normal((2, config.n_beams))
        ),
        "dual scan + noise": best_microseconds(lambda: lidar.scan(unwrapped.world, poses, rng)),
        "progress tracking": best_microseconds(unwrapped._progress),
        "info dict": best_microseconds(lambda: unwrapped._info(0.0, 0.0, False)),
        "env.step (unwrapped)": best_microseconds(lambda: unwrapped.step(still)),
        "env.step (gym.make)": best_microseconds(lambda: env.step(still)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="duration of each rate [s]")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}, python {platform.python_version()}")
    wall_ref, cpu_ref = rates(partial(gym.make, "CartPole-v1"), args.seconds)
    print(f"reference CartPole-v1: {wall_ref:,.0f} steps/s wall, {cpu_ref:,.0f} steps/s CPU")
    print(f"{'':<16}{'-------- wall clock --------':>30}{'------ CPU time (one core) ------':>36}")
    print(f"{'world':<16}{'steps/s':>10}{'noiseless':>11}{'vs Cart':>9}"
          f"{'steps/s':>12}{'noiseless':>11}{'vs Cart':>9}{'vs target':>11}")
    for world in WORLD_NAMES:
        wall, cpu = rates(partial(gym.make, "DualLidar-v0", world=world), args.seconds)
        if world == "random":
            print(f"{world:<16}{wall:>10,.0f}{'':>11}{wall / wall_ref:>9.2f}{cpu:>12,.0f}{'':>11}"
                  f"{cpu / cpu_ref:>9.2f}{cpu / TARGET_STEPS_PER_SECOND:>11.2f}"
                  "   (a new world at every reset)")
            continue
        clean_wall, clean_cpu = rates(
            partial(gym.make, "DualLidar-v0", world=world,
                    config={"lidars": lidar_env.lidars_with_noise(range_noise_std=0.0)}),
            args.seconds,
        )
        print(f"{world:<16}{wall:>10,.0f}{clean_wall:>11,.0f}{wall / wall_ref:>9.2f}"
              f"{cpu:>12,.0f}{clean_cpu:>11,.0f}{cpu / cpu_ref:>9.2f}"
              f"{cpu / TARGET_STEPS_PER_SECOND:>11.2f}")
    print("\nper-step breakdown [us of CPU], best of 5 (world closed_to_open):")
    parts = breakdown("closed_to_open")
    for name, micros in parts.items():
        print(f"  {name:<26}{micros:>8.2f}")
    ratio = parts["car motion (pymunk ref)"] / parts["car motion (kernel)"]
    print(f"  car kernel is {ratio:.1f}x faster than the pymunk step + query")
    overhead = parts["env.step (unwrapped)"] - parts["dual scan + noise"]
    print(f"  env overhead beyond the scan: {overhead:.2f} us per step")
    loop = parts["action_space.sample"] + parts["env.step (gym.make)"]
    print(f"  sample + step: {loop:.2f} us = {1e6 / loop:,.0f} steps/s on one core; the step "
          f"alone {1e6 / parts['env.step (gym.make)']:,.0f} steps/s")


if __name__ == "__main__":
    main()
