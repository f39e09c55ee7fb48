"""pc_fusion on a clock that stamps its scans in bunches (as the Intel Lab log's logger does)."""

from __future__ import annotations

import numpy as np
import pytest

import estimators
from tests.benchmarks.bench_modules import load
from tests.estimators.odometry.test_fusion import drive_through_corridor


def bunched_stamps(count: int, bunch: int, period: float) -> np.ndarray:
    """Stamps [s] of ``count`` scans taken every ``period`` [s] but stamped ``bunch`` at a
    time, 1 ms apart, one bunch every ``bunch * period``."""
    k = np.arange(count)
    return (k // bunch) * bunch * period + (k % bunch) * 1e-3


@pytest.mark.parametrize("bunch", [2, 3])
def test_scans_stamped_in_bunches_cross_a_featureless_corridor_at_the_scans_own_speed(
        bunch: int) -> None:
    # Along the corridor only the velocity carries the car on. The scans come every 0.1 s
    # but are stamped a few within a millisecond, then none for the rest of the bunch's time:
    # counted by their stamps, the steps' speeds are off many times over.
    setup, observations, truth = drive_through_corridor(0.0, seed=1)
    estimator = estimators.make("pc_fusion")
    estimator.reset(setup, truth[0])
    for observation, t in zip(observations, bunched_stamps(len(observations), bunch, 0.1),
                              strict=True):
        estimator.update(observation, float(t))
    along = estimator.trajectory[:, 0] - truth[:, 0]
    entry = np.argmax(truth[:, 0] > 13.0)
    assert abs(along[-1] - along[entry]) < 0.1


bench = load("bench_faults")
needs_intel = pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("intel")),
                                 reason="needs the Intel Lab Radish log")


@needs_intel
@pytest.mark.parametrize("first", [3000, 6000])
def test_intel_with_half_the_beams_dropped_meets_the_fault_targets(first: int) -> None:
    # Intel's logger stamps its ~5 Hz scans in bunches (median interval 0.06 s, mean 0.2 s)
    recording = bench.log_recording("intel", first, 600)
    clean, _, _ = bench.run("pc_fusion", recording, bench.start_of(recording.truth))
    clean_jump, clean_final = bench.score(clean, clean, recording.truth)
    run = bench.faulted_score("pc_fusion", recording, "dropout_half", clean)
    assert bench.verdict(run, clean_jump, clean_final)
