"""The lines the ``icp`` estimator pairs scans with: midpoints on the fitted curves between the
returns of small cylinders, none on flat walls; and the fault matrix's cells among cylinders
(open_cylinders/right_turn, half the beams dropped or one Lidar frozen) and on ACES (blind
3 s at a time), where the pulls of convex surfaces added up."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.surface_fits import MAX_SAGITTA, surface_reference
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")

#: (x, y, radius) [m] of the cylinders, in the first scan's frame
CYLINDERS = np.array([[3.0, 2.5, 0.25], [4.5, -1.0, 0.3], [6.0, 3.5, 0.2], [2.0, -3.0, 0.35],
                      [7.5, 0.5, 0.3], [5.0, 5.5, 0.25]])


def cylinder_scan(pose: np.ndarray, beams: int = 360) -> np.ndarray:
    """Returns (M, 2) [m, frame of ``pose``] of a noiseless Lidar at ``pose`` (3,) in the first
    scan's frame, one beam a degree, on the cylinders alone (exact circle intersections)."""
    angles = pose[2] + np.radians(np.arange(beams) * 360.0 / beams)
    directions = np.column_stack([np.cos(angles), np.sin(angles)])
    offset = pose[:2] - CYLINDERS[:, :2]  # (C, 2)
    along = directions @ offset.T  # (B, C)
    square = along**2 - (offset**2).sum(axis=1) + CYLINDERS[:, 2] ** 2
    ranges = np.where(square >= 0, -along - np.sqrt(np.maximum(square, 0.0)), np.inf)
    ranges = np.where(ranges > 0, ranges, np.inf).min(axis=1)
    hit = np.isfinite(ranges)
    world = pose[:2] + directions[hit] * ranges[hit, None]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return (world - pose[:2]) @ np.array([[c, -s], [s, c]])


def test_flat_walls_keep_the_fitted_curves_alone() -> None:
    along = np.linspace(-3.0, 3.0, 121)
    walls = np.vstack([np.column_stack([along, np.full_like(along, 1.5)]),
                       np.column_stack([along, np.full_like(along, -1.5)])])
    reference = surface_reference(walls, 9, 72)
    fitted = PointToLineReference.with_estimated_normals(walls, 9, True, 72)
    assert np.array_equal(reference.points, fitted.points)
    assert np.array_equal(reference.normals, fitted.normals)
    assert np.array_equal(reference.anchors, fitted.anchors)


def test_the_midpoints_lie_on_the_cylinders() -> None:
    previous = cylinder_scan(np.zeros(3))
    reference = surface_reference(previous, 9, 72)
    added = reference.points[len(previous):]
    assert len(added) > 0
    gaps = np.hypot(added[:, None, 0] - CYLINDERS[:, 0], added[:, None, 1] - CYLINDERS[:, 1])
    # nearer the surface than the chords between the returns, which run MAX_SAGITTA inside
    assert np.all(np.abs(gaps - CYLINDERS[:, 2]).min(axis=1) < MAX_SAGITTA)


def faulted_final(recording, fault: str) -> float:
    """[m] the end-point error of ``icp`` on ``recording`` with the matrix's ``fault``."""
    return bench.faulted_score("icp", recording, fault).final


@pytest.mark.parametrize(("fault", "limit"), [("dropout_half", 0.44), ("frozen", 0.2)])
def test_among_cylinders_the_faulted_drives_end_near_the_truth(fault, limit) -> None:
    assert faulted_final(bench.record_drive("open_cylinders/right_turn"), fault) < limit  # [m]


@pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("aces")),
                    reason="ACES or aces-corrected absent")
def test_aces_blind_three_seconds_at_a_time_ends_within_its_clean_drift() -> None:
    # the robot stops and turns 113 degrees on the spot while blind: the turn is searched for
    recording = bench.log_recording("aces", 0, 600)
    clean = bench.score(bench.run("icp", recording, bench.start_of(recording.truth))[0],
                        recording.truth, recording.truth)[1]
    assert faulted_final(recording, "blind_3s") <= (
        bench.FINAL_FACTOR * clean + bench.FINAL_MARGIN)  # [m] the fault matrix's target
