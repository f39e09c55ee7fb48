"""The real recordings the leaderboard scores on, and their ground-truth relations.

A :class:`RealLog` is a CARMEN log with a relations file (Kümmerle et al. 2009: ``t1 t2 x y z
roll pitch yaw`` per line; by default the Radish ACES log) or a ROS bag
(:func:`estimators.datasets.load_bag`: one Lidar per LaserScan topic, K of them) scored either
on a relations file or on the relations of the bag's ground-truth topic: each pair of
consecutive scans (the "local" relations, under 2 s) and each pair :data:`TRUTH_WINDOW`
apart. The estimators see only the scans (:func:`estimators.datasets.real_log.run_on_log`).

A user's log is stored under its file name and a digest of its bytes, so a changed file is
scored anew; the ACES log keeps the identity it always had (name and scan count only).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from estimators.evaluation.relations import Relations, load_relations, relations_from_trajectory
from estimators.leaderboard.records import Scenario
from lidar_env.core import ConfigError

#: Endings of the bag files :func:`estimators.datasets.load_bag` reads (or a ROS 2 directory).
BAG_SUFFIXES: tuple[str, ...] = (".bag", ".db3", ".mcap")
#: Span [s] of the longer relations taken from a bag's ground-truth poses.
TRUTH_WINDOW = 5.0


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` names a ROS bag (a bag file or a ROS 2 bag directory)."""
    path = Path(path)
    return path.is_dir() or path.suffix.lower() in BAG_SUFFIXES


def file_digest(path: str | Path) -> str:
    """The first 16 hex digits of the SHA-256 of a file's bytes (of a directory's files, in
    name order, each with its name)."""
    path = Path(path)
    digest = hashlib.sha256()
    for part in sorted(path.rglob("*")) if path.is_dir() else [path]:
        if part.is_file():
            digest.update(part.relative_to(path).as_posix().encode() if path.is_dir() else b"")
            with part.open("rb") as handle:
                for block in iter(lambda: handle.read(1 << 20), b""):
                    digest.update(block)
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class RealLog:
    """A recorded log scored on its first ``scans`` scans (all when ``None``).

    Attributes:
        name: the name it is stored and shown under.
        log_path: a CARMEN log (plain, ``.gz``, ``.bz2``) or a ROS bag.
        relations_path: a relations file; ``None`` for a bag scored on ``truth_topic``.
        scans: how many scans to replay.
        truth_topic: a bag's ``nav_msgs/Odometry`` or ``geometry_msgs/PoseStamped`` topic of
            true base poses, used when there is no relations file.
        topics: a bag's LaserScan topics (Lidar 1 first); ``None`` takes every one.
        digest: the file's :func:`file_digest`, part of the stored identity when set.
    """

    name: str
    log_path: str
    relations_path: str | None = None
    scans: int | None = None
    truth_topic: str | None = None
    topics: tuple[str, ...] | None = None
    digest: str | None = None

    def __post_init__(self) -> None:
        if self.relations_path is None and not (is_bag(self.log_path) and self.truth_topic):
            raise ConfigError(f"{self.log_path}: expected a relations file, or a bag with a "
                              "ground-truth topic (truth_topic), to score the log on")

    @property
    def scenario(self) -> Scenario:
        config: dict[str, Any] = {"scans": self.scans}
        if self.digest is not None:
            config["digest"] = self.digest
        return Scenario(self.name, "log", 0, config, driver="recorded", kind="real")

    def load(self) -> Any:
        """The parsed log: a :class:`~estimators.datasets.carmen.CarmenLog` or a bag's
        :class:`~estimators.datasets.recording.Recording` (kept per process)."""
        return _load(self.log_path, self.topics, self.truth_topic)

    @property
    def n_lidars(self) -> int:
        """Lidars the estimators see: a CARMEN log's front laser, or a bag's K topics."""
        return self.load().setup.n_lidars if is_bag(self.log_path) else 1

    def relations(self) -> Relations:
        """The ground-truth relations the runs are scored on."""
        if self.relations_path is not None:
            return load_relations(self.relations_path)
        recording = self.load()  # with a truth_topic, load_bag gives truth or raises
        known = np.all(np.isfinite(recording.truth), axis=1)  # scans with a truth pose
        parts = [relations_from_trajectory(recording.times[known], recording.truth[known],
                                           window) for window in (None, TRUTH_WINDOW)]
        return Relations(*(np.concatenate([getattr(p, key) for p in parts])
                           for key in ("t1", "t2", "poses")))


