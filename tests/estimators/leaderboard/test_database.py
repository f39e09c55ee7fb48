"""The experiment database: round trip, idempotent writes, atomic transactions, and bad files
refused without being touched."""

from __future__ import annotations

import os
import shlex
import shutil
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from estimators.base import SensorSetup, default_beam_angles
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.records import Scenario, SensorDataset, TraceDataset
from estimators.leaderboard.schema import (
    SCHEMA_VERSION,
    CorruptDatabaseError,
    DatabaseLocationError,
    ForeignDatabaseError,
    NotADatabaseError,
    SchemaVersionError,
)
from lidar_env import lidars_with_noise

SCENARIO = Scenario("hallway", "zigzag", 3, {"lidars": lidars_with_noise(range_noise_std=0.01)})


def synthetic_dataset(rng: np.random.Generator, n_steps: int = 40) -> SensorDataset:
    """Random but well-formed sensor data (the database must store any such data exactly)."""
    setup = SensorSetup(np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]]),
                        default_beam_angles(360), 10.0)
    return SensorDataset(
        setup=setup,
        times=0.1 * np.arange(n_steps),
        scans={key: rng.uniform(0.1, 10.0, (n_steps, 360)).astype(np.float32)
               for key in setup.keys},
        poses=rng.normal(size=(n_steps, 3)),
        lidar_poses=rng.normal(size=(n_steps, 2, 3)),
        env_config={"lidars": lidars_with_noise(range_noise_std=0.01)},
        world={"name": "box", "circles": [[1.0, 2.0, 0.5]], "walls": [], "polygons": [],
               "bounds": [0.0, 0.0, 5.0, 5.0]},
    )


def synthetic_trace(rng: np.random.Generator, n_steps: int = 40) -> TraceDataset:
    return TraceDataset("pc", {"size": 400}, 0.1 * np.arange(n_steps),
                        rng.normal(size=(n_steps, 3)), rng.uniform(0.5, 2.0, n_steps))


@pytest.fixture
def filled_db(tmp_path: Path) -> Path:
    """A database holding one sensor dataset and one scored trace."""
    rng = np.random.default_rng(0)
    path = tmp_path / "experiments.sqlite"
    with ExperimentDatabase(path) as db:
        db.save_sensor_dataset(SCENARIO, synthetic_dataset(rng))
        db.save_trace(SCENARIO, synthetic_trace(rng), {"ate_m": 0.5, "accuracy_pct": 80.0})
    return path


