"""A SHA-256 checksum per stored sensor dataset and per trace, so a damaged or edited row of
the experiment database is named on read instead of silently changing a result.

SQLite's own ``quick_check`` finds a broken page structure, not a changed value inside a row
(of 40 random 64-byte overwrites of data pages, 32 went unnoticed). The checksum covers every
column of the dataset's rows as SQLite returns them: the scenario's row (kind, world, trace,
seed, driver, config, so swapping two scenarios' seeds is a mismatch), then the header row and
all steps of a sensor dataset, or a trace's row, poses and metrics. It is computed by the same
queries when a dataset is stored and when it is read. Stored checksums carry their version
(``v2:<hex>``); a bare hex checksum (version 1, written before the scenario row was covered)
is checked against the rows without it. A dataset with no checksum at all (deleted, or
written before checksums existed) cannot be verified and is refused on read.

A checksum detects damage and edits made without recomputing it; it is not a signature
against someone who rewrites the file with this module.

Table (created on open if absent; it is not part of the schema-version-1 check, so files
written before it existed still open)::

    checksums (kind 'sensor_dataset' | 'trace', key scenario_id | trace_id, sha256 text,
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

#: The rows each kind's version-1 checksum covers, in a fixed order (``?`` is the key).
_QUERIES_V1: dict[str, tuple[str, ...]] = {
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

#: Version 2 adds the scenario's row in front (what the dataset is labelled with).
_SCENARIO_ROW = "SELECT kind, world, trace, seed, driver, config FROM scenarios WHERE id = {}"
_QUERIES: dict[str, tuple[str, ...]] = {
    "sensor_dataset": (_SCENARIO_ROW.format("?"), *_QUERIES_V1["sensor_dataset"]),
    "trace": (_SCENARIO_ROW.format("(SELECT scenario_id FROM traces WHERE id = ?)"),
              *_QUERIES_V1["trace"]),
}
#: Prefix of a version-2 checksum in the ``sha256`` column.
VERSION_2 = "v2:"


def digest(conn: sqlite3.Connection, kind: Kind, key: int, version: int = 2) -> str:
    """SHA-256 (hex) of every row of dataset ``kind`` ``key`` (see the module docstring)."""
    sha = hashlib.sha256()
    for query in (_QUERIES if version == 2 else _QUERIES_V1)[kind]:
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
        (kind, key, VERSION_2 + digest(conn, kind, key)),
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
            raise CorruptDatabaseError(
                f"{path}: the {rows} {key} ({label}) have no checksum (it was deleted, or they "
                "were written before checksums existed), so their values cannot be verified; "
                "delete them (or the database) and re-run to record them again"
            )
        expected = str(stored[0])
        if expected.startswith(VERSION_2):
            expected, actual = expected[len(VERSION_2):], digest(conn, kind, key)
        else:
            actual = digest(conn, kind, key, version=1)
    except sqlite3.DatabaseError as error:
        raise CorruptDatabaseError(
            f"{path}: the {rows} {key} ({label}) cannot be read ({error}); restore a backup "
            "or delete them and re-run"
        ) from error
    if actual != expected:
        raise CorruptDatabaseError(
            f"{path}: the {rows} {key} ({label}) or their scenario's row were changed after "
            "they were stored (checksum mismatch); restore a backup or delete them and re-run"
        )
