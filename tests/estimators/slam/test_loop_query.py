"""Loop matches of a keyframe that sees only a few posts: made with the posts passed just
before it (never with the old place's own keyframes), placed by a front end that drifts as
little as a scan-to-map one does, they measure the relation between the two keyframes better
than the keyframe's scan alone does."""

from __future__ import annotations

import numpy as np

from estimators import SensorSetup
from estimators.matching.scan_matching import scan_to_points
from estimators.slam.graph_slam import GraphSlam
from lidar_env.core.se2 import compose, relative
from lidar_env.sensors.lidar import cast_rays

ANGLES = 2 * np.pi * np.arange(360) / 360
MAX_RANGE = 3.5  # a TurtleBot-class Lidar
NO_WALLS = np.zeros((0, 4))


def pillar_hall(seed: int = 3) -> np.ndarray:
    """``(P, 3)`` posts (x, y, radius) scattered over a 20 x 14 m hall, none on the route."""
    rng = np.random.default_rng(seed)
    posts = np.column_stack([rng.uniform(0, 20, 60), rng.uniform(0, 14, 60),
                             rng.uniform(0.1, 0.3, 60)])
    phase = np.linspace(0, 2 * np.pi, 400)
    route = np.column_stack([10 + 6.5 * np.cos(phase), 7 + 4.2 * np.sin(phase)])
    clearance = np.min(np.hypot(*(posts[:, None, :2] - route[None]).transpose(2, 0, 1)), axis=1)
    return posts[clearance > posts[:, 2] + 0.6]


def drive(n: int = 500) -> tuple[np.ndarray, np.ndarray]:
    """True poses around the hall (1.2 laps) and odometry with a 0.15 deg/m heading drift
    (a scan-to-map front end's in a hall of posts: 0.45 deg over 3 m)."""
    phase = 2 * np.pi * 1.2 * np.arange(n) / n
    truth = np.column_stack([10 + 6.5 * np.cos(phase), 7 + 4.2 * np.sin(phase),
                             np.arctan2(4.2 * np.cos(phase), -6.5 * np.sin(phase))])
    steps = relative(truth[:-1], truth[1:])
    steps[:, 2] += np.radians(0.15) * np.hypot(steps[:, 0], steps[:, 1])
    odometry = [truth[0]]
    for step in steps:
        odometry.append(compose(odometry[-1], step))
    return truth, np.array(odometry)


def loop_heading_errors(slam: GraphSlam) -> np.ndarray:
    """Heading errors [rad] of every accepted loop match against the true relation."""
    truth, odometry = drive()
    posts = pillar_hall()
    ranges = cast_rays((posts, NO_WALLS), truth, ANGLES, MAX_RANGE)
    noisy = np.where(ranges < MAX_RANGE,
                     ranges + np.random.default_rng(0).normal(0, 0.01, ranges.shape), ranges)
    slam.reset(SensorSetup(np.zeros((1, 3)), ANGLES, MAX_RANGE), truth[0])
    scan_of_keyframe = []
    for k, (row, pose) in enumerate(zip(noisy, odometry, strict=True)):
        slam.add_scan(scan_to_points(row, ANGLES, MAX_RANGE), pose)
        scan_of_keyframe += [k] * (len(slam.keyframes) - len(scan_of_keyframe))
    kept = truth[scan_of_keyframe]
    return np.array([relative(relative(kept[old], kept[new]), result.pose)[2]
                     for old, new, result in slam.loop_attempts if result.accepted])


def test_a_sparse_keyframe_is_matched_with_the_posts_passed_before_it() -> None:
    slam = GraphSlam(global_every=0)
    loop_heading_errors(slam)
    held = np.array([len(keyframe.points) for keyframe in slam.keyframes])
    sparse = np.flatnonzero(held < slam.min_query_points)
    assert len(sparse) > 10
    for new in sparse[sparse >= 8]:
        for old, earliest in ((new - 8, new - slam.loop_query_keyframes),  # a revisit's place
                              (new - 6, new - 6 + slam.submap_neighbours + 1)):  # an overlap's
            # the keyframes before it, newest first, until they hold enough points
            counts = np.cumsum(held[earliest:new + 1][::-1])
            enough = np.flatnonzero(counts >= slam.min_query_points)
            expected = counts[enough[0]] if len(enough) else counts[-1]
            assert len(slam._query(new, old)) == expected


def test_loop_edges_of_few_posts_measure_the_heading_better_with_the_recent_posts() -> None:
    alone = loop_heading_errors(GraphSlam(global_every=0, min_query_points=0))
    with_recent = loop_heading_errors(GraphSlam(global_every=0))
    assert len(alone) and len(with_recent)
    rms = [np.degrees(np.sqrt(np.mean(errors**2))) for errors in (alone, with_recent)]
    assert rms[1] < 0.8 * rms[0]
