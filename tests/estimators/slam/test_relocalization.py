"""Where the front end lost its place, ``slam`` searches the keyframes after in the map before
and re-anchors them once two matches agree; with nothing to find it closes no loop."""

from __future__ import annotations

import numpy as np

from estimators.slam.graph_slam import GraphSlam
from lidar_env.core.se2 import compose
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")

#: Where the lost front end puts the car relative to the truth: 1.8 m and 29 degrees off.
OFFSET = np.array([1.5, -1.0, 0.5])


def run_losing_place(at: int) -> tuple[GraphSlam, np.ndarray]:
    """``slam`` on the open_cylinders drive, its front end losing its place at observation
    ``at`` (flagged lost, its poses from there on :data:`OFFSET` off); its trajectory and
    the truth."""
    recording = bench.record_drive("open_cylinders/right_turn")
    slam = GraphSlam()
    slam.reset(recording.setup, recording.truth[0])
    frontend, update, seen = slam._frontend, slam._frontend.update, [0]

    def lost_update(observation: dict, t: float) -> np.ndarray:
        pose, index = update(observation, t), seen[0]
        seen[0] += 1
        if index == at:
            frontend.health.note_lost(at)
        return compose(OFFSET, pose) if index >= at else pose

    frontend.update = lost_update
    for observation, t in zip(recording.observations(), recording.times, strict=True):
        slam.update(observation, float(t))
    return slam, recording.truth


def test_a_front_end_that_lost_its_place_is_re_anchored_on_the_map_before() -> None:
    slam, truth = run_losing_place(120)
    assert slam.health.lost_scans == 1 and slam.health.lost == [120]
    assert slam.lost_from is None  # found again
    errors = np.hypot(*(slam.trajectory[:, :2] - truth[:, :2]).T)
    assert errors[-1] < 0.2 and np.max(errors[:110]) < 0.2
    odometry = slam.odometry_trajectory
    assert np.hypot(*(odometry[-1, :2] - truth[-1, :2])) > 1.0  # the front end stays off
