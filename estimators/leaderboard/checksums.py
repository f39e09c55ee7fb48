"""A SHA-256 checksum per stored sensor dataset and per trace, so a damaged row of the
experiment database is named on read instead of silently changing a result.

SQLite's own ``quick_check`` finds a broken page structure, not a changed value inside a row
(of 40 random 64-byte overwrites of data pages, 32 went unnoticed). The checksum covers every
column of the dataset's rows (header row and all steps; a trace's row, poses and metrics) as
SQLite returns them, so it is computed by the same query when a dataset is stored and when it
is read. Rows stored before checksums existed (no entry in ``checksums``) read unverified.

Table (created on open if absent; it is not part of the schema-version-1 check, so files
written before it existed still open)::

    checksums (kind 'sensor_dataset' | 'trace', key scenario_id | trace_id, sha256 hex,
               PRIMARY KEY (kind, key))
"""

from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path
from typing import Literal

from estimators.leaderboard.schema import CorruptDatabaseError

CREATE_CHECKSUMS = (
    "CREATE TABLE IF NOT EXISTS checksums (kind TEXT NOT NULL CHECK (kind IN "
    "('sensor_dataset', 'trace')), key INTEGER NOT NULL, sha256 TEXT NOT NULL, "
    "PRIMARY KEY (kind, key))"
)

Kind = Literal["sensor_dataset", "trace"]

#: The rows each kind's checksum covers, in a fixed order (``?`` is the key).
_QUERIES: dict[str, tuple[str, ...]] = {
    "sensor_dataset": (
        "SELECT n_steps, n_beams, max_range, world_aligned, mounts, beam_angles, env_config, "
        "world, package_version, recorded_at FROM sensor_datasets WHERE scenario_id = ?",
        "SELECT step, time, lidar_1, lidar_2, x, y, heading, lidar_poses FROM sensor_steps "
        "WHERE scenario_id = ? ORDER BY step",
    ),
    "trace": (
        "SELECT scenario_id, estimator, params, package_version, n_steps, ms_per_step, "
        "created_at FROM traces WHERE id = ?",
        "SELECT step, time, x, y, heading, ms FROM trace_poses WHERE trace_id = ? ORDER BY step",
        "SELECT metric, value FROM results WHERE trace_id = ? ORDER BY metric",
    ),
}


def digest(conn: sqlite3.Connection, kind: Kind, key: int) -> str:
    """SHA-256 (hex) of every row of dataset ``kind`` ``key`` (see the module docstring)."""
    sha = hashlib.sha256()
    for query in _QUERIES[kind]:
        for row in conn.execute(query, (key,)):
            for value in row:
                data = value if isinstance(value, bytes) else repr(value).encode()
                sha.update(type(value).__name__.encode() + len(data).to_bytes(8, "little"))
                sha.update(data)
    return sha.hexdigest()


def store_checksum(conn: sqlite3.Connection, kind: Kind, key: int) -> None:
    """Record the checksum of dataset ``kind`` ``key`` (inside the transaction that wrote it)."""
    conn.execute(
        "INSERT OR REPLACE INTO checksums (kind, key, sha256) VALUES (?, ?, ?)",
        (kind, key, digest(conn, kind, key)),
    )


def verify_checksum(conn: sqlite3.Connection, path: Path, kind: Kind, key: int, label: str) -> None:
    """Raise :class:`CorruptDatabaseError` naming the rows of ``kind`` ``key`` (``label``
    describes them) when they no longer match their stored checksum, or cannot be read."""
    rows = "sensor_datasets/sensor_steps rows of scenario_id" if kind == "sensor_dataset" else (
        "traces/trace_poses/results rows of trace_id")
    try:
        stored = conn.execute(
            "SELECT sha256 FROM checksums WHERE kind = ? AND key = ?", (kind, key)
        ).fetchone()
        if stored is None:
            return  # written before checksums existed
        actual = digest(conn, kind, key)
    except sqlite3.DatabaseError as error:
        raise CorruptDatabaseError(
            f"{path}: the {rows} {key} ({label}) cannot be read ({error}); restore a backup "
            "or delete them and re-run"
        ) from error
    if actual != stored[0]:
        raise CorruptDatabaseError(
            f"{path}: the {rows} {key} ({label}) were changed after they were stored (checksum "
            "mismatch); restore a backup or delete them and re-run"
        )
