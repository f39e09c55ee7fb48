"""Spread over seeds and tie marking of the leaderboard's ranks (estimators.leaderboard.ranking
and the headline table built on it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.leaderboard.headline import annotate_rows, headline_markdown
from estimators.leaderboard.matrix import Group
from estimators.leaderboard.ranking import (
    mark_ties,
    paired_p_value,
    seed_spread,
    tied_ranks,
)
from estimators.leaderboard.records import Scenario, TraceDataset, TraceRecord
from estimators.leaderboard.tables import rank_table
from estimators.leaderboard.tasks import EstimatorSpec


def record(scenario: Scenario, name: str, ate: float, trace_id: int) -> TraceRecord:
    empty = np.empty((0,))
    trace = TraceDataset(name, {}, empty, np.empty((0, 3)), empty)
    return TraceRecord(trace_id, scenario, trace, {"ate_rmse_m": ate, "accuracy_percent": 90.0})


def constructed_board(seed: int = 0) -> tuple[list[Group], dict[str, list[Scenario]],
                                              dict[tuple[Scenario, str], TraceRecord]]:
    """Six groups x two seeds, registered names standing in: "slam" is "lidar_odometry" plus
    zero-mean noise (no real difference);
    "icp" is "lidar_odometry" plus a consistent 5 cm."""
    rng = np.random.default_rng(seed)
    groups = [Group(f"g{i}", "hallway", f"trace{i}") for i in range(6)]
    scenarios = {g.name: [Scenario(g.world, g.trace, s, {}) for s in (0, 1)] for g in groups}
    records = {}
    for scenario in (s for runs in scenarios.values() for s in runs):
        base = rng.uniform(0.05, 0.5)
        for name, ate in (("lidar_odometry", base), ("slam", base + rng.normal(0.0, 0.002)),
                          ("icp", base + 0.05 + rng.normal(0.0, 0.002))):
            records[(scenario, name)] = record(scenario, name, ate, len(records))
    return groups, scenarios, records


def test_estimators_that_differ_by_noise_only_tie_and_a_real_gap_does_not() -> None:
    groups, scenarios, records = constructed_board()
    specs = [EstimatorSpec(n) for n in ("icp", "slam", "lidar_odometry")]
    rows = rank_table(groups, scenarios, specs, records, None, "ate_rmse_m")
    rows = annotate_rows(rows, groups, scenarios, records, "ate_rmse_m")
    order = [row["estimator"] for row in rows]
    assert order[2] == "icp"
    assert [row["rank"] for row in rows] == ["1", "=1", "3"]  # the twins tie, worse is 3rd
    assert rows[1]["tie_p"] >= 0.05 > rows[2]["tie_p"]
    table = headline_markdown(rows, None)
    assert f"| =1 | {order[1]} |" in table and "| 3 | icp |" in table


def test_tie_marks_are_stable_over_noise_draws() -> None:
    """Over many noise draws, the noise-only pair ties about as often as the test's level
    allows (it is a test: ~5 % false separations), the 5 cm gap always separates."""
    separated_twins = 0
    for seed in range(40):
        groups, scenarios, records = constructed_board(seed)
        every = [s for runs in scenarios.values() for s in runs]
        values = {n: [records[(s, n)].metrics["ate_rmse_m"] for s in every]
                  for n in ("lidar_odometry", "slam", "icp")}
        assert paired_p_value(values["slam"], values["icp"]) < 0.01
        separated_twins += paired_p_value(values["lidar_odometry"], values["slam"]) < 0.05
    assert separated_twins <= 6


def test_identical_values_tie_and_too_few_runs_cannot_separate() -> None:
    assert paired_p_value([0.1, 0.2, 0.3], [0.1, 0.2, 0.3]) == 1.0
    # five runs, one estimator better in every one: still p = 0.0625 (exact, two-sided)
    assert paired_p_value([1, 2, 3, 4, 5], [2, 3, 4, 5, 6]) == pytest.approx(0.0625)
    assert mark_ties(["a", "b"], {"a": [1, 2, 3, 4, 5], "b": [2, 3, 4, 5, 6]}) == [False, True]


def test_tied_ranks_share_the_rank_of_the_first_of_a_tied_run() -> None:
    assert tied_ranks([False, True, True, False, True]) == ["1", "=1", "=1", "4", "=4"]
    assert tied_ranks([False, False]) == ["1", "2"]


def test_seed_spread_is_the_std_of_the_per_seed_means() -> None:
    groups, scenarios, records = constructed_board()
    every = [s for runs in scenarios.values() for s in runs]
    spread = seed_spread(every, "lidar_odometry", "ate_rmse_m", records)
    per_seed = [np.mean([records[(s, "lidar_odometry")].metrics["ate_rmse_m"] for s in every
                         if s.seed == seed]) for seed in (0, 1)]
    assert spread.mean == pytest.approx(np.mean(per_seed))
    assert spread.std == pytest.approx(np.std(per_seed))
    assert (spread.seeds, spread.runs) == (2, 12)
    missing = seed_spread(every, "nobody", "ate_rmse_m", records)
    assert math.isnan(missing.mean) and missing.runs == 0 and missing.text(3) == "n/a"
