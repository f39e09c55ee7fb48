"""Speed of the dual-Lidar kernel against a per-beam pymunk ray-query loop on the same poses.

Run: ``python benchmarks/bench_lidar.py [--poses 300] [--seed 0]`` (about 15 s).

Then other layouts: 1, 2 and 4 Lidars of 360 degrees, and 1 x 180, 2 x 270 and
4 x 90 degrees, every scan of a car in one :meth:`lidar_env.sensors.lidar_layout.LidarLayout.scan`
call (the env's whole sensor model, float32 readings), against pymunk per beam. Target: >= 80x.

The worlds are built inline and bracket the built-in ones: 40 cylinders + 100 free-standing
walls, and 80 + 220, inside a 40 m x 40 m boundary (144 and 304 primitives), in which a 10 m
Lidar sees a fair share of the obstacles; and a 1000 x 1000 px occupancy map at 5 cm traced
by ``World.from_image`` (thousands of edges), the paper's kind of world. Both methods scan the
same random free car poses with the default mounts (lidar_1 at +0.25 m, lidar_2 at -0.25 m),
in turns (a block of kernel scans, then one pymunk scan), so a shared machine's load weighs on
both alike; their results are checked to agree.
"""

from __future__ import annotations

import argparse
import platform
import time

import numba
import numpy as np
import pymunk

from lidar_env.core.se2 import compose
from lidar_env.sensors.lidar import Lidar, cast_rays, pymunk_cast_rays
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout
from lidar_env.world.world import World

MOUNTS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])
#: Other layouts: K Lidars of their own fov, cast in one call by LidarLayout.scan.
LAYOUTS: dict[str, list[LidarConfig]] = {
    **{f"{k} x 360 deg": [LidarConfig((0.25 - 0.5 * j / max(k - 1, 1), 0.0, 0.0))
                          for j in range(k)] for k in (1, 2, 4)},
    "1 x 180 deg front": [LidarConfig((0.35, 0.0, 0.0), 181, np.pi)],
    "2 x 270 deg corners": [LidarConfig((0.35, 0.2, np.pi / 4), 271, 1.5 * np.pi),
                            LidarConfig((-0.35, -0.2, -0.75 * np.pi), 271, 1.5 * np.pi)],
    "4 x 90 deg corners": [LidarConfig((sx * 0.35, sy * 0.2, np.arctan2(sy, sx)), 91, np.pi / 2)
                           for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))],
}


