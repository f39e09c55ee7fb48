"""The global loop search's confirmation: two candidates of one query (neighbouring old
keyframes, one piece of evidence) do not confirm each other; a second query implying the same
correction does."""

from __future__ import annotations

import numpy as np
import pytest

import estimators.slam.keyframe_matching as keyframe_matching
from estimators import SensorSetup
from estimators.slam.graph_slam import GraphSlam
from estimators.slam.loop_closure import LoopVerification
from lidar_env.core.se2 import relative

ANGLES = 2 * np.pi * np.arange(360) / 360


def test_two_candidates_of_one_query_do_not_confirm_a_global_loop(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # 30 m straight, every scan alike (one descriptor everywhere); no local candidates
    # (overlap_radius ~0, no drift allowance) and no automatic global search.
    slam = GraphSlam(global_every=0, overlap_radius=1e-3, loop_drift=0.0, check_steps=False,
                     match_odometry=False)
    truth = np.column_stack([np.arange(301) * 0.1, np.zeros(301), np.zeros(301)])
    slam.reset(SensorSetup(np.zeros((1, 3)), ANGLES, 10.0), truth[0])
    points = np.random.default_rng(0).uniform(-4.0, 4.0, (200, 2))
    for pose in truth:
        slam.add_scan(points, pose)
    assert slam.n_loops == 0
    # Every candidate matches where the graph has it (the same correction: none), and the
    # gate lets it through: only the confirmation rule decides.
    poses = slam.graph.poses

    def matched(place: int, query: np.ndarray, guess: np.ndarray, window: float, params,
                measure_rejected: bool) -> LoopVerification:
        return LoopVerification(True, "accepted", relative(poses[place], poses[current]),
                                1e4 * np.eye(3), 1.0, 1.0, 0.0)

    monkeypatch.setattr(keyframe_matching, "verify_loop", matched)
    monkeypatch.setattr(slam, "_place", lambda index, neighbours=None: index)
    monkeypatch.setattr(slam, "_gate", lambda old, new, result: result)
    current = 40
    slam._close_global_loops(current)  # two candidates of one query
    assert len(slam.loop_attempts) == 2 and slam.n_loops == 0
    current = 46
    slam._close_global_loops(current)  # another query, the same correction: confirmed
    assert slam.n_loops == 2
    assert {int(slam.graph.edges[k, 1]) for k in np.flatnonzero(slam.graph.is_loop)} == {40, 46}
