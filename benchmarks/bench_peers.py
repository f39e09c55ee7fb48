"""Peers benchmark: our odometry against KISS-ICP, or our Lidar against IR-SIM's and VMAS's.

    python benchmarks/bench_peers.py                          # ACES and Intel, 2,000 scans each
    python benchmarks/bench_peers.py --limit 500 my.clf.gz my_bag --json peers.json
    python benchmarks/bench_peers.py --peers-path /tmp/kiss   # KISS-ICP installed with --target
    python benchmarks/bench_peers.py --kernels                # + CPU inside compiled kernels
    python benchmarks/bench_peers.py --env --peers-path DIR   # the peers' Lidars, not the logs

Runs ``lidar_odometry``, ``slam`` and ``icp`` (``--estimators``) and KISS-ICP (PyPI
``kiss-icp``, the ``peers`` extra; its Python API, ``KissICP.register_frame``) over the first
``--limit`` scans of ACES and Intel (``../shared/data/radish``) and of every CARMEN log or ROS
bag given on the command line (a bag's first Lidar). The runners are interleaved scan by scan,
so a machine whose speed wanders slows all of them alike, and each is charged the CPU time
(``time.process_time``) of its own calls, after an untimed run over the first 50 scans that
loads its numba kernels. KISS-ICP gets each scan's returns (readings below the
maximum range) as z = 0 points in the robot frame (the laser mount applied), voxel 0.25 m,
deskew off, one thread, the log's maximum range; its pose's x, y and yaw are its planar
trajectory. Printed per log: CPU ms per scan of each, the ratios to KISS-ICP (and ``slam`` to
``lidar_odometry``), and the relation errors where the log has a reference (ACES: Kümmerle's
relations; Intel: the SLAM-corrected log's poses, pseudo ground truth); ``--json`` writes all
of it with the settings and the machine. ``--kernels`` runs each of ours once more under
cProfile and reports the CPU it spends inside its compiled kernels alone
(:mod:`kernel_time`), also as a ratio to KISS-ICP's whole CPU: what no faster Python around
the kernels could remove. The clocks are bench_real_logs.py's: ACES on the IPC
stamps, Intel on the logger's made to run forward (``estimators.datasets.real_log``).

``--env`` times the simulators' Lidars instead: IR-SIM's (PyPI ``ir-sim``) and VMAS's (PyPI
``vmas``, on torch) 360-beam scans against our kernel on one walled room of discs and boxes from
``--seed``, at ``--poses`` random free poses (``--batch`` of them a call), CPU time per scan
in turns, each peer's ranges checked against ours (``peer_lidars``). A peer that does not
import is skipped with a line naming its pip command. It replaces the log runs, whose peers and
measure (odometry) differ.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import peer_lidars
from kernel_time import kernel_seconds
from numpy.typing import NDArray

from estimators import make
from estimators.base import SensorSetup
from estimators.datasets.carmen import load_log
from estimators.datasets.real_log import (
    LogRun,
    forward_clock,
    pseudo_truth_relations,
    score_relations,
    setup_from_log,
)
from estimators.evaluation.relations import Relations, load_relations, relation_errors
from estimators.paths import SHARED_DATA
from lidar_env.core import EstimatorInputError

DATA = SHARED_DATA / "radish"
PEER = "kiss_icp"
#: Scans each of our estimators runs untimed first, loading its kernels from numba's cache.
WARM_SCANS = 50
#: KISS-ICP's settings for planar scans, stated in the output.
KISS_SETTINGS = {"voxel_size_m": 0.25, "deskew": False, "max_num_threads": 1,
                 "points": "z = 0 returns below max_range, robot frame", "api": "Python"}


@dataclass(frozen=True)
class LogSource:
    """Scans of one Lidar: ``ranges`` ``(N, n)`` [m] at ``times`` ``(N,)`` [s], fed forward;
    ``reference`` maps a label to relations to score against (empty: timing only)."""

    name: str
    setup: SensorSetup
    times: NDArray[np.float64]
    ranges: NDArray[np.float64]
    reference: dict[str, Relations]
    scored_times: NDArray[np.float64]


def carmen_source(path: Path, name: str, clock: str, limit: int,
                  reference: dict[str, Relations]) -> LogSource:
    """The first ``limit`` scans of a CARMEN log on ``clock``."""
    log = load_log(path)
    scans = log.scans[:limit]
    logged = log.scan_times(clock)[: len(scans)]
    return LogSource(name, setup_from_log(log), forward_clock(logged),
                     np.stack([scan.ranges for scan in scans]), reference, logged)


def bag_source(path: Path, limit: int) -> LogSource:
    """The first ``limit`` scans of a ROS bag's first Lidar (timing only)."""
    from estimators.datasets.rosbag_reader import load_bag

    recording = load_bag(path)
    sensor = recording.setup.sensors[0]
    first = SensorSetup(sensor.mount[None, :], sensor.beam_angles, sensor.max_range)
    ranges = recording.scans[recording.setup.keys[0]][:limit]
    times = recording.times[: len(ranges)]
    return LogSource(path.name, first, forward_clock(times), ranges, {}, times)


