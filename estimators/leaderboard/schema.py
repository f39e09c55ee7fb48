"""The experiment database's file: its SQLite schema (:data:`SCHEMA_VERSION` 1, laid out in
:mod:`estimators.leaderboard.database`'s docstring), the errors a refused file raises (one
:class:`DatabaseError` subclass per reason) and the read-only checks made before a file is
opened for writing: the SQLite header, integrity, a foreign or other-version schema, and
whether the file and its directory accept writes.
"""

from __future__ import annotations

import sqlite3
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path

from lidar_env.core import DatabaseError

#: The schema this module reads and writes (see the module docstring).
SCHEMA_VERSION = 1


_SQLITE_HEADER = b"SQLite format 3\x00"


SCHEMA = """
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


class NotADatabaseError(DatabaseError):
    """The file is not an SQLite database at all."""


class CorruptDatabaseError(DatabaseError):
    """The file is SQLite but damaged."""


class ForeignDatabaseError(DatabaseError):
    """The file is a healthy SQLite database that this project did not create."""


class SchemaVersionError(DatabaseError):
    """The database was written with another schema version."""


class SchemaMismatchError(DatabaseError):
    """The file states our schema version but lacks a table or column that version has."""


class DatabaseLocationError(DatabaseError):
    """The database file cannot be created or written where it was asked for."""


class DatabaseWriteError(DatabaseError):
    """A write to the database failed (the disk is full, another writer held the lock too
    long, the file became read-only); the transaction was rolled back, so nothing stored
    before is lost."""


@contextmanager
def write_transaction(conn: sqlite3.Connection, path: Path) -> Iterator[sqlite3.Connection]:
    """One write transaction on ``conn``: everything inside commits together or not at all.
    A write SQLite refuses (``sqlite3.OperationalError``) is rolled back and raised as a
    :class:`DatabaseWriteError` naming ``path``."""
    try:
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            raise
        conn.execute("COMMIT")
    except sqlite3.OperationalError as error:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise DatabaseWriteError(
            f"could not write to the database {path} ({error}); the write was rolled back, so "
            "everything stored before is intact: free space on its disk (or wait for the other "
            "writer) and re-run to resume"
        ) from error


def check_header(path: Path) -> None:
    """Refuse a non-empty file that does not start with the SQLite header (reads 16 bytes)."""
    with path.open("rb") as handle:
        header = handle.read(len(_SQLITE_HEADER))
    if header and header != _SQLITE_HEADER:
        raise NotADatabaseError(
            f"{path} is not an SQLite database (expected a file starting with "
            f"{_SQLITE_HEADER!r}, found {header!r}); refusing to touch it"
        )


def inspect_existing(path: Path, verify: bool) -> None:
    """Check the existing database file ``path`` read-only; raise the matching error, leave
    the file as is.

    One exception: a *hot journal* next to the file means a write of ours was killed
    mid-transaction. SQLite then has to roll it back before anything can be read, which
    needs write access; that rollback restores the last committed state, so it is done.
    """
    try:
        conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
        try:
            _inspect(conn, path, verify)
            return
        except sqlite3.OperationalError:
            if not Path(f"{path}-journal").exists():
                raise
        finally:
            conn.close()
        conn = sqlite3.connect(path)
        try:
            _inspect(conn, path, verify)
        finally:
            conn.close()
    except sqlite3.DatabaseError as error:
        raise CorruptDatabaseError(
            f"{path} cannot be read as SQLite ({error}); left untouched"
        ) from error

def _inspect(conn: sqlite3.Connection, path: Path, verify: bool) -> None:
    if verify:
        problems = [row[0] for row in conn.execute("PRAGMA quick_check")]
        if problems != ["ok"]:
            raise CorruptDatabaseError(
                f"{path} is a damaged SQLite file ({'; '.join(problems[:3])}); "
                "left untouched: restore a backup or choose another --db path"
            )
    tables = {row[0] for row in conn.execute(
        "SELECT name FROM sqlite_master WHERE type = 'table'"
    )}
    if tables and "schema_version" not in tables:
        raise ForeignDatabaseError(
            f"{path} is an SQLite database of another program (tables: "
            f"{', '.join(sorted(tables))}; expected a schema_version table); left untouched"
        )
    if tables:
        versions = [row[0] for row in conn.execute("SELECT version FROM schema_version")]
        if versions != [SCHEMA_VERSION]:
            raise SchemaVersionError(
                f"{path} has schema version {versions}, this duallidar reads version "
                f"{SCHEMA_VERSION}; left untouched: use another --db path or the duallidar "
                "version that wrote it"
            )
        _check_tables(conn, path)


@cache
def expected_columns() -> dict[str, tuple[str, ...]]:
    """Table name -> its column names, as :data:`SCHEMA` lays them out."""
    conn = sqlite3.connect(":memory:")
    try:
        conn.executescript(SCHEMA)
        return {table: _columns(conn, table) for (table,) in conn.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'")}
    finally:
        conn.close()


def _columns(conn: sqlite3.Connection, table: str) -> tuple[str, ...]:
    return tuple(row[1] for row in conn.execute(f"PRAGMA table_info('{table}')"))


def _check_tables(conn: sqlite3.Connection, path: Path) -> None:
    """Every table of the schema is there with every one of its columns (extra ones may be)."""
    problems = []
    for table, columns in expected_columns().items():
        present = _columns(conn, table)
        if not present:
            problems.append(f"table {table} is missing")
            continue
        missing = [column for column in columns if column not in present]
        if missing:
            problems.append(f"table {table} lacks column(s) {', '.join(missing)}")
    if problems:
        raise SchemaMismatchError(
            f"{path} claims schema version {SCHEMA_VERSION} but {'; '.join(problems)}; left "
            "untouched: it was edited by hand or by another program"
        )

def check_writable(path: Path) -> None:
    """The file ``path`` (if present) and its directory (for the journal) must accept writes."""
    parent = path.parent
    if not parent.is_dir():
        raise DatabaseLocationError(
            f"cannot create {path}: directory {parent} does not exist"
        )
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
        if path.exists():
            with path.open("r+b"):
                pass
    except OSError as error:
        what = "open" if path.exists() else "create"
        raise DatabaseLocationError(
            f"cannot {what} {path} for writing: {error.strerror} "
            f"(the file and its directory {parent} must be writable)"
        ) from error
