"""Per-episode scoring of an estimator running online on an env (like ``RecordEpisodeStatistics``).

Example:
    >>> env = ScoreEstimator(gym.make("DualLidar-v0"), "pc")
    >>> obs, info = env.reset(seed=0)
    >>> ...  # step until terminated or truncated
    >>> info["estimator"]["ate_rmse_m"], info["estimator"]["ms_per_step"]

Under a vector env pass the wrapper by name so every sub-env gets its own estimator:
``gym.make_vec("DualLidar-v0", 2, wrappers=[functools.partial(ScoreEstimator, estimator="pc")])``.

With ``map_resolution`` the wrapper also builds the obstacle map online, from every scan at the
pose the estimator has just returned, shows it in the env's ``render()`` and scores it at the
episode's end (``map_iou`` ...):

    >>> env = ScoreEstimator(gym.make("DualLidar-v0", render_mode="rgb_array"), "pc_fusion",
    ...                      map_resolution=0.05)
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator, SensorSetup
from estimators.evaluation.metrics import ALIGNMENTS, DEFAULT_MIN_STEP, TrajectoryMetrics, evaluate
from estimators.registry import make
from lidar_env.core import ArgumentTypeError, ConfigError

if TYPE_CHECKING:  # numba loads only when a map is built
    from estimators.mapping.occupancy import OccupancyGrid


class ScoreEstimator(gym.Wrapper):
    """Runs ``estimator`` on every observation; at episode end adds ``info["estimator"]``.

    The estimator is reset at every ``reset`` to the true start pose (``info["pose"]``), so
    estimate and truth share their start and frame; after that it sees only the scans and
    ``info["time"]``. Ground truth comes from ``info["pose"]`` after each step.

    ``info["estimator"]`` (on the step that terminates or truncates) holds the numeric fields
    of :class:`~estimators.evaluation.metrics.TrajectoryMetrics` plus ``ms_per_step``, the mean
    wall time [ms] of one ``update`` after the first.

    With ``map_resolution`` [m] an :class:`~estimators.mapping.occupancy.OccupancyGrid` over the
    world's bounds (:attr:`grid`) takes every observation at the pose the estimator returned
    for it (the map as it is built live: later corrections of a smoother do not move cells
    already mapped), is drawn by the env's ``render()`` (``set_render_map``), and at the
    episode's end ``info["estimator"]`` adds ``map_precision``, ``map_recall`` and ``map_iou``
    (occupied cells at one cell of tolerance over the visible true cells,
    :func:`estimators.mapping.map_scoring.score_occupancy`); the truth for that is computed then,
    once.

    Args:
        env: a ``DualLidar-v0`` env (possibly wrapped).
        estimator: an :class:`Estimator` or a registered name (see ``estimators.names()``).
        min_step: eq. 11's minimum true step [m].
        align: ``"none"`` or ``"se2"``, see :func:`estimators.evaluation.metrics.evaluate`.
        map_resolution: cell side [m] of the online map; ``None`` (default): no map.
    """

    def __init__(
        self,
        env: gym.Env,
        estimator: Estimator | str,
        min_step: float = DEFAULT_MIN_STEP,
        align: str = "none",
        map_resolution: float | None = None,
    ) -> None:
        super().__init__(env)
        if isinstance(estimator, str):
            self.estimator_name = estimator
            estimator = make(estimator)
        elif isinstance(estimator, Estimator):
            self.estimator_name = type(estimator).__name__
        else:
            raise ArgumentTypeError(
                f"estimator: expected an Estimator or a registered name, got {type(estimator)}"
            )
        if align not in ALIGNMENTS:
            raise ConfigError(f"unknown align {align!r}: expected one of {', '.join(ALIGNMENTS)}")
        if not np.isfinite(min_step) or min_step <= 0:
            raise ConfigError(f"min_step: expected a positive number [m], got {min_step!r}")
        if map_resolution is not None and not (np.isfinite(map_resolution)
                                               and map_resolution > 0):
            raise ConfigError(f"map_resolution: expected a positive cell side [m] or None, "
                             f"got {map_resolution!r}")
        self.map_resolution = map_resolution
        self.grid: OccupancyGrid | None = None
        self._setup: SensorSetup | None = None
        self.estimator = estimator
        self.min_step = min_step
        self.align = align
        self._truth: list[NDArray[np.float64]] = []
        self._update_seconds = 0.0
        self.last_metrics: TrajectoryMetrics | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self._setup = SensorSetup.from_env(self.env)
        self.estimator.reset(self._setup, info["pose"])
        pose = self.estimator.update(observation, float(info["time"]))
        if self.map_resolution is not None:
            from estimators.mapping.occupancy import OccupancyGrid

            self.grid = OccupancyGrid(self.env.unwrapped.world.bounds, self.map_resolution)
            self.grid.integrate_observation(observation, pose, self._setup)
            self.env.unwrapped.set_render_map(self.grid)
        self._truth = [np.asarray(info["pose"], dtype=np.float64).copy()]
        self._update_seconds = 0.0
        self.last_metrics = None
        return observation, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        start = time.perf_counter()
        pose = self.estimator.update(observation, float(info["time"]))
        self._update_seconds += time.perf_counter() - start
        if self.grid is not None:
            self.grid.integrate_observation(observation, pose, self._setup)
        self._truth.append(np.asarray(info["pose"], dtype=np.float64).copy())
        if terminated or truncated:
            info = {**info, "estimator": self._episode_summary()}
        return observation, reward, terminated, truncated, info

    def _episode_summary(self) -> dict[str, float]:
        n_updates = len(self._truth) - 1
        summary: dict[str, float] = {
            "ms_per_step": 1000.0 * self._update_seconds / n_updates,
            "steps": float(n_updates),
        }
        self.last_metrics = evaluate(
            self.estimated_trajectory, self.true_trajectory, self.min_step, self.align
        )
        for key, value in self.last_metrics.as_dict().items():
            if not isinstance(value, str):
                summary[key] = float(value)
        if self.grid is not None:
            summary.update(self._map_scores())
        return summary

    def _map_scores(self) -> dict[str, float]:
        from estimators.mapping.map_scoring import score_occupancy
        from estimators.mapping.run_maps import map_truth

        assert self.grid is not None and self._setup is not None
        truth = map_truth(self.env.unwrapped.world, self.true_trajectory, self._setup,
                          self.grid.resolution)
        scores = score_occupancy(self.grid.occupied(), truth.image, 1, truth.visible)
        return {"map_precision": scores.precision, "map_recall": scores.recall,
                "map_iou": scores.iou}

    @property
    def estimated_trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` estimated car poses of the current episode."""
        return self.estimator.trajectory

    @property
    def true_trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` true car poses of the current episode (``info["pose"]``)."""
        return np.array(self._truth, dtype=np.float64).reshape(-1, 3)
