"""Compile the numba kernels once per source: at set-up, or before the worker pool runs the matrix.

Every kernel is ``@njit(cache=True)``: the first process that calls it compiles it (tens of
seconds for the ray caster on a 2-core machine) and writes the machine code beside the source,
in ``__pycache__``; later processes load it in milliseconds. ``scripts/setup.sh`` runs
:func:`main` (``python scripts/compile_kernels.py``) as its last step, so the first
``gym.make`` + ``reset`` + ``step`` and the leaderboard's first run load instead of compiling.
The work is five tasks on two processes (:func:`tasks`): the single env's kernels beside the
batched env's, then the kernels of the estimators in two families that share none (the ICP
family and the paper's phase correlation), each over a recorded drive that revisits a place,
and the mapper's and walkers'. Every task after the first needs the single env's kernels:
started after it, they load them instead of compiling them a second time. A marker keyed by the
source digest skips it all once this source has been compiled. numba keys a cached kernel by
its own file only, so a kernel whose callee in another file changed would load stale code: a
compile for a new source first deletes the packages' numba cache files, so every kernel is
rebuilt from the current source.

Before compiling, one line says so and how long it took the last time on this machine (or the
range it takes on a 2-core machine); on a terminal a bar of elapsed against expected seconds
moves while it runs, while a log that is not a terminal (CI) gets no bar frames, only that line
and the caller's line saying how long it took. The leaderboard calls :func:`warm_up` on its
own pool (a Dask cluster, whose workers cache elsewhere, or one worker skip it); after the
first run nothing is said.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_EXCEPTION, Executor, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from estimators.base import SensorSetup
from estimators.leaderboard.recording import record, replay
from estimators.leaderboard.records import Scenario, source_digest
from estimators.leaderboard.tasks import EstimatorSpec, ScenarioTask, run_scenario_task
from estimators.matching.correlative import correlative_search
from estimators.matching.likelihood_grids import likelihood_grid
from estimators.matching.nearest import PointIndex
from estimators.matching.scan_matching import LikelihoodField, scans_to_car_points
from estimators.odometry.moving_points import MovingPointFilter
from estimators.paths import PROJECT_ROOT
from lidar_env.core import DualLidarError, kernel_cache

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


#: A cold compile of every kernel on a 2-core x86-64 machine, two processes [s]: said before
#: the first compile, until one has been timed on this machine.
COMPILE_SECONDS = (60, 180)
#: Every how many seconds the bar moves.
TICK_SECONDS = 0.5


#: The packages that hold kernels: their sources key the marker and hold the cache files.
KERNEL_PACKAGES = ("estimators", "lidar_env")


def marker_path() -> Path:
    """The file whose presence says the kernels of this source are compiled and cached."""
    digest = source_digest(PROJECT_ROOT, KERNEL_PACKAGES)
    return PROJECT_ROOT / "estimators" / "leaderboard" / "__pycache__" / f"warm-{digest}"


def timing_path() -> Path:
    """The file holding how long the last compile took on this machine [s]."""
    return marker_path().parent / "warm-seconds.json"


def warm_drive() -> None:
    """Compile the single env's kernels (ray casting, the car) by recording the drive the
    estimators' tasks replay."""
    with _env_notice_off():
        record(WARMUP_REVISIT)


def warm_batched() -> None:
    """Compile the batched env's kernels and the odometry fallback's correlative search."""
    with _env_notice_off():
        _step_batched()
    _search_exhaustively()


def warm_mapping() -> None:
    """Compile the mapper's and the movers' kernels (map reference and scores, circle fits,
    walkers) on :data:`WARMUP_SCENARIOS` (raises if a stage failed)."""
    with _env_notice_off():
        for scenario in WARMUP_SCENARIOS:
            outcome = run_scenario_task(ScenarioTask(scenario, (EstimatorSpec("zero"),)))
            if outcome.failures:
                raise DualLidarError(f"warm-up on {scenario.label} failed: {outcome.failures}")


def warm_estimators(names: tuple[str, ...]) -> None:
    """Compile the kernels of the named estimators by running each over a drive that revisits
    a place, and the nearest-neighbour queries a drive may not reach (loop closure's
    pairing)."""
    with _env_notice_off():
        dataset = record(WARMUP_REVISIT)
    for name in names:
        replay(dataset, name)
    index = PointIndex(np.zeros((2, 2)))
    for k in (1, 2):
        index.query(np.zeros((1, 2)), k=k, distance_upper_bound=1.0)
    _walk_away()


@contextmanager
def _env_notice_off() -> Iterator[None]:
    """Silence the env's own first-compile notice (:mod:`lidar_env.core.kernel_cache`): the
    warm-up has said what it compiles."""
    logger = logging.getLogger("lidar_env")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def estimator_families(names: Iterable[str]) -> list[tuple[str, ...]]:
    """``names`` in two groups whose kernels overlap little, so two processes compile them
    side by side without compiling the same kernel twice: the paper's phase-correlation
    family (``pc*``) and the rest (ICP, scan-to-map odometry and SLAM share their matching
    kernels). Empty groups are left out."""
    names = tuple(names)
    phase = tuple(name for name in names if name.startswith("pc"))
    rest = tuple(name for name in names if not name.startswith("pc"))
    return [group for group in (rest, phase) if group]


