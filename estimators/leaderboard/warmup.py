"""Compile the numba kernels once, before the worker pool runs the matrix.

Every kernel is ``@njit(cache=True)``: the first process that calls it compiles it (tens of
seconds for the ray caster on a 2-core machine) and writes the machine code beside the source,
in ``__pycache__``; later processes load it in milliseconds. Left alone, each worker of a cold
run compiles every kernel it touches, all of them twice over with two workers. Here two warm-up
tasks run on the pool first, one compiling the env and mapping kernels, the other the
estimators' (both record a drive first, so the simulator's kernels, the ray caster's above all,
are the ones compiled twice),
and a marker keyed by the source digest skips the warm-up once this source has been compiled.
One worker (no pool) or a Dask cluster (whose workers cache elsewhere) gain nothing from it and
skip it.
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from estimators.base import SensorSetup
from estimators.leaderboard.recording import record, replay
from estimators.leaderboard.records import Scenario, source_digest
from estimators.leaderboard.tasks import EstimatorSpec, ScenarioTask, run_scenario_task
from estimators.matching.correlative import correlative_search
from estimators.matching.nearest import PointIndex
from estimators.matching.scan_matching import LikelihoodField, scans_to_car_points
from estimators.odometry.moving_points import MovingPointFilter
from estimators.paths import PROJECT_ROOT
from lidar_env.core import DualLidarError

#: Short drives through the map scoring a worker runs (:func:`run_scenario_task`, with the
#: cheapest estimator): past cylinders, where from 2 s on the detector cuts a round arc out of
#: a cluster not round as a whole (the circle fit's arc kernels), and among walkers in
#: the closed area, whose world asks the primitive grid for the clearance of writable points
#: (and the movers' labels and scores). Left to the workers, those compiled inside their first
#: such scenario.
WARMUP_SCENARIOS = (
    Scenario("open_cylinders", "right_turn", 0, config={"max_episode_time": 2.5}),
    Scenario("closed_to_open", "zigzag", 0, config={
        "max_episode_time": 1.0, "moving_obstacles": 5, "mover_model": "yielding"}),
)
#: Down a corridor and back (25 s, 251 steps): the estimators' kernels that a few steps do not
#: reach run on it too, loop closure's search and solver and the moving-point filter's
#: "moved on" test; left to the workers, each would compile them inside its first such scenario.
WARMUP_REVISIT = Scenario("hallway", "out_and_back", 0, config={"max_episode_time": 25.0})


def marker_path() -> Path:
    """The file whose presence says the kernels of this source are compiled and cached."""
    digest = source_digest(PROJECT_ROOT)
    return PROJECT_ROOT / "estimators" / "leaderboard" / "__pycache__" / f"warm-{digest}"


def warm_env_and_mapping() -> None:
    """Compile the simulator's and the mapper's kernels (ray casting, car, map reference and
    scores, the movers' scores) and the correlative search (raises if a stage failed)."""
    for scenario in WARMUP_SCENARIOS:
        outcome = run_scenario_task(ScenarioTask(scenario, (EstimatorSpec("zero"),)))
        if outcome.failures:
            raise DualLidarError(f"warm-up on {scenario.label} failed: {outcome.failures}")
    _search_exhaustively()


def warm_estimators(names: tuple[str, ...]) -> None:
    """Compile the kernels of the named estimators by running each over a drive that revisits
    a place, and the nearest-neighbour queries a drive may not reach (loop closure's
    pairing)."""
    dataset = record(WARMUP_REVISIT)
    for name in names:
        replay(dataset, name)
    index = PointIndex(np.zeros((2, 2)))
    for k in (1, 2):
        index.query(np.zeros((1, 2)), k=k, distance_upper_bound=1.0)
    _walk_away()


def _search_exhaustively() -> None:
    """The correlative search of the odometry's fallback, which a drive reaches only where ICP
    loses track: 3 headings x 9 translations of 3 points. Here rather than in
    :func:`warm_estimators`, the longer task."""
    points = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    correlative_search(LikelihoodField(points, resolution=0.1), points, np.zeros(3),
                       linear_window=0.1, angular_window=np.radians(1.0))


def _walk_away() -> None:
    """The moving-point filter's "moved on" test, which no static drive may reach: a thing
    2 m ahead of one Lidar (3 beams) steps 0.25 m away between two scans."""
    setup = SensorSetup(np.zeros((1, 3)), np.radians(np.arange(360.0)), 10.0)
    moving_filter = MovingPointFilter(setup)
    pose = np.zeros(3)
    for distance in (2.0, 2.25):
        ranges = np.full(360, 5.0)
        ranges[[359, 0, 1]] = distance
        scans = {setup.keys[0]: ranges}
        points = scans_to_car_points(scans, setup)
        moving_filter.classify(points, pose, scans, [])
        moving_filter.remember(pose, scans, points, 0.1)


def warm_up(executor: ProcessPoolExecutor, estimators: tuple[str, ...]) -> float:
    """Compile the kernels on two of ``executor``'s workers unless the marker says they are
    cached; returns the wall time spent [s]. A failure here is left to the real tasks, which
    report it per scenario and estimator (and the marker is not written)."""
    marker = marker_path()
    if marker.exists():
        return 0.0
    started = time.perf_counter()
    jobs = [executor.submit(warm_env_and_mapping), executor.submit(warm_estimators, estimators)]
    try:
        for job in jobs:
            job.result()
    except Exception:  # noqa: BLE001 - reported by the task that meets it again
        return time.perf_counter() - started
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()
    return time.perf_counter() - started
