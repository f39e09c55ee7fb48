"""Odometry edges carry the front end's own error where it measures it: keyframes that share
no walls leave their match loose, but not the step the front end pinned on its local map, so
a wrong loop edge cannot bend it; a step the keyframe check replaced is not the front end's,
and keeps the keyframes' match information."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators import SensorSetup
from estimators.slam.frontend_drift import FrontEndDrift
from estimators.slam.graph_slam import GraphSlam
from lidar_env.core.se2 import compose, relative
from tests.estimators.slam.test_step_check import (
    ANGLES,
    CURRENT,
    MAX_RANGE,
    PREVIOUS,
    keyframe_points,
)


@dataclass
class ScanMatches:
    """What FrontEndDrift reads of a front end (LocalMapOdometry's defaults)."""

    scan_information: np.ndarray = field(default_factory=lambda: np.diag([100.0, 180.0, 1000.0]))
    noise_sigma: float = 0.02
    keyframe_distance: float = 0.25
    keyframe_angle: float = np.radians(10.0)
    n_keyframes: int = 10


def sparse_drive(measured: bool) -> GraphSlam:
    """5 m straight on; every scan sees 6 posts no other scan sees (the keyframes' match
    pins nothing); the front end, where ``measured``, reports well-pinned scan matches."""
    slam = GraphSlam(overlap_radius=1e-3, loop_drift=0.0, global_every=0, check_steps=False)
    slam.reset(SensorSetup(np.zeros((1, 3)), 2 * np.pi * np.arange(360) / 360, 3.5),
               np.zeros(3))
    slam._drift = FrontEndDrift(ScanMatches() if measured else object(), slam.keyframe_distance)
    rng = np.random.default_rng(3)
    for x in np.arange(0.0, 5.0, 0.1):
        slam._drift.add(0.0)
        slam.add_scan(rng.uniform(-3.0, 3.0, (6, 2)), np.array([x, 0.0, 0.0]))
    return slam


def test_an_odometry_edge_is_as_tight_as_the_front_end_s_measured_error() -> None:
    slam = sparse_drive(measured=True)
    odometry = ~slam.graph.is_loop
    heading = np.degrees(np.sqrt(np.linalg.inv(slam.graph.information[odometry])[:, 2, 2]))
    position = np.sqrt(np.linalg.inv(slam.graph.information[odometry])[:, 0, 0])
    noise, drift = slam._odometry_error(np.array([0.5, 0.0, 0.0]))
    assert np.all(heading < 0.5) and np.all(position < 0.05)  # not the posts' loose match
    assert np.all(heading <= np.degrees(np.sqrt(noise[2, 2] + drift[2, 2])))


def test_a_wrong_loop_edge_does_not_bend_a_step_the_front_end_pinned() -> None:
    """A loop edge 10 deg off over 3 m of keyframes whose scans share no post: dropped as
    irreconcilable with the front end's steps, the map stays straight."""
    slam = sparse_drive(measured=True)
    last = len(slam.keyframes) - 1
    old = last - 6
    wrong = relative(slam.graph.pose(old), slam.graph.pose(last)) + [0.0, 0.3, np.radians(10)]
    slam.add_loop_closure(old, last, wrong, np.diag([1e3, 1e3, np.radians(1.0)**-2]))
    slam.optimize()
    kept = relative(slam.graph.pose(old), slam.graph.pose(last))
    assert abs(np.degrees(kept[2])) < 1.0
    assert slam.dropped_loops == [(old, last)]


def test_without_measured_drift_the_keyframes_match_still_weakens_the_edge() -> None:
    """A front end that reports no scan matches: the distance model plus the keyframes'
    match covariance (``match_odometry``), loose where the keyframes share no post."""
    slam = sparse_drive(measured=False)
    odometry = ~slam.graph.is_loop
    heading = np.degrees(np.sqrt(np.linalg.inv(slam.graph.information[odometry])[:, 2, 2]))
    assert np.all(heading > 5.0)


def test_a_step_the_keyframe_check_replaced_does_not_take_the_front_end_s_error() -> None:
    """A turn the front end lost (40 deg) replaced by the keyframes' match: the edge's
    information is the match's, whatever the front end claims of its own step."""
    truth = relative(PREVIOUS, CURRENT)
    lost = compose(PREVIOUS, compose(truth, np.array([0.0, 0.0, np.radians(-40.0)])))
    informations = []
    for frontend in (ScanMatches(), object()):
        slam = GraphSlam(global_every=0)
        slam.reset(SensorSetup(np.zeros((1, 3)), ANGLES, MAX_RANGE), PREVIOUS)
        slam._drift = FrontEndDrift(frontend, slam.keyframe_distance)
        for seed, (pose, odometry) in enumerate(((PREVIOUS, PREVIOUS), (CURRENT, lost))):
            slam._drift.add(float(odometry[2]))
            slam.add_scan(keyframe_points(pose, np.zeros((0, 3)), seed), odometry)
        assert len(slam.step_checks) == 1
        error = relative(truth, slam.graph.measurements[0])
        assert abs(error[2]) < np.radians(1.0)  # replaced
        informations.append(slam.graph.information[0])
    np.testing.assert_array_equal(informations[0], informations[1])
