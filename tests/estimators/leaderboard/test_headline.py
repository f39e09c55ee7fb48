"""The board's Markdown: the lead paragraph first, then the headline table and its notes, and
per-group tables ranked by the group's own result with the overall rank in a column."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from estimators.leaderboard.headline import annotate_rows, board_markdown, group_markdown
from estimators.leaderboard.matrix import Group
from estimators.leaderboard.records import Scenario, TraceDataset, TraceRecord
from estimators.leaderboard.report import split_board
from estimators.leaderboard.tables import rank_table
from estimators.leaderboard.tasks import EstimatorSpec

G1 = Group("G1 open+right_turn", "open_cylinders", "right_turn")
G2 = Group("G2 hallway+zigzag", "hallway", "zigzag")
#: ATE [m] per (group, estimator): slam wins overall, lidar_odometry wins G1 (as in a real run).
ATE = {("G1 open+right_turn", "slam"): 0.007, ("G1 open+right_turn", "lidar_odometry"): 0.004,
       ("G1 open+right_turn", "zero"): 14.0, ("G2 hallway+zigzag", "slam"): 0.013,
       ("G2 hallway+zigzag", "lidar_odometry"): 0.030, ("G2 hallway+zigzag", "zero"): 19.0}
#: eq.-11 accuracy [%] per (group, estimator): higher is better.
ACCURACY = {"slam": 99.0, "lidar_odometry": 99.5, "zero": 0.0}


def board() -> tuple[list[dict[str, Any]], list[Group]]:
    groups = [G1, G2]
    scenarios = {g.name: [Scenario(g.world, g.trace, seed, {}) for seed in (0, 1)]
                 for g in groups}
    records = {}
    for group in groups:
        for scenario in scenarios[group.name]:
            for name in ("zero", "lidar_odometry", "slam"):
                trace = TraceDataset(name, {}, np.empty(0), np.empty((0, 3)), np.empty(0))
                ate = ATE[(group.name, name)] * (1 + 0.01 * scenario.seed)
                records[(scenario, name)] = TraceRecord(len(records), scenario, trace, {
                    "ate_rmse_m": ate, "accuracy_percent": ACCURACY[name]})
    specs = [EstimatorSpec(n) for n in ("zero", "lidar_odometry", "slam")]
    rows = rank_table(groups, scenarios, specs, records, None, "ate_rmse_m")
    return annotate_rows(rows, groups, scenarios, records, "ate_rmse_m"), groups


def table_rows(markdown: str) -> list[list[str]]:
    lines = [line for line in markdown.splitlines() if line.startswith("|")][2:]
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in lines]


def test_a_group_table_is_ranked_by_the_groups_own_metric_with_the_overall_rank() -> None:
    rows, _ = board()
    assert [r["estimator"] for r in rows] == ["slam", "lidar_odometry", "zero"]  # overall
    g1 = table_rows(group_markdown(rows, G1, "ate_rmse_m"))
    assert [(r[0], r[1], r[-1]) for r in g1] == [("1", "lidar_odometry", "=1"),
                                                 ("2", "slam", "1"), ("3", "zero", "=1")]
    assert g1[0][3].startswith("0.004") and g1[1][3].startswith("0.007")
    g2 = table_rows(group_markdown(rows, G2, "ate_rmse_m"))
    assert [r[1] for r in g2] == ["slam", "lidar_odometry", "zero"]
    # higher is better for accuracy: the group table turns round
    by_accuracy = table_rows(group_markdown(rows, G2, "accuracy_percent"))
    assert [r[1] for r in by_accuracy] == ["lidar_odometry", "slam", "zero"]


def test_a_missing_group_value_goes_last() -> None:
    rows, _ = board()
    rows[0] = {**rows[0], "G1 open+right_turn ate_rmse_m": math.nan}  # slam did not run in G1
    g1 = table_rows(group_markdown(rows, G1, "ate_rmse_m"))
    assert [r[1] for r in g1] == ["lidar_odometry", "zero", "slam"]
    assert g1[-1][3] == "n/a"


def test_the_board_leads_with_the_answer_then_the_headline_then_the_groups() -> None:
    rows, groups = board()
    parts = split_board(board_markdown(rows, groups, None, "ate"))
    assert parts.lead.startswith("3 estimators (slam, lidar_odometry, zero) ran on 4 simulated")
    assert "slam ranks first" in parts.lead
    assert [r[1] for r in table_rows(parts.table)] == ["slam", "lidar_odometry", "zero"]
    assert "Simulated figures" in parts.notes and "Wilcoxon" in parts.notes
    assert parts.rest.startswith("## Per group: each table ranked by the group's own ATE [m]")
    assert "### G1 open+right_turn (mean ± std over seeds)\n\n| # | estimator |" in parts.rest
    assert "## Maps at the estimated poses" in parts.rest
