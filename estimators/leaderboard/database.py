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
with a specific error before anything is written to it.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.base import LIDAR_KEYS, SensorSetup
from estimators.paths import PROJECT_ROOT

#: The schema this module reads and writes (see the module docstring).
SCHEMA_VERSION = 1
#: The packages whose code makes a trace (hashed into :func:`package_version`).
SOURCE_PACKAGES = ("agents", "estimators", "lidar_env")

_SQLITE_HEADER = b"SQLite format 3\x00"

_SCHEMA = """
CREATE TABLE schema_version (version INTEGER NOT NULL);
CREATE TABLE scenarios (
    id INTEGER PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('sim', 'real')),
    world TEXT NOT NULL,
    trace TEXT NOT NULL,
    seed INTEGER NOT NULL,
    driver TEXT NOT NULL,
    config TEXT NOT NULL,
    UNIQUE (kind, world, trace, seed, driver, config)
);
CREATE TABLE sensor_datasets (
    scenario_id INTEGER PRIMARY KEY REFERENCES scenarios (id),
    n_steps INTEGER NOT NULL,
    n_beams INTEGER NOT NULL,
    max_range REAL NOT NULL,
    world_aligned INTEGER NOT NULL,
    mounts TEXT NOT NULL,
    beam_angles BLOB NOT NULL,
    env_config TEXT NOT NULL,
    world TEXT NOT NULL,
    package_version TEXT NOT NULL,
    recorded_at TEXT NOT NULL
);
CREATE TABLE sensor_steps (
    scenario_id INTEGER NOT NULL REFERENCES sensor_datasets (scenario_id),
    step INTEGER NOT NULL,
    time REAL NOT NULL,
    lidar_1 BLOB NOT NULL,
    lidar_2 BLOB,
    x REAL NOT NULL,
    y REAL NOT NULL,
    heading REAL NOT NULL,
    lidar_poses BLOB NOT NULL,
    PRIMARY KEY (scenario_id, step)
);
CREATE TABLE traces (
    id INTEGER PRIMARY KEY,
    scenario_id INTEGER NOT NULL REFERENCES scenarios (id),
    estimator TEXT NOT NULL,
    params TEXT NOT NULL,
    package_version TEXT NOT NULL,
    n_steps INTEGER NOT NULL,
    ms_per_step REAL NOT NULL,
    created_at TEXT NOT NULL,
    UNIQUE (scenario_id, estimator, params, package_version)
);
CREATE TABLE trace_poses (
    trace_id INTEGER NOT NULL REFERENCES traces (id),
    step INTEGER NOT NULL,
    time REAL NOT NULL,
    x REAL NOT NULL,
    y REAL NOT NULL,
    heading REAL NOT NULL,
    ms REAL NOT NULL,
    PRIMARY KEY (trace_id, step)
);
CREATE TABLE results (
    trace_id INTEGER NOT NULL REFERENCES traces (id),
    metric TEXT NOT NULL,
    value REAL,
    PRIMARY KEY (trace_id, metric)
);
"""


class DatabaseError(Exception):
    """Base class of the experiment database's errors."""


class NotADatabaseError(DatabaseError):
    """The file is not an SQLite database at all."""


class CorruptDatabaseError(DatabaseError):
    """The file is SQLite but damaged."""


class ForeignDatabaseError(DatabaseError):
    """The file is a healthy SQLite database that this project did not create."""


class SchemaVersionError(DatabaseError):
    """The database was written with another schema version."""


class DatabaseLocationError(DatabaseError):
    """The database file cannot be created or written where it was asked for."""


def package_version() -> str:
    """The installed duallidar version and a digest of its source, e.g. ``0.1.0+src.1a2b3c4d5e6f``,
    recorded with every dataset and trace.

    The digest is why: an editable install keeps its version number while the code changes, and
    a stored trace must not stand in for an estimator that has changed since (a re-run then
    replays the stored sensor datasets through the new code)."""
    try:
        version = metadata.version("duallidar")
    except metadata.PackageNotFoundError:
        version = "0+unknown"
    return f"{version}+src.{source_digest(PROJECT_ROOT)}"


@lru_cache(maxsize=4)
def source_digest(root: Path, packages: tuple[str, ...] = SOURCE_PACKAGES) -> str:
    """SHA-256 (first 12 hex digits) of the paths and contents of the ``*.py`` files of
    ``packages`` under ``root``, read once per process (worker processes forked later inherit
    it, so one run has one version)."""
    digest = hashlib.sha256()
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def canonical_json(value: Any) -> str:
    """Compact JSON with sorted keys, numpy scalars/arrays and tuples as plain lists/numbers.

    Used for configs and params so that equal settings give equal strings (UNIQUE keys).
    """

    def plain(item: Any) -> Any:
        if isinstance(item, np.ndarray):
            return item.tolist()
        if isinstance(item, np.generic):
            return item.item()
        raise TypeError(f"cannot store {type(item).__name__} {item!r} as JSON")

    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=plain)