def representative_world(rng: np.random.Generator, n_circles: int, n_walls: int) -> World:
    """Random circles and walls in a 40 m square with a boundary of 4 walls, in metres."""
    circles = np.column_stack(
        [rng.uniform(-18, 18, (n_circles, 2)), rng.uniform(0.15, 1.0, n_circles)]
    )
    starts = rng.uniform(-18, 18, (n_walls, 2))
    angles = rng.uniform(0, 2 * np.pi, n_walls)
    lengths = rng.uniform(0.5, 4.0, n_walls)
    ends = starts + lengths[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    corners = np.array([[-20, -20], [20, -20], [20, 20], [-20, 20]], dtype=float)
    boundary = np.hstack([corners, np.roll(corners, -1, axis=0)])
    return World(circles, np.vstack([np.hstack([starts, ends]), boundary]), name="bench")


def occupancy_map_world(rng: np.random.Generator, pixels: int = 1000) -> World:
    """A ``pixels`` x ``pixels`` occupancy image at 5 cm (the paper's kind of world map):
    a border wall, 150 discs and 60 rectangles, traced by :meth:`World.from_image`."""
    image = np.zeros((pixels, pixels), dtype=np.uint8)
    image[:8], image[-8:], image[:, :8], image[:, -8:] = 255, 255, 255, 255
    rows, cols = np.ogrid[:pixels, :pixels]
    for _ in range(150):
        r, c, radius = rng.integers(20, pixels - 20, 2).tolist() + [rng.integers(4, 20)]
        image[(rows - r) ** 2 + (cols - c) ** 2 < radius**2] = 255
    for _ in range(60):
        r, c = rng.integers(20, pixels - 60, 2)
        image[r : r + rng.integers(4, 50), c : c + rng.integers(4, 50)] = 255
    return World.from_image(image, 0.05, name="occupancy map")


def free_sensor_poses(world: World, rng: np.random.Generator, count: int) -> np.ndarray:
    """``(count, 2, 3)`` sensor poses of cars whose both Lidars have >= 0.3 m clearance."""
    xmin, ymin, xmax, ymax = world.bounds
    cars = np.column_stack(
        [rng.uniform(xmin + 1, xmax - 1, 20 * count), rng.uniform(ymin + 1, ymax - 1, 20 * count),
         rng.uniform(-np.pi, np.pi, 20 * count)]
    )
    sensors = np.stack([compose(cars, mount) for mount in MOUNTS], axis=1)
    clear = np.all(world.clearance(sensors[..., :2].reshape(-1, 2)).reshape(-1, 2) > 0.3, axis=1)
    if clear.sum() < count:
        raise RuntimeError(f"found only {clear.sum()} free poses, wanted {count}")
    return sensors[clear][:count]


def machine() -> str:
    """CPU model (from /proc/cpuinfo where available), OS and library versions."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as info:
            cpu = next(line.split(":", 1)[1].strip() for line in info if "model name" in line)
    except (OSError, StopIteration):
        pass
    return (f"{cpu}, {platform.system()}, python {platform.python_version()}, "
            f"numba {numba.__version__}, numpy {np.__version__}, pymunk {pymunk.version}")


def interleaved_cpu(fast, reference, poses: np.ndarray, repeats: int = 5,
                    block: int = 10) -> tuple[float, float]:
    """CPU time [us] per call of ``fast(pose)`` and of ``reference(pose)``, measured in turns:
    for each block of ``block`` poses, ``fast`` on all of them ``repeats`` times (after one
    untimed pass, as the env scans step after step with warm caches), then ``reference`` on the
    block's first, so a neighbour's load on a shared machine weighs on both alike."""
    fast_cpu = reference_cpu = 0.0
    fast_calls = reference_calls = 0
    for start in range(0, len(poses), block):
        part = poses[start:start + block]
        for pose in part:
            fast(pose)
        cpu = time.process_time()
        for _ in range(repeats):
            for pose in part:
                fast(pose)
        fast_cpu += time.process_time() - cpu
        fast_calls += repeats * len(part)
        cpu = time.process_time()
        reference(part[0])
        reference_cpu += time.process_time() - cpu
        reference_calls += 1
    return fast_cpu / fast_calls * 1e6, reference_cpu / reference_calls * 1e6


def bench_world(world: World, sensors: np.ndarray, lidar: Lidar) -> None:
    """Time both methods on the same sensor poses and print one block of figures.

    Also times the whole sensor model, ``lidar.scan`` (exact ranges, the Gaussian draws from a
    generator, noise, clipping and float32 readings), as the env calls it every step.
    """
    angles, max_range = lidar.beam_angles, lidar.max_range
    rng = np.random.default_rng(0)
    cast_rays(world, sensors[0], angles, max_range)  # compile (or load the numba cache)
    lidar.scan(world, sensors[0], rng)
    space = world.build_space()
    # CPU time (process_time) is the headline: the machine may be shared, and wall time then
    # measures the neighbours.
    kernel_cpu, pymunk_cpu = interleaved_cpu(
        lambda pair: cast_rays(world, pair, angles, max_range),
        lambda pair: pymunk_cast_rays(space, pair, angles, max_range), sensors)
    model_cpu, _ = interleaved_cpu(lambda pair: lidar.scan(world, pair, rng), lambda _: None,
                                   sensors)
    reference_poses = sensors[::10]
    kernel = [cast_rays(world, pair, angles, max_range) for pair in reference_poses]
    reference = [pymunk_cast_rays(space, pair, angles, max_range) for pair in reference_poses]
    worst = max(np.max(np.abs(a - b)) for a, b in zip(kernel, reference, strict=True))
    seen = np.mean(np.array(kernel) < max_range)
    print(f"\nworld: {len(world.circles)} circles + {len(world.segments)} segments; "
          f"{len(sensors)} car poses, 2 x {len(angles)} beams, max_range {max_range} m, "
          f"{seen:.0%} of beams hit")
    print("per dual scan:                      CPU [us]")
    print(f"cast_rays (both scans, one call): {kernel_cpu:10.1f}")
    print(f"Lidar.scan, {lidar.noise_std:g} m noise:         {model_cpu:10.1f}")
    print(f"pymunk segment_query_first loop:  {pymunk_cpu:10.1f}   ({len(reference_poses)} poses,"
          f" in turns with the kernel)")
    print(f"speed-up: {pymunk_cpu / kernel_cpu:.0f}x CPU   (max |difference| {worst:.1e} m)")


def bench_layout(world: World, cars: np.ndarray, name: str, lidars: list[LidarConfig]) -> float:
    """Time :meth:`LidarLayout.scan` (all K scans in one call, noiseless) against pymunk's
    per-beam queries for each Lidar, on the same car poses in turns; print one line and return
    the speed-up."""
    layout = LidarLayout.exact(lidars)
    sensors = np.stack([compose(cars, np.array(lidar.mount)) for lidar in lidars], axis=1)
    clear = np.all(world.clearance(sensors[..., :2].reshape(-1, 2)).reshape(len(cars), -1) > 0.05,
                   axis=1)
    sensors = np.ascontiguousarray(sensors[clear])
    rng = np.random.default_rng(0)
    layout.scan(world, sensors[0], rng)  # compile (or load the numba cache)
    space = world.build_space()

    def reference(poses: np.ndarray) -> list[np.ndarray]:
        return [pymunk_cast_rays(space, poses[k], lidar.beam_angles, lidar.max_range)[0]
                for k, lidar in enumerate(lidars)]

    kernel_cpu, pymunk_cpu = interleaved_cpu(lambda poses: layout.scan(world, poses, rng),
                                             reference, sensors)
    worst = max(np.max(np.abs(a - b)) for poses in sensors[::10]
                for a, b in zip(layout.scan(world, poses, rng), reference(poses), strict=True))
    beams = sum(lidar.n_beams for lidar in lidars)
    print(f"{name:<22} {beams:5d} beams  kernel {kernel_cpu:8.1f} us  pymunk {pymunk_cpu:9.1f} us"
          f"  speed-up {pymunk_cpu / kernel_cpu:5.0f}x CPU  (max |difference| {worst:.1e} m,"
          f" float32 readings)")
    return pymunk_cpu / kernel_cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=300, help="car poses (dual scans) to time")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    print(f"machine: {machine()}")
    rng = np.random.default_rng(args.seed)
    lidar = Lidar(noise_std=0.01)  # the env's default noise; cast_rays ignores it
    for n_circles, n_walls in ((40, 100), (80, 220)):
        world = representative_world(rng, n_circles, n_walls)
        bench_world(world, free_sensor_poses(world, rng, args.poses), lidar)
    world = occupancy_map_world(rng)
    bench_world(world, free_sensor_poses(world, rng, args.poses), lidar)
    print("\nother layouts, all K scans in one LidarLayout.scan call, on the 80 + 220 world and "
          "the occupancy map:")
    dense = representative_world(np.random.default_rng(args.seed + 1), 80, 220)
    for scanned in (dense, world):
        cars = free_sensor_poses(scanned, rng, args.poses)[:, 0, :]  # lidar_1 poses as cars
        print(f"world: {len(scanned.circles)} circles + {len(scanned.segments)} segments")
        ratios = {name: bench_layout(scanned, cars, name, lidars)
                  for name, lidars in LAYOUTS.items()}
        short = [name for name, ratio in ratios.items() if ratio < 80]
        print(f"  target >= 80x: {len(ratios) - len(short)} of {len(ratios)} layouts"
              + (f" (short: {', '.join(short)})" if short else ""))

if __name__ == "__main__":
    main()
