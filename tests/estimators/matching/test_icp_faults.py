"""The ``icp`` estimator finds the car again after a blinded Lidar: 3 s of scans skipped through
a 45-degree turn (open_cylinders) or a zigzag (closed_to_open), or 10 s on open_cylinders,
and its pose after each stretch meets the fault matrix's targets (benchmarks/bench_faults.py)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from estimators.datasets.faults import with_faults

_BENCHMARKS = str(Path(__file__).resolve().parents[3] / "benchmarks")
sys.path.insert(0, _BENCHMARKS)
try:
    bench = importlib.import_module("bench_faults")
finally:
    sys.path.remove(_BENCHMARKS)

CELLS = [("open_cylinders/right_turn", "blind_3s"), ("open_cylinders/right_turn", "blind_100"),
         ("closed_to_open/zigzag", "blind_3s")]


@pytest.fixture(scope="module")
def drives() -> dict:
    return {group: bench.record_drive(group) for group in {group for group, _ in CELLS}}


@pytest.mark.parametrize(("group", "fault"), CELLS)
def test_icp_finds_the_pose_again_after_blind_scans(drives, group, fault) -> None:
    recording = drives[group]
    clean, _, _ = bench.run("icp", recording, recording.truth[0])
    clean_jump, clean_final = bench.score(clean, recording.truth)
    period = float(np.median(np.diff(recording.times)))
    faulted = with_faults(recording, bench.faults_for(period, recording.setup.n_lidars)[fault](),
                          seed=0)
    poses, health, _ = bench.run("icp", faulted, recording.truth[0])
    jump, final = bench.score(poses, recording.truth[bench.steps_of(recording, faulted)])
    assert health["skipped_scans"] > 0 and health["blind_stretches"] > 0
    assert jump - clean_jump <= bench.JUMP_MARGIN, (jump, clean_jump)
    assert final <= bench.FINAL_FACTOR * clean_final + bench.FINAL_MARGIN, (final, clean_final)
