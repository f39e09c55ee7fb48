"""``pc_fusion`` after a long blind stretch: a match placed short of the car along a corridor
sees through the walls the car drove past, and the place that sees through none is taken."""

from __future__ import annotations

import numpy as np

import estimators
from estimators.matching.scan_recovery import least_seen_through_place, seen_through_counts
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")


def corridor(end: float) -> np.ndarray:
    """Points (N, 2) of two walls at y = +-2 from x = 0 to ``end``, 5 cm apart."""
    x = np.arange(0.0, end, 0.05)
    return np.concatenate([np.column_stack([x, np.full_like(x, 2.0)]),
                           np.column_stack([x, np.full_like(x, -2.0)])])


def scan_at(x: float, end: float) -> np.ndarray:
    """Car-frame scan (M, 2) from (x, 0), heading 0: the corridor's walls up to ``end`` and a
    wall across at ``end + 6`` beyond its open end."""
    y = np.arange(-8.0, 8.0, 0.05)
    seen = np.concatenate([corridor(end), np.column_stack([np.full_like(y, end + 6.0), y])])
    return seen - [x, 0.0]


def test_a_scan_placed_short_of_where_it_was_taken_sees_through_the_walls_passed() -> None:
    scan = scan_at(8.0, 10.0)  # the car at x = 8, the walls ending at x = 10
    walls = corridor(14.0)  # the keyframe saw them on to x = 14
    counts = seen_through_counts(walls, scan, np.array([[8.0, 0, 0], [12.0, 0, 0],
                                                        [4.0, 0, 0]]))
    assert counts[0] > 20 and counts[1] <= 3  # placed 4 m on: the walls lie behind
    walls = corridor(10.0)
    assert seen_through_counts(walls, scan, np.array([[8.0, 0, 0]]))[0] == 0
    assert seen_through_counts(walls, scan, np.array([[4.0, 0, 0]]))[0] > 20


def test_the_place_found_sees_through_nothing_where_every_place_short_fits() -> None:
    """Every place short of x = 8 explains the corridor's walls; only x = 8 sees none of
    them through the scan's open end."""
    scan = scan_at(8.0, 10.0)
    walls = corridor(10.0)
    place = least_seen_through_place(walls, scan, np.array([3.0, 0.0, 0.0]), 6.0)
    assert abs(place[0] - 8.0) <= 0.4 and abs(place[1]) <= 0.2 and place[2] == 0.0


def test_after_100_blind_scans_leaving_the_corridor_the_place_is_found_again() -> None:
    """closed_to_open: the car drives 8 m out of the corridor while blind; matched on the
    last keyframe alone, the scan fits the corridor where the car went blind best (8 m
    off)."""
    recording = bench.record_drive("closed_to_open/zigzag")
    faulted = bench.with_faults(recording, bench.faults_for(0.1, 2)["blind_100"](), seed=0)
    estimator = estimators.make("pc_fusion")
    estimator.reset(recording.setup, recording.truth[0])
    for observation, t in zip(faulted.observations(), faulted.times, strict=True):
        estimator.update(observation, float(t))
    assert estimator.health.blind_stretches == 1
    error = np.hypot(*(estimator.trajectory[-1, :2] - recording.truth[-1, :2]))
    assert error < 0.15  # (clean: 0.02 m)
