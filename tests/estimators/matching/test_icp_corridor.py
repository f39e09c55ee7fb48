"""The ``icp`` estimator along the fault matrix's hallway: the corridor's axis, which the scans
leave free, follows the motion model rather than the noise of walls seen at grazing angles,
with half the beams dropped or one Lidar frozen."""

from __future__ import annotations

import pytest

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
    run = bench.faulted_score("icp", recording, fault)
    assert run.jump - clean_jump <= bench.JUMP_MARGIN, (run.jump, clean_jump)
    assert run.final <= bench.FINAL_FACTOR * clean_final + bench.FINAL_MARGIN, (run.final,
                                                                                clean_final)