@dataclass(frozen=True)
class Scenario:
    """One simulated (or recorded) run: world, trace seed, env seed, driver and env config.

    ``config`` holds the env config overrides passed to ``gym.make(..., config=...)``; it is
    part of the scenario's identity (two noise levels are two scenarios).
    """

    world: str
    trace: str
    seed: int
    config: Mapping[str, Any] = field(default_factory=dict)
    driver: str = "scripted"
    kind: str = "sim"

    def __hash__(self) -> int:  # config is a dict: hash its canonical JSON instead
        return hash((self.kind, self.world, self.trace, self.seed, self.driver, self.config_json))

    @property
    def config_json(self) -> str:
        return canonical_json(dict(self.config))

    @property
    def label(self) -> str:
        """Short human-readable name, e.g. ``hallway/zigzag/s0``; scans in another frame than
        the sensor's (the paper's world-aligned ones) add it: ``hallway/zigzag/s0/world``."""
        label = f"{self.world}/{self.trace}/s{self.seed}"
        frame = self.config.get("scan_frame", "sensor")
        return label if frame == "sensor" else f"{label}/{frame}"


@dataclass(frozen=True)
class SensorDataset:
    """What the Lidars saw along one scenario, with the ground truth beside it.

    Attributes:
        setup: the sensor geometry an estimator may know.
        times: ``(N,)`` observation times [s].
        scans: ``{key: (N, n_beams) float32}`` ranges [m] in each sensor's own frame, keyed by
            ``setup.keys``; ``>= setup.max_range`` means no return.
        poses: ``(N, 3)`` true car poses (x [m], y [m], heading [rad]) in the world frame.
        lidar_poses: ``(N, K, 3)`` true sensor poses in the world frame.
        env_config: every resolved env setting (JSON-able), for the record.
        world: the world map's geometry (``name``, ``circles`` (N, 3), ``walls`` (M, 4),
            ``polygons``, ``bounds``; metres, world frame), so the map can be drawn as it was
            when recorded; empty when unknown.
    """

    setup: SensorSetup
    times: NDArray[np.float64]
    scans: dict[str, NDArray[np.float32]]
    poses: NDArray[np.float64]
    lidar_poses: NDArray[np.float64]
    env_config: Mapping[str, Any] = field(default_factory=dict)
    world: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.times)
        if n < 1:
            raise ValueError("a sensor dataset needs at least one step, got 0")
        k, n_beams = self.setup.n_lidars, len(self.setup.beam_angles)
        if set(self.scans) != set(self.setup.keys):
            raise ValueError(f"scans: expected keys {self.setup.keys}, got {tuple(self.scans)}")
        for key, scan in self.scans.items():
            if scan.shape != (n, n_beams) or scan.dtype != np.float32:
                raise ValueError(
                    f"scans[{key!r}]: expected float32 ({n}, {n_beams}), "
                    f"got {scan.dtype} {scan.shape}"
                )
        if self.poses.shape != (n, 3):
            raise ValueError(f"poses: expected shape ({n}, 3), got {self.poses.shape}")
        if self.lidar_poses.shape != (n, k, 3):
            raise ValueError(
                f"lidar_poses: expected shape ({n}, {k}, 3), got {self.lidar_poses.shape}"
            )

    def __len__(self) -> int:
        return len(self.times)

    def observations(self) -> Iterator[dict[str, NDArray[np.float32]]]:
        """The observations in order, as the env emitted them."""
        for step in range(len(self)):
            yield {key: scan[step] for key, scan in self.scans.items()}


@dataclass(frozen=True)
class TraceDataset:
    """What one estimator made of one sensor dataset.

    Attributes:
        estimator: registered name; ``params``: every parameter it ran with (JSON-able).
        times: ``(N,)`` [s]; poses: ``(N, 3)`` estimated car poses (x [m], y [m], heading
        [rad]); step_ms: ``(N,)`` wall time of each ``update`` call [ms].
    """

    estimator: str
    params: Mapping[str, Any]
    times: NDArray[np.float64]
    poses: NDArray[np.float64]
    step_ms: NDArray[np.float64]
    package_version: str = field(default_factory=package_version)

    def __post_init__(self) -> None:
        n = len(self.times)
        if self.poses.shape != (n, 3) or self.step_ms.shape != (n,):
            raise ValueError(
                f"a trace of {n} times needs poses ({n}, 3) and step_ms ({n},), "
                f"got {self.poses.shape} and {self.step_ms.shape}"
            )

    @property
    def params_json(self) -> str:
        return canonical_json(dict(self.params))

    @property
    def ms_per_step(self) -> float:
        """Mean wall time [ms] of one ``update`` after the first (which only takes the scan),
        as :class:`estimators.evaluation.scoring.ScoreEstimator` reports it."""
        return float(np.mean(self.step_ms[1:] if len(self.step_ms) > 1 else self.step_ms))


@dataclass(frozen=True)
class TraceRecord:
    """A stored trace with its scenario and metrics (what :meth:`ExperimentDatabase.traces`
    returns)."""

    trace_id: int
    scenario: Scenario
    trace: TraceDataset
    metrics: dict[str, float]


def _blob(array: NDArray[Any], dtype: str) -> bytes:
    return np.ascontiguousarray(array, dtype=dtype).tobytes()


