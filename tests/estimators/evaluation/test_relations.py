"""Kümmerle relations metric: file format, closed-form errors, time matching, summaries."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimators.datasets.carmen import load_log
from estimators.evaluation.relations import (
    Relations,
    load_relations,
    match_times,
    relation_errors,
    relations_from_trajectory,
)
from estimators.paths import SHARED_DATA
from lidar_env.core.se2 import compose, relative

DATA = SHARED_DATA / "radish"


def _trajectory(n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    times = 10.0 + 0.1 * np.arange(n)
    steps = np.tile([0.1, 0.0, 0.05], (n, 1))
    poses = [np.zeros(3)]
    for step in steps[1:]:
        poses.append(compose(poses[-1], step))
    return times, np.array(poses)


def test_load_relations_reads_x_y_yaw(tmp_path: Path):
    path = tmp_path / "r.relations"
    path.write_text("1.0 2.0 0.5 -0.25 0 0 0 0.1\n# comment\n\n3.0 5.5 1 2 0 0 0 -0.2\n")
    relations = load_relations(path)
    np.testing.assert_array_equal(relations.t1, [1.0, 3.0])
    np.testing.assert_array_equal(relations.t2, [2.0, 5.5])
    np.testing.assert_array_equal(relations.poses, [[0.5, -0.25, 0.1], [1.0, 2.0, -0.2]])
    assert len(relations.local()) == 1


@pytest.mark.parametrize(
    ("text", "reason"),
    [("1 2 3 4 5 6 7\n", "expected 8 fields"), ("1 2 3 4 5 6 7 x\n", "expected numbers")],
)
def test_load_relations_rejects_malformed_lines(tmp_path: Path, text: str, reason: str):
    path = tmp_path / "r.relations"
    path.write_text(text)
    with pytest.raises(ValueError, match=f"line 1: {reason}"):
        load_relations(path)


def test_exact_trajectory_has_zero_error():
    times, poses = _trajectory()
    relations = relations_from_trajectory(times, poses, window=0.35)
    errors = relation_errors(times, poses, relations)
    np.testing.assert_allclose(errors.translation, 0.0, atol=1e-12)
    np.testing.assert_allclose(errors.rotation, 0.0, atol=1e-9)


def test_errors_match_closed_form_perturbations():
    times, truth = _trajectory()
    relations = relations_from_trajectory(times, truth)  # consecutive pairs
    estimate = truth.copy()
    # Shift the last pose 3 cm along its own heading, and turn the one before by 2 degrees
    # in place: relation k compares x_k^-1 x_{k+1}.
    estimate[-1] = compose(truth[-1], [0.03, 0.0, 0.0])
    estimate[-3] = compose(truth[-3], [0.0, 0.0, np.radians(2.0)])
    errors = relation_errors(times, estimate, relations)
    assert errors.translation[-1] == pytest.approx(0.03)
    assert errors.rotation[-1] == pytest.approx(0.0, abs=1e-9)
    # Relation (-4, -3): the estimated end turned 2 deg in place, no translation error.
    assert errors.rotation[-3] == pytest.approx(2.0)
    assert errors.translation[-3] == pytest.approx(0.0, abs=1e-12)
    # Relation (-3, -2): the start turned by 2 deg, so the 0.1 m step swings by 2 deg.
    assert errors.rotation[-2] == pytest.approx(2.0)
    assert errors.translation[-2] == pytest.approx(2 * 0.1 * np.sin(np.radians(1.0)), rel=1e-6)
    assert np.count_nonzero(errors.translation > 1e-9) == 2


def test_summary_means_and_failures():
    times, truth = _trajectory(6)
    relations = relations_from_trajectory(times, truth)
    estimate = truth.copy()
    estimate[-1] = compose(truth[-1], [0.5, 0.0, 0.0])
    summary = relation_errors(times, estimate, relations).summary()
    assert summary.count == 5
    assert summary.translation_mean == pytest.approx(0.1)
    assert summary.failure_rate == pytest.approx(0.2)  # one of five beyond 0.2 m
    assert "failures 20.0%" in str(summary)


def test_windowed_relations_pair_first_pose_at_least_window_later():
    times = np.array([0.0, 0.4, 1.0, 1.3, 2.5])
    poses = np.column_stack([times, np.zeros(5), np.zeros(5)])
    relations = relations_from_trajectory(times, poses, window=1.0)
    np.testing.assert_array_equal(relations.t1, [0.0, 0.4, 1.0, 1.3])
    np.testing.assert_array_equal(relations.t2, [1.0, 2.5, 2.5, 2.5])
    np.testing.assert_allclose(relations.poses[:, 0], relations.t2 - relations.t1)
    with pytest.raises(ValueError, match="strictly increasing"):
        relations_from_trajectory(times[::-1], poses)
    with pytest.raises(ValueError, match="positive duration"):
        relations_from_trajectory(times, poses, window=0.0)


def test_missing_relation_time_is_an_error():
    times, poses = _trajectory()
    relations = Relations(np.array([10.0]), np.array([10.55]), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="no scan within 0.001 s, e.g. t=10.55"):
        relation_errors(times, poses, relations)
    with pytest.raises(ValueError, match="expected shape"):
        relation_errors(times, poses[:-1], relations)


def test_match_times_picks_the_nearest():
    np.testing.assert_array_equal(match_times([1.0, 2.0, 3.0], [2.9996, 1.0004], 1e-3), [2, 0])
    # Unsorted times (glitching logs) still map to the right original index.
    np.testing.assert_array_equal(match_times([2.0, 1.0, 3.0], [1.0, 3.0, 2.0]), [1, 2, 0])
    with pytest.raises(ValueError, match="at least one timestamp"):
        match_times([], [1.0])


@pytest.mark.skipif(not DATA.is_dir(), reason=f"real logs absent: expected them in {DATA}")
def test_every_aces_relation_names_a_scan():
    relations = load_relations(DATA / "aces.relations")
    times = load_log(DATA / "aces.clf.bz2").scan_times("ipc")
    assert len(relations) == 1279
    i = match_times(times, relations.t1)
    j = match_times(times, relations.t2)
    assert np.all(j > i)
    # Relations state the pose at t2 in the frame at t1: the true motion between nearby scans
    # is small, so local relations cannot exceed a few metres.
    local = relations.local()
    assert 0 < len(local) < len(relations)
    assert np.all(np.hypot(local.poses[:, 0], local.poses[:, 1]) < 3.0)
    assert relative(np.zeros(3), local.poses).shape == local.poses.shape
