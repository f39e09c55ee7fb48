"""The experiment database: sensor datasets, trace datasets and their scores in one SQLite file.

The paper's system (Fig. 1, section IV.B) keeps two kinds of results: *sensor datasets* (what
the Lidars saw along a trace) and *trace datasets* (what an estimator made of them), and
replays one sensor dataset through every method. This module stores both, plus the metrics
of every trace, in a single SQLite file (embedded, no server). Schema version 1::

    schema_version   (version)                        -- one row; this module writes 1
    scenarios        (id, kind, world, trace, seed, driver, config,
                      UNIQUE (kind, world, trace, seed, driver, config))
                     kind 'sim' (DualLidar-v0) or 'real' (a recorded log); trace is the
                     paper's "trace seed" (straight, right_turn, zigzag); seed is the
                     env.reset seed; config the canonical JSON of the env config overrides.
    sensor_datasets  (scenario_id PK -> scenarios, n_steps, n_beams, max_range, world_aligned,
                      mounts JSON (K,3) [m, m, rad] car frame, beam_angles BLOB float64 (n,)
                      [rad], env_config JSON (every resolved setting), world JSON (the map's
                      geometry [m]: name, circles, walls, polygons, bounds), package_version,
                      recorded_at)
    sensor_steps     (scenario_id, step, time [s], lidar_1 BLOB, lidar_2 BLOB,
                      x, y, heading, lidar_poses BLOB, PRIMARY KEY (scenario_id, step))
                     scans: little-endian float32 (n_beams,) ranges [m] in the sensor frame,
                     >= max_range = no return; lidar_2 NULL for a one-Lidar dataset;
                     x [m], y [m], heading [rad]: true car pose in the world frame;
                     lidar_poses: little-endian float64 (K, 3) true sensor world poses.
    traces           (id, scenario_id -> scenarios, estimator, params JSON, package_version,
                      n_steps, ms_per_step, created_at,
                      UNIQUE (scenario_id, estimator, params, package_version))
    trace_poses      (trace_id, step, time [s], x [m], y [m], heading [rad], ms,
                      PRIMARY KEY (trace_id, step))  -- estimated car poses, ms = update time
    results          (trace_id, metric, value, PRIMARY KEY (trace_id, metric))
                     one row per metric of a trace (long form, so new metrics need no
                     schema change); units are in the metric's name (``ate_m``, ``drift_pct``).

Every write is one transaction: a sensor dataset with all its steps, or a trace with all its
poses and metrics. An interrupted run therefore leaves only complete datasets, and the
UNIQUE constraints make a re-run skip what is stored instead of duplicating it. A file that is
not SQLite, is corrupt, belongs to another program or has another schema version is refused
with a specific error before anything is written to it (:mod:`estimators.leaderboard.schema`).
Each dataset and trace carries a SHA-256 checksum verified on read
(:mod:`estimators.leaderboard.checksums`). The dataclasses stored are
:mod:`estimators.leaderboard.records`.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Mapping, Sequence
from contextlib import AbstractContextManager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.base import LIDAR_KEYS, SensorSetup
from estimators.leaderboard.checksums import CREATE_CHECKSUMS, store_checksum, verify_checksum
from estimators.leaderboard.records import (
    Scenario,
    SensorDataset,
    TraceDataset,
    TraceRecord,
    canonical_json,
    package_version,
)
from estimators.leaderboard.schema import (
    SCHEMA,
    SCHEMA_VERSION,
    CorruptDatabaseError,
    DatabaseLocationError,
    check_header,
    check_writable,
    inspect_existing,
    write_transaction,
)
from lidar_env.core import UnknownNameError


def _blob(array: NDArray[Any], dtype: str) -> bytes:
    return np.ascontiguousarray(array, dtype=dtype).tobytes()


class ExperimentDatabase:
    """The SQLite experiment database (schema in the module docstring).

    Opening an existing file first inspects it read-only, so a file that is not SQLite,
    corrupt, foreign or of another schema version raises its specific :class:`DatabaseError`
    subclass and is left byte-for-byte unchanged. ``verify`` runs SQLite's ``quick_check``
    (linear in the file size; turn it off for very large files you trust). The file uses
    SQLite's default rollback journal, not WAL: it works on network filesystems and a
    read-only inspection creates no side files.
    """

    def __init__(self, path: str | os.PathLike[str], *, verify: bool = True) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise DatabaseLocationError(f"{self.path} is a directory; expected a database file")
        if self.path.exists():
            check_header(self.path)
            inspect_existing(self.path, verify)
        check_writable(self.path)
        try:
            self._conn = sqlite3.connect(self.path, isolation_level=None, timeout=30.0)
            self._conn.execute("PRAGMA foreign_keys = ON")
            if not self._has_schema():
                # Checked again inside the write lock: another process opening the same new
                # file at the same moment may have written the schema in between.
                with self._transaction():
                    if not self._has_schema():
                        for statement in filter(str.strip, SCHEMA.split(";")):
                            self._conn.execute(statement)
                        self._conn.execute(
                            "INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,)
                        )
            self._conn.execute(CREATE_CHECKSUMS)
        except sqlite3.OperationalError as error:
            raise DatabaseLocationError(f"cannot open {self.path} for writing: {error}") from error

    def _has_schema(self) -> bool:
        return self._conn.execute(
            "SELECT 1 FROM sqlite_master WHERE name = 'schema_version'").fetchone() is not None

    def _transaction(self) -> AbstractContextManager[sqlite3.Connection]:
        """One write transaction (a failed write is a DatabaseWriteError, rolled back)."""
        return write_transaction(self._conn, self.path)

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> ExperimentDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- scenarios and sensor datasets -----------------------------------------------------

    def _scenario_id(self, scenario: Scenario) -> int | None:
        row = self._conn.execute(
            "SELECT id FROM scenarios WHERE kind = ? AND world = ? AND trace = ? AND seed = ? "
            "AND driver = ? AND config = ?",
            (scenario.kind, scenario.world, scenario.trace, int(scenario.seed), scenario.driver,
             scenario.config_json),
        ).fetchone()
        return None if row is None else int(row[0])

    def _ensure_scenario(self, scenario: Scenario) -> int:
        """The scenario's id, inserting it (call inside a transaction)."""
        self._conn.execute(
            "INSERT OR IGNORE INTO scenarios (kind, world, trace, seed, driver, config) "
            "VALUES (?, ?, ?, ?, ?, ?)",
            (scenario.kind, scenario.world, scenario.trace, int(scenario.seed), scenario.driver,
             scenario.config_json),
        )
        scenario_id = self._scenario_id(scenario)
        assert scenario_id is not None
        return scenario_id

    def scenarios(self) -> list[Scenario]:
        """Every stored scenario, in insertion order."""
        rows = self._conn.execute(
            "SELECT kind, world, trace, seed, driver, config FROM scenarios ORDER BY id"
        )
        return [
            Scenario(world, trace, seed, json.loads(config), driver, kind)
            for kind, world, trace, seed, driver, config in rows
        ]

    def has_sensor_dataset(self, scenario: Scenario) -> bool:
        scenario_id = self._scenario_id(scenario)
        return scenario_id is not None and self._conn.execute(
            "SELECT 1 FROM sensor_datasets WHERE scenario_id = ?", (scenario_id,)
        ).fetchone() is not None

    def save_sensor_dataset(self, scenario: Scenario, dataset: SensorDataset) -> bool:
        """Store a recorded sensor dataset in one transaction; ``False`` if already stored."""
        setup = dataset.setup
        with self._transaction() as conn:
            scenario_id = self._ensure_scenario(scenario)
            stored = conn.execute(
                "INSERT OR IGNORE INTO sensor_datasets (scenario_id, n_steps, n_beams, max_range, "
                "world_aligned, mounts, beam_angles, env_config, world, package_version, "
                "recorded_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (scenario_id, len(dataset), len(setup.beam_angles), setup.max_range,
                 int(setup.world_aligned), canonical_json(setup.mounts),
                 _blob(setup.beam_angles, "<f8"), canonical_json(dict(dataset.env_config)),
                 canonical_json(dict(dataset.world)), package_version(), _now()),
            ).rowcount
            if not stored:
                return False
            second = dataset.scans.get(LIDAR_KEYS[1])
            conn.executemany(
                "INSERT INTO sensor_steps (scenario_id, step, time, lidar_1, lidar_2, x, y, "
                "heading, lidar_poses) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    (scenario_id, step, float(dataset.times[step]),
                     _blob(dataset.scans[LIDAR_KEYS[0]][step], "<f4"),
                     None if second is None else _blob(second[step], "<f4"),
                     *map(float, dataset.poses[step]),
                     _blob(dataset.lidar_poses[step], "<f8"))
                    for step in range(len(dataset))
                ),
            )
            store_checksum(conn, "sensor_dataset", scenario_id)
        return True

    def load_sensor_dataset(self, scenario: Scenario) -> SensorDataset:
        """The stored sensor dataset of ``scenario`` (KeyError naming it when absent)."""
        scenario_id = self._scenario_id(scenario)
        header = None if scenario_id is None else self._conn.execute(
            "SELECT n_steps, n_beams, max_range, world_aligned, mounts, beam_angles, env_config, "
            "world FROM sensor_datasets WHERE scenario_id = ?", (scenario_id,)
        ).fetchone()
        if header is None:
            raise UnknownNameError(f"no sensor dataset recorded for scenario {scenario.label}")
        assert scenario_id is not None
        verify_checksum(self._conn, self.path, "sensor_dataset", scenario_id, scenario.label)
        n_steps, n_beams, max_range, world_aligned, mounts, angles, env_config, world = header
        setup = SensorSetup(np.array(json.loads(mounts), dtype=np.float64),
                            np.frombuffer(angles, dtype="<f8").copy(), max_range,
                            bool(world_aligned))
        rows = self._conn.execute(
            "SELECT time, lidar_1, lidar_2, x, y, heading, lidar_poses FROM sensor_steps "
            "WHERE scenario_id = ? ORDER BY step", (scenario_id,)
        ).fetchall()
        if len(rows) != n_steps:
            raise CorruptDatabaseError(
                f"{self.path}: scenario {scenario.label} should have {n_steps} steps, "
                f"found {len(rows)}"
            )
        scans = {LIDAR_KEYS[0]: np.stack([np.frombuffer(r[1], dtype="<f4") for r in rows])}
        if setup.n_lidars == 2:
            scans[LIDAR_KEYS[1]] = np.stack([np.frombuffer(r[2], dtype="<f4") for r in rows])
        return SensorDataset(
            setup=setup,
            times=np.array([r[0] for r in rows], dtype=np.float64),
            scans={key: scan.astype(np.float32) for key, scan in scans.items()},
            poses=np.array([r[3:6] for r in rows], dtype=np.float64),
            lidar_poses=np.stack(
                [np.frombuffer(r[6], dtype="<f8").reshape(setup.n_lidars, 3) for r in rows]
            ),
            env_config=json.loads(env_config),
            world=json.loads(world),
        )

    # -- trace datasets and results --------------------------------------------------------

    def has_trace(self, scenario: Scenario, estimator: str, params: Mapping[str, Any],
                  version: str | None = None) -> bool:
        """Whether this estimator with these params (and package version) already ran here."""
        return self._trace_id(scenario, estimator, canonical_json(dict(params)),
                              version or package_version()) is not None

    def _trace_id(self, scenario: Scenario, estimator: str, params_json: str,
                  version: str) -> int | None:
        row = self._conn.execute(
            "SELECT traces.id FROM traces JOIN scenarios ON scenarios.id = traces.scenario_id "
            "WHERE kind = ? AND world = ? AND trace = ? AND seed = ? AND driver = ? "
            "AND config = ? AND estimator = ? AND params = ? AND package_version = ?",
            (scenario.kind, scenario.world, scenario.trace, int(scenario.seed), scenario.driver,
             scenario.config_json, estimator, params_json, version),
        ).fetchone()
        return None if row is None else int(row[0])

    def save_trace(self, scenario: Scenario, trace: TraceDataset,
                   metrics: Mapping[str, float]) -> int | None:
        """Store a trace with its poses and metrics in one transaction.

        Returns the new trace id, or ``None`` when the same estimator, params and version were
        already stored for this scenario (nothing is written then).
        """
        return self.save_traces(scenario, [(trace, metrics)])[0]

    def save_traces(self, scenario: Scenario,
                    traces: Sequence[tuple[TraceDataset, Mapping[str, float]]]
                    ) -> list[int | None]:
        """Store several traces of one scenario, each with its poses and metrics, in one
        transaction (one commit, one disk sync, for all the estimators of a scenario).

        Returns the new trace ids in order, ``None`` for each trace already stored (same
        estimator, params and version), which is left as it is.
        """
        ids: list[int | None] = []
        with self._transaction() as conn:
            scenario_id = self._ensure_scenario(scenario)
            for trace, metrics in traces:
                ids.append(self._insert_trace(conn, scenario_id, trace, metrics))
        return ids

    @staticmethod
    def _insert_trace(conn: sqlite3.Connection, scenario_id: int, trace: TraceDataset,
                      metrics: Mapping[str, float]) -> int | None:
        cursor = conn.execute(
            "INSERT OR IGNORE INTO traces (scenario_id, estimator, params, package_version, "
            "n_steps, ms_per_step, created_at) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (scenario_id, trace.estimator, trace.params_json, trace.package_version,
             len(trace.times), trace.ms_per_step, _now()),
        )
        if not cursor.rowcount:
            return None
        trace_id = int(cursor.lastrowid)  # type: ignore[arg-type]
        conn.executemany(
            "INSERT INTO trace_poses (trace_id, step, time, x, y, heading, ms) "
            "VALUES (?, ?, ?, ?, ?, ?, ?)",
            (
                (trace_id, step, float(trace.times[step]), *map(float, trace.poses[step]),
                 float(trace.step_ms[step]))
                for step in range(len(trace.times))
            ),
        )
        conn.executemany(
            "INSERT INTO results (trace_id, metric, value) VALUES (?, ?, ?)",
            ((trace_id, name, None if value is None else float(value))
             for name, value in metrics.items()),
        )
        store_checksum(conn, "trace", trace_id)
        return trace_id

    def traces(self, scenario: Scenario | None = None, *,
               poses: bool = True) -> list[TraceRecord]:
        """Stored traces (all, or those of one scenario) with their metrics, by insertion.

        ``poses=False`` reads the metrics only (the trace's times, poses and step_ms are then
        empty), which is what a summary over many scenarios needs. Every trace is checked
        against its checksum either way.
        """
        query = (
            "SELECT traces.id, kind, world, trace, seed, driver, config, estimator, params, "
            "package_version FROM traces JOIN scenarios ON scenarios.id = traces.scenario_id"
        )
        args: tuple[Any, ...] = ()
        if scenario is not None:
            scenario_id = self._scenario_id(scenario)
            if scenario_id is None:
                return []
            query += " WHERE scenario_id = ?"
            args = (scenario_id,)
        records = []
        for row in self._conn.execute(query + " ORDER BY traces.id", args).fetchall():
            trace_id, kind, world, trace_name, seed, driver, config = row[:7]
            estimator, params, version = row[7:]
            table = np.empty((0, 5))
            verify_checksum(self._conn, self.path, "trace", trace_id,
                            f"{estimator} on {world}/{trace_name}/seed {seed}")
            if poses:
                table = np.array(self._conn.execute(
                    "SELECT time, x, y, heading, ms FROM trace_poses WHERE trace_id = ? "
                    "ORDER BY step", (trace_id,),
                ).fetchall(), dtype=np.float64).reshape(-1, 5)
            metrics = self._conn.execute(
                "SELECT metric, value FROM results WHERE trace_id = ?", (trace_id,)
            ).fetchall()
            records.append(TraceRecord(
                trace_id=trace_id,
                scenario=Scenario(world, trace_name, seed, json.loads(config), driver, kind),
                trace=TraceDataset(estimator, json.loads(params), table[:, 0], table[:, 1:4],
                                   table[:, 4], version),
                metrics={name: (np.nan if value is None else value) for name, value in metrics},
            ))
        return records

    def counts(self) -> dict[str, int]:
        """Row count of every table (for summaries and tests)."""
        tables = ("scenarios", "sensor_datasets", "sensor_steps", "traces", "trace_poses",
                  "results")
        return {name: self._conn.execute(f"SELECT COUNT(*) FROM {name}").fetchone()[0]
                for name in tables}

    def export_tum(self, trace_id: int, path: str | os.PathLike[str]) -> Path:
        """Write one stored trace as a TUM file (``t x y z qx qy qz qw``, z = 0, yaw only)."""
        from estimators.evaluation.tum import write_tum

        rows = self._conn.execute(
            "SELECT time, x, y, heading FROM trace_poses WHERE trace_id = ? ORDER BY step",
            (trace_id,),
        ).fetchall()
        if not rows:
            raise UnknownNameError(f"no trace with id {trace_id} in {self.path}")
        table = np.array(rows, dtype=np.float64)
        out = Path(path)
        write_tum(out, table[:, 0], table[:, 1:4])
        return out

    def export_truth_tum(self, scenario: Scenario, path: str | os.PathLike[str]) -> Path:
        """Write a sensor dataset's true car poses as a TUM file (the reference for
        ``evo_ape tum truth.tum estimate.tum``)."""
        from estimators.evaluation.tum import write_tum

        dataset = self.load_sensor_dataset(scenario)
        out = Path(path)
        write_tum(out, dataset.times, dataset.poses)
        return out


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
