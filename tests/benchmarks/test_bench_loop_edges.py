"""The loop-edge benchmark: it finds the scan each keyframe was made from, and on a small
sparse hall scores every loop edge slam keeps against the truth and the front end."""

from __future__ import annotations

import numpy as np

import estimators
from tests.benchmarks.bench_modules import load

bench = load("bench_loop_edges")
halls = load("bench_sparse_halls")


def test_quick_hall_scores_loop_edges_against_the_front_end() -> None:
    recording = halls.record(halls.QUICK["hall_12x9_burger_turns"])
    slam = estimators.make("slam")
    slam.reset(recording.setup, recording.poses[0])
    for observation, t in zip(recording.observations, recording.times, strict=True):
        slam.update(observation, t)
    rows = bench.keyframe_observations(slam, len(recording.poses))
    odometry = np.asarray(slam.odometry_trajectory)
    np.testing.assert_array_equal(odometry[slam.keyframe_scans],
                                  [keyframe.odometry for keyframe in slam.keyframes])
    assert np.all(np.diff(rows) > 0) and rows[-1] < len(recording.poses)

    edges = bench.loop_edges(recording, {})
    assert edges.shape[1] == 7 and len(edges) > 0
    assert np.all(np.isfinite(edges)) and np.all(edges[:, [0, 1, 2, 4, 6]] >= 0)
    assert np.all(np.abs(edges[:, [3, 5]]) < 10)  # deg: no edge of a clean drive is off by more
    assert "edges: heading" in bench.summary(edges)
