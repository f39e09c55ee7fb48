"""A mount wrong by 5 cm / 3 degrees degrades the estimators; self-calibration recovers them."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.calibration.comparison import compare_mounts, comparison_table, perturbed
from estimators.leaderboard.recording import record
from estimators.leaderboard.records import Scenario
from lidar_env.core.errors import EstimatorInputError


def test_perturbed_moves_only_the_chosen_lidar() -> None:
    setup = record(Scenario("hallway", "zigzag", 0, config={"max_episode_time": 2.0})).setup
    wrong = perturbed(setup, (0.03, 0.04, 0.05))
    np.testing.assert_array_equal(wrong.mounts[0], setup.mounts[0])
    np.testing.assert_allclose(wrong.mounts[1], setup.mounts[1] + [0.03, 0.04, 0.05])
    with pytest.raises(EstimatorInputError, match="k: expected a Lidar index in 1..1, got 2"):
        perturbed(setup, (0.0, 0.0, 0.0), k=2)


@pytest.mark.slow
def test_a_wrong_mount_degrades_and_the_calibrated_one_recovers() -> None:
    dataset = record(Scenario("closed_to_open", "zigzag", 5, config={"max_episode_time": 25.0}))
    results = compare_mounts(dataset, (0.03, 0.04, np.radians(3.0)), ["pc_fusion",
                                                                      "lidar_odometry"])
    for estimator in ("pc_fusion", "lidar_odometry"):
        true, wrong, calibrated = (results[s][estimator]["ate_rmse_m"]
                                   for s in ("true", "wrong", "calibrated"))
        assert wrong > 3 * true and wrong > 0.03, (estimator, true, wrong)
        assert calibrated < 1.5 * true + 0.005, (estimator, true, calibrated)
    assert "| calibrated | lidar_odometry |" in comparison_table(results)
