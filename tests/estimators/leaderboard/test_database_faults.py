"""A damaged experiment database is named, never silently read: a file
that claims our schema version but lacks a table or column is refused at open, and a changed
value inside a stored sensor dataset or trace fails its checksum on read, naming the rows."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.schema import CorruptDatabaseError, SchemaMismatchError
from lidar_env.core.errors import DatabaseError
from tests.estimators.leaderboard.test_database import (
    SCENARIO,
    synthetic_dataset,
    synthetic_trace,
)


@pytest.fixture
def stored(tmp_path: Path):
    """A database with one sensor dataset and one trace, and what was stored."""
    rng = np.random.default_rng(0)
    path = tmp_path / "experiments.sqlite"
    dataset, trace = synthetic_dataset(rng), synthetic_trace(rng)
    with ExperimentDatabase(path) as db:
        db.save_sensor_dataset(SCENARIO, dataset)
        db.save_trace(SCENARIO, trace, {"ate_m": 0.5})
    return path, dataset, trace


def edit(path: Path, *statements: str) -> None:
    conn = sqlite3.connect(path)
    for statement in statements:
        conn.execute(statement)
    conn.commit()
    conn.close()


@pytest.mark.parametrize(
    ("statements", "message"),
    [
        (["DROP TABLE results"], "table results is missing"),
        (["ALTER TABLE trace_poses RENAME COLUMN ms TO millis"], "table trace_poses lacks column"
                                                                 r"\(s\) ms"),
    ],
)
def test_a_file_missing_tables_or_columns_is_refused_at_open(stored, statements, message):
    path = stored[0]
    edit(path, *statements)
    before = path.read_bytes()
    with pytest.raises(SchemaMismatchError, match=message):
        ExperimentDatabase(path)
    assert path.read_bytes() == before


def test_a_changed_scan_value_is_named_on_read(stored):
    path = stored[0]
    edit(path, "UPDATE sensor_steps SET x = x + 1e-9 WHERE step = 7")
    with ExperimentDatabase(path) as db, pytest.raises(
        CorruptDatabaseError, match="sensor_steps rows of scenario_id 1 .*checksum mismatch"
    ):
        db.load_sensor_dataset(SCENARIO)


def test_a_changed_trace_pose_or_metric_is_named_on_read(stored):
    path = stored[0]
    for statement in ("UPDATE trace_poses SET heading = 0 WHERE step = 3",
                      "UPDATE results SET value = 0.25"):
        edit(path, statement)
        with ExperimentDatabase(path) as db, pytest.raises(
            CorruptDatabaseError, match="trace_poses/results rows of trace_id 1 .*pc on hallway"
        ):
            db.traces()


def test_random_overwrites_are_named_or_harmless(stored):
    """The audit's fault: 64 random bytes over a data page. Each outcome is a named error (at
    open or on read) or data identical to what was stored, never a silently changed row."""
    path, dataset, trace = stored
    pristine = path.read_bytes()
    rng = np.random.default_rng(18)
    outcomes = {"named": 0, "unchanged": 0}
    for _ in range(40):
        data = bytearray(pristine)
        start = int(rng.integers(4096, len(data) - 64))  # past page 1 (the header)
        data[start : start + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
        path.write_bytes(bytes(data))
        try:
            with ExperimentDatabase(path) as db:
                loaded = db.load_sensor_dataset(SCENARIO)
                record = db.traces()[0]
        except DatabaseError:
            outcomes["named"] += 1
            continue
        for key in dataset.scans:
            np.testing.assert_array_equal(loaded.scans[key], dataset.scans[key])
        np.testing.assert_array_equal(loaded.poses, dataset.poses)
        np.testing.assert_array_equal(record.trace.poses, trace.poses)
        assert record.metrics == {"ate_m": 0.5}
        outcomes["unchanged"] += 1
    assert outcomes["named"] > 0