class KissRunner:
    """KISS-ICP over planar scans: returns as z = 0 points in the robot frame."""

    def __init__(self, setup: SensorSetup) -> None:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP

        config = KISSConfig()
        config.data.deskew = False
        config.data.max_range = float(setup.max_range)
        config.data.min_range = 0.0
        config.mapping.voxel_size = KISS_SETTINGS["voxel_size_m"]
        config.registration.max_num_threads = KISS_SETTINGS["max_num_threads"]
        self.odometry = KissICP(config)
        x, y, heading = setup.mounts[0]
        angles = np.asarray(setup.beam_angles, dtype=np.float64).ravel() + heading
        self.cos, self.sin = np.cos(angles), np.sin(angles)
        self.offset = np.array([x, y])
        self.max_range = float(setup.max_range)
        self.poses: list[tuple[float, float, float]] = []

    def update(self, ranges: NDArray[np.float64], t: float) -> None:
        valid = (ranges > 0.0) & (ranges < self.max_range) & np.isfinite(ranges)
        r = ranges[valid]
        points = np.zeros((len(r), 3))
        points[:, 0] = r * self.cos[valid] + self.offset[0]
        points[:, 1] = r * self.sin[valid] + self.offset[1]
        self.odometry.register_frame(points, np.zeros(len(r)))
        pose = self.odometry.last_pose
        self.poses.append((pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])))

    @property
    def trajectory(self) -> NDArray[np.float64]:
        return np.array(self.poses)


class OurRunner:
    """One of our estimators fed one Lidar's ranges."""

    def __init__(self, name: str, setup: SensorSetup) -> None:
        self.estimator = make(name)
        self.estimator.reset(setup, np.zeros(3))
        self.key = setup.keys[0]

    def update(self, ranges: NDArray[np.float64], t: float) -> None:
        self.estimator.update({self.key: ranges}, t)

    @property
    def trajectory(self) -> NDArray[np.float64]:
        return self.estimator.trajectory


def run_interleaved(source: LogSource, runners: dict[str, Any]) -> dict[str, float]:
    """Feed every scan to every runner in turn; the CPU seconds per scan of each."""
    spent = dict.fromkeys(runners, 0.0)
    clock = time.process_time
    for ranges, t in zip(source.ranges, source.times, strict=True):
        for name, runner in runners.items():
            start = clock()
            runner.update(ranges, float(t))
            spent[name] += clock() - start
    return {name: seconds / len(source.times) for name, seconds in spent.items()}


def relation_scores(source: LogSource, trajectory: NDArray[np.float64]) -> dict[str, Any]:
    """Mean translational [m] and rotational [deg] relation errors per reference label."""
    run = LogRun(source.scored_times, trajectory, 0.0)
    scores: dict[str, Any] = {}
    for label, relations in source.reference.items():
        try:
            summaries = _summaries(run, label, relations)
        except EstimatorInputError:  # no relation within the scans run
            continue
        for key, summary in summaries.items():
            scores[key] = {"translation_m": summary.translation_mean,
                           "rotation_deg": summary.rotation_mean, "count": summary.count}
    return scores


