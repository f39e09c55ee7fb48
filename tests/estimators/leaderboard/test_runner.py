"""The scenario runner: resume after a killed worker, and the same code on Dask."""

from __future__ import annotations

import multiprocessing
import os
import signal
import sqlite3
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.records import Scenario
from estimators.leaderboard.runner import (
    RunInterrupted,
    SideRun,
    run_matrix,
    run_real_logs,
    run_scenarios,
)
from estimators.leaderboard.tasks import EstimatorSpec
from lidar_env import lidars_with_noise

# Short episodes (4 s of driving, 41 observations) keep the test quick.
SHORT = {"lidars": lidars_with_noise(range_noise_std=0.01), "max_episode_time": 4.0}
SCENARIOS = [Scenario(world, trace, seed, SHORT)
             for world, trace in (("open_cylinders", "right_turn"), ("hallway", "zigzag"))
             for seed in (0, 1, 2)]
ESTIMATORS = [EstimatorSpec("zero"), EstimatorSpec("pc")]


def stored_traces(path: Path) -> list[tuple[int, str, str, int, str]]:
    """(trace id, world, trace, seed, estimator) of every stored trace, read independently."""
    with sqlite3.connect(path) as conn:
        rows = conn.execute(
            "SELECT traces.id, world, trace, seed, estimator FROM traces "
            "JOIN scenarios ON scenarios.id = traces.scenario_id ORDER BY traces.id"
        ).fetchall()
    conn.close()
    return rows


@pytest.mark.slow
def test_a_killed_worker_loses_only_unfinished_scenarios_and_a_rerun_resumes(
    tmp_path: Path,
) -> None:
    path = tmp_path / "db.sqlite"
    killed: list[int] = []

    def kill_a_worker(_: Scenario) -> None:
        if not killed:
            victim = multiprocessing.active_children()[0]
            os.kill(victim.pid, signal.SIGKILL)
            killed.append(victim.pid)

    with ExperimentDatabase(path) as db, ProcessPoolExecutor(2) as pool:
        with pytest.raises(RunInterrupted, match="re-run to resume"):
            run_scenarios(db, SCENARIOS, ESTIMATORS, pool, max_in_flight=2,
                          on_done=kill_a_worker)
    assert killed
    before = stored_traces(path)
    finished = {row[1:4] for row in before}
    assert 1 <= len(finished) < len(SCENARIOS)
    assert len(before) == len(ESTIMATORS) * len(finished)  # finished scenarios are complete

    with ExperimentDatabase(path) as db:
        summary = run_scenarios(db, SCENARIOS, ESTIMATORS)
        assert summary.skipped == len(finished)
        assert summary.recorded == len(SCENARIOS) - len(finished)
        assert not summary.failures
        counts = db.counts()
    after = stored_traces(path)
    assert after[: len(before)] == before  # committed rows untouched, same ids
    assert len(after) == len(set(row[1:] for row in after)) == len(SCENARIOS) * len(ESTIMATORS)
    assert counts["sensor_datasets"] == len(SCENARIOS)
    assert counts["sensor_steps"] == 41 * len(SCENARIOS)

    with ExperimentDatabase(path) as db:  # a third run has nothing left to do
        summary = run_scenarios(db, SCENARIOS, ESTIMATORS)
        assert (summary.skipped, summary.recorded, summary.traces) == (len(SCENARIOS), 0, 0)
        assert db.counts() == counts


@pytest.mark.slow
def test_two_scenarios_through_dask_match_a_serial_run(tmp_path: Path) -> None:
    distributed = pytest.importorskip("distributed")
    dask = pytest.importorskip("dask")  # its scratch folder (lock files) goes to tmp_path
    scenarios = SCENARIOS[:2]
    with dask.config.set({"temporary-directory": str(tmp_path)}), distributed.Client(
            processes=False, dashboard_address=None) as client:
        with ExperimentDatabase(tmp_path / "dask.sqlite") as db:
            summary = run_scenarios(db, scenarios, ESTIMATORS, client)
            on_dask = {(r.scenario, r.trace.estimator): r for r in db.traces()}
    assert (summary.recorded, summary.traces, summary.failures) == (2, 4, {})
    with ExperimentDatabase(tmp_path / "serial.sqlite") as db:
        run_scenarios(db, scenarios, ESTIMATORS)
        serial = {(r.scenario, r.trace.estimator): r for r in db.traces()}
    assert on_dask.keys() == serial.keys()
    for key, record in serial.items():
        np.testing.assert_array_equal(on_dask[key].trace.poses, record.trace.poses)
        timing_free = {k: v for k, v in record.metrics.items() if k != "ms_per_step"}
        assert {k: on_dask[key].metrics[k] for k in timing_free} == timing_free


