"""Record a scenario once, replay it through any estimator without re-simulating.

The paper's step 2 (section IV.B) creates a *sensor dataset* by driving a trace through a
world; step 3 feeds that same dataset, as if it were live, to every estimator. Here
:func:`record` drives ``DualLidar-v0`` with a named driver and keeps every observation with
the ground truth from ``info``; :func:`replay` runs one estimator over the stored scans and
:func:`score` turns the resulting trace into the metrics of :mod:`estimators.evaluation.metrics`.

Replay sees exactly what an online run sees (the reset observation, then one observation per
``env.step`` up to and including the last one), as float32 scans bit-for-bit, so replayed
metrics equal those of online scoring with :class:`estimators.evaluation.scoring.ScoreEstimator`.

:func:`score_map` adds the scores of the obstacle map an estimator's poses yield
(:mod:`estimators.mapping.map_scoring`): the occupancy grid built from every scan at the
estimated poses against the true world at :data:`MAP_RESOLUTION` and one cell of tolerance,
and in worlds with cylinders the tracked cylinders against the true ones. What the maps are
scored against (:func:`map_reference`) depends only on the scenario, so it is computed once
per scenario.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from agents.driver import make_driver
from estimators.base import SensorSetup
from estimators.leaderboard.records import Scenario, SensorDataset, TraceDataset
from estimators.registry import make
from lidar_env.core import ConfigError, DatabaseError

if TYPE_CHECKING:
    from estimators.mapping.obstacles import Obstacle
    from estimators.mapping.run_maps import MapTruth

ENV_ID = "DualLidar-v0"
#: Cell side [m] of the scored maps: 10 cm, about the size of the smallest obstacle detail that
#: matters for driving and twice the cost-cheaper side of the 5 cm benchmark grid (each beam
#: crosses half as many cells), so mapping every scan stays a few ms per step next to the
#: estimators. Scores are at a tolerance of one cell (10 cm).
MAP_RESOLUTION = 0.10
MAP_TOLERANCE_CELLS = 1
#: Scans between two obstacle-detection steps: every scan. Detection and tracking cost about
#: 1 ms per step (compiled fits, array association); a stride of 10 missed cylinders that stay
#: in view for only a few scans (leaderboard cylinder recall 0.974 at stride 10, 1.000 at 1).
OBSTACLE_STRIDE = 1


def make_env(scenario: Scenario) -> Any:
    """The ``DualLidar-v0`` env of a scenario (not reset yet)."""
    import gymnasium as gym

    import lidar_env  # noqa: F401  (registers DualLidar-v0)

    if scenario.kind != "sim":
        raise ConfigError(f"scenario {scenario.label} is a {scenario.kind!r} log, not a simulation")
    return gym.make(ENV_ID, world=scenario.world, trace=scenario.trace,
                    config=dict(scenario.config))


def _config_dict(config: Any) -> dict[str, Any]:
    if hasattr(config, "to_dict"):
        return dict(config.to_dict())
    if dataclasses.is_dataclass(config):
        return dataclasses.asdict(config)
    return dict(config)


def world_geometry(world: Any) -> dict[str, Any]:
    """A :class:`lidar_env.World`'s geometry as plain lists (metres, world frame)."""
    return {
        "name": world.name,
        "circles": np.asarray(world.circles).tolist(),
        "walls": np.asarray(world.walls).tolist(),
        "polygons": [np.asarray(polygon).tolist() for polygon in world.polygons],
        "bounds": [float(v) for v in world.bounds],
    }


def world_from_geometry(geometry: Mapping[str, Any]) -> Any:
    """The :class:`lidar_env.World` stored by :func:`world_geometry`."""
    from lidar_env.world import World

    return World(circles=geometry["circles"], segments=geometry["walls"],
                 polygons=geometry["polygons"], name=geometry["name"],
                 bounds=geometry["bounds"])


def _drive(scenario: Scenario) -> tuple[list[Any], list[dict[str, Any]], Any]:
    """The observations and infos of the scenario's drive, and its env (closed)."""
    driver = make_driver(scenario.driver)
    env = make_env(scenario)
    try:
        observation, info = env.reset(seed=int(scenario.seed))
        driver.reset(env)
        observations, infos = [observation], [info]
        done = False
        while not done:
            observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
            observations.append(observation)
            infos.append(info)
            done = terminated or truncated
    finally:
        env.close()
    return observations, infos, env


def record(scenario: Scenario) -> SensorDataset:
    """Drive the scenario's trace once with its driver; return every observation and the truth.

    The episode runs until the env terminates or truncates it; the observation after the last
    step is kept, as an online estimator would see it.
    """
    return record_with_movers(scenario)[0]


