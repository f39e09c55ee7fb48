"""FrontEndDrift: a keyframe step's drift covariance from the front end's scan matches, by
the closed form; tight where many returns pinned the scans, loose where few did; none without
a front end that reports its matches; with it, the loop gate refuses a depot's next aisle."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators import SensorSetup
from estimators.slam.frontend_drift import INFORMATION_FLOOR, FrontEndDrift
from estimators.slam.graph_slam import GraphSlam
from lidar_env.core.se2 import compose, relative


@dataclass
class ScanMatches:
    """What FrontEndDrift reads of a front end (LocalMapOdometry's defaults)."""

    scan_information: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    noise_sigma: float = 0.02
    keyframe_distance: float = 0.25
    keyframe_angle: float = np.radians(10.0)
    n_keyframes: int = 10


def test_the_drift_is_the_mean_scan_s_error_per_map_keyframe_times_a_map_s_span() -> None:
    frontend = ScanMatches()
    drift = FrontEndDrift(frontend, keyframe_distance=0.5)
    world = np.diag([300.0, 20.0, 900.0])  # shelf faces across world x pin it, y far less
    for information in (world, 3 * world):
        frontend.scan_information = information
        drift.add(np.pi / 2)  # the car faces world y: its x is world y
    mean = np.diag([40.0, 600.0, 1800.0]) + INFORMATION_FLOOR * np.eye(3)
    step = np.array([0.5, 0.0, 0.0])  # two map keyframes; a map spans 5 graph keyframes
    expected = 0.02**2 * 2 * 5 * np.linalg.inv(mean)
    np.testing.assert_allclose(drift.take(step), expected, rtol=1e-12, atol=1e-15)
    assert drift.take(step) is None  # taken: the next step starts empty
    frontend.scan_information = world
    drift.add(0.0)
    turn = np.array([0.0, 0.0, np.radians(20.0)])  # a turn on the spot: two map keyframes
    np.testing.assert_allclose(drift.take(turn), 0.02**2 * 2 * 5 * np.linalg.inv(
        world + INFORMATION_FLOOR * np.eye(3)), rtol=1e-12, atol=1e-15)


def test_few_returns_leave_the_step_loose_and_many_tight() -> None:
    frontend = ScanMatches()
    drift = FrontEndDrift(frontend, keyframe_distance=0.5)
    step = np.array([0.5, 0.0, 0.0])
    sigmas = []
    for returns in (5, 300):  # half squarely facing x, half y, all 2 m away
        frontend.scan_information = returns * np.diag([0.5, 0.5, 4.0])
        drift.add(0.0)
        sigmas.append(np.sqrt(np.diag(drift.take(step))))
    assert np.all(sigmas[0] > 7 * sigmas[1])  # sqrt(60), less the floor
    assert sigmas[1][2] < np.radians(0.15)  # a depot scan: a tenth of a degree per step


def test_a_front_end_that_reports_no_matches_gives_no_drift() -> None:
    drift = FrontEndDrift(object(), keyframe_distance=0.5)
    drift.add(0.0)
    assert drift.take(np.array([0.5, 0.0, 0.0])) is None
    frontend = ScanMatches(scan_information=np.eye(3))
    drift = FrontEndDrift(frontend, keyframe_distance=0.5)
    drift.add(0.0)
    assert drift.take(None) is None  # the first keyframe: no step
    assert drift.take(np.array([0.5, 0.0, 0.0])) is None  # cleared by the first take


def test_the_loop_gate_refuses_the_next_aisle_after_a_drive_the_front_end_pinned() -> None:
    """50 m up and down two aisles of a depot whose scans each pinned the front end with ~280
    returns: a match one aisle pitch (3.5 m) across is beyond the loop gate under the front
    end's measured drift, within it under the distance model (2 %, 0.5 deg/m, correlated),
    and the true revisit passes both."""
    leg = np.arange(0.0, 25.0, 0.1)
    truth = np.vstack([np.column_stack([leg, np.zeros_like(leg), np.zeros_like(leg)]),
                       np.column_stack([25.0 - leg, np.full_like(leg, 3.5),
                                        np.full_like(leg, np.pi)])])
    points = np.random.default_rng(1).uniform(-3.0, 3.0, (100, 2))
    distances = {}
    for measured in (True, False):
        slam = GraphSlam(overlap_radius=1e-3, loop_drift=0.0, global_every=0,
                         check_steps=False, match_odometry=False)
        slam.reset(SensorSetup(np.zeros((1, 3)), 2 * np.pi * np.arange(360) / 360, 3.5),
                   truth[0])
        frontend = ScanMatches(scan_information=np.diag([100.0, 180.0, 1000.0]))
        if measured:
            slam._drift = FrontEndDrift(frontend, slam.keyframe_distance)
        for pose in truth:
            slam._drift.add(float(pose[2]))
            slam.add_scan(points, pose)
        last = len(slam.keyframes) - 1
        old = int(np.argmin(np.hypot(*(slam.graph.poses[:last - 20, :2]
                                       - slam.graph.poses[last, :2] + [0.0, 3.5]).T)))
        true_loop = relative(slam.graph.poses[old], slam.graph.poses[last])
        next_aisle = compose(true_loop, np.array([0.0, 3.5, 0.0]))
        information = np.diag([1e4, 1e4, 1e4])
        distances[measured] = [slam.loop_mahalanobis(old, last, z, information)
                               for z in (true_loop, next_aisle)]
    assert distances[True][0] < 1.0 and distances[False][0] < 1.0
    assert distances[True][1] > GraphSlam.loop_gate > distances[False][1]