def test_round_trip_is_exact_and_survives_reopening(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    dataset, trace = synthetic_dataset(rng), synthetic_trace(rng)
    path = tmp_path / "db.sqlite"
    with ExperimentDatabase(path) as db:
        assert db.save_sensor_dataset(SCENARIO, dataset)
        trace_id = db.save_trace(SCENARIO, trace, {"ate_m": 0.25, "drift_pct": np.float64(3.0)})
        assert trace_id is not None
    with ExperimentDatabase(path) as db:
        assert db.scenarios() == [SCENARIO]
        loaded = db.load_sensor_dataset(SCENARIO)
        for key in dataset.scans:
            assert loaded.scans[key].dtype == np.float32
            np.testing.assert_array_equal(loaded.scans[key], dataset.scans[key])
        np.testing.assert_array_equal(loaded.times, dataset.times)
        np.testing.assert_array_equal(loaded.poses, dataset.poses)
        np.testing.assert_array_equal(loaded.lidar_poses, dataset.lidar_poses)
        np.testing.assert_array_equal(loaded.setup.mounts, dataset.setup.mounts)
        np.testing.assert_array_equal(loaded.setup.beam_angles, dataset.setup.beam_angles)
        assert loaded.setup.max_range == 10.0 and not loaded.setup.world_aligned
        assert loaded.env_config == dataset.env_config and loaded.world == dataset.world
        (record,) = db.traces(SCENARIO)
        assert record.trace_id == trace_id and record.scenario == SCENARIO
        np.testing.assert_array_equal(record.trace.poses, trace.poses)
        np.testing.assert_array_equal(record.trace.step_ms, trace.step_ms)
        assert record.trace.params == {"size": 400}
        assert record.metrics == {"ate_m": 0.25, "drift_pct": 3.0}


def test_rewriting_stored_work_adds_no_rows(filled_db: Path) -> None:
    rng = np.random.default_rng(0)
    with ExperimentDatabase(filled_db) as db:
        before = db.counts()
        assert before["sensor_steps"] == 40 and before["traces"] == 1 and before["results"] == 2
        assert not db.save_sensor_dataset(SCENARIO, synthetic_dataset(rng))
        assert db.save_trace(SCENARIO, synthetic_trace(rng), {"ate_m": 9.0}) is None
        assert db.has_trace(SCENARIO, "pc", {"size": 400})
        assert not db.has_trace(SCENARIO, "pc", {"size": 800})
        assert db.counts() == before
        assert db.traces()[0].metrics["ate_m"] == 0.5  # the first write stays


def test_a_failing_write_leaves_no_partial_trace(filled_db: Path) -> None:
    rng = np.random.default_rng(5)
    other = Scenario("open_cylinders", "right_turn", 0)
    with ExperimentDatabase(filled_db) as db:
        before = db.counts()
        with pytest.raises(ValueError):  # the metric fails after the poses were inserted
            db.save_trace(other, synthetic_trace(rng), {"ate_m": "not a number"})
        assert db.counts() == before
        assert not db.has_trace(other, "pc", {"size": 400})


def test_a_scenario_batch_commits_together_and_skips_stored_traces(filled_db: Path) -> None:
    rng = np.random.default_rng(6)
    stored, new = synthetic_trace(rng), synthetic_trace(rng)
    new = TraceDataset("icp", {}, new.times, new.poses, new.step_ms)
    broken = TraceDataset("slam", {}, new.times, new.poses, new.step_ms)
    with ExperimentDatabase(filled_db) as db:
        before = db.counts()
        with pytest.raises(ValueError):  # the last trace fails: the whole batch is rolled back
            db.save_traces(SCENARIO, [(new, {"ate_m": 0.1}), (broken, {"ate_m": "nan?"})])
        assert db.counts() == before
        ids = db.save_traces(SCENARIO, [(stored, {"ate_m": 9.0}), (new, {"ate_m": 0.1})])
        assert ids[0] is None and isinstance(ids[1], int)  # "pc" was stored: left as it was
        metrics = {r.trace.estimator: r.metrics["ate_m"] for r in db.traces(poses=False)}
        assert metrics == {"pc": 0.5, "icp": 0.1}
        assert db.counts()["trace_poses"] == before["trace_poses"] + len(new.times)


def test_unknown_scenario_is_a_readable_key_error(filled_db: Path) -> None:
    with ExperimentDatabase(filled_db) as db, pytest.raises(KeyError, match="open_cylinders"):
        db.load_sensor_dataset(Scenario("open_cylinders", "straight", 0))


def test_write_killed_mid_transaction_keeps_committed_work(filled_db: Path) -> None:
    code = f"""
        import os
        import numpy as np
        from estimators.leaderboard.database import ExperimentDatabase
        db = ExperimentDatabase({str(filled_db)!r})
        db._conn.execute("PRAGMA cache_size = 10")  # spill pages into the file before COMMIT
        with db._transaction() as conn:
            for step in range(2000):
                conn.execute("INSERT INTO trace_poses VALUES (1, ?, 0, 0, 0, 0, 0)", (100 + step,))
                conn.execute("INSERT INTO results VALUES (1, ?, 0)", (str(step) + "x" * 3000,))
            os.kill(os.getpid(), 9)
    """
    subprocess.run([sys.executable, "-c", textwrap.dedent(code)], check=False, timeout=60)
    assert Path(f"{filled_db}-journal").exists()  # a hot journal: the kill hit mid-transaction
    with ExperimentDatabase(filled_db) as db:
        counts = db.counts()
        assert counts["trace_poses"] == 40 and counts["results"] == 2
        assert db.traces()[0].metrics == {"ate_m": 0.5, "accuracy_pct": 80.0}


def _assert_refused_untouched(path: Path, error: type[Exception], match: str) -> None:
    content, mtime = path.read_bytes(), path.stat().st_mtime_ns
    with pytest.raises(error, match=match):
        ExperimentDatabase(path)
    assert path.read_bytes() == content and path.stat().st_mtime_ns == mtime
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]


def test_other_schema_version_is_refused_untouched(filled_db: Path) -> None:
    with sqlite3.connect(filled_db) as conn:
        conn.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION + 1,))
    conn.close()
    expected = f"schema version \\[{SCHEMA_VERSION + 1}"
    _assert_refused_untouched(filled_db, SchemaVersionError, expected)


def test_corrupt_file_is_refused_untouched(filled_db: Path) -> None:
    data = bytearray(filled_db.read_bytes())
    page = 4096
    assert len(data) > 4 * page
    data[2 * page: 4 * page] = np.random.default_rng(2).bytes(2 * page)
    filled_db.write_bytes(bytes(data))
    _assert_refused_untouched(filled_db, CorruptDatabaseError, "left untouched")


def test_truncated_file_is_refused_untouched(filled_db: Path) -> None:
    filled_db.write_bytes(filled_db.read_bytes()[:3 * 4096 + 100])
    _assert_refused_untouched(filled_db, CorruptDatabaseError, "untouched")


def test_non_sqlite_file_is_refused_untouched(tmp_path: Path) -> None:
    path = tmp_path / "notes.sqlite"
    path.write_text("t x y z qx qy qz qw\n")
    _assert_refused_untouched(path, NotADatabaseError, "not an SQLite database")


def test_foreign_sqlite_database_is_refused_untouched(tmp_path: Path) -> None:
    path = tmp_path / "other.sqlite"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE invoices (id INTEGER)")
    conn.close()
    _assert_refused_untouched(path, ForeignDatabaseError, "invoices")