@lru_cache(maxsize=2)
def _load(path: str, topics: tuple[str, ...] | None, truth_topic: str | None) -> Any:
    if is_bag(path):
        from estimators.datasets import load_bag

        return load_bag(path, topics, truth_topic=truth_topic)
    from estimators.datasets.carmen import load_log

    return load_log(path)


def user_log(path: str | Path, relations: str | Path | None = None, scans: int | None = None,
             truth_topic: str | None = None, topics: tuple[str, ...] | None = None) -> RealLog:
    """A user's recording as a :class:`RealLog` named after its file, with its digest."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"--real-log: no such file or bag directory {path}")
    if relations is not None and not Path(relations).is_file():
        raise ConfigError(f"--relations: no such file {relations}")
    name = path.name.split(".")[0] or "log"
    return RealLog(name, str(path), None if relations is None else str(relations), scans,
                   truth_topic, topics, file_digest(path))


def add_real_log_arguments(parser: Any) -> None:
    """The leaderboard's real-log options on an ``argparse`` parser."""
    group = parser.add_argument_group("real log", "score on a recorded log (default: ACES)")
    group.add_argument("--no-real", action="store_true",
                       help="skip the real-log results")
    group.add_argument("--real-log", type=Path, metavar="PATH",
                       help="your own log instead of ACES: a CARMEN log (with --relations) or "
                            "a ROS 1/2 bag (with --relations or --truth-topic)")
    group.add_argument("--relations", type=Path, metavar="FILE",
                       help="ground-truth relations of --real-log (t1 t2 x y z roll pitch yaw)")
    group.add_argument("--truth-topic", metavar="TOPIC",
                       help="the bag's ground-truth pose topic to score --real-log on")
    group.add_argument("--topics", nargs="+", metavar="TOPIC",
                       help="the bag's LaserScan topics, Lidar 1 first (default: all)")
    group.add_argument("--real-scans", type=int, metavar="N", default=None,
                       help="scans of the real log to replay, 0 = all (default: the first "
                            "1000 of ACES, all of --real-log)")


def real_logs_from(args: Any, aces_dir: Path, aces_scans: int) -> list[RealLog]:
    """The real logs the parsed ``args`` ask for: none (``--no-real``), the user's
    ``--real-log``, or the ACES log of ``aces_dir`` (its first ``aces_scans`` scans by default)
    when it is there (none when it is not). Raises :class:`ConfigError` naming the option at
    fault."""
    if args.real_scans is not None and args.real_scans < 0:
        raise ConfigError(f"--real-scans: expected an integer >= 0, got {args.real_scans}")
    given = [name for name, value in (("--relations", args.relations), ("--truth-topic",
             args.truth_topic), ("--topics", args.topics)) if value is not None]
    if args.real_log is None and given:
        raise ConfigError(f"{given[0]}: expected it with --real-log PATH")
    if args.no_real:
        return []
    if args.real_log is not None:
        if not is_bag(args.real_log) and (args.truth_topic or args.topics):
            raise ConfigError(f"--truth-topic/--topics: {args.real_log} is a CARMEN log, not a "
                              f"bag (a bag ends in {', '.join(BAG_SUFFIXES)} or is a directory)")
        log = user_log(args.real_log, args.relations, args.real_scans or None,
                       args.truth_topic, None if args.topics is None else tuple(args.topics))
        log.load()  # read here, so that a bad file fails before any run
        return [log]
    scans = aces_scans if args.real_scans is None else args.real_scans or None
    log = RealLog("aces", str(aces_dir / "aces.clf.bz2"), str(aces_dir / "aces.relations"), scans)
    if Path(log.log_path).exists() and Path(str(log.relations_path)).exists():
        return [log]
    return []  # the caller notes it (after its own checks)
