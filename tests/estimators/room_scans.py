"""A test scene shared by the scan-matching tests: a 16 m x 10 m room with an inner wall and a
few pillars, and noisy 360-beam scans of it ray-cast at any pose (car frame, metres)."""

from __future__ import annotations

import numpy as np

from estimators.matching.scan_matching import scan_to_points
from lidar_env.sensors.lidar import cast_rays

ANGLES = 2 * np.pi * np.arange(360) / 360
MAX_RANGE = 12.0


def room() -> tuple[np.ndarray, np.ndarray]:
    """A 16 m x 10 m room with an inner wall and a few pillars (circles x, y, r; segments)."""
    walls = np.array([[0, 0, 16, 0], [16, 0, 16, 10], [16, 10, 0, 10], [0, 10, 0, 0],
                      [6, 0, 6, 4], [10, 10, 10, 7]], dtype=float)
    pillars = np.array([[3, 7, 0.4], [12, 3, 0.3], [8.5, 5.5, 0.5], [13.5, 8, 0.25]])
    return pillars, walls


def scan_points(pose: np.ndarray, rng: np.random.Generator, noise: float = 0.01) -> np.ndarray:
    """Car-frame points of one noisy 360-beam scan taken at world ``pose``."""
    ranges = cast_rays(room(), pose, ANGLES, MAX_RANGE)[0]
    ranges = np.where(ranges < MAX_RANGE, ranges + rng.normal(0, noise, ranges.shape), ranges)
    return scan_to_points(ranges, ANGLES, MAX_RANGE)
