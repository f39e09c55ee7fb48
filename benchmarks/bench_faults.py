"""Fault matrix: every sensor fault of :mod:`lidar_env.faults` x estimator x drive, each run
against the same drive without the fault.

    python benchmarks/bench_faults.py                       # default matrix (~8 min)
    python benchmarks/bench_faults.py --estimators lidar_odometry --groups hallway/zigzag
    python benchmarks/bench_faults.py --logs --json faults.json         # paper groups only
    python benchmarks/bench_faults.py --groups --logs intel:3000 aces:6000  # other windows

Drives: the three paper groups (open_cylinders/right_turn, hallway/zigzag,
closed_to_open/zigzag, seed 0, pure-pursuit driver, ground truth from the env) and windows of
the real logs (``--logs NAME:SCAN``, default :data:`LOG_WINDOWS`): ``--log-scans`` scans of
``NAME.clf.bz2`` (``../shared/data/radish``; skipped when absent) from its first scan with
truth at or after scan ``SCAN``, so every run starts on a known pose that no fault covers;
their truth is pseudo truth at keyframes only: the poses of ``NAME-corrected.log.gz``
(another SLAM system's output, keyframes 0.5-1 m apart) at the scans they were logged with
(same logger stamps). A fault's seconds are turned into scans by the drive's mean scan
interval. Each drive is recorded once
and the faults are applied to the recording (``estimators.datasets.faults.with_faults``), so
a faulted run sees the same world as its clean run.

Per run: ``jump`` [m] the worst step error (an estimated step's translation against the true
one, over the observations that arrive; on ACES, which has no truth per scan, against the
clean run's step), ``final`` [m] the end-point error (the translation error of the last scan
with truth relative to the first one, which is the start on the simulated drives); ``jump+``
the worst step error beyond the clean run's. Targets (issue 43): ``jump+ <= 0.3 m`` and
``final <= 2 x clean final + 0.1 m`` under every fault with at most 3 s blind in a row. After a
longer blind stretch (``blind_100``) the issue asks for no jump when the returns come back,
the stretch flagged, and the pose found again where the map still covers the place: a run
passes when its step onto the first scan with returns is at most 0.3 m beyond the clean run's
worst, ``health`` counts the stretch, and the end-point bound holds, or else that first scan
does not cover the place (under half its points within 0.2 m of the last scan's before the
stretch, both placed at their true poses: ``covered``) and the estimator reports the scan
lost (``lost_scans``) rather than trusting a placement. ``health`` is the estimator's own
report (skipped, frozen, clock jumps, blind stretches, and ``lost_scans``: scans after which
it lost its place). CPU seconds per run are measured with ``time.process_time``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
from scipy.spatial import cKDTree

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents import PurePursuitDriver
from estimators import SensorSetup
from estimators.datasets.faults import recording_from_log, with_faults
from estimators.datasets.recording import Recording
from estimators.datasets.truth import match_truth
from estimators.matching.scan_matching import CarPoints
from estimators.paths import SHARED_DATA
from lidar_env.core.se2 import relative, transform_points
from lidar_env.faults import BeamDropout, Blind, ClockJump, Fault, FrozenLidar, ScanLoss

GROUPS = ("open_cylinders/right_turn", "hallway/zigzag", "closed_to_open/zigzag")
ESTIMATORS = ("lidar_odometry", "slam", "pc_fusion", "icp")
RADISH = SHARED_DATA / "radish"
#: The real-log windows the matrix runs by default: ACES from its first truth, and one window
#: further on in each log (Intel: a 180-degree Lidar on a bursty clock).
LOG_WINDOWS = (("aces", 0), ("aces", 6000), ("intel", 3000))
JUMP_MARGIN = 0.3  # [m]
FINAL_FACTOR, FINAL_MARGIN = 2.0, 0.1  # final <= 2 x clean + 0.1 m
#: [s] blind in a row beyond which a stretch is a long one, judged by :func:`verdict`'s rule.
LONG_STRETCH = 3.0
#: A scan covers the place when this share of another's points lies within COVER_DISTANCE [m].
COVERED_SHARE, COVER_DISTANCE = 0.5, 0.2


def faults_for(period: float, n_lidars: int) -> dict[str, Callable[[], list[Fault]]]:
    """The matrix's faults for a drive with scans every ``period`` [s] and ``n_lidars``."""
    three_seconds = max(1, round(3.0 / period))
    frozen = (FrozenLidar(keys=("lidar_2",)) if n_lidars > 1
              else FrozenLidar(keys=("lidar_1",), after=40, duration=three_seconds))
    return {
        "blind_every_other": lambda: [Blind(every=2)],
        "dropout_half": lambda: [BeamDropout(fraction=0.5, burst=1)],
        "frozen": lambda: [frozen],
        "clock_jump_3s": lambda: [ClockJump(jump=3.0, every=50, offset=20)],
        "gaps": lambda: [ScanLoss(probability=0.0, every=60, offset=30, stretch=10)],
        "blind_3s": lambda: [Blind(every=3 * three_seconds, stretch=three_seconds, offset=30)],
        "blind_100": lambda: [Blind(every=10_000, stretch=100, offset=60)],
    }


