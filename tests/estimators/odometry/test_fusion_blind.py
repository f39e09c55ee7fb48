"""``pc_fusion`` after a long blind stretch: a match placed short of the car along a corridor
sees through the walls the car drove past, and the place that sees through none is taken."""

from __future__ import annotations

import numpy as np

from estimators.matching.scan_recovery import least_seen_through_place
from tests.benchmarks.bench_modules import load
from tests.estimators.corridor_scans import corridor, scan_at

bench = load("bench_faults")


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
    run = bench.faulted_score("pc_fusion", recording, "blind_100")
    assert run.health["blind_stretches"] == 1
    assert run.final < 0.15  # (clean: 0.02 m)
