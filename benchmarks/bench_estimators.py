"""CPU time per scan of every registered estimator on the same recorded data, as a ratio to
``icp`` measured in the same run, and the real-time factor at the data's own scan rate.

    python benchmarks/bench_estimators.py                    # every estimator, sim + ACES
    python benchmarks/bench_estimators.py --estimators icp lidar_odometry --real-scans 500
    python benchmarks/bench_estimators.py --scenarios hallway:zigzag:0 --no-real --repeats 3

The simulated data are leaderboard scenarios (``world:trace:seed``, 1 cm range noise,
sensor-frame scans, the scripted driver), recorded once and replayed through every estimator;
the real data are the first ``--real-scans`` scans of the Radish logs in
``../shared/data/radish`` (skipped, with a message, when that folder is absent). Time is
``time.process_time`` around the whole replay (one core's CPU seconds; wall time on a shared
machine over-states the cost), the first scan included, of a second replay: the first one
loads (or compiles) every numba kernel the data reach, e.g. the loop closure's, which a short
warm-up drive does not. ``--repeats R`` times R replays after it and reports the fastest (this
VM's speed wanders by up to 30 % within minutes). Intel's logged clock runs backwards
631 times, which the estimators refuse, so its stamps are made to run forward first
(:func:`forward_clock`).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

import estimators
from estimators.base import LIDAR_KEYS, SensorSetup
from estimators.datasets.carmen import CarmenLog, load_log
from estimators.datasets.real_log import forward_clock, setup_from_log
from estimators.leaderboard.matrix import DEFAULT_NOISE
from estimators.leaderboard.recording import record
from estimators.leaderboard.records import Scenario
from estimators.paths import SHARED_DATA
from lidar_env import lidars_with_noise
from lidar_env.core.errors import EstimatorInputError

REFERENCE = "icp"
DATA = SHARED_DATA / "radish"
#: The leaderboard's default groups, seed 0.
SCENARIOS = ("open_cylinders:right_turn:0", "hallway:zigzag:0", "closed_to_open:zigzag:0",
             "hallway:straight:0", "hallway:out_and_back:0")
#: Log name -> (file, clock the estimators are fed).
LOGS = {"aces": ("aces.clf.bz2", "ipc"), "intel": ("intel.clf.bz2", "logger")}


@dataclasses.dataclass(frozen=True)
class Data:
    """One recording as estimators see it: setup, start pose, times [s], observations."""

    label: str
    setup: SensorSetup
    initial_pose: NDArray[np.float64]
    times: NDArray[np.float64]
    observations: list[Mapping[str, NDArray[np.floating]]]

    @property
    def scan_period(self) -> float:
        """Median time between scans [s]."""
        return float(np.median(np.diff(self.times)))


def simulated(spec: str, max_episode_time: float | None = None) -> Data:
    """Record a leaderboard scenario ``world:trace:seed`` (cut after ``max_episode_time`` [s]
    of driving when given)."""
    world, trace, seed = spec.split(":")
    config: dict[str, Any] = {"lidars": lidars_with_noise(range_noise_std=DEFAULT_NOISE)}
    if max_episode_time is not None:
        config["max_episode_time"] = max_episode_time
    dataset = record(Scenario(world, trace, int(seed), config=config))
    return Data(f"{world}/{trace}/s{seed}", dataset.setup, dataset.poses[0], dataset.times,
                list(dataset.observations()))


def real(name: str, scans: int | None) -> Data:
    """The first ``scans`` scans of a Radish log, on the clock its relations use."""
    file, clock = LOGS[name]
    log: CarmenLog = load_log(DATA / file)
    chosen = log.scans if scans is None else log.scans[:scans]
    times = forward_clock(log.scan_times(clock)[: len(chosen)])
    return Data(f"{name} ({len(chosen)} scans)", setup_from_log(log), np.zeros(3), times,
                [{LIDAR_KEYS[0]: scan.ranges} for scan in chosen])


def cpu_seconds_per_scan(name: str, data: Data, repeats: int = 1) -> float:
    """CPU seconds per scan of a fresh ``name`` replaying ``data``: the fastest of ``repeats``
    timed replays after an untimed one (which loads the compiled kernels this data reach).
    On a shared machine the fastest replay is the one least slowed by other work."""
    fastest = np.inf
    for replay in range(1 + repeats):
        estimator = estimators.make(name)
        start = time.process_time()
        estimator.reset(data.setup, data.initial_pose)
        for observation, t in zip(data.observations, data.times, strict=True):
            estimator.update(observation, float(t))
        seconds = max(time.process_time() - start, 1e-9)
        if replay > 0:
            fastest = min(fastest, seconds)
    return fastest / len(data.times)


def rows(names: list[str], data: Data, repeats: int = 1
         ) -> Iterator[tuple[str, float, float, float]]:
    """(name, ms/scan, ratio to the reference, real-time factor), the reference first; NaN
    for an estimator the data cannot feed (``pc_offset``/``pc_pg`` on a one-Lidar log)."""
    reference = cpu_seconds_per_scan(REFERENCE, data, repeats)
    yield REFERENCE, 1e3 * reference, 1.0, data.scan_period / reference
    for name in names:
        if name == REFERENCE:
            continue
        try:
            seconds = cpu_seconds_per_scan(name, data, repeats)
        except EstimatorInputError:
            seconds = float("nan")
        yield name, 1e3 * seconds, seconds / reference, data.scan_period / seconds


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--estimators", nargs="+", default=estimators.names())
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS),
                        help="world:trace:seed")
    parser.add_argument("--logs", nargs="+", default=["aces"], choices=sorted(LOGS))
    parser.add_argument("--real-scans", type=int, default=1000,
                        help="first N scans of each log (0: all)")
    parser.add_argument("--no-real", action="store_true", help="simulated data only")
    parser.add_argument("--max-episode-time", type=float, default=None,
                        help="[s] cut the simulated drives (a quick look; default: whole)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="timed replays per estimator after the untimed one; the fastest "
                             "is reported (default 1)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats: expected a number of replays >= 1, got {args.repeats}")
    unknown = sorted(set(args.estimators) - set(estimators.names()))
    if unknown:
        parser.error(f"unknown estimators {unknown}: expected some of {estimators.names()}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"python {platform.python_version()}; CPU time (time.process_time), one process")
    cut = args.max_episode_time
    sources = [lambda spec=spec: simulated(spec, cut) for spec in args.scenarios]
    if args.no_real:
        pass
    elif DATA.is_dir():
        scans = args.real_scans or None
        sources += [lambda name=name: real(name, scans) for name in args.logs]
    else:
        print(f"real logs skipped: {DATA} not found")
    for source in sources:
        data = source()
        print(f"\n{data.label}: {len(data.times)} scans at {1 / data.scan_period:.1f} Hz")
        print(f"{'estimator':<16}{'ms/scan':>9}{'x ' + REFERENCE:>8}{'x real time':>13}")
        for name, ms, ratio, realtime in rows(args.estimators, data, args.repeats):
            if np.isnan(ms):
                print(f"{name:<16}{'n/a (needs more Lidars than the data has)':>30}", flush=True)
            else:
                print(f"{name:<16}{ms:9.3f}{ratio:8.2f}{realtime:13.1f}", flush=True)


if __name__ == "__main__":
    main()
