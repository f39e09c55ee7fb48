"""Speed of the batched ``DualLidar-v0`` against ``SyncVectorEnv`` over N single envs.

Prints, in one run on this machine:

* env steps/s (CPU time of this process, ``time.process_time``; random actions, autoresets
  included) of ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` and of
  ``vectorization_mode="sync"`` at N = 1, 16, 64, 256, and their ratio;
* where a batched env step goes at the largest N, from the same loop with less work: without
  range noise (no Gaussian draws), and noiseless with 8-beam Lidars (nearly no ray casting),
  so the differences are the cost of the range noise and of the exact rays [us per env step];
  the scan call of the 8-beam Lidars is split into its cost per call (the same Lidars in a
  world with no obstacles) and the cost of the circles and edges in range (the rest);
* memory per env: the batched env's own arrays (``nbytes``) and what ``tracemalloc`` sees
  allocated by building and resetting each kind of vector env, divided by N.

``--moving-obstacles M`` (and ``--mover-model``) runs every figure with M pedestrians per env
(``config["moving_obstacles"]``) and adds the batched env without them at the largest N, so the
difference is the crowd's cost (the movers' step, the car's collision checks among them, their
circles in the scans).

Targets (issue 21): >= 200,000 env steps/s at N = 256 on this 2-core machine, and >= 5x
``SyncVectorEnv``.

Run: ``python benchmarks/bench_vector_env.py [--seconds 2] [--sizes 1 16 64 256]
[--moving-obstacles 10] [--mover-model yielding|waypoints]``
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import tracemalloc
from typing import Any

import gymnasium as gym
import numpy as np

import lidar_env  # registers DualLidar-v0
from lidar_env.config import MOVER_MODELS
from lidar_env.world import World

TARGET_STEPS_PER_SECOND = 200_000
TARGET_RATIO = 5.0
#: Noiseless Lidars of 8 beams: what is left of a step without draws and with few rays.
FEW_BEAMS = {"lidars": [{"mount": (0.25, 0.0, 0.0), "n_beams": 8, "range_noise_std": 0.0},
                        {"mount": (-0.25, 0.0, 0.0), "n_beams": 8, "range_noise_std": 0.0}]}
#: The default Lidars without range noise.
NOISELESS = {"lidars": lidar_env.lidars_with_noise(range_noise_std=0.0)}
#: [m] a 60 m square with nothing in it, driven along its middle: a scan with no primitives.
EMPTY_WORLD = {"world": World(np.empty((0, 3)), np.empty((0, 4)), bounds=(0.0, 0.0, 60.0, 60.0)),
               "trace": np.array([[5.0, 30.0], [55.0, 30.0]])}


#: Config keys every env of the run gets (the movers of ``--moving-obstacles``).
BASE: dict[str, Any] = {}


def make(mode: str, num_envs: int, config: dict[str, Any] | None = None,
         **kwargs: Any) -> gym.vector.VectorEnv:
    return gym.make_vec("DualLidar-v0", num_envs=num_envs, vectorization_mode=mode,
                        config={**BASE, **(config or {})}, **kwargs)


def cpu_steps_per_second(env: gym.vector.VectorEnv, seconds: float, seed: int = 0) -> float:
    """Env steps (N per vector step) per CPU second, random actions, autoreset included.

    One step is taken before timing, so compiling (or loading the numba cache) is not timed.
    """
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(64)]
    env.step(actions[0])
    steps = 0
    start = time.process_time()
    while time.process_time() - start < seconds:
        env.step(actions[steps % len(actions)])
        steps += 1
    return steps * env.num_envs / (time.process_time() - start)


def scan_microseconds(env: Any, seconds: float) -> float:
    """CPU time [us] per env of the batched env's scan call alone (every sub-env)."""
    env.reset(seed=0)
    every = np.arange(env.num_envs)
    calls = 0
    start = time.process_time()
    while time.process_time() - start < seconds:
        env._observe(every)
        calls += 1
    return (time.process_time() - start) / calls / env.num_envs * 1e6


def traced_bytes_per_env(mode: str, num_envs: int) -> float:
    """Bytes ``tracemalloc`` sees allocated and kept by building and resetting the env, / N
    (numba's own allocations, e.g. its typed lists, are not traced)."""
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    env = make(mode, num_envs)
    env.reset(seed=0)
    after = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    del env
    return (after - before) / num_envs


