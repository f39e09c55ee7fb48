"""MoverScore: tracked movers scored against the true (M, 5) movers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.evaluation.mover_scores import MoverScore
from estimators.mapping.motion_tracking import MotionTracker, MovingTrack
from estimators.mapping.obstacles import detect_obstacles
from lidar_env.core.se2 import transform_points
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World

ANGLES = 2 * np.pi * np.arange(360) / 360
SENSORS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])


def _track(track_id: int, x: float, y: float, vx: float, vy: float, moving: bool,
           hits: int = 10) -> MovingTrack:
    return MovingTrack(track_id, np.array([x, y, vx, vy]), np.eye(4), 0.25, hits, 0.0, 1.0,
                       1.0, moving)


def _ring(x: float, y: float, radius: float, n: int = 12) -> np.ndarray:
    a = np.linspace(0, np.pi, n)
    return np.column_stack([x + radius * np.cos(a), y + radius * np.sin(a)])


def test_a_tracked_crossing_scores_full_recall_and_small_errors() -> None:
    rng = np.random.default_rng(1)
    tracker, score = MotionTracker(), MoverScore()
    for k in range(60):
        t = 0.1 * k
        mover = np.array([[3.0, -3.0 + t, 0.0, 1.0, 0.25]])
        world = World(circles=[(5.0, 2.0, 0.3), tuple(mover[0, [0, 1, 4]])])
        detections, returns = [], []
        for scan, pose in zip(cast_rays(world, SENSORS, ANGLES, 10.0), SENSORS, strict=True):
            noisy = np.where(scan < 10.0, scan + 0.01 * rng.standard_normal(scan.shape), scan)
            detections += detect_obstacles(noisy, ANGLES, pose, 10.0)
            hit = noisy < 10.0
            local = np.column_stack([noisy * np.cos(ANGLES), noisy * np.sin(ANGLES)])[hit]
            returns.append(transform_points(pose, local))
        tracker.update(detections, t)
        score.add(tracker.detected_tracks(), mover, (0.0, 0.0), np.vstack(returns))
    s = score.summary()
    assert s["visible"] == 60 and s["recall"] == 1.0
    assert s["position_error"] < 0.05 and s["velocity_error"] < 0.1
    assert s["id_switches"] == 0 and s["moving_precision"] == 1.0
    assert s["label_accuracy"] > 0.95


def test_hidden_or_far_movers_are_not_counted() -> None:
    score = MoverScore()
    movers = [[3.0, 0.0, 1.0, 0.0, 0.25], [9.0, 0.0, 1.0, 0.0, 0.25]]
    score.add([], movers, (0.0, 0.0), np.zeros((0, 2)))  # nothing returned: hidden
    score.add([], movers, (0.0, 0.0), np.vstack([_ring(3.0, 0.0, 0.25), _ring(9.0, 0.0, 0.25)]))
    assert score.visible == 1 and score.matched == 0 and score.summary()["recall"] == 0.0


def test_id_switches_and_false_moving_labels_are_counted() -> None:
    score = MoverScore()
    mover = [[3.0, 0.0, 1.0, 0.0, 0.25]]
    ring = _ring(3.0, 0.0, 0.25)
    score.add([_track(0, 3.0, 0.0, 1.0, 0.0, True), _track(1, 5.0, 0.0, 0.0, 0.0, True)],
              mover, (0.0, 0.0), ring)
    score.add([_track(2, 3.01, 0.0, 0.9, 0.0, True)], mover, (0.0, 0.0), ring)
    s = score.summary()
    assert s["id_switches"] == 1 and s["recall"] == 1.0
    assert s["moving_precision"] == pytest.approx(2 / 3)
    assert s["velocity_error"] == pytest.approx(0.05)
    assert math.isnan(MoverScore().summary()["recall"])
