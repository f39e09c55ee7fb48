"""The ``icp`` estimator along the fault matrix's hallway: the corridor's axis, which the scans
leave free, follows the motion model rather than the noise of walls seen at grazing angles,
with half the beams dropped or one Lidar frozen."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.datasets.faults import with_faults
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")


@pytest.fixture(scope="module")
def hallway():
    recording = bench.record_drive("hallway/zigzag")
    clean, _, _ = bench.run("icp", recording, recording.truth[0])
    return recording, bench.score(clean, recording.truth, recording.truth)


def test_the_clean_hallway_ends_within_a_quarter_metre(hallway) -> None:
    _, (_, final) = hallway
    assert final < 0.25  # [m] after 40 m


@pytest.mark.parametrize("fault", ["dropout_half", "frozen"])
def test_the_hallway_cells_meet_the_fault_matrix_targets(hallway, fault) -> None:
    recording, (clean_jump, clean_final) = hallway
    period = float(np.median(np.diff(recording.times)))
    faulted = with_faults(recording, bench.faults_for(period, recording.setup.n_lidars)[fault](),
                          seed=0)
    poses, _, _ = bench.run("icp", faulted, recording.truth[0])
    kept = recording.truth[bench.steps_of(recording, faulted)]
    jump, final = bench.score(poses, kept, kept)
    assert jump - clean_jump <= bench.JUMP_MARGIN, (jump, clean_jump)
    assert final <= bench.FINAL_FACTOR * clean_final + bench.FINAL_MARGIN, (final, clean_final)
