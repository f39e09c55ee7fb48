"""``icp`` after a long blind stretch: a match short of the car along a corridor sees through
the last scan's walls, and the match from a place that sees through none is kept."""

from __future__ import annotations

import numpy as np

from estimators.matching.match_result import MatchResult
from estimators.matching.scan_recovery import off_seen_through
from estimators.matching.seen_through import SEEN_THROUGH_SLACK
from tests.benchmarks.bench_modules import load
from tests.estimators.odometry.test_fusion_blind import corridor, scan_at

bench = load("bench_faults")


def judged(match: MatchResult) -> tuple[np.ndarray, float]:
    return match.pose, match.quality


def test_a_match_that_sees_through_walls_is_replaced_by_one_that_sees_through_none() -> None:
    scan, walls = scan_at(8.0, 10.0), corridor(10.0)
    tried = []

    def match_from(start: np.ndarray) -> MatchResult:
        tried.append(start)
        return MatchResult(start.copy(), 1.0, 0.01, 5, True, None)

    short = MatchResult(np.array([3.0, 0.0, 0.0]), 1.0, 0.01, 5, True, None)
    kept, seen, start = off_seen_through(match_from, short, judged, walls, scan, 6.0)
    assert seen <= SEEN_THROUGH_SLACK and start is not None and np.array_equal(kept.pose, start)
    assert abs(kept.pose[0] - 8.0) <= 0.4
    # a match the scan does not contradict stands, and nothing is matched again
    at_car = MatchResult(np.array([8.0, 0.0, 0.0]), 1.0, 0.01, 5, True, None)
    tried.clear()
    assert off_seen_through(match_from, at_car, judged, walls, scan, 6.0)[0] is at_car
    assert not tried


def test_a_place_that_sees_through_fewer_but_explains_far_less_is_not_taken() -> None:
    """A place that overlaps the reference little sees through little: it is no better."""
    scan, walls = scan_at(8.0, 10.0), corridor(10.0)

    def match_from(start: np.ndarray) -> MatchResult:
        return MatchResult(start.copy(), 0.3, 0.01, 5, True, None)

    short = MatchResult(np.array([3.0, 0.0, 0.0]), 0.9, 0.01, 5, True, None)
    assert off_seen_through(match_from, short, judged, walls, scan, 6.0)[0] is short


def test_after_100_blind_scans_leaving_the_corridor_icp_finds_the_place_again() -> None:
    """closed_to_open: the car drives 8 m out of the corridor while blind; matched on the
    last scan alone, a place between the corridor and the car fits best (4 m off)."""
    recording = bench.record_drive("closed_to_open/zigzag")
    run = bench.faulted_score("icp", recording, "blind_100")
    assert run.health["blind_stretches"] == 1
    assert run.final < 0.5  # (clean: 0.21 m; the cell's bound 2 x clean + 0.1 m)
