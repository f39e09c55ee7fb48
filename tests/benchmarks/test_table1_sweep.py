"""The Table I density sweep's bookkeeping: its scenarios, the per-density summary and the
density where a line first reaches the paper's figure (the runs themselves are the benchmark)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.leaderboard.records import TraceDataset, TraceRecord
from lidar_env.world.feature_worlds import parse_world_name
from tests.benchmarks.bench_modules import load

sweep = load("table1_sweep")


def test_crossing_is_linear_between_the_densities_and_never_extrapolates() -> None:
    densities = [0.0, 1.0, 2.0, 4.0]
    assert sweep.crossing(densities, [0.0, 20.0, 40.0, 80.0], 60.0) == pytest.approx(3.0)
    assert sweep.crossing(densities, [70.0, 20.0, 40.0, 80.0], 60.0) == 0.0
    assert sweep.crossing(densities, [0.0, 65.0, 40.0, 80.0], 60.0) == pytest.approx(60 / 65)
    assert math.isnan(sweep.crossing(densities, [0.0, 10.0, 20.0, 59.9], 60.0))
    assert sweep.crossing(densities, [0.0, math.nan, 50.0, 70.0], 60.0) == pytest.approx(3.0)


def test_the_sweep_runs_each_area_density_seed_and_frame_with_features_from_the_seed() -> None:
    scenarios = sweep.sweep_scenarios([0.0, 2.0], [0, 1])
    assert len(scenarios) == len(set(scenarios)) == 2 * 2 * 2 * 2
    for s in scenarios:
        base, options = parse_world_name(s.world)
        assert base in sweep.AREAS and s.trace == "zigzag" and s.driver == "scripted"
        assert options.seed == (s.seed if options.density else 0)
        assert s.config["scan_frame"] in ("world", "sensor")
    assert {s.world for s in scenarios if "?" not in s.world} == set(sweep.AREAS)


def test_summary_means_each_line_over_its_seeds() -> None:
    scenarios = sweep.sweep_scenarios([0.0, 2.0], [0, 1], areas=("hallway",))
    records = {}
    for s in scenarios:
        density = parse_world_name(s.world)[1].density
        value = 10.0 * density + s.seed  # seeds 0 and 1: mean +0.5, std 0.5
        trace = TraceDataset("pc_pg", {}, np.zeros(1), np.zeros((1, 3)), np.zeros(1))
        records[(s, "pc_pg")] = TraceRecord(0, s, trace, {"accuracy_percent": value,
                                                          "ate_rmse_m": 1.0})
    rows = sweep.summarise(scenarios, [0.0, 2.0], records, areas=("hallway",))
    line = [r for r in rows if (r["frame"], r["estimator"]) == ("world", "pc_pg")]
    assert [(r["density"], r["seeds"]) for r in line] == [(0.0, 2), (2.0, 2)]
    assert [r["accuracy_mean"] for r in line] == pytest.approx([0.5, 20.5])
    assert [r["accuracy_std"] for r in line] == pytest.approx([0.5, 0.5])
    assert all(r["seeds"] == 0 and math.isnan(r["accuracy_mean"]) for r in rows
               if r["estimator"] != "pc_pg")