def tasks(estimators: Iterable[str]) -> list[tuple[Callable[..., None], tuple[Any, ...]]]:
    """The warm-up's tasks in the order two workers take them: the single env's (the shortest,
    whose kernels every later task needs) beside the batched env's, then each estimator
    family's (:func:`estimator_families`) and the mapper's, which find the single env's
    kernels cached by the time they start."""
    return ([(warm_drive, ()), (warm_batched, ())]
            + [(warm_estimators, (group,)) for group in estimator_families(estimators)]
            + [(warm_mapping, ())])


def drop_numba_caches(root: Path = PROJECT_ROOT) -> int:
    """Delete the numba cache files (``*.nbi`` index, ``*.nbc`` code) of the project's
    packages under ``root``; returns how many. numba keys a cached kernel by its own source
    file, not its callees', so after a source change only a full rebuild is sure to be
    current."""
    return sum(kernel_cache.drop_numba_caches(root / package) for package in KERNEL_PACKAGES)


def last_seconds() -> float | None:
    """How long the last compile took on this machine [s], None if none has been timed."""
    try:
        return float(json.loads(timing_path().read_text())["seconds"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _announcement(expected: float | None) -> str:
    """The line said before compiling."""
    low, high = COMPILE_SECONDS
    how_long = (f"about {expected:.0f} s, as the last time on this machine"
                if expected is not None else f"{low}-{high} s on a 2-core machine")
    return (f"compiling the numba kernels once for this source ({how_long}); later runs load "
            "them from __pycache__")

def _step_batched() -> None:
    """The batched env's kernels (``make_vec``'s ``vector_entry_point``): two envs of the
    default layout reset and stepped, then among walkers."""
    import gymnasium as gym

    import lidar_env  # noqa: F401 - registers DualLidar-v0

    for config in (None, {"moving_obstacles": 3}):
        envs = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point",
                            config=config)
        envs.reset(seed=0)
        for _ in range(3):
            envs.step(np.tile(np.array([[0.5, 0.1]], np.float32), (2, 1)))
        envs.close()


def _search_exhaustively() -> None:
    """The correlative search of the odometry's fallback, which a drive reaches only where ICP
    loses track: 3 headings x 9 translations of 3 points, and the stamped likelihood grid of
    the far-apart search (scans a metre or more apart, as on real logs). Here rather than in
    :func:`warm_estimators`, the longer task."""
    points = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    correlative_search(LikelihoodField(points, resolution=0.1), points, np.zeros(3),
                       linear_window=0.1, angular_window=np.radians(1.0))
    likelihood_grid(points, np.array([-2.0, -2.0]), (40, 40), 0.1)


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


def warm_up(executor: Executor, estimators: tuple[str, ...], *,
            progress: bool = True, stream: Any = None) -> float:
    """Compile the kernels on two of ``executor``'s workers unless the marker says they are
    cached; returns the wall time spent [s] (0 when cached). Before it starts, one line on
    ``stream`` (stderr) says what runs and how long it takes; with ``progress``, and
    ``stream`` a terminal, a bar of elapsed seconds moves until it ends. A failure here is
    left to the real tasks, which report it per scenario and estimator (and the marker is not
    written)."""
    marker = marker_path()
    if marker.exists():
        return 0.0
    stream = sys.stderr if stream is None else stream
    expected = last_seconds()
    print(_announcement(expected), file=stream, flush=True)
    drop_numba_caches()
    started = time.perf_counter()
    jobs = [executor.submit(task, *args) for task, args in tasks(estimators)]
    bar_seconds = max(1.0, expected if expected is not None else COMPILE_SECONDS[0])
    if not _wait(jobs, bar_seconds, progress, stream, started):
        return time.perf_counter() - started
    seconds = time.perf_counter() - started
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()
    timing_path().write_text(json.dumps({"seconds": round(seconds, 1)}))
    return seconds


def _wait(jobs: list[Future], expected: float, progress: bool, stream: Any,
          started: float) -> bool:
    """Wait for ``jobs``, moving a bar of elapsed against ``expected`` seconds every
    :data:`TICK_SECONDS` when ``progress`` and ``stream`` is a terminal; True if every job
    succeeded."""
    from tqdm import tqdm

    pending = set(jobs)
    # disable=None: tqdm draws nothing on a stream that is not a terminal, where each frame
    # would be one more carriage-return line in the log
    with tqdm(total=round(expected), unit="s", file=stream, disable=None if progress else True,
              bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} s{postfix}",
              desc="compiling") as bar:
        while pending:
            done, pending = wait(pending, timeout=TICK_SECONDS, return_when=FIRST_EXCEPTION)
            if any(job.exception() is not None for job in done):
                return False
            bar.total = max(bar.total, round(time.perf_counter() - started))
            bar.n = round(time.perf_counter() - started)
            bar.set_postfix_str(f"tasks {len(jobs) - len(pending)}/{len(jobs)}")
    return True


def main() -> int:
    """Compile every kernel of this source on two processes (``scripts/setup.sh``'s last
    step); exit status 0 when compiled or already cached, 1 if a task failed."""
    import estimators

    if marker_path().exists():
        return 0
    with ProcessPoolExecutor(max_workers=2) as pool:
        seconds = warm_up(pool, tuple(estimators.names()))
    if not marker_path().exists():
        print("the kernels did not all compile: runs compile what they use on first use",
              file=sys.stderr)
        return 1
    print(f"compiled the numba kernels in {seconds:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
