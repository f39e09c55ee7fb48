"""How many scan intervals ``pc_fusion`` counts since the last scan it used (its fault-matrix
cells are in ``tests/benchmarks/test_bench_faults.py``)."""

from __future__ import annotations

import pytest

from estimators.odometry.fusion_recovery import intervals_since_used


def test_intervals_count_skipped_scans_and_clock_gaps() -> None:
    assert intervals_since_used(0, False, 0.1, [0.1]) == 1.0
    assert intervals_since_used(30, False, 3.1, [0.1]) == 31.0
    assert intervals_since_used(0, True, 1.1, [0.1]) == pytest.approx(11.0)
    assert intervals_since_used(2, True, 0.2, []) == 3.0  # no typical step known yet