def record_with_movers(scenario: Scenario) -> tuple[SensorDataset, NDArray[np.float64]]:
    """:func:`record`, and the true movers ``(N, M, 5)`` of the same drive (which a
    :class:`SensorDataset` does not keep; :func:`mover_truth` recovers them later)."""
    observations, infos, env = _drive(scenario)
    setup = SensorSetup.from_env(env)
    return SensorDataset(
        setup=setup,
        times=np.array([i["time"] for i in infos], dtype=np.float64),
        scans={key: np.stack([np.asarray(o[key], dtype=np.float32) for o in observations])
               for key in setup.keys},
        poses=np.array([i["pose"] for i in infos], dtype=np.float64),
        lidar_poses=np.array([i["lidar_poses"] for i in infos], dtype=np.float64),
        env_config=_config_dict(env.unwrapped.config),
        world=world_geometry(env.unwrapped.world),
    ), np.stack([i["moving_obstacles"] for i in infos])


def replay(dataset: SensorDataset, estimator: str, params: Mapping[str, Any] | None = None,
           *, resolved_params: Mapping[str, Any] | None = None) -> TraceDataset:
    """Run one estimator over a stored sensor dataset, step by step as if live.

    The estimator starts at the true first pose (the paper's known start location) and sees
    only the scans. ``resolved_params`` (every parameter, defaults included) is what gets
    recorded; it defaults to ``params``.
    """
    model = make(estimator, **dict(params or {}))
    model.reset(dataset.setup, initial_pose=dataset.poses[0])
    step_ms = np.empty(len(dataset), dtype=np.float64)
    for step, observation in enumerate(dataset.observations()):
        start = time.perf_counter()
        model.update(observation, float(dataset.times[step]))
        step_ms[step] = 1e3 * (time.perf_counter() - start)
    return TraceDataset(
        estimator=estimator,
        params=dict(resolved_params if resolved_params is not None else params or {}),
        times=dataset.times.copy(),
        poses=model.trajectory,
        step_ms=step_ms,
    )


def metrics_dict(metrics: Any) -> dict[str, float]:
    """The scalar fields of a metrics object (dataclass or mapping) as ``{name: float}``."""
    fields = dataclasses.asdict(metrics) if dataclasses.is_dataclass(metrics) else dict(metrics)
    scalars: dict[str, float] = {}
    for name, value in fields.items():
        if isinstance(value, (bool, np.bool_)):
            continue
        if isinstance(value, (int, float, np.integer, np.floating)):
            scalars[name] = float(value)
    return scalars


def score(trace: TraceDataset, truth: NDArray[np.float64]) -> dict[str, float]:
    """The trace's metrics against the true car poses ``(N, 3)``, plus its ``ms_per_step``."""
    from estimators.evaluation.metrics import evaluate

    result = metrics_dict(evaluate(trace.poses, truth))
    result["ms_per_step"] = trace.ms_per_step
    return result


def map_reference(dataset: SensorDataset, resolution: float = MAP_RESOLUTION,
                  obstacle_stride: int = OBSTACLE_STRIDE) -> MapTruth | None:
    """What every estimator's map of ``dataset`` is scored against (once per scenario): the
    true world's image and visible cells along the true poses, and the cylinders observable in
    the scans the detector gets (every ``obstacle_stride``-th). ``None`` when the dataset holds
    no world geometry (nothing to score against)."""
    from estimators.mapping.map_scoring import observable_cylinders
    from estimators.mapping.obstacles import DetectorParams
    from estimators.mapping.occupancy import sensor_poses
    from estimators.mapping.run_maps import map_truth

    if not dataset.world:
        return None
    world = world_from_geometry(dataset.world)
    truth = map_truth(world, dataset.poses, dataset.setup, resolution)
    if len(truth.circles) == 0:
        return truth
    detected_at = sensor_poses(dataset.poses[::obstacle_stride], dataset.setup).reshape(-1, 3)
    observable = observable_cylinders(world, detected_at, dataset.setup.beam_angles,
                                      dataset.setup.max_range,
                                      DetectorParams().min_circle_points)
    return dataclasses.replace(truth, observable=observable)


