"""Speed of the batched ``DualLidar-v0`` against ``SyncVectorEnv`` over N single envs.

Prints, in one run on this machine:

* env steps/s (CPU time of this process, ``time.process_time``; random actions, autoresets
  included) of ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` and of
  ``vectorization_mode="sync"`` at N = 1, 16, 64, 256, and their ratio (the two timed in
  alternating slices of 50 ms, so load from other work on the machine falls on both alike);
* where a batched env step goes at the largest N [us per env step]: the scan call alone
  (every sub-env, 50 random steps after a reset) of the default Lidars, of the same without
  range noise, of noiseless 8-beam Lidars and of those in a world with no obstacles, so the
  differences are the noise, the exact rays, the obstacles in range and the cost per call;
  the noise split into its Gaussian draws alone (a compiled loop drawing them as the scan
  does) and the rest; the step's remainder split into its Python (the action conversion,
  observation copies, infos) and the compiled action check, motion, collision, progress and
  reward (every figure of the split, the whole step included, timed in one run of
  alternating slices, so their differences see the same load); the whole step against what
  the draws and the noiseless scan alone take; and the batched env in a large map (2,000
  walls);
* memory per env: the batched env's own arrays (``nbytes``) and what ``tracemalloc`` sees
  allocated by building and resetting each kind of vector env, divided by N.

``--moving-obstacles M`` (and ``--mover-model``) runs every figure with M pedestrians per env
(``config["moving_obstacles"]``) and adds the batched env without them at the largest N, so the
difference is the crowd's cost (the movers' step, the car's collision checks among them, their
circles in the scans).

Also the single env (``gym.make``, its default wrappers, reset when an episode ends) against
the batched env at N = 1, measured the same way.

Targets, each a ratio measured in the same run: >= 8x ``SyncVectorEnv`` at N = 256, and the
batched env at N = 1 at least as fast as the single env.

Run: ``python benchmarks/bench_vector_env.py [--seconds 2] [--sizes 1 16 64 256]
[--moving-obstacles 10] [--mover-model yielding|waypoints] [--json OUT]`` (``--json`` writes
every figure and each target's verdict; ``python benchmarks/publish.py vector`` publishes them)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numba import njit
from numpy.typing import NDArray

import lidar_env  # registers DualLidar-v0
from lidar_env.config import MOVER_MODELS
from lidar_env.vector.draws import fill_standard_normal_pair, fill_standard_normals
from lidar_env.world.world import World

TARGET_RATIO = 8.0
#: The batched env at N = 1 against the single env.
TARGET_SINGLE_RATIO = 1.0
#: Noiseless Lidars of 8 beams: what is left of a step without draws and with few rays.
FEW_BEAMS = {"lidars": [{"mount": (0.25, 0.0, 0.0), "n_beams": 8, "range_noise_std": 0.0},
                        {"mount": (-0.25, 0.0, 0.0), "n_beams": 8, "range_noise_std": 0.0}]}
#: The default Lidars without range noise.
NOISELESS = {"lidars": lidar_env.lidars_with_noise(range_noise_std=0.0)}
#: [m] a 60 m square with nothing in it, driven along its middle: a scan with no primitives.
EMPTY_WORLD = {"world": World(np.empty((0, 3)), np.empty((0, 4)), bounds=(0.0, 0.0, 60.0, 60.0)),
               "trace": np.array([[5.0, 30.0], [55.0, 30.0]])}




def cluttered_world(walls: int, seed: int = 0) -> dict[str, Any]:
    """``world`` and ``trace`` kwargs: EMPTY_WORLD's 60 m square strewn with ``walls`` 0.5 m
    walls (none within 3 m of its middle line, the trace): a large map's many primitives."""
    rng = np.random.default_rng(seed)
    starts = rng.uniform(0.0, 60.0, (3 * walls, 2))
    starts = starts[np.abs(starts[:, 1] - 30.0) > 3.0][:walls]
    angles = rng.uniform(0.0, np.pi, len(starts))
    ends = starts + 0.5 * np.column_stack([np.cos(angles), np.sin(angles)])
    return {"world": World(np.empty((0, 3)), np.hstack([starts, ends]),
                           bounds=(0.0, 0.0, 60.0, 60.0)), "trace": EMPTY_WORLD["trace"]}


