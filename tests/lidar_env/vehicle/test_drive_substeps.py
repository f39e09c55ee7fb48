""":func:`drive_arc` shares the cosine and sine of the start heading between its substeps and
wraps the heading once: its poses and hits must be those of the plain loop (each substep's pose
from the unicycle arc, its own box test, the heading wrapped at every free substep) bit for
bit, with and without moving obstacles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lidar_env.vehicle.car import box_touches_obstacles, drive_arc, drive_arc_among_movers

HALF_LENGTH, HALF_WIDTH = 0.4, 0.25


def plain_drive(pose: np.ndarray, speed: float, yaw_rate: float, duration: float, substeps: int,
                circles: np.ndarray, segments: np.ndarray, movers: np.ndarray,
                velocities: np.ndarray) -> bool:
    x0, y0, h0 = pose
    for k in range(1, substeps + 1):
        t = duration * k / substeps
        h = h0 + yaw_rate * t
        if abs(yaw_rate) < 1e-9:
            x, y = x0 + speed * t * math.cos(h0), y0 + speed * t * math.sin(h0)
        else:
            radius = speed / yaw_rate
            x = x0 + radius * (math.sin(h) - math.sin(h0))
            y = y0 - radius * (math.cos(h) - math.cos(h0))
        moved = movers.copy()
        moved[:, :2] += velocities * t
        if (box_touches_obstacles(x, y, h, HALF_LENGTH, HALF_WIDTH, circles, segments)
                or box_touches_obstacles(x, y, h, HALF_LENGTH, HALF_WIDTH, moved,
                                         np.empty((0, 4)))):
            return True
        pose[:] = x, y, (h + math.pi) % (2.0 * math.pi) - math.pi
    return False


@pytest.mark.parametrize("with_movers", [False, True], ids=["static", "movers"])
def test_drive_matches_the_plain_substep_loop_bit_for_bit(with_movers: bool) -> None:
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(600):
        n_circles, n_segments = rng.integers(0, 5), rng.integers(0, 4)
        circles = np.column_stack([rng.uniform(-3, 3, (n_circles, 2)),
                                   rng.uniform(0.05, 0.5, n_circles)])
        segments = rng.uniform(-3, 3, (n_segments, 4))
        movers = (np.column_stack([rng.uniform(-3, 3, (3, 2)), np.full(3, 0.3)]) if with_movers
                  else np.empty((0, 3)))
        velocities = rng.uniform(-2, 2, (len(movers), 2))
        pose = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-7.0, 7.0)])
        speed = float(rng.choice([0.0, rng.uniform(-3, 3)]))
        yaw_rate = float(rng.choice([0.0, 1e-10, rng.uniform(-3, 3)]))
        substeps, duration = int(rng.integers(0, 9)), 0.1 * int(rng.integers(1, 20))
        expected_pose, got = pose.copy(), pose.copy()
        expected = plain_drive(expected_pose, speed, yaw_rate, duration, substeps, circles,
                               segments, movers, velocities)
        if with_movers:
            hit = drive_arc_among_movers(got, speed, yaw_rate, duration, substeps, HALF_LENGTH,
                                         HALF_WIDTH, circles, segments, movers, velocities)
        else:
            hit = drive_arc(got, speed, yaw_rate, duration, substeps, HALF_LENGTH, HALF_WIDTH,
                            circles, segments)
        assert hit == expected
        assert got.tobytes() == expected_pose.tobytes()
        hits += hit
    assert 100 < hits < 500, "the drives should both hit and pass"
