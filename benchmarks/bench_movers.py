"""Speed of the Lidar scan among 20 moving obstacles against per-beam pymunk ray queries.

Run: ``python benchmarks/bench_movers.py [--poses 200] [--movers 20] [--seed 0]`` (about 30 s).

Target: the compiled scan (both default 360-beam Lidars in one
:meth:`lidar_env.sensors.lidar_layout.LidarLayout.scan` call, float32 readings) stays >= 80x faster
than pymunk's ``segment_query_first`` per beam with 20 movers in view, the movers added to pymunk's
space as circles. Both scan the same random free car poses, each with its own 20 movers of
0.25 m radius scattered within 8 m of the car (free of the obstacles and of each other), so many
beams end on a mover; the results are checked to agree. The worlds are bench_lidar's two
representative ones (40 + 104 and 80 + 224 primitives) and the built-in ``open_cylinders`` and
``hallway``. CPU time (``time.process_time``), one core; wall time drops under load.

Then the whole env step among 0, 10 and 20 movers (crowd simulation, collision among movers,
scans, info) in ``open_cylinders``, as steps per second, for both mover models ("waypoints"
and "yielding", which also keep clear of the car).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import pymunk
from bench_lidar import machine, representative_world

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.config import EnvConfig
from lidar_env.core.se2 import compose
from lidar_env.sensors.lidar import pymunk_cast_rays
from lidar_env.sensors.lidar_layout import LidarLayout
from lidar_env.world.built_in import make_world
from lidar_env.world.world import World

RADIUS = 0.25  # [m] the env's default mover radius


def cars_with_movers(world: World, rng: np.random.Generator, count: int, movers: int
                     ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` (sensor poses (2, 3), movers (M, 3)) pairs: car poses whose Lidars have
    0.3 m clearance, each with ``movers`` free circles within 8 m of the car."""
    mounts = EnvConfig().mounts_array
    xmin, ymin, xmax, ymax = world.bounds
    found = []
    while len(found) < count:
        car = np.array([rng.uniform(xmin + 1, xmax - 1), rng.uniform(ymin + 1, ymax - 1),
                        rng.uniform(-np.pi, np.pi)])
        sensors = np.stack([compose(car, mount) for mount in mounts])
        if np.any(world.clearance(sensors[:, :2]) <= 0.3):
            continue
        circles: list[np.ndarray] = []
        for _ in range(50 * movers):
            if len(circles) == movers:
                break
            angle, distance = rng.uniform(-np.pi, np.pi), rng.uniform(1.0, 8.0)
            point = car[:2] + distance * np.array([np.cos(angle), np.sin(angle)])
            if world.clearance(point[None])[0] <= RADIUS + 0.05:
                continue
            if any(np.hypot(*(point - c[:2])) <= 2 * RADIUS + 0.05 for c in circles):
                continue
            circles.append(np.array([*point, RADIUS]))
        if len(circles) == movers:
            found.append((sensors, np.array(circles)))
    return found


def bench_world(name: str, world: World, cases: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """Time the scan with and without movers and pymunk per beam; print one line, return the
    speed-up."""
    cfg = EnvConfig()
    layout = LidarLayout.exact(cfg.lidars)
    rng = np.random.default_rng(0)
    layout.scan(world, cases[0][0], rng, cases[0][1])  # compile (or load the numba cache)
    layout.scan(world, cases[0][0], rng)
    repeats = 5
    cpu = time.process_time()
    for _ in range(repeats):
        scans = [layout.scan(world, sensors, rng, movers) for sensors, movers in cases]
    with_movers = (time.process_time() - cpu) / (repeats * len(cases)) * 1e6
    cpu = time.process_time()
    for _ in range(repeats):
        for sensors, _ in cases:
            layout.scan(world, sensors, rng)
    without = (time.process_time() - cpu) / (repeats * len(cases)) * 1e6

    count = max(1, len(cases) // 10)
    spaces = []
    for _, movers in cases[:count]:
        space = world.build_space()
        for x, y, r in movers:
            space.add(pymunk.Circle(space.static_body, float(r), offset=(float(x), float(y))))
        spaces.append(space)
    cpu = time.process_time()
    reference = [[pymunk_cast_rays(space, sensors[k], lidar.beam_angles, lidar.max_range)[0]
                  for k, lidar in enumerate(cfg.lidars)]
                 for space, (sensors, _) in zip(spaces, cases, strict=False)]
    pymunk_cpu = (time.process_time() - cpu) / count * 1e6
    worst = max(np.max(np.abs(a - b)) for got, want in zip(scans, reference, strict=False)
                for a, b in zip(got, want, strict=True))
    static = LidarLayout.exact(cfg.lidars)
    on_movers = np.mean([np.mean(np.concatenate(got) < np.concatenate(
        static.scan(world, sensors, rng)) - 1e-6) for got, (sensors, _) in zip(scans, cases,
                                                                                strict=True)])
    ratio = pymunk_cpu / with_movers
    print(f"{name:<34} scan {with_movers:7.1f} us (no movers {without:6.1f})  pymunk "
          f"{pymunk_cpu:8.1f} us  speed-up {ratio:5.0f}x CPU  ({on_movers:.0%} of beams on a "
          f"mover, max |difference| {worst:.1e} m)")
    return ratio


def bench_env(movers: int, steps: int = 2000, model: str = "waypoints") -> None:
    """Steps per second of the whole env among ``movers`` movers walking by ``model``."""
    env = gym.make("DualLidar-v0", world="open_cylinders",
                   config={"moving_obstacles": movers, "mover_model": model}).unwrapped
    env.reset(seed=0)
    action = np.array([0.3, 0.0], dtype=np.float32)
    for _ in range(20):  # compile
        env.step(action)
    done, cpu = 0, time.process_time()
    while done < steps:
        _, _, terminated, truncated, _ = env.step(action)
        done += 1
        if terminated or truncated:
            env.reset()
    per_step = (time.process_time() - cpu) / steps * 1e6
    print(f"env step among {movers:2d} {model:9s} movers: {per_step:7.1f} us  "
          f"({1e6 / per_step:8,.0f} steps/s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=200, help="car poses (dual scans) to time")
    parser.add_argument("--movers", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"machine: {machine()}")
    rng = np.random.default_rng(args.seed)
    worlds = {
        "40 circles + 104 segments": representative_world(rng, 40, 100),
        "80 circles + 224 segments": representative_world(rng, 80, 220),
        "open_cylinders (120 circles)": make_world("open_cylinders"),
        "hallway (12 walls)": make_world("hallway"),
    }
    print(f"dual 360-beam scan among {args.movers} movers of {RADIUS} m, {args.poses} poses:")
    ratios = [bench_world(name, world, cars_with_movers(world, rng, args.poses, args.movers))
              for name, world in worlds.items()]
    print(f"lowest speed-up {min(ratios):.0f}x (target >= 80x)")
    bench_env(0)
    for movers in (10, 20):
        for model in ("waypoints", "yielding"):
            bench_env(movers, model=model)


if __name__ == "__main__":
    main()
