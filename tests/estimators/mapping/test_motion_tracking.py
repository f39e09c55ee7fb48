"""MotionTracker: velocities and static/moving labels of round obstacles."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.mapping.motion_tracking import MotionTracker
from estimators.mapping.obstacles import detect_obstacles
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World

ANGLES = 2 * np.pi * np.arange(360) / 360
SENSORS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])  # a standing car's two Lidars
WALLS = [[-2.0, 6.0, 10.0, 6.0], [-2.0, -6.0, 10.0, -6.0]]
CYLINDER = (5.0, 2.0, 0.3)


def crossing(tracker: MotionTracker, velocity: tuple[float, float], steps: int = 80,
             seed: int = 0) -> list[list[int | None]]:
    """A pedestrian (r = 0.25 m) crosses 3 m ahead of the car past a static cylinder."""
    rng = np.random.default_rng(seed)
    ids = []
    for k in range(steps):
        t = 0.1 * k
        x, y = 3.0 + velocity[0] * t, -4.0 + velocity[1] * t
        world = World(circles=[CYLINDER, (x, y, 0.25)], segments=WALLS)
        detections = []
        for scan, pose in zip(cast_rays(world, SENSORS, ANGLES, 10.0), SENSORS, strict=True):
            noisy = np.where(scan < 10.0, scan + 0.01 * rng.standard_normal(scan.shape), scan)
            detections += detect_obstacles(noisy, ANGLES, pose, 10.0)
        ids.append(tracker.update(detections, t))
    return ids


def test_a_crossing_pedestrian_keeps_one_id_and_its_velocity() -> None:
    tracker = MotionTracker()
    crossing(tracker, (0.0, 1.0))
    by_place = sorted(tracker.tracks, key=lambda track: track.position[0])
    assert len(by_place) == 2
    walker, cylinder = by_place
    assert walker.id == 1 and walker.hits == 80  # one id all the way, both Lidars merged
    np.testing.assert_allclose(walker.velocity, (0.0, 1.0), atol=0.1)
    np.testing.assert_allclose(walker.position, (3.0, -4.0 + 7.9), atol=0.05)
    assert walker.moving and not cylinder.moving
    np.testing.assert_allclose(cylinder.position, CYLINDER[:2], atol=0.05)
    assert cylinder.speed < 0.1
    assert tracker.moving_tracks() == [walker]


def test_a_diagonal_walker_is_labelled_moving_after_min_hits() -> None:
    tracker = MotionTracker(min_hits=5)
    crossing(tracker, (0.5, 0.8), steps=4)
    assert not any(track.moving for track in tracker.tracks)
    crossing_more = MotionTracker(min_hits=5)
    crossing(crossing_more, (0.5, 0.8), steps=30)
    (walker,) = crossing_more.moving_tracks()
    np.testing.assert_allclose(walker.velocity, (0.5, 0.8), atol=0.1)


def turning(tracker: MotionTracker, turn_step: int = 30, steps: int = 32) -> None:
    """A pedestrian walks at 1 m/s along +y, then turns back at once (-y) at ``turn_step``,
    as the env's walkers do at a waypoint."""
    rng = np.random.default_rng(1)
    y = -2.0
    for k in range(steps):
        y += 0.1 * (1.0 if k < turn_step else -1.0) if k else 0.0
        world = World(circles=[(3.0, y, 0.25)], segments=WALLS)
        detections = []
        for scan, pose in zip(cast_rays(world, SENSORS, ANGLES, 10.0), SENSORS, strict=True):
            noisy = np.where(scan < 10.0, scan + 0.01 * rng.standard_normal(scan.shape), scan)
            detections += detect_obstacles(noisy, ANGLES, pose, 10.0)
        tracker.update(detections, 0.1 * k)


def test_an_abrupt_turn_is_followed_at_once() -> None:
    tracker = MotionTracker()
    turning(tracker)
    (walker,) = tracker.tracks
    assert walker.hits == 32
    np.testing.assert_allclose(walker.velocity, (0.0, -1.0), atol=0.1)  # 2 steps after
    assert walker.moving
    slow = MotionTracker(maneuver_gate=float("inf"))  # no maneuver detection: still turning
    turning(slow)
    assert abs(slow.tracks[0].velocity[1] + 1.0) > 0.5


def test_extended_detections_get_no_track() -> None:
    tracker = MotionTracker()
    world = World(segments=WALLS)
    scan = cast_rays(world, SENSORS[0], ANGLES, 10.0)[0]
    detections = detect_obstacles(scan, ANGLES, SENSORS[0], 10.0)
    assert detections and tracker.update(detections, 0.0) == [None] * len(detections)
    assert tracker.tracks == []


def test_a_track_not_seen_for_max_age_is_dropped() -> None:
    tracker = MotionTracker(max_age=0.25)
    crossing(tracker, (0.0, 1.0), steps=5)
    assert len(tracker.tracks) == 2
    tracker.update([], 0.4 + 0.3)
    assert tracker.tracks == []


@pytest.mark.parametrize(("key", "value"), [("gate", 0.0), ("moving_speed", -1.0),
                                            ("max_age", float("nan")), ("min_hits", 0),
                                            ("maneuver_gate", 0.0),
                                            ("maneuver_gate", float("nan")),
                                            ("max_age", float("inf"))])
def test_bad_parameters_name_themselves(key: str, value: float) -> None:
    with pytest.raises(ValueError, match=key):
        MotionTracker(**{key: value})


def test_time_must_increase() -> None:
    tracker = MotionTracker()
    tracker.update([], 1.0)
    with pytest.raises(ValueError, match="t: expected a finite time after 1.0"):
        tracker.update([], 1.0)


def test_the_static_map_keeps_the_post_and_leaves_the_walker_out() -> None:
    from estimators.mapping.tracking import ObstacleTracker

    rng = np.random.default_rng(4)
    static = ObstacleTracker()
    for k in range(60):
        world = World(circles=[CYLINDER, (3.0, -3.0 + 0.1 * k, 0.25)], segments=WALLS)
        detections = []
        for scan, pose in zip(cast_rays(world, SENSORS, ANGLES, 10.0), SENSORS, strict=True):
            noisy = np.where(scan < 10.0, scan + 0.01 * rng.standard_normal(scan.shape), scan)
            detections += detect_obstacles(noisy, ANGLES, pose, 10.0)
        static.update(detections)
    (post,) = static.cylinders()
    np.testing.assert_allclose(post, CYLINDER, atol=0.03)