def own_bytes_per_env(env: Any) -> float:
    """Bytes of the batched env's per-env state arrays and scenes (each shared scene once), / N."""
    arrays = [value for value in vars(env).values() if isinstance(value, np.ndarray)]
    return (sum(a.nbytes for a in arrays) + env._slots.nbytes() + env._crowds.nbytes()
            ) / env.num_envs


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="CPU seconds per figure")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 16, 64, 256])
    parser.add_argument("--moving-obstacles", type=int, default=0, help="movers per env")
    parser.add_argument("--mover-model", choices=MOVER_MODELS,
                        default="yielding")
    args = parser.parse_args(argv)
    BASE.clear()
    if args.moving_obstacles:
        BASE.update(moving_obstacles=args.moving_obstacles, mover_model=args.mover_model)
        print(f"every env: {args.moving_obstacles} {args.mover_model} moving obstacles")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{platform.python_implementation()} {platform.python_version()}, "
          f"gymnasium {gym.__version__}")
    print(f"{'N':>5} {'batched steps/s':>16} {'sync steps/s':>13} {'ratio':>6}")
    rates, ratios = {}, {}
    for n in args.sizes:
        batched = cpu_steps_per_second(make("vector_entry_point", n), args.seconds)
        sync = cpu_steps_per_second(make("sync", n), args.seconds)
        rates[n], ratios[n] = batched, batched / sync
        print(f"{n:>5} {batched:>16,.0f} {sync:>13,.0f} {batched / sync:>5.1f}x")
    n = max(args.sizes)
    noiseless = cpu_steps_per_second(make("vector_entry_point", n, NOISELESS), args.seconds)
    few_env = make("vector_entry_point", n, FEW_BEAMS)
    few = cpu_steps_per_second(few_env, args.seconds)
    few_scan = scan_microseconds(few_env.unwrapped, args.seconds)
    call_scan = scan_microseconds(make("vector_entry_point", n, FEW_BEAMS, **EMPTY_WORLD).unwrapped,
                                  args.seconds)
    full_us, noiseless_us, few_us = (1e6 / r for r in (rates[n], noiseless, few))
    print(f"\nper batched env step at N = {n} [us of CPU]: {full_us:.2f} in all =\n"
          f"  {full_us - noiseless_us:5.2f} the range noise (720 Gaussian draws, adding them)\n"
          f"  {noiseless_us - few_us:5.2f} the other 704 exact rays and their noise pass\n"
          f"  {few_scan - call_scan:5.2f} the scan's obstacles (2 Lidars x 8 beams: the circles and"
          " edges in range, their bearings, the inside-a-polygon test)\n"
          f"  {call_scan:5.2f} the scan call per env (2 Lidars x 8 beams, no obstacles: beam "
          "directions, grid bounds, readings)\n"
          f"  {few_us - few_scan:5.2f} motion, collision, progress, reward, infos and Python"
          + (" (the crowd's step and the scans' movers included)" if BASE else ""))
    print(f"  noiseless: {noiseless:,.0f} steps/s; 8-beam Lidars, noiseless: {few:,.0f} steps/s")
    if BASE:
        still = cpu_steps_per_second(make("vector_entry_point", n, {"moving_obstacles": 0}),
                                     args.seconds)
        print(f"  of which the crowd: {full_us - 1e6 / still:5.2f} (without movers: {still:,.0f}"
              " steps/s)")
    env = make("vector_entry_point", n)
    env.reset(seed=0)
    print(f"\nmemory per env at N = {n}: batched env arrays {own_bytes_per_env(env.unwrapped):,.0f}"
          f" B; traced by tracemalloc: batched {traced_bytes_per_env('vector_entry_point', n):,.0f}"
          f" B, sync {traced_bytes_per_env('sync', n):,.0f} B")
    for name, value, target in (("steps/s", rates[n], TARGET_STEPS_PER_SECOND),
                                ("ratio to sync", ratios[n], TARGET_RATIO)):
        verdict = "meets" if value >= target else "misses"
        print(f"target {name} >= {target:,g} at N = 256: {value:,.1f} at N = {n} {verdict} it")


if __name__ == "__main__":
    main()
