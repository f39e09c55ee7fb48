"""The vectorised circle windows of :func:`lidar_env.sensors.ray_casting.sweep_circles` are the
one-circle forms' values bit for bit: :func:`~lidar_env.sensors.ray_casting._circle_windows`
against :func:`~lidar_env.sensors.ray_casting._circle_window` called per circle, and the
branch-free :func:`~lidar_env.sensors.ray_casting._wrap_positive` against the plain loop."""

from __future__ import annotations

import math

import numpy as np

from lidar_env.sensors.ray_casting import _circle_window, _circle_windows, _wrap_positive


def looped_wrap(angle: float) -> float:
    """The plain form: whole turns added, then taken off, one at a time."""
    while angle < 0.0:
        angle += 2.0 * math.pi
    while angle >= 2.0 * math.pi:
        angle -= 2.0 * math.pi
    return angle


def test_the_branch_free_wrap_is_the_loops_wrap() -> None:
    rng = np.random.default_rng(0)
    two_pi = 2.0 * math.pi
    angles = np.concatenate([rng.uniform(-2.0 * two_pi, 2.0 * two_pi, 20_000),
                             [0.0, -0.0, -1e-300, -1e-17, two_pi, -two_pi, 2.0 * two_pi - 1e-15,
                              -2.0 * two_pi, np.nextafter(two_pi, 0.0), np.nextafter(0.0, -1.0)]])
    for angle in angles:
        assert _wrap_positive(angle) == looped_wrap(angle), angle


def test_all_circles_windows_at_once_are_each_circles_own() -> None:
    rng = np.random.default_rng(1)
    count = 5_000
    near = np.zeros((6, count + 3))
    near[0], near[1] = rng.uniform(-12.0, 12.0, count + 3), rng.uniform(-12.0, 12.0, count + 3)
    near[2] = rng.uniform(0.0, 1.0, count + 3)
    for ox, oy, heading in ((0.0, 0.0, 0.0), (0.3, -0.2, 3.0), (1.0, 2.0, 2.0 * math.pi - 1e-12)):
        _circle_windows(near, count, ox, oy, heading)
        outside = 0
        for k in range(count):
            fx, fy, r = near[0, k] - ox, near[1, k] - oy, near[2, k]
            d = math.sqrt(fx * fx + fy * fy)
            assert near[3, k] == d
            if d > r:  # a circle holding the sensor has no window
                outside += 1
                assert (near[4, k], near[5, k]) == _circle_window(fx, fy, d, r, heading)
        assert outside > count * 0.99
        assert not np.any(near[3:, count:])  # rows past count untouched
