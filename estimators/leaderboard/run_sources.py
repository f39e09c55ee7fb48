"""What ``duallidar run`` reads: a recording and its ground truth, as one :class:`RunInput`.

A recording is a CARMEN log (``.clf``/``.log``, plain, ``.gz`` or ``.bz2``; its front laser),
a ROS 1/2 bag (every LaserScan topic, or ``topics``; :func:`estimators.datasets.load_bag`),
or a simulated drive stored in a leaderboard database (``experiments.sqlite``; ``scenario``
picks one). Truth is one of: a bag's pose topic, a TUM file or a ``*-corrected`` CARMEN log
(:func:`estimators.datasets.truth.read_truth_file`), each matched to the scans within a
tolerance (:func:`estimators.datasets.truth.match_truth`); a relations file (Kümmerle et al.
2009, relative poses only); a simulated drive's own true poses; or none (then only the
trajectories, maps and timing are written).

Stamps that run backwards (631 of the Intel log's logger stamps) reach the estimators moved
1 us past their predecessor (:func:`estimators.datasets.real_log.forward_clock`); the truth is
matched on the logged stamps and written on the estimators' clock, so the TUM files of a run
share their timestamps exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimators.datasets.recording import Recording
from estimators.datasets.truth import (
    TruthMatch,
    default_tolerance,
    match_truth,
    read_truth_file,
)
from estimators.evaluation.relations import Relations, load_relations
from estimators.leaderboard.real_logs import is_bag
from lidar_env.core import ConfigError

#: Endings of a leaderboard experiment database read as a recorded simulated drive.
DATABASE_SUFFIXES: tuple[str, ...] = (".sqlite", ".sqlite3")
#: CARMEN clocks: ``ipc`` (Kümmerle's relation files) and ``logger`` (``*-corrected`` logs).
CLOCKS: tuple[str, ...] = ("ipc", "logger")


class OptionError(ConfigError):
    """A command-line value that cannot be used; ``option`` names it (``RECORDING``, ...)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"{option}: {message}")
        self.option = option


@dataclass(frozen=True)
class RunInput:
    """A recording ready to run, and what it is scored on.

    Attributes:
        name: the recording's name (its file name without endings).
        recording: the scans, their setup and the estimators' clock ``times`` (N,) [s],
            strictly increasing.
        logged_times: ``(N,)`` the stamps as logged [s] (relations are matched on them).
        truth: truth poses matched to scans (``None`` without pose truth).
        relations: a relations file's relative poses on ``logged_times`` (or ``None``).
        truth_label: where the truth came from, for the summary.
        notes: what the reader had to do (stamps moved forward, scans dropped).
    """

    name: str
    recording: Recording
    logged_times: NDArray[np.float64]
    truth: TruthMatch | None = None
    relations: Relations | None = None
    truth_label: str = "none"
    notes: tuple[str, ...] = field(default_factory=tuple)


def is_database(path: Path) -> bool:
    """Whether ``path`` names a leaderboard experiment database."""
    return path.suffix.lower() in DATABASE_SUFFIXES


def _carmen(path: Path, clock: str, limit: int | None) -> tuple[Recording, NDArray[np.float64]]:
    from estimators.datasets.carmen import load_log
    from estimators.datasets.real_log import setup_from_log

    log = load_log(path)
    setup = setup_from_log(log)
    scans = log.scans[:limit]
    logged = log.scan_times(clock)[: len(scans)]
    ranges = np.minimum(np.stack([scan.ranges for scan in scans]), setup.max_range)
    recording = Recording(str(path), setup, logged, {setup.keys[0]: ranges},
                          (f"{path.name}:front laser",), ("laser",))
    return recording, logged


def _database(path: Path, scenario: str | None, limit: int | None) -> Recording:
    from estimators.leaderboard.database import ExperimentDatabase

    with ExperimentDatabase(path) as db:
        stored = {s.label: s for s in db.scenarios()
                  if s.kind == "sim" and db.has_sensor_dataset(s)}
        if not stored:
            raise OptionError("RECORDING", f"{path} holds no recorded simulated drive")
        if scenario is None and len(stored) > 1:
            raise OptionError("--scenario", f"{path} holds {len(stored)} drives; expected one "
                              f"of {', '.join(stored)}")
        label = scenario if scenario is not None else next(iter(stored))
        if label not in stored:
            raise OptionError("--scenario", f"unknown drive {label!r}: expected one of "
                              f"{', '.join(stored)}")
        dataset = db.load_sensor_dataset(stored[label])
    count = len(dataset) if limit is None else min(limit, len(dataset))
    scans = {key: np.asarray(scan[:count], dtype=np.float64)
             for key, scan in dataset.scans.items()}
    return Recording(f"{path}:{label}", dataset.setup, dataset.times[:count], scans,
                     dataset.setup.keys, dataset.setup.keys, dataset.poses[:count])