def _check_header(path: Path) -> None:
    """Refuse a non-empty file that does not start with the SQLite header (reads 16 bytes)."""
    with path.open("rb") as handle:
        header = handle.read(len(_SQLITE_HEADER))
    if header and header != _SQLITE_HEADER:
        raise NotADatabaseError(
            f"{path} is not an SQLite database (expected a file starting with "
            f"{_SQLITE_HEADER!r}, found {header!r}); refusing to touch it"
        )


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
            _check_header(self.path)
            self._inspect_existing(verify)
        self._check_writable()
        try:
            self._conn = sqlite3.connect(self.path, isolation_level=None, timeout=30.0)
            self._conn.execute("PRAGMA foreign_keys = ON")
            has_schema = self._conn.execute(
                "SELECT 1 FROM sqlite_master WHERE name = 'schema_version'"
            ).fetchone()
            if not has_schema:
                with self._transaction():
                    for statement in filter(str.strip, _SCHEMA.split(";")):
                        self._conn.execute(statement)
                    self._conn.execute(
                        "INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,)
                    )
        except sqlite3.OperationalError as error:
            raise DatabaseLocationError(f"cannot open {self.path} for writing: {error}") from error

    # -- opening ---------------------------------------------------------------------------

    def _inspect_existing(self, verify: bool) -> None:
        """Check an existing file read-only; raise the matching error, leave the file as is.

        One exception: a *hot journal* next to the file means a write of ours was killed
        mid-transaction. SQLite then has to roll it back before anything can be read, which
        needs write access; that rollback restores the last committed state, so it is done.
        """
        try:
            conn = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True)
            try:
                self._inspect(conn, verify)
                return
            except sqlite3.OperationalError:
                if not Path(f"{self.path}-journal").exists():
                    raise
            finally:
                conn.close()
            conn = sqlite3.connect(self.path)
            try:
                self._inspect(conn, verify)
            finally:
                conn.close()
        except sqlite3.DatabaseError as error:
            raise CorruptDatabaseError(
                f"{self.path} cannot be read as SQLite ({error}); left untouched"
            ) from error

    def _inspect(self, conn: sqlite3.Connection, verify: bool) -> None:
        if verify:
            problems = [row[0] for row in conn.execute("PRAGMA quick_check")]
            if problems != ["ok"]:
                raise CorruptDatabaseError(
                    f"{self.path} is a damaged SQLite file ({'; '.join(problems[:3])}); "
                    "left untouched: restore a backup or choose another --db path"
                )
        tables = {row[0] for row in conn.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'"
        )}
        if tables and "schema_version" not in tables:
            raise ForeignDatabaseError(
                f"{self.path} is an SQLite database of another program (tables: "
                f"{', '.join(sorted(tables))}; expected a schema_version table); left untouched"
            )
        if tables:
            versions = [row[0] for row in conn.execute("SELECT version FROM schema_version")]
            if versions != [SCHEMA_VERSION]:
                raise SchemaVersionError(
                    f"{self.path} has schema version {versions}, this duallidar reads version "
                    f"{SCHEMA_VERSION}; left untouched: use another --db path or the duallidar "
                    "version that wrote it"
                )

    def _check_writable(self) -> None:
        """The file (if present) and its directory (for the journal) must accept writes."""
        parent = self.path.parent
        if not parent.is_dir():
            raise DatabaseLocationError(
                f"cannot create {self.path}: directory {parent} does not exist"
            )
        try:
            with tempfile.TemporaryFile(dir=parent):
                pass
            if self.path.exists():
                with self.path.open("r+b"):
                    pass
        except OSError as error:
            what = "open" if self.path.exists() else "create"
            raise DatabaseLocationError(
                f"cannot {what} {self.path} for writing: {error.strerror} "
                f"(the file and its directory {parent} must be writable)"
            ) from error

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction: everything inside commits together or not at all."""
        self._conn.execute("BEGIN IMMEDIATE")
        try:
            yield self._conn
        except BaseException:
            self._conn.execute("ROLLBACK")
            raise
        self._conn.execute("COMMIT")

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
        return True

    def load_sensor_dataset(self, scenario: Scenario) -> SensorDataset:
        """The stored sensor dataset of ``scenario`` (KeyError naming it when absent)."""
        scenario_id = self._scenario_id(scenario)
        header = None if scenario_id is None else self._conn.execute(
            "SELECT n_steps, n_beams, max_range, world_aligned, mounts, beam_angles, env_config, "
            "world FROM sensor_datasets WHERE scenario_id = ?", (scenario_id,)
        ).fetchone()
        if header is None:
            raise KeyError(f"no sensor dataset recorded for scenario {scenario.label}")
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
        return trace_id

    def traces(self, scenario: Scenario | None = None, *,
               poses: bool = True) -> list[TraceRecord]:
        """Stored traces (all, or those of one scenario) with their metrics, by insertion.

        ``poses=False`` reads the metrics only (the trace's times, poses and step_ms are then
        empty), which is what a summary over many scenarios needs.
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
            raise KeyError(f"no trace with id {trace_id} in {self.path}")
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
