"""``World.from_image`` on speckle: is tracing near-linear in the image size?

Times 5 % random speckle at 250 x 250 (the reference, measured in the same run) and 1000 x
1000 px (16x the pixels) and prints the CPU-time ratio: about 16 for a linear tracer
(pymunk's ``march_hard`` gives ~150 s at 1000 x 1000).

    .venv/bin/python benchmarks/bench_from_image.py
"""

from __future__ import annotations

import platform
import time

import numpy as np

from lidar_env.world.world import World


def cpu_seconds(side: int) -> tuple[float, int]:
    image = np.random.default_rng(0).random((side, side)) < 0.05
    start = time.process_time()
    world = World.from_image(image, 0.05)
    return time.process_time() - start, len(world.polygons)


def main() -> None:
    reference, _ = cpu_seconds(250)
    large, polygons = cpu_seconds(1000)
    print(f"from_image 1000x1000 speckle: {large:.2f} s CPU, {polygons} polygons; "
          f"250x250 reference {reference:.2f} s; ratio {large / reference:.1f} for 16x the "
          f"pixels (linear: 16) on {platform.machine()} {platform.python_version()}")


if __name__ == "__main__":
    main()