def test_unknown_estimator_and_bad_window_are_readable_errors(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown estimator 'pcc': expected one of .*pc"):
        EstimatorSpec("pcc")
    with ExperimentDatabase(tmp_path / "db.sqlite") as db, pytest.raises(
        ValueError, match="max_in_flight: expected an integer >= 1, got 0"
    ):
        run_scenarios(db, SCENARIOS[:1], ESTIMATORS, max_in_flight=0)


def test_the_map_reference_is_computed_once_per_scenario(monkeypatch: pytest.MonkeyPatch,
                                                        tmp_path: Path) -> None:
    from estimators.leaderboard import tasks

    calls = []

    def counted(dataset):  # noqa: ANN001, ANN202 - a spy around the real function
        calls.append(len(dataset))
        return real(dataset)

    real = tasks.map_reference
    monkeypatch.setattr(tasks, "map_reference", counted)
    with ExperimentDatabase(tmp_path / "db.sqlite") as db:
        summary = run_scenarios(db, SCENARIOS[:1], ESTIMATORS)
        records = db.traces(poses=False)
    assert calls == [41] and summary.traces == 2
    assert set(summary.stage_seconds) == {"record", "estimators", "map reference", "map scores"}
    for record in records:  # every trace got map scores, the zero estimator's worse
        assert {"map_iou", "cylinder_recall", "cylinder_error_m"} <= set(record.metrics)
    iou = {r.trace.estimator: r.metrics["map_iou"] for r in records}
    assert 0 <= iou["zero"] < iou["pc"] <= 1


def test_a_failing_map_score_keeps_the_trace(monkeypatch: pytest.MonkeyPatch,
                                             tmp_path: Path) -> None:
    from estimators.leaderboard import tasks

    real = tasks.score_map

    def fails_for_zero(reference, poses, dataset, **kwargs):  # noqa: ANN001, ANN003, ANN202
        if not np.any(np.diff(poses, axis=0)):  # a faulty mapper
            raise FloatingPointError("no motion")
        return real(reference, poses, dataset, **kwargs)

    monkeypatch.setattr(tasks, "score_map", fails_for_zero)
    with ExperimentDatabase(tmp_path / "db.sqlite") as db:
        summary = run_scenarios(db, SCENARIOS[:1], ESTIMATORS)
        metrics = {r.trace.estimator: r.metrics for r in db.traces(poses=False)}
    assert summary.traces == 2 and list(summary.failures) == [
        f"{SCENARIOS[0].label}: zero map"]
    assert "FloatingPointError: no motion" in summary.failures[f"{SCENARIOS[0].label}: zero map"]
    assert "map_iou" not in metrics["zero"] and "ate_rmse_m" in metrics["zero"]
    assert "map_iou" in metrics["pc"]


def test_a_side_run_replays_its_own_scenarios_through_its_own_estimators(
    tmp_path: Path,
) -> None:
    main = SCENARIOS[0]
    world_aligned = Scenario(main.world, main.trace, main.seed,
                             {**main.config, "scan_frame": "world"})
    side = SideRun((world_aligned,), (EstimatorSpec("pc"),))
    with ExperimentDatabase(tmp_path / "db.sqlite") as db:
        summary = run_matrix(db, [main], (), ESTIMATORS, side_runs=[side])
        assert (summary.recorded, summary.traces, summary.failures) == (2, 3, {})
        assert db.load_sensor_dataset(world_aligned).setup.world_aligned
        assert not db.load_sensor_dataset(main).setup.world_aligned
        metrics = {(r.scenario, r.trace.estimator): r.metrics for r in db.traces(poses=False)}
        again = run_matrix(db, [main], (), ESTIMATORS, side_runs=[side])
    assert sorted(name for scenario, name in metrics if scenario == world_aligned) == ["pc"]
    assert "map_iou" not in metrics[(world_aligned, "pc")]  # side runs are not mapped
    assert "map_iou" in metrics[(main, "pc")]
    assert world_aligned.label == f"{main.label}/world"
    assert (again.skipped, again.recorded, again.traces) == (2, 0, 0)


def test_estimators_that_need_more_lidars_than_a_log_has_are_neither_run_nor_failed(
    tmp_path: Path,
) -> None:
    # The log's files do not exist: any estimator that is attempted fails, which is how this
    # test tells "not run" from "run".
    log = RealLog("aces", str(tmp_path / "none.clf"), str(tmp_path / "none.relations"))
    specs = [EstimatorSpec("pc_offset"), EstimatorSpec("pc_pg"), EstimatorSpec("pc")]
    settled: list[Scenario] = []
    with ExperimentDatabase(tmp_path / "db.sqlite") as db:
        summary = run_real_logs(db, [log], specs, on_done=settled.append)
    assert summary.not_applicable == {"aces/log/s0: pc_offset": "needs 2 Lidars",
                                      "aces/log/s0: pc_pg": "needs 2 Lidars"}
    assert list(summary.failures) == ["aces/log/s0: pc"]
    assert settled == [log.scenario] * 3  # a progress bar still reaches its end
    assert EstimatorSpec("pc_offset").not_applicable(2) is None
    assert EstimatorSpec("pc", {"lidar": 1}).not_applicable(1) == "needs 2 Lidars"
