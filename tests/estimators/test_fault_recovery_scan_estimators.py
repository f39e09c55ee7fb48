"""Fault-matrix cells of the scan-to-scan estimators (``pc_fusion``, ``icp``): after scans
lost (a clock gap) or skipped (a blinded Lidar), the pose is found again, and a clock that
only jumped while the scans ran on is not taken for a gap."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from estimators.datasets.faults import with_faults
from estimators.odometry.fusion_recovery import intervals_since_used

_BENCHMARKS = str(Path(__file__).resolve().parents[2] / "benchmarks")
sys.path.insert(0, _BENCHMARKS)
try:
    bench = importlib.import_module("bench_faults")
finally:
    sys.path.remove(_BENCHMARKS)

GROUPS = ("hallway/zigzag", "closed_to_open/zigzag")


@pytest.fixture(scope="module")
def drives() -> dict:
    return {group: bench.record_drive(group) for group in GROUPS}


CELLS = [
    ("pc_fusion", "closed_to_open/zigzag", "gaps"),
    ("pc_fusion", "hallway/zigzag", "blind_3s"),
    # a turn while blind: the recovered motion is matched again until it converges
    ("pc_fusion", "closed_to_open/zigzag", "blind_3s"),
    # half the beams dropped: a match fooled along the corridor does not outvote the others
    ("pc_fusion", "closed_to_open/zigzag", "dropout_half"),
    # the longer guess must not be taken where only the stamp jumped
    ("pc_fusion", "hallway/zigzag", "clock_jump_3s"),
    ("pc_fusion", "closed_to_open/zigzag", "clock_jump_3s"),
]


@pytest.mark.parametrize(("name", "group", "fault"), CELLS)
def test_the_pose_is_found_again_after_the_fault(drives, name, group, fault) -> None:
    recording = drives[group]
    clean, _, _ = bench.run(name, recording, recording.truth[0])
    clean_jump, clean_final = bench.score(clean, recording.truth)
    period = float(np.median(np.diff(recording.times)))
    faulted = with_faults(recording, bench.faults_for(period, recording.setup.n_lidars)[fault](),
                          seed=0)
    poses, health, _ = bench.run(name, faulted, recording.truth[0])
    jump, final = bench.score(poses, recording.truth[bench.steps_of(recording, faulted)])
    assert jump - clean_jump <= bench.JUMP_MARGIN, (jump, clean_jump)
    assert final <= bench.FINAL_FACTOR * clean_final + bench.FINAL_MARGIN, (final, clean_final)
    assert fault == "dropout_half" or health["skipped_scans"] + health["clock_jumps"] > 0


def test_intervals_count_skipped_scans_and_clock_gaps() -> None:
    assert intervals_since_used(0, False, 0.1, [0.1]) == 1.0
    assert intervals_since_used(30, False, 3.1, [0.1]) == 31.0
    assert intervals_since_used(0, True, 1.1, [0.1]) == pytest.approx(11.0)
    assert intervals_since_used(2, True, 0.2, []) == 3.0  # no typical step known yet