def score_map(reference: MapTruth, poses: NDArray[np.float64], dataset: SensorDataset,
              obstacle_stride: int = OBSTACLE_STRIDE,
              label_movers: bool = True,
              car_frame: Sequence[Sequence[Obstacle]] | None = None) -> dict[str, float]:
    """The map metrics of car poses ``poses`` (N, 3) on ``dataset`` against ``reference``
    (:func:`map_reference` with the same ``obstacle_stride``).

    ``map_precision``, ``map_recall``, ``map_iou``: occupied cells of the grid built from every
    scan at ``poses``, at :data:`MAP_TOLERANCE_CELLS` over the visible true cells; in worlds
    with cylinders ``cylinder_recall`` (share of the observable ones found),
    ``cylinder_precision`` and ``cylinder_error_m`` (mean centre error [m] of the matched ones)
    of the cylinders tracked over every ``obstacle_stride``-th scan. With ``label_movers``
    both leave out the returns the motion tracker finds on moving things
    (:mod:`estimators.mapping.moving_returns`, 1-2 ms per scan); the leaderboard asks for it
    in scenarios with moving obstacles only (in a static one it labels nothing: the maps of
    the 6 static drives of ``bench_movers_estimators`` came out the same either way). Without
    ``label_movers``, the scans' ``car_frame`` obstacles
    (:func:`~estimators.mapping.run_maps.car_frame_obstacles`, every ``obstacle_stride``-th
    scan) spare detecting them again for each estimate of the poses."""
    from estimators.mapping.map_scoring import score_cylinders, score_occupancy
    from estimators.mapping.moving_returns import label_run
    from estimators.mapping.run_maps import from_estimator_run, track_obstacles

    if isinstance(obstacle_stride, bool) or not isinstance(obstacle_stride, int) \
            or obstacle_stride < 1:
        raise ConfigError(f"obstacle_stride: expected an integer >= 1, got {obstacle_stride!r}")
    observations = list(dataset.observations())
    moving = label_run(poses, observations, dataset.setup, dataset.times) if (
        label_movers) else None
    grid = from_estimator_run(poses, observations, dataset.setup, reference.resolution,
                              bounds=reference.bounds, moving=moving)
    cells = score_occupancy(grid.occupied(), reference.image, MAP_TOLERANCE_CELLS,
                            reference.visible)
    metrics = {"map_precision": cells.precision, "map_recall": cells.recall,
               "map_iou": cells.iou}
    if len(reference.circles):
        tracker = track_obstacles(poses[::obstacle_stride], observations[::obstacle_stride],
                                  dataset.setup,
                                  moving=None if moving is None else moving[::obstacle_stride],
                                  car_frame=None if moving is not None else car_frame)
        cylinders = score_cylinders(tracker.cylinders(), reference.circles,
                                    observable=reference.observable)
        metrics.update({"cylinder_recall": cylinders.recall,
                        "cylinder_precision": cylinders.precision,
                        "cylinder_error_m": cylinders.mean_error})
    return metrics


def mover_truth(scenario: Scenario, dataset: SensorDataset) -> NDArray[np.float64]:
    """The true movers ``(N, M, 5)`` (x, y, vx, vy, radius) at every observation of the
    scenario's drive, driven again (the env and its driver are deterministic per seed; a
    stored dataset does not keep them). Raises :class:`DatabaseError` if the drive does not
    reproduce ``dataset``'s scans bit for bit."""
    again, movers = record_with_movers(scenario)
    same = len(again) == len(dataset) and all(
        np.array_equal(again.scans[key], dataset.scans[key]) for key in dataset.setup.keys)
    if not same:
        raise DatabaseError(f"scenario {scenario.label}: driving it again did not reproduce "
                            "the stored scans, so its movers cannot be recovered")
    return movers


def score_movers(dataset: SensorDataset, poses: NDArray[np.float64],
                 movers: NDArray[np.float64]) -> dict[str, float]:
    """The moving-obstacle tracker (:class:`estimators.mapping.motion_tracking.MotionTracker`,
    fed the detections of every scan at car poses ``poses`` (N, 3)) scored against the true
    ``movers`` (N, M, 5) (:class:`estimators.evaluation.mover_scores.MoverScore`):
    ``mover_recall``, ``mover_position_error_m``, ``mover_velocity_error_mps``,
    ``mover_id_switches``, ``moving_label_precision``."""
    from estimators.evaluation.mover_scores import MoverScore
    from estimators.mapping.motion_tracking import MotionTracker
    from estimators.mapping.obstacles import detect_in_observation
    from estimators.matching.scan_matching import scans_to_car_points
    from lidar_env.core.se2 import transform_points

    tracker, scores = MotionTracker(), MoverScore()
    setup = dataset.setup
    for step, observation in enumerate(dataset.observations()):
        tracker.update(detect_in_observation(observation, poses[step], setup),
                       float(dataset.times[step]))
        scans = {key: np.asarray(observation[key], dtype=np.float64) for key in setup.keys}
        returns = transform_points(dataset.poses[step], scans_to_car_points(scans, setup))
        scores.add(tracker.detected_tracks(), movers[step], dataset.poses[step], returns)
    summary = scores.summary()
    return {"mover_recall": summary["recall"],
            "mover_position_error_m": summary["position_error"],
            "mover_velocity_error_mps": summary["velocity_error"],
            "mover_id_switches": summary["id_switches"],
            "moving_label_precision": summary["moving_precision"]}