def test_missing_directory_is_a_location_error(tmp_path: Path) -> None:
    with pytest.raises(DatabaseLocationError, match="does not exist"):
        ExperimentDatabase(tmp_path / "nowhere" / "db.sqlite")
    with pytest.raises(DatabaseLocationError, match="is a directory"):
        ExperimentDatabase(tmp_path)


def run_without_root_powers(code: str) -> subprocess.CompletedProcess[str]:
    """Run Python ``code`` in a process that file permissions apply to (as root: with the
    capabilities that bypass them dropped through ``capsh``)."""
    command = [sys.executable, "-c", textwrap.dedent(code)]
    if os.geteuid() == 0:
        capsh = shutil.which("capsh")
        if capsh is None:
            pytest.skip("running as root and capsh is missing: no way to make a directory "
                        "read-only for the test process")
        command = [capsh, "--drop=cap_dac_override,cap_dac_read_search,cap_fowner", "--", "-c",
                   shlex.join(command)]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)


def test_read_only_directory_is_a_clear_error_and_loses_nothing(filled_db: Path) -> None:
    read_only = filled_db.parent / "read_only"
    read_only.mkdir()
    stored = read_only / "stored.sqlite"
    shutil.copy(filled_db, stored)
    content = stored.read_bytes()
    read_only.chmod(0o555)
    try:
        result = run_without_root_powers(f"""
            from estimators.leaderboard import cli as leaderboard
            from estimators.leaderboard.database import DatabaseLocationError, ExperimentDatabase
            for name in ("new.sqlite", "stored.sqlite"):
                try:
                    ExperimentDatabase({str(read_only)!r} + "/" + name)
                except DatabaseLocationError as error:
                    print("refused:", error)
            status = leaderboard.main(["--out", {str(read_only)!r}, "--estimators", "zero",
                                       "--db", {str(stored)!r}, "--no-progress"])
            print("leaderboard exit status", status)
        """)
    finally:
        read_only.chmod(0o755)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 3, result.stdout
    assert "cannot create" in lines[0] and "new.sqlite" in lines[0]
    assert "cannot open" in lines[1] and "stored.sqlite" in lines[1]
    assert lines[2] == "leaderboard exit status 2"
    assert f"output directory {read_only} is not writable" in result.stderr
    assert stored.read_bytes() == content
    assert sorted(p.name for p in read_only.iterdir()) == ["stored.sqlite"]


def test_tum_export_is_read_back_by_evo(filled_db: Path, tmp_path: Path) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    with ExperimentDatabase(filled_db) as db:
        (record,) = db.traces()
        path = db.export_tum(record.trace_id, tmp_path / "pc.tum")
        with pytest.raises(KeyError, match="no trace with id 99"):
            db.export_tum(99, tmp_path / "missing.tum")
    trajectory = file_interface.read_tum_trajectory_file(str(path))
    np.testing.assert_allclose(trajectory.timestamps, record.trace.times)
    np.testing.assert_allclose(trajectory.positions_xyz[:, :2], record.trace.poses[:, :2],
                               atol=1e-8)
    yaw = np.array([np.arctan2(2 * (w * z), 1 - 2 * z * z)
                    for w, _, _, z in trajectory.orientations_quat_wxyz])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - record.trace.poses[:, 2]))), 0,
                               atol=1e-8)


def test_the_recorded_version_follows_the_source_code(tmp_path: Path) -> None:
    from estimators.leaderboard.records import code_digest, package_version

    assert "+src." in package_version() and package_version() == package_version()
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    module = tmp_path / "pkg" / "sub" / "a.py"

    def digest(source: str) -> str:
        module.write_text(source)
        code_digest.cache_clear()
        return code_digest(tmp_path, ("pkg",))

    before = digest('"""A module."""\n\ndef f():\n    return 1\n')
    assert digest('"""A module."""\n\ndef f():\n    return 1\n') == before  # same code
    # new words, comments and blank lines are no new code: stored traces stay valid
    assert digest('"""Reworded."""\n# why\n\n\ndef f():\n    """Says one."""\n    return 1\n'
                  ) == before
    assert digest('"""A module."""\n\ndef f():\n    return 2\n') != before  # new code
    assert digest('"""A module."""\n\ndef f():\n    return "1"\n') != before  # a string
    assert digest('"""A module."""\n\ndef f():\n    pass\nreturn_ = 1\n') != before


def test_two_processes_creating_one_new_database_at_once_both_open_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The schema is written under the write lock only if it is still missing there: a second
    process that saw an empty file before the first wrote its schema opens it as it is."""
    path = tmp_path / "shared.sqlite"
    ExperimentDatabase(path).close()  # the first process wrote the schema
    answers = [False]  # what the second saw just before: no schema yet
    original = ExperimentDatabase._has_schema
    monkeypatch.setattr(ExperimentDatabase, "_has_schema",
                        lambda self: answers.pop() if answers else original(self))
    with ExperimentDatabase(path) as db:
        assert db.counts()["sensor_datasets"] == 0