def _cut(recording: Recording, limit: int | None) -> Recording:
    if limit is None or limit >= len(recording):
        return recording
    return Recording(recording.source, recording.setup, recording.times[:limit],
                     {key: scans[:limit] for key, scans in recording.scans.items()},
                     recording.topics, recording.frames, None, recording.dropped)


def load_run_input(path: str | Path, *, relations: str | Path | None = None,
                   truth: str | Path | None = None, truth_topic: str | None = None,
                   topics: list[str] | None = None, clock: str | None = None,
                   truth_tolerance: float | None = None, max_scans: int | None = None,
                   scenario: str | None = None) -> RunInput:
    """Read ``path`` and its truth (see the module docstring). ``clock`` (CARMEN logs only)
    defaults to ``logger`` with a ``--truth`` file and ``ipc`` otherwise. Raises
    :class:`OptionError` naming the option at fault, or the reader's own error (a
    :class:`~lidar_env.core.DualLidarError` or :class:`OSError`) for a broken file."""
    from estimators.datasets.real_log import forward_clock

    path = Path(path)
    if not path.exists():
        raise OptionError("RECORDING", f"no such file or bag directory {path}")
    bag, database = is_bag(path), is_database(path)
    if truth_topic is not None and not bag:
        raise OptionError("--truth-topic", f"{path} is not a ROS bag (a bag ends in .bag, "
                          ".db3 or .mcap, or is a directory)")
    if topics is not None and not bag:
        raise OptionError("--topics", f"{path} is not a ROS bag")
    if scenario is not None and not database:
        raise OptionError("--scenario", f"{path} is not a leaderboard database "
                          f"({', '.join(DATABASE_SUFFIXES)})")
    if clock is not None and (bag or database):
        raise OptionError("--clock", f"{path} is no CARMEN log; a bag or database has one "
                          "clock")
    for option, given in (("--relations", relations), ("--truth", truth)):
        if given is not None and not Path(given).is_file():
            raise OptionError(option, f"no such file {given}")
    notes: list[str] = []
    if bag:
        from estimators.datasets import load_bag

        recording = _cut(load_bag(path, topics), max_scans)
        logged = recording.times
        if recording.dropped:
            notes.append(f"{recording.dropped} scans of {recording.topics[0]} had no partner "
                         "in every other topic and were left out")
    elif database:
        recording = _database(path, scenario, max_scans)
        logged = recording.times
    else:
        chosen = clock or ("logger" if truth is not None else "ipc")
        recording, logged = _carmen(path, chosen, max_scans)
        notes.append(f"CARMEN {chosen} clock")
    fed = forward_clock(logged)
    if moved := int(np.count_nonzero(fed != logged)):
        notes.append(f"{moved} stamps that do not run forward reach the estimators moved 1 us "
                     "past the one before")
    run = Recording(recording.source, recording.setup, fed, recording.scans, recording.topics,
                    recording.frames, None, recording.dropped)
    name = path.name.split(".")[0] or "recording"
    if truth_topic is not None:
        from estimators.datasets.rosbag_reader import read_truth_topic

        stamps, poses = read_truth_topic(path, truth_topic)
        match = _matched("--truth-topic", logged, stamps, poses, truth_tolerance, notes)
        return RunInput(name, run, logged, match, None, f"topic {truth_topic}", tuple(notes))
    if truth is not None:
        stamps, poses, _ = read_truth_file(truth)
        match = _matched("--truth", logged, stamps, poses, truth_tolerance, notes)
        return RunInput(name, run, logged, match, None, Path(truth).name, tuple(notes))
    if relations is not None:
        return RunInput(name, run, logged, None, load_relations(relations),
                        f"relations {Path(relations).name}", tuple(notes))
    if recording.truth is not None:  # a simulated drive: truth at every scan
        match = match_truth(logged, logged, recording.truth, 0.0)
        return RunInput(name, run, logged, match, None, "the simulation's true poses",
                        tuple(notes))
    return RunInput(name, run, logged, None, None, "none", tuple(notes))


def _matched(option: str, logged: NDArray[np.float64], stamps: NDArray[np.float64],
             poses: NDArray[np.float64], tolerance: float | None, notes: list[str]
             ) -> TruthMatch:
    """The truth poses within the scans' time span matched to scans (those outside it, as
    after ``--max-scans``, are noted and not counted as left out)."""
    reach = default_tolerance(logged) if tolerance is None else tolerance
    inside = (stamps >= logged.min() - reach) & (stamps <= logged.max() + reach)
    if outside := int(np.count_nonzero(~inside)):
        notes.append(f"{outside} truth poses lie outside the scans' time span")
    match = match_truth(logged, stamps[inside], poses[inside], tolerance)
    if match.matched < 2:
        raise OptionError(option, f"expected truth poses at two scans or more, {match.describe()}"
                          f"; the scans span {logged.min():.3f} .. {logged.max():.3f} s, the "
                          f"truth {np.min(stamps):.3f} .. {np.max(stamps):.3f} s (another "
                          "clock? --clock, --truth-tolerance)")
    return match