def _summaries(run: LogRun, label: str, relations: Relations) -> dict[str, Any]:
    """Relation summaries of ``run``: Kümmerle's local and all, or one per pseudo-truth
    window."""
    if label == "kuemmerle":
        return score_relations(run, relations)
    inside = relations.select((relations.t1 >= run.times[0])
                              & (relations.t2 <= run.times[-1] + 0.01))
    # the corrected log prints 6 significant digits: 10 ms covers its rounding
    return {label: relation_errors(run.times, run.poses, inside, tolerance=0.01).summary()}


def feed(source: LogSource, runner: Any) -> None:
    """Every scan of ``source`` to ``runner``, in order."""
    for ranges, t in zip(source.ranges, source.times, strict=True):
        runner.update(ranges, float(t))


def bench_log(source: LogSource, names: list[str], with_peer: bool,
              kernels: bool = False) -> dict[str, Any]:
    """One log: CPU ms per scan, ratios and relation errors of every runner; with
    ``kernels``, also the CPU ms per scan each of ours spends inside compiled kernels
    (:func:`kernel_time.kernel_seconds`, a second, profiled run)."""
    for name in names:  # load (or compile) each estimator's kernels outside the timing
        warm = OurRunner(name, source.setup)
        for ranges, t in zip(source.ranges[:WARM_SCANS], source.times[:WARM_SCANS],
                             strict=True):
            warm.update(ranges, float(t))
    runners: dict[str, Any] = {name: OurRunner(name, source.setup) for name in names}
    if with_peer:
        runners[PEER] = KissRunner(source.setup)
    per_scan = run_interleaved(source, runners)
    result: dict[str, Any] = {"scans": len(source.times), "beams": source.ranges.shape[1],
                              "cpu_ms_per_scan": {n: 1e3 * s for n, s in per_scan.items()},
                              "errors": {}}
    for name, runner in runners.items():
        if source.reference:
            result["errors"][name] = relation_scores(source, runner.trajectory)
    ratios = {}
    if with_peer:
        ratios.update({f"{n}/{PEER}": per_scan[n] / per_scan[PEER] for n in names})
    if "slam" in per_scan and "lidar_odometry" in per_scan:
        ratios["slam/lidar_odometry"] = per_scan["slam"] / per_scan["lidar_odometry"]
    if kernels:
        result["kernel_ms_per_scan"] = {name: 1e3 * kernel_seconds(
            lambda name=name: feed(source, OurRunner(name, source.setup))) / len(source.times)
            for name in names}
        if with_peer:
            ratios.update({f"{n} kernels/{PEER}": result["kernel_ms_per_scan"][n]
                           / result["cpu_ms_per_scan"][PEER] for n in names})
    result["ratios"] = ratios
    return result


def print_log(name: str, result: dict[str, Any]) -> None:
    print(f"{name}: {result['scans']} scans of {result['beams']} beams")
    for runner, ms in result["cpu_ms_per_scan"].items():
        errors = result["errors"].get(runner, {})
        shown = "; ".join(f"{label} {e['translation_m']:.4f} m / {e['rotation_deg']:.3f} deg"
                          for label, e in errors.items())
        inside = result.get("kernel_ms_per_scan", {}).get(runner)
        kernels = "" if inside is None else f" ({inside:.3f} in kernels)"
        print(f"  {runner:15s} {ms:7.3f} ms/scan CPU{kernels}  {shown}")
    for label, ratio in result["ratios"].items():
        print(f"  {label:32s} {ratio:6.2f}x CPU")


def sources(args: argparse.Namespace) -> list[Callable[[], LogSource]]:
    """Loaders of the logs to run, in order (loaded one at a time)."""
    loaders: list[Callable[[], LogSource]] = []
    if not args.no_default_logs and DATA.is_dir():
        loaders.append(lambda: carmen_source(
            DATA / "aces.clf.bz2", "ACES", "ipc", args.limit,
            {"kuemmerle": load_relations(DATA / "aces.relations")}))
        loaders.append(lambda: carmen_source(
            DATA / "intel.clf.bz2", "Intel", "logger", args.limit,
            {"1 s": pseudo_truth_relations(load_log(DATA / "intel-corrected.log.gz"),
                                           (1.0,))["1 s"]}))
    for path in args.logs:
        if path.is_dir() or path.suffix in (".bag", ".db3", ".mcap"):
            loaders.append(lambda path=path: bag_source(path, args.limit))
        else:
            loaders.append(lambda path=path: carmen_source(path, path.name, "ipc", args.limit,
                                                           {}))
    return loaders