#: The matrix's faults, in its order.
FAULT_NAMES = tuple(faults_for(1.0, 1))


def record_drive(group: str, seed: int = 0) -> Recording:
    """A pure-pursuit drive of ``world/trace`` as a recording with ground truth."""
    world, trace = group.split("/")
    env = gym.make("DualLidar-v0", world=world, trace=trace)
    observation, info = env.reset(seed=seed)
    driver = PurePursuitDriver()
    driver.reset(env)
    setup = SensorSetup.from_env(env)
    rows = [(observation, info["time"], info["pose"])]
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        rows.append((observation, info["time"], info["pose"]))
        done = terminated or truncated
    env.close()
    scans = {key: np.stack([np.asarray(o[key], dtype=np.float64) for o, _, _ in rows])
             for key in setup.keys}
    return Recording(source=group, setup=setup, times=np.array([t for _, t, _ in rows]),
                     scans=scans, topics=setup.keys, frames=setup.keys,
                     truth=np.stack([p for _, _, p in rows]))


def log_paths(name: str) -> tuple[Path, Path]:
    """The Radish log ``name`` (e.g. ``aces``, ``intel``) and its corrected log."""
    return RADISH / f"{name}.clf.bz2", RADISH / f"{name}-corrected.log.gz"


def log_window(spec: str) -> tuple[str, int]:
    """``NAME:SCAN`` (``:SCAN`` optional, 0) as the log's name and the scan to start from; an
    ``argparse`` type."""
    name, _, start = spec.partition(":")
    if not name or not (start or "0").isdigit():
        raise argparse.ArgumentTypeError(
            f"expected NAME:SCAN (a Radish log's name and a scan index >= 0), got {spec!r}")
    return name, int(start or 0)


def positive_count(text: str) -> int:
    """An integer >= 1; an ``argparse`` type."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return int(text)


def log_recording(name: str, start: int, limit: int) -> Recording:
    """``limit`` scans of the Radish log ``name`` (IPC clock) from its first scan with truth
    at or after scan ``start``, with the pseudo truth of its corrected log at that log's
    keyframes' scans (matched on the logger clock both logs carry) and NaN rows elsewhere."""
    log_path, truth_path = log_paths(name)
    log = estimators.datasets.load_log(log_path)
    recording = recording_from_log(log)
    corrected = estimators.datasets.load_log(truth_path)
    match = match_truth(log.scan_times("logger"), corrected.scan_times("logger"),
                        corrected.logged_poses())
    return from_first_truth(dataclasses.replace(recording, truth=match.on_scans(len(recording))),
                            limit, start)


def from_first_truth(recording: Recording, limit: int, start: int = 0) -> Recording:
    """``limit`` scans of ``recording`` from its first scan with truth on at or after scan
    ``start``: every run starts on a known pose and the faults' offsets count from it, so the
    final error's anchor (the first truth) never lies inside a fault, as on the simulated
    drives."""
    known = np.flatnonzero(np.isfinite(recording.truth[:, 0]))
    known = known[known >= start]
    if not len(known):
        raise ValueError(f"{recording.source}: no scan from scan {start} on has truth")
    window = slice(int(known[0]), int(known[0]) + limit)
    return dataclasses.replace(recording, times=recording.times[window],
                               scans={key: scans[window]
                                      for key, scans in recording.scans.items()},
                               truth=recording.truth[window])


def run(name: str, recording: Recording, initial_pose: np.ndarray) -> tuple[np.ndarray, dict,
                                                                             float]:
    """Trajectory, health counts and CPU seconds of ``name`` over ``recording``."""
    estimator = estimators.make(name)
    start = time.process_time()
    estimator.reset(recording.setup, initial_pose)
    for observation, t in zip(recording.observations(), recording.times, strict=True):
        estimator.update(observation, float(t))
    seconds = time.process_time() - start
    health = getattr(estimator, "health", None)
    counts = {} if health is None else {**health.counts(), "lost_scans": health.lost_scans}
    return estimator.trajectory, counts, seconds


