"""Loading a large ROS map_server map and scanning it: ``World.from_ros_map`` on a
2000 x 2000 px map (5 cm: 100 m x 100 m of rooms, walls, pillars, unknown border), then the
exact Lidar against pymunk's ``segment_query_first`` on the world it gives.

Targets: load <= 5 s; scans agree with pymunk to <= 1e-6 m. The load time is split
into reading the PGM/YAML and tracing the outlines (``World.from_image``), CPU time.

    python benchmarks/bench_ros_map.py [--pixels 2000] [--poses 20] [--seed 0]
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from lidar_env.sensors.lidar import cast_rays, pymunk_cast_rays
from lidar_env.world.ros_map import read_ros_map, save_ros_map
from lidar_env.world.world import World


def building(pixels: int, rng: np.random.Generator) -> np.ndarray:
    """``(pixels, pixels)`` occupancy probabilities: an unknown border, a grid of rooms with
    doors, and pillars (NaN = unknown, 0.05 free, 0.95 occupied)."""
    grid = np.full((pixels, pixels), 0.05)
    grid[:20], grid[-20:], grid[:, :20], grid[:, -20:] = np.nan, np.nan, np.nan, np.nan
    for k in range(100, pixels - 50, 200):
        grid[k:k + 4, 20:-20] = 0.95
        grid[20:-20, k:k + 4] = 0.95
        for d in range(150, pixels - 50, 200):
            grid[k:k + 4, d:d + 30] = 0.05  # doors
            grid[d:d + 30, k:k + 4] = 0.05
    rows, cols = np.ogrid[:pixels, :pixels]
    for _ in range(pixels // 10):
        r, c = rng.integers(30, pixels - 30, 2)
        grid[(rows - r) ** 2 + (cols - c) ** 2 < rng.integers(9, 64)] = 0.95
    return grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pixels", type=int, default=2000)
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}")
    with tempfile.TemporaryDirectory() as folder:
        yaml_path, _ = save_ros_map(Path(folder) / "building.yaml",
                                    building(args.pixels, rng), 0.05)
        cpu = time.process_time()
        ros = read_ros_map(yaml_path)
        read_s = time.process_time() - cpu
        cpu = time.process_time()
        world = World.from_ros_map(ros)
        trace_s = time.process_time() - cpu
    print(f"{args.pixels} x {args.pixels} px map: read {read_s:.2f} s, traced into "
          f"{len(world.segments)} edges in {trace_s:.2f} s; from_ros_map total "
          f"{read_s + trace_s:.2f} s CPU (target <= 5 s)")
    xmin, ymin, xmax, ymax = world.bounds
    candidates = np.column_stack([rng.uniform(xmin, xmax, 50 * args.poses),
                                  rng.uniform(ymin, ymax, 50 * args.poses),
                                  rng.uniform(-np.pi, np.pi, 50 * args.poses)])
    poses = candidates[world.clearance(candidates[:, :2]) > 0.3][: args.poses]
    angles = 2 * np.pi * np.arange(360) / 360
    exact = cast_rays(world, poses, angles, 10.0)
    oracle = pymunk_cast_rays(world.build_space(), poses, angles, 10.0)
    print(f"{len(poses)} poses x 360 beams: max |cast_rays - pymunk| = "
          f"{np.max(np.abs(exact - oracle)):.1e} m (target <= 1e-6 m), "
          f"{np.mean(exact < 10.0):.0%} of beams hit")


if __name__ == "__main__":
    main()