def existing_path(text: str) -> Path:
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"no such log or bag: {text}")
    return path


def positive(text: str) -> int:
    value = int(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a count > 0, got {text}")
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("logs", nargs="*", type=existing_path, default=[],
                        help="more CARMEN logs or ROS bags (a bag's first Lidar)")
    parser.add_argument("--limit", type=positive, default=2000, help="first N scans of each")
    parser.add_argument("--estimators", nargs="+", default=["lidar_odometry", "slam", "icp"],
                        help="our estimators to run beside KISS-ICP")
    parser.add_argument("--no-default-logs", action="store_true",
                        help="skip ACES and Intel")
    parser.add_argument("--peers-path", type=existing_path, default=None,
                        help="a directory holding the peers (pip install --target DIR kiss-icp, "
                             "or a venv's site-packages holding ir-sim and vmas), searched "
                             "after this environment's packages")
    parser.add_argument("--env", action="store_true",
                        help="time IR-SIM's and VMAS's Lidars against ours instead of the logs")
    parser.add_argument("--poses", type=positive, default=300, help="--env: poses to scan")
    parser.add_argument("--batch", type=positive, default=1,
                        help="--env: poses per scan call (VMAS's environments, our sensors)")
    parser.add_argument("--seed", type=int, default=0, help="--env: the scene and the poses")
    parser.add_argument("--kernels", action="store_true",
                        help="also run each of ours once more under cProfile and report the "
                             "CPU it spends inside compiled kernels")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    if args.peers_path is not None:
        sys.path.append(str(args.peers_path))
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
               f"python {platform.python_version()}")
    if args.env:
        if args.logs:
            parser.error("--env scans a simulated room: give no logs with it")
        if args.batch > args.poses:
            parser.error(f"--batch: expected at most --poses ({args.poses}), got {args.batch}")
        return bench_env(args, machine)
    try:
        import kiss_icp
        peer_version = getattr(kiss_icp, "__version__", "unknown")
    except ImportError:
        peer_version = None
        print("KISS-ICP not installed (pip install 'duallidar[peers]', or --peers-path): "
              "our estimators only", file=sys.stderr)
    loaders = sources(args)
    if not loaders:
        parser.error(f"no logs: {DATA} is missing and none was given")
    print(f"machine: {machine}; CPU time per scan, runners interleaved scan by scan")
    if peer_version:
        print(f"KISS-ICP {peer_version}: {KISS_SETTINGS}")
    report: dict[str, Any] = {"machine": machine, "peer": PEER, "peer_version": peer_version,
                              "peer_settings": KISS_SETTINGS, "limit": args.limit, "logs": {}}
    for load in loaders:
        source = load()
        result = bench_log(source, args.estimators, peer_version is not None, args.kernels)
        print_log(source.name, result)
        report["logs"][source.name] = result
    write_json(args.json, report)
    return 0


def bench_env(args: argparse.Namespace, machine: str) -> int:
    """``--env``: the peers' Lidars against ours on one scene (see :mod:`peer_lidars`)."""
    print(f"machine: {machine}; CPU time per scan, scanners in turns over blocks of poses")
    result, skipped = peer_lidars.run(list(peer_lidars.PEERS), args.seed, args.poses,
                                      args.batch)
    for line in skipped:
        print(line, file=sys.stderr)
    peer_lidars.print_result(result)
    write_json(args.json, {"machine": machine, "env": result})
    return 0


def write_json(path: Path | None, report: dict[str, Any]) -> None:
    if path is not None:
        path.write_text(json.dumps(report, indent=1))
        print(f"wrote {path}")


if __name__ == "__main__":
    raise SystemExit(main())
