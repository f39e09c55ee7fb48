"""After a long blind stretch, a Lidar that sees a place no earlier scan covers leaves every
estimator lost: it says so (``health.lost_scans``) and keeps the motion model's pose instead
of jumping to wherever the new scan fits best."""

from __future__ import annotations

import numpy as np
import pytest

import estimators
from estimators import SensorSetup
from lidar_env.sensors.lidar import cast_rays
from tests.estimators.room_scans import ANGLES, MAX_RANGE, room

#: The car stands still at this world pose (x [m], y [m], heading [rad]) in the room.
STANDING = np.array([3.0, 5.0, 0.0])
PERIOD = 0.1  # [s] between scans
BLIND_SCANS = 100


def _run(name: str) -> tuple[estimators.Estimator, np.ndarray, np.ndarray]:
    """The estimator after 20 scans of the room, 100 blind ones, then 5 of a round hall 11 m
    across every way (the room's walls all lie nearer: the new scans see through all of
    them); with its pose before the stretch and its poses on the hall's scans."""
    rng = np.random.default_rng(0)
    setup = SensorSetup(mounts=[[0.0, 0.0, 0.0]], beam_angles=ANGLES, max_range=MAX_RANGE)
    estimator = estimators.make(name)
    estimator.reset(setup)
    room_ranges = cast_rays(room(), STANDING, ANGLES, MAX_RANGE)[0]
    scans = [room_ranges + rng.normal(0.0, 0.01, len(ANGLES)) for _ in range(20)]
    scans += [np.full(len(ANGLES), MAX_RANGE)] * BLIND_SCANS
    scans += [11.0 + rng.normal(0.0, 0.01, len(ANGLES)) for _ in range(5)]
    for k, ranges in enumerate(scans):
        estimator.update({"lidar_1": ranges}, k * PERIOD)
    trajectory = estimator.trajectory
    return estimator, trajectory[19], trajectory[20 + BLIND_SCANS:]


@pytest.mark.parametrize("name", ["icp", "pc_fusion", "lidar_odometry", "slam"])
def test_a_place_never_seen_after_a_blind_stretch_is_flagged_and_does_not_move_the_car(
        name: str) -> None:
    estimator, before, after = _run(name)
    assert estimator.health.counts()["blind_stretches"] == 1
    assert estimator.health.lost_scans >= 1
    # the car stood still before the stretch: the motion model keeps it where it was
    assert np.hypot(*(after[:, :2] - before[:2]).T).max() < 0.1
    assert np.abs(np.remainder(after[:, 2] - before[2] + np.pi, 2 * np.pi) - np.pi).max() < (
        np.radians(2.0))
