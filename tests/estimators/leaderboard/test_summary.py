"""The leaderboard's lead paragraph: what ran, who wins by how much, which estimators tie and
why, the best per group and on the real log, all read from the ranked rows."""

from __future__ import annotations

import math
import re
from typing import Any

from estimators.leaderboard.matrix import Group
from estimators.leaderboard.summary import MIN_SEPARABLE_RUNS, lead_paragraph

GROUPS = [Group("G1 open+right_turn", "open_cylinders", "right_turn"),
          Group("G2 hallway+zigzag", "hallway", "zigzag")]


def row(name: str, rank: str, ate: float, tie_p: float, g1: float, g2: float,
        runs: int = 4, **extra: Any) -> dict[str, Any]:
    return {"estimator": name, "rank": rank, "ate_rmse_m": ate, "tie_p": tie_p,
            "scenarios": runs, "scenarios_run": runs, "seeds": 2,
            "G1 open+right_turn ate_rmse_m": g1, "G2 hallway+zigzag ate_rmse_m": g2, **extra}


def test_the_paragraph_names_what_ran_the_leader_the_gap_and_the_ties() -> None:
    rows = [row("slam", "1", 0.020, math.nan, 0.007, 0.033),
            row("lidar_odometry", "=1", 0.021, 0.62, 0.004, 0.038),
            row("icp", "3", 0.400, 0.01, 0.3, 0.5),
            row("zero", "4", 16.0, 0.01, 14.0, 18.0)]
    text = lead_paragraph(rows, GROUPS, None, "ate_rmse_m")
    assert "\n" not in text
    assert text.startswith("4 estimators (slam, lidar_odometry, icp, zero) ran on 4 simulated "
                           "runs: 2 scenario groups (G1 open+right_turn, G2 hallway+zigzag) × 2 "
                           "seeds; no real log.")
    assert "slam ranks first at 0.020 m; lidar_odometry follows at 0.021 m (1.05× the leader's)"\
        in text
    # the first estimator the test separates, and by how much
    assert "the first the test separates from the leader is icp (rank 3) at 0.400 m " \
           "(20× the leader's)" in text
    assert "Ties: slam and lidar_odometry share rank 1" in text and "p = 0.62" in text
    assert f"fewer than {MIN_SEPARABLE_RUNS} paired runs" in text  # 4 runs can never separate
    # per group: the group's own winner, even where it is not the overall one
    assert "lidar_odometry in 1 of 2 (G1 open+right_turn)" in text
    assert "slam in 1 of 2 (G2 hallway+zigzag)" in text


def test_enough_runs_without_ties_say_every_neighbour_differs() -> None:
    rows = [row("slam", "1", 0.02, math.nan, 0.01, 0.03, runs=10),
            row("icp", "2", 0.40, 0.002, 0.3, 0.5, runs=10)]
    text = lead_paragraph(rows, GROUPS, None, "ate_rmse_m")
    assert "Every neighbour in the ranking differs" in text and "10 runs" in text
    assert "Ties" not in text and "fewer than" not in text
    assert "slam in 2 of 2" in text


def test_accuracy_ranking_reports_a_difference_not_a_ratio() -> None:
    rows = [row("slam", "1", 0.02, math.nan, 0.01, 0.03, accuracy_percent=99.2),
            row("pc", "2", 0.5, 0.001, 0.4, 0.6, accuracy_percent=90.1)]
    rows[0].update({"G1 open+right_turn accuracy_percent": 99.0,
                    "G2 hallway+zigzag accuracy_percent": 99.4})
    rows[1].update({"G1 open+right_turn accuracy_percent": 99.5,
                    "G2 hallway+zigzag accuracy_percent": 80.7})
    text = lead_paragraph(rows, GROUPS, None, "accuracy_percent")
    assert "By mean eq.-11 accuracy, slam ranks first at 99.2%; pc follows at 90.1% (9.1 behind)"\
        in text
    assert "pc in 1 of 2 (G1 open+right_turn)" in text  # higher is better per group too


def test_the_real_log_best_and_estimators_that_did_not_run() -> None:
    rows = [row("slam", "1", 0.02, math.nan, 0.01, 0.03, relations_all_translation_m=0.041),
            row("lidar_odometry", "=1", 0.021, 0.5, 0.01, 0.03,
                relations_all_translation_m=0.035),
            row("pc_pg", "3", math.nan, math.nan, math.nan, math.nan,
                relations_all_translation_m=math.nan)]
    text = lead_paragraph(rows, GROUPS, "ACES", "ate_rmse_m")
    assert "and on the ACES log." in text
    assert "On ACES, lidar_odometry has the smallest mean relation translation error, 0.035 m " \
           "(next: slam, 0.041 m)." in text
    assert "nan" not in text.lower()
    nothing = [row("zero", "1", math.nan, math.nan, math.nan, math.nan)]
    assert "No estimator has a finite ATE." in lead_paragraph(nothing, GROUPS, None,
                                                              "ate_rmse_m")
    assert lead_paragraph([], GROUPS, None, "ate_rmse_m") == "No estimator ran."


def test_every_number_in_the_paragraph_comes_from_the_rows() -> None:
    rows = [row("slam", "1", 0.0173, math.nan, 0.0071, 0.0275),
            row("icp", "=1", 0.4261, 0.125, 0.221, 0.631)]
    text = lead_paragraph(rows, GROUPS, None, "ate_rmse_m")
    numbers = set(re.findall(r"\d+(?:\.\d+)?", text))
    # ATEs, the ratio (0.4261 / 0.0173), the p-value and the level; counts of runs and groups
    assert numbers == {"0.017", "0.426", "25", "0.12", "0.05", "4", "2", "1", "6"}, numbers