#: Config keys every env of the run gets (the movers of ``--moving-obstacles``).
BASE: dict[str, Any] = {}


def make(mode: str, num_envs: int, config: dict[str, Any] | None = None,
         **kwargs: Any) -> gym.vector.VectorEnv:
    return gym.make_vec("DualLidar-v0", num_envs=num_envs, vectorization_mode=mode,
                        config={**BASE, **(config or {})}, **kwargs)


def single_stepper(seed: int = 0) -> Callable[[], int]:
    """One step of a ``gym.make`` env per call (random actions, reset when an episode ends);
    returns the env steps taken (1). One step is taken first, so compiling (or loading the
    numba cache) is not timed."""
    env = gym.make("DualLidar-v0", config=dict(BASE) or None)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(64)]
    env.step(actions[0])
    steps = 0

    def step() -> int:
        nonlocal steps
        _, _, terminated, truncated, _ = env.step(actions[steps % len(actions)])
        if terminated or truncated:
            env.reset()
        steps += 1
        return 1

    return step


def vector_stepper(env: gym.vector.VectorEnv, seed: int = 0) -> Callable[[], int]:
    """One step of ``env`` per call (random actions, autoreset included); returns the env
    steps taken (N). One step is taken first, as :func:`single_stepper`."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(64)]
    env.step(actions[0])
    steps = 0

    def step() -> int:
        nonlocal steps
        env.step(actions[steps % len(actions)])
        steps += 1
        return env.num_envs

    return step


def cpu_steps_per_second(*steppers: Callable[[], int], seconds: float,
                         slice_seconds: float = 0.05) -> list[float]:
    """Env steps per CPU second of each stepper, timed in alternating slices of about
    ``slice_seconds`` each until each has had ``seconds``: on a machine shared with other
    work, the envs compared see the same load, so their ratio does not follow it."""
    steps, spent = [0] * len(steppers), [0.0] * len(steppers)
    while min(spent) < seconds:
        for k, step in enumerate(steppers):
            start = time.process_time()
            while time.process_time() - start < slice_seconds:
                steps[k] += step()
            spent[k] += time.process_time() - start
    return [count / cpu for count, cpu in zip(steps, spent, strict=True)]


def scan_call(env: Any, warmup_steps: int = 50) -> Callable[[], int]:
    """The batched env's scan call alone (every sub-env) per call, at the poses
    ``warmup_steps`` random steps after a reset (where the timed loop's cars are, not at their
    starts); returns N, the envs scanned."""
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(warmup_steps):
        env.step(env.action_space.sample())
    every = np.arange(env.num_envs)
    env._observe(every)

    def scan() -> int:
        env._observe(every)
        return env.num_envs

    return scan


@njit(cache=True)
def draw_standard_normals(items: Any, out: NDArray[np.float64],
                          other_out: NDArray[np.float64]) -> None:
    """``out`` and ``other_out`` (n,) overwritten with n standard normals from each sub-env's
    generator (its state words, the last of its item in ``items``,
    :attr:`lidar_env.vector.slots.SceneSlots.scene`'s typed list), two sub-envs at a time, drawn
    as :func:`lidar_env.vector.kernel.observe_envs` draws them."""
    count = len(items)
    for i in range(0, count - 1, 2):
        fill_standard_normal_pair(items[i][5], out, items[i + 1][5], other_out)
    if count % 2:
        fill_standard_normals(items[count - 1][5], out)


def draw_call(env: Any) -> Callable[[], int]:
    """The range noise's draws alone per call: one standard normal per beam from each sub-env's
    generator, as the batched scan draws them (compiled PCG64 draws, bit-identical to numpy's
    ``Generator.standard_normal``); returns N."""
    env.reset(seed=0)
    out = np.empty(env._scans.shape[1]), np.empty(env._scans.shape[1])  # one per beam
    draw_standard_normals(env._slots.scene[0], *out)

    def draw() -> int:
        draw_standard_normals(env._slots.scene[0], *out)
        return env.num_envs

    return draw


def python_call(env: Any) -> Callable[[], int]:
    """A batched step's Python around its compiled call, per call: the action conversion, the
    observation copies and the infos (the action check itself is compiled, in the step's one
    call); returns N."""
    env.reset(seed=0)
    actions = np.zeros((env.num_envs, 2), np.float32)

    def outputs() -> int:
        env._actions(actions)
        env._observation()
        env._infos(None)
        env._rewards.copy(), env._terminations.copy(), env._truncations.copy()
        return env.num_envs

    return outputs


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


def speeds(sizes: list[int], seconds: float) -> dict[str, Any]:
    """Batched and sync steps/s at each N, and the single env against the batched env at N = 1,
    printed as measured."""
    print(f"{'N':>5} {'batched steps/s':>16} {'sync steps/s':>13} {'ratio':>6}")
    by_size = {}
    for n in sizes:
        batched, sync = cpu_steps_per_second(vector_stepper(make("vector_entry_point", n)),
                                             vector_stepper(make("sync", n)), seconds=seconds)
        by_size[str(n)] = {"batched": batched, "sync": sync, "ratio": batched / sync}
        print(f"{n:>5} {batched:>16,.0f} {sync:>13,.0f} {batched / sync:>5.1f}x")
    single, one = cpu_steps_per_second(single_stepper(),
                                       vector_stepper(make("vector_entry_point", 1)),
                                       seconds=seconds)
    print(f"single env (gym.make): {single:,.0f} steps/s; the batched env at N = 1: {one:,.0f} "
          f"steps/s, {one / single:.2f}x")
    return {"sizes": by_size, "single": {"single": single, "batched": one, "ratio": one / single}}


def split(n: int, seconds: float) -> dict[str, float]:
    """Where a batched env step goes at N = ``n`` [us of CPU per env step], printed."""
    scans = [scan_call(make("vector_entry_point", n, config, **kwargs).unwrapped)
             for config, kwargs in ((None, {}), (NOISELESS, {}), (FEW_BEAMS, {}),
                                    (FEW_BEAMS, EMPTY_WORLD))]
    # every figure of the split in one interleaved run: their differences see the same load
    rates_split = cpu_steps_per_second(
        vector_stepper(make("vector_entry_point", n)), *scans,
        draw_call(make("vector_entry_point", n).unwrapped),
        python_call(make("vector_entry_point", n).unwrapped),
        vector_stepper(make("vector_entry_point", n, NOISELESS)),
        vector_stepper(make("vector_entry_point", n, FEW_BEAMS)), seconds=seconds)
    full_us, full_scan, noiseless_scan, few_scan, call_scan, draws, python = (
        1e6 / rate for rate in rates_split[:7])
    noiseless, few = rates_split[7:]
    figures = {"step": full_us, "noise_draws": draws,
               "noise_rest": full_scan - noiseless_scan - draws,
               "exact_rays": noiseless_scan - few_scan, "obstacles": few_scan - call_scan,
               "scan_call": call_scan, "compiled_rest": full_us - full_scan - python,
               "python": python}
    print(f"\nper batched env step at N = {n} [us of CPU]: {full_us:.2f} in all =\n"
          f"  {draws:5.2f} the 720 Gaussian draws of the range noise alone (compiled PCG64 "
          "ziggurat over each sub-env's generator state)\n"
          f"  {figures['noise_rest']:5.2f} the rest of the noise (adding it; the "
          "draws in the scan beyond a bare loop of them)\n"
          f"  {figures['exact_rays']:5.2f} the other 704 exact rays and their readings\n"
          f"  {figures['obstacles']:5.2f} the scan's obstacles (2 Lidars x 8 beams: the circles "
          "and edges in range, their bearings, the inside-a-polygon test)\n"
          f"  {call_scan:5.2f} the scan call per env (2 Lidars x 8 beams, no obstacles: beam "
          "directions, grid bounds, readings)\n"
          f"  {figures['compiled_rest']:5.2f} action check, motion, collision, progress, "
          "reward (compiled)"
          + (" (the crowd's step and the scans' movers included)" if BASE else "") + "\n"
          f"  {python:5.2f} Python: the action conversion, observation copies, infos\n"
          "  (the scan figures are the scan call alone, 50 random steps into the episodes; the "
          "rest the step's)")
    print(f"  the step's {full_us:.2f} us against the draws and the noiseless scan alone: "
          f"{draws:.2f} + {noiseless_scan:.2f} = {draws + noiseless_scan:.2f} us")
    print(f"  noiseless: {noiseless:,.0f} steps/s; 8-beam Lidars, noiseless: {few:,.0f} steps/s")
    if BASE:
        still, = cpu_steps_per_second(
            vector_stepper(make("vector_entry_point", n, {"moving_obstacles": 0})),
            seconds=seconds)
        figures["crowd"] = full_us - 1e6 / still
        print(f"  of which the crowd: {figures['crowd']:5.2f} (without movers: {still:,.0f}"
              " steps/s)")
    cluttered, = cpu_steps_per_second(
        vector_stepper(make("vector_entry_point", n, **cluttered_world(2000))), seconds=seconds)
    print(f"  in a 60 m square of 2,000 short walls: {cluttered:,.0f} steps/s")
    return figures


def targets(speed: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Each target with the figure measured for it (at the largest N run) and whether it is met,
    printed."""
    at_n = speed["sizes"][str(n)]
    found = [{"target": f"batched / SyncVectorEnv at N = 256 >= {TARGET_RATIO:g}",
              "n": n, "value": at_n["ratio"], "threshold": TARGET_RATIO},
             {"target": f"batched at N = 1 / single env >= {TARGET_SINGLE_RATIO:g}",
              "n": 1, "value": speed["single"]["ratio"], "threshold": TARGET_SINGLE_RATIO}]
    for target in found:
        target["met"] = bool(target["value"] >= target["threshold"])
        print(f"target {target['target']}: {target['value']:,.2f} at N = {target['n']} "
              f"{'meets' if target['met'] else 'misses'} it")
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--seconds", type=float, default=2.0, help="CPU seconds per figure")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 16, 64, 256],
                        help="the N of the batched and sync envs compared")
    parser.add_argument("--moving-obstacles", type=int, default=0, help="movers per env")
    parser.add_argument("--mover-model", choices=MOVER_MODELS, default="yielding")
    parser.add_argument("--json", type=Path, default=None,
                        help="also write every figure here (steps/s, split, memory, targets)")
    args = parser.parse_args(argv)
    if args.seconds <= 0:
        parser.error(f"--seconds: expected a positive duration, got {args.seconds}")
    if min(args.sizes) < 1:
        parser.error(f"--sizes: expected counts >= 1, got {min(args.sizes)}")
    BASE.clear()
    if args.moving_obstacles:
        BASE.update(moving_obstacles=args.moving_obstacles, mover_model=args.mover_model)
        print(f"every env: {args.moving_obstacles} {args.mover_model} moving obstacles")
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
               f"{platform.python_implementation()} {platform.python_version()}, "
               f"gymnasium {gym.__version__}")
    print(f"machine: {machine}")
    speed = speeds(args.sizes, args.seconds)
    n = max(args.sizes)
    step_split = split(n, args.seconds)
    env = make("vector_entry_point", n)
    env.reset(seed=0)
    memory = {"batched_arrays": own_bytes_per_env(env.unwrapped),
              "traced_batched": traced_bytes_per_env("vector_entry_point", n),
              "traced_sync": traced_bytes_per_env("sync", n)}
    print(f"\nmemory per env at N = {n}: batched env arrays {memory['batched_arrays']:,.0f} B; "
          f"traced by tracemalloc: batched {memory['traced_batched']:,.0f} B, sync "
          f"{memory['traced_sync']:,.0f} B")
    report = {"machine": machine, "seconds": args.seconds, "config": dict(BASE), **speed,
              "split_us_per_step": step_split, "bytes_per_env": memory,
              "targets": targets(speed, n)}
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
