"""pc_fusion on a clock that stamps its scans in bunches (as the Intel Lab log's logger does)."""

from __future__ import annotations

import numpy as np
import pytest

import estimators
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

