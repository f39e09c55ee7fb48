"""Edited, full and shared databases: rows whose checksum was deleted are refused, not read
unverified; swapping two scenarios' seeds is a checksum mismatch; a full disk is one named
error after which everything stored before is intact; the command line prints these as one
line with exit status 2; and a second run on the same database counts what the first stored
meanwhile as already stored instead of redoing it."""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard import cli as leaderboard
from estimators.leaderboard import runner
from estimators.leaderboard.checksums import digest
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.schema import CorruptDatabaseError, DatabaseWriteError
from tests.estimators.leaderboard.test_database import (
    SCENARIO,
    synthetic_dataset,
    synthetic_trace,
)
from tests.estimators.leaderboard.test_runner import ESTIMATORS, SCENARIOS

OTHER = dataclasses.replace(SCENARIO, seed=SCENARIO.seed + 1)


@pytest.fixture
def stored(tmp_path: Path) -> Path:
    """A database holding two scenarios (seeds s and s + 1), each with a dataset and a trace
    whose ATE differs."""
    rng = np.random.default_rng(0)
    path = tmp_path / "experiments.sqlite"
    with ExperimentDatabase(path) as db:
        for scenario, ate in ((SCENARIO, 0.5), (OTHER, 2.0)):
            db.save_sensor_dataset(scenario, synthetic_dataset(rng))
            db.save_trace(scenario, synthetic_trace(rng), {"ate_rmse_m": ate})
    return path


def edit(path: Path, *statements: str) -> None:
    conn = sqlite3.connect(path)
    for statement in statements:
        conn.execute(statement)
    conn.commit()
    conn.close()


def test_a_metric_forged_after_deleting_the_checksums_is_refused(stored: Path) -> None:
    edit(stored, "DELETE FROM checksums", "UPDATE results SET value = 0.001")
    with ExperimentDatabase(stored) as db:
        with pytest.raises(CorruptDatabaseError, match="have no checksum .* cannot be verified"):
            db.traces(poses=False)
        with pytest.raises(CorruptDatabaseError, match="sensor_steps rows of scenario_id 1 .* "
                                                       "no checksum"):
            db.load_sensor_dataset(SCENARIO)


def test_swapping_two_scenarios_seeds_is_a_checksum_mismatch(stored: Path) -> None:
    seeds = (SCENARIO.seed, OTHER.seed)
    edit(stored, f"UPDATE scenarios SET seed = -1 WHERE seed = {seeds[0]}",
         f"UPDATE scenarios SET seed = {seeds[0]} WHERE seed = {seeds[1]}",
         f"UPDATE scenarios SET seed = {seeds[1]} WHERE seed = -1")
    with ExperimentDatabase(stored) as db:
        with pytest.raises(CorruptDatabaseError, match="scenario's row were changed"):
            db.traces(poses=False)
        with pytest.raises(CorruptDatabaseError, match="checksum mismatch"):
            db.load_sensor_dataset(SCENARIO)


def test_checksums_of_the_first_version_still_verify(stored: Path) -> None:
    conn = sqlite3.connect(stored)
    for kind, key in conn.execute("SELECT kind, key FROM checksums").fetchall():
        conn.execute("UPDATE checksums SET sha256 = ? WHERE kind = ? AND key = ?",
                     (digest(conn, kind, key, version=1), kind, key))
    conn.commit()
    conn.close()
    with ExperimentDatabase(stored) as db:
        assert sorted(r.metrics["ate_rmse_m"] for r in db.traces()) == [0.5, 2.0]
        db.load_sensor_dataset(OTHER)
    edit(stored, "UPDATE results SET value = 0.001")
    with ExperimentDatabase(stored) as db, pytest.raises(CorruptDatabaseError, match="mismatch"):
        db.traces(poses=False)


def test_a_full_disk_is_named_and_loses_nothing_stored(stored: Path) -> None:
    with ExperimentDatabase(stored) as db:
        before = db.counts()
        pages = db._conn.execute("PRAGMA page_count").fetchone()[0]
        db._conn.execute(f"PRAGMA max_page_count = {pages}")  # SQLite's own "disk is full"
        third = dataclasses.replace(SCENARIO, seed=SCENARIO.seed + 7)
        with pytest.raises(DatabaseWriteError, match=r"could not write to the database .*"
                           r"experiments.sqlite \(database or disk is full\); .* intact"):
            db.save_sensor_dataset(third, synthetic_dataset(np.random.default_rng(1)))
        assert db.counts() == before
    with ExperimentDatabase(stored) as db:
        assert db.counts() == before
        assert len(db.traces()) == 2


@pytest.mark.parametrize(("error", "printed"), [
    (CorruptDatabaseError("db.sqlite: the traces rows ... (checksum mismatch)"),
     "error: db.sqlite: the traces rows ... (checksum mismatch)"),
    (OSError(28, "No space left on device", "board/results.csv"),
     "error: could not write board/results.csv (No space left on device); everything stored in "
     "the database is intact"),
])
def test_the_command_line_prints_database_and_disk_errors_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        error: Exception, printed: str) -> None:
    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(leaderboard, "_run", fail)
    status = leaderboard.main(["--no-real", "--no-progress", "--out", str(tmp_path / "board")])
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith(printed) and "Traceback" not in err and err.count("\n") == 1


def test_a_second_run_counts_what_the_first_stored_meanwhile(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The first scenario's completion makes "another process" (a second connection) run the
    second scenario; the first run then finds it stored and neither records nor replays it."""
    path, first, second = tmp_path / "db.sqlite", SCENARIOS[0], SCENARIOS[1]
    estimators = ESTIMATORS[:1]
    ran: list[str] = []
    run_task = runner.run_task
    monkeypatch.setattr(runner, "run_task", lambda task: ran.append(task.scenario.label)
                        or run_task(task))

    def other_process(scenario) -> None:
        if scenario == first:
            with ExperimentDatabase(path) as other:
                done = runner.run_scenarios(other, [second], estimators)
            assert (done.recorded, done.traces) == (1, 1)

    with ExperimentDatabase(path) as db:
        summary = runner.run_scenarios(db, [first, second], estimators, on_done=other_process)
    assert (summary.recorded, summary.traces, summary.skipped) == (1, 1, 1)
    assert ran == [first.label, second.label]  # each scenario ran once, in either process