def step_errors(poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """[m] per step, the estimated step's translation against the true one (world frame)."""
    return np.linalg.norm(np.diff(poses[:, :2], axis=0) - np.diff(truth[:, :2], axis=0), axis=1)


def score(poses: np.ndarray, steps: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Worst step error [m] against ``steps`` (the truth, or the clean run where truth comes
    at keyframes only) and the final error [m] against ``truth`` (NaN rows: no truth)."""
    jumps = step_errors(poses, steps)
    known = np.flatnonzero(np.isfinite(truth[:, 0]))
    first, last = (known[0], known[-1]) if len(known) else (0, 0)
    error = relative(poses[first], poses[last])[:2] - relative(truth[first], truth[last])[:2]
    return (float(jumps.max()) if len(jumps) else 0.0,
            float(np.linalg.norm(error)) if len(known) else float("nan"))


def steps_of(recording: Recording, faulted: Recording) -> np.ndarray:
    """Indices into ``recording`` of ``faulted``'s observations (lost ones left out): all of
    them when none was lost (a clock fault moves the stamps, not the scans), else those whose
    stamps it kept."""
    if len(faulted) == len(recording):
        return np.arange(len(faulted))
    steps = np.searchsorted(recording.times, faulted.times)
    if not np.array_equal(recording.times[np.minimum(steps, len(recording) - 1)],
                          faulted.times):
        raise ValueError("faulted: scans lost and stamps moved at once; no reference")
    return steps


def start_of(truth: np.ndarray) -> np.ndarray:
    """The pose (3,) a run starts from: the first truth, the origin where it is unknown."""
    return truth[0] if np.all(np.isfinite(truth[0])) else np.zeros(3)


@dataclasses.dataclass(frozen=True)
class FaultedRun:
    """One faulted run: worst step error and final error [m] (:func:`score`), ``health``
    counts, CPU seconds, and after a long blind stretch (:func:`long_stretch`) the step error
    [m] onto the first scan with returns and the share of that scan the last one before the
    stretch covers (None without one)."""

    jump: float
    final: float
    health: dict
    seconds: float
    return_jump: float | None = None
    covered: float | None = None


def long_stretch(faulted: Recording, truth: np.ndarray) -> tuple[int, float] | None:
    """Index of the first observation with returns after ``faulted``'s longest run of
    observations without any, where that run is longer than :data:`LONG_STRETCH`, and the
    share of its points within :data:`COVER_DISTANCE` of the last scan's before the run, both
    placed at their poses in ``truth`` (one row per observation); None otherwise."""
    points = CarPoints(faulted.setup)
    scans = [points({key: faulted.scans[key][i] for key in faulted.setup.keys})
             for i in range(len(faulted))]
    blind = np.array([len(p) == 0 for p in scans] + [False])
    edges = np.flatnonzero(np.diff(np.concatenate([[False], blind]).astype(int)))
    starts, ends = edges[::2], edges[1::2]  # [start, end) of each blind run
    if not len(starts):
        return None
    k = int(np.argmax(ends - starts))
    first, after = int(starts[k]), int(ends[k])
    period = mean_period(faulted.times)
    if after - first <= round(LONG_STRETCH / period) or first == 0 or after >= len(faulted):
        return None
    before = transform_points(truth[first - 1], scans[first - 1])
    seen = transform_points(truth[after], scans[after])
    distances, _ = cKDTree(before).query(seen)
    return after, float(np.mean(distances <= COVER_DISTANCE))


def mean_period(times: np.ndarray) -> float:
    """[s] the mean scan interval of ``times``: what turns the faults' seconds into scans (a
    bursty clock's median interval, as Intel's 0.06-0.12 s against its 0.2 s mean, would make
    "3 s" of scans twice as long or more)."""
    return float((times[-1] - times[0]) / (len(times) - 1))


def faulted_run(name: str, recording: Recording, faults: list[Fault],
                reference: np.ndarray | None = None) -> FaultedRun:
    """``name`` on ``recording`` with ``faults`` (seed 0), steps against ``reference`` (the
    clean run where truth comes at keyframes only; default the truth)."""
    faulted = with_faults(recording, faults, seed=0)
    truth = recording.truth
    poses, health, seconds = run(name, faulted, start_of(truth))
    kept = steps_of(recording, faulted)
    steps = (truth if reference is None else reference)[kept]
    jump, final = score(poses, steps, truth[kept])
    stretch = long_stretch(faulted, steps)
    if stretch is None:
        return FaultedRun(jump, final, health, seconds)
    after, covered = stretch
    return FaultedRun(jump, final, health, seconds,
                      float(step_errors(poses[after - 1:after + 1], steps[after - 1:after + 1])[0]),
                      covered)


def faulted_score(name: str, recording: Recording, fault: str,
                  reference: np.ndarray | None = None) -> FaultedRun:
    """:func:`faulted_run` with the matrix's ``fault``."""
    period = mean_period(recording.times)
    return faulted_run(name, recording, faults_for(period, recording.setup.n_lidars)[fault](),
                       reference)


def final_bound(clean_final: float) -> float:
    """[m] the end-point error a faulted run may reach: 2 x the clean run's + 0.1 m."""
    return FINAL_FACTOR * clean_final + FINAL_MARGIN


def verdict(run: FaultedRun, clean_jump: float, clean_final: float) -> bool:
    """Whether ``run`` meets issue 43's targets (the module docstring)."""
    bound = final_bound(clean_final)
    if run.return_jump is None:
        return run.jump - clean_jump <= JUMP_MARGIN and run.final <= bound
    return (run.health.get("blind_stretches", 0) >= 1
            and run.return_jump - clean_jump <= JUMP_MARGIN
            and (run.final <= bound or (run.covered < COVERED_SHARE
                                        and run.health.get("lost_scans", 0) >= 1)))


def matrix(drives: dict[str, Recording], names: list[str], selected: list[str] | None,
           results: list[dict]) -> None:
    for group, recording in drives.items():
        for name in names:
            truth = recording.truth
            if truth is None:
                raise ValueError(f"{group}: the matrix needs truth, per scan or at keyframes")
            clean, health, seconds = run(name, recording, start_of(truth))
            reference = truth if np.all(np.isfinite(truth)) else clean
            clean_jump, clean_final = score(clean, reference, truth)
            print(f"{group:28s} {name:15s} {'clean':18s} jump {clean_jump:6.3f} final "
                  f"{clean_final:6.3f}  {seconds:6.1f} s  {health}", flush=True)
            for fault_name in FAULT_NAMES:
                if selected and fault_name not in selected:
                    continue
                faulted = faulted_score(name, recording, fault_name, reference)
                ok = verdict(faulted, clean_jump, clean_final)
                results.append({"drive": group, "estimator": name, "fault": fault_name,
                                "jump": faulted.jump, "clean_jump": clean_jump,
                                "final": faulted.final, "clean_final": clean_final,
                                "return_jump": faulted.return_jump, "covered": faulted.covered,
                                "pass": bool(ok), "cpu_s": faulted.seconds,
                                "health": faulted.health})
                stretch = "" if faulted.covered is None else (
                    f"  return jump+ {faulted.return_jump - clean_jump:6.3f} covered "
                    f"{faulted.covered:4.2f}")
                print(f"{group:28s} {name:15s} {fault_name:18s} jump+ "
                      f"{faulted.jump - clean_jump:6.3f} final {faulted.final:6.3f} (clean "
                      f"{clean_final:6.3f}){stretch}  {'pass' if ok else 'FAIL'}  "
                      f"{faulted.seconds:6.1f} s  {faulted.health}", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--estimators", nargs="+", default=list(ESTIMATORS),
                        choices=estimators.names())
    parser.add_argument("--groups", nargs="*", default=list(GROUPS), choices=GROUPS,
                        help="paper groups (none: only the logs)")
    parser.add_argument("--faults", nargs="+", default=None,
                        help="only these faults (default: all)")
    parser.add_argument("--logs", nargs="*", type=log_window, default=list(LOG_WINDOWS),
                        metavar="NAME:SCAN",
                        help="Radish log windows: NAME.clf.bz2 from its first scan with truth "
                             "at or after SCAN (none: no log)")
    parser.add_argument("--log-scans", type=positive_count, default=600,
                        help="scans per log window")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}")
    drives = {group: record_drive(group) for group in args.groups}
    for name, first in args.logs:
        paths = log_paths(name)
        label = f"{name}:{first}" if first else name
        if not all(path.exists() for path in paths):
            print(f"{label} skipped: {' or '.join(str(p) for p in paths)} absent")
            continue
        drives[label] = log_recording(name, first, args.log_scans)
    results: list[dict] = []
    matrix(drives, args.estimators, args.faults, results)
    failed = [r for r in results if not r["pass"]]
    print(f"{len(results) - len(failed)} of {len(results)} runs meet the targets")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    return 0 if not failed else 1


if __name__ == "__main__":
    sys.exit(main())
