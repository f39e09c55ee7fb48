"""Table I's column at the matched feature density: which scenarios run, and what it reports."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.leaderboard import matrix
from estimators.leaderboard.records import Scenario, TraceDataset, TraceRecord
from estimators.leaderboard.table_one import table_one, table_one_markdown
from estimators.leaderboard.tasks import EstimatorSpec
from lidar_env import lidars_with_noise
from lidar_env.world.feature_worlds import FEATURE_WORLDS, parse_world_name


def _scenarios(groups):
    config = {"lidars": lidars_with_noise(range_noise_std=0.01)}
    return {g.name: [Scenario(g.world, g.trace, seed, config)
                     for seed in (0, 1)] for g in groups}


def test_the_closed_areas_also_run_world_aligned_at_the_matched_density() -> None:
    groups = matrix.build_groups(None, None)
    runs = matrix.table_one_scenarios(groups, _scenarios(groups), [EstimatorSpec("pc_pg")])
    assert set(runs["matched"]) == {(c.world, c.trace) for c in matrix.TABLE_I
                                    if c.world in FEATURE_WORLDS}
    for (world, _), matched in runs["matched"].items():
        plain = runs["world"][(world, "zigzag")]
        assert [s.seed for s in matched] == [s.seed for s in plain]
        for s, p in zip(matched, plain, strict=True):
            base, options = parse_world_name(s.world)
            assert (base, options.density, options.seed) == (world, matrix.MATCHED_DENSITY,
                                                              s.seed)
            assert (s.trace, s.config, s.driver) == (p.trace, p.config, p.driver)
    side = matrix.side_scenarios(runs)
    assert len(side) == 2 * 3 + 2 * 2 and len(set(side)) == len(side)
    none = matrix.table_one_scenarios(groups, _scenarios(groups), [EstimatorSpec("icp")])
    assert none["matched"] == {} and matrix.side_scenarios(none) == ()


def test_table_one_reports_ours_at_the_matched_density_beside_the_bare_walls() -> None:
    pair = ("hallway", "zigzag")
    plain = [Scenario(*pair, seed, {"scan_frame": "world"}) for seed in (0, 1)]
    groups = [matrix.Group("G2", *pair)]
    runs = matrix.table_one_scenarios(groups, {"G2": plain}, [EstimatorSpec("pc_pg")])
    records = {}
    for scenario, value in zip(runs["matched"][pair], [58.0, 64.0], strict=True):
        trace = TraceDataset("pc_pg", {}, np.zeros(1), np.zeros((1, 3)), np.zeros(1))
        records[(scenario, "pc_pg")] = TraceRecord(0, scenario, trace,
                                                   {"accuracy_percent": value})
    rows = {r["case"]: r for r in table_one(runs, records)}
    assert rows[4]["ours_matched_accuracy_percent"] == pytest.approx(61.0)
    assert rows[4]["ours_matched_std_percent"] == pytest.approx(3.0)
    assert rows[4]["ours_world_seeds"] == 0  # the bare-wall runs are a column of their own
    assert rows[3]["ours_matched_seeds"] == 0 and math.isnan(
        rows[3]["ours_matched_accuracy_percent"])
    table = table_one_markdown(list(rows.values()))
    assert (f"ours at the density where the paper's closed-area figure is matched "
            f"({matrix.MATCHED_DENSITY:g} features / 10 m, world-aligned) [%] |") in table
    assert "| 61.00 ± 3.00 (2) |" in table
