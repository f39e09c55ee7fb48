"""Drive on estimated poses: any driver, steered by a Lidar-only estimator running online.

:class:`EstimatedPoseDriver` wraps a driver and an estimator (``estimators.registry`` name).
At every step it feeds the scans to the estimator and hands the driver an ``info`` whose
``"pose"`` is the estimate instead of the env's ground truth, so the car steers by what its
Lidars tell it: the closed loop the paper's system exists for. The estimator starts from the
trace's start pose (where the env places the car, as a robot knows where it was put down);
after that it reads only the scans and the time stamp. The wrapped driver sees an ``info`` of
just ``"pose"`` (the estimate) and ``"time"``: every ground-truth key of the env's ``info``
(true pose, Lidar poses, progress, cross-track error) stays with the pipeline that scores the
drive.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from agents.interface import Driver
from estimators import registry
from estimators.base import Estimator, SensorSetup
from lidar_env.core import ArgumentTypeError, ConfigError

#: ``pose_source`` value for the env's ground-truth pose (no estimator).
TRUE_POSE = "true"


def check_pose_source(pose_source: str) -> str:
    """``pose_source`` if it is ``"true"`` or a registered estimator, else a ConfigError."""
    valid = (TRUE_POSE, *registry.names())
    if not isinstance(pose_source, str) or pose_source not in valid:
        raise ConfigError(
            f"pose_source: expected one of {', '.join(valid)}, got {pose_source!r}")
    return pose_source


class EstimatedPoseDriver:
    """``driver`` steering by the poses ``estimator`` computes from the scans.

    Args:
        driver: any :class:`~agents.driver.Driver` that reads ``info["pose"]``.
        estimator: a registered estimator name (``estimators.registry.names()``) or an
            :class:`~estimators.base.Estimator` instance (reset at every episode).
        params: the named estimator's parameters over its defaults (``estimators.make``), e.g.
            ``{"sideslip_sigma": 6e-4}`` for ``lidar_odometry`` on a car whose frame is the
            wheels' no-slip point, as the simulated car's is.

    ``last_estimate`` is the pose (x [m], y [m], heading [rad], world frame) given to the
    driver at the latest step.
    """

    def __init__(self, driver: Driver, estimator: str | Estimator,
                 params: Mapping[str, Any] | None = None) -> None:
        if params is not None and not isinstance(params, Mapping):
            raise ArgumentTypeError(f"params: expected a mapping of parameter names to values, "
                                    f"got {type(params).__name__}")
        if isinstance(estimator, str):
            if estimator == TRUE_POSE:
                raise ConfigError("estimator: expected an estimator name, got 'true' (the env's "
                                  "pose needs no EstimatedPoseDriver)")
            estimator = registry.make(check_pose_source(estimator), **(params or {}))
        elif params:
            raise ConfigError(f"params: only with an estimator name, not with an Estimator "
                              f"instance (got {dict(params)!r})")
        if not isinstance(estimator, Estimator):
            raise ArgumentTypeError(f"estimator: expected an estimator name or an Estimator, got "
                            f"{type(estimator).__name__}")
        self.driver = driver
        self.estimator = estimator
        self.last_estimate: NDArray[np.float64] | None = None

    def reset(self, env: gym.Env) -> None:
        """Reset the driver and start the estimator at the trace's start pose."""
        self.driver.reset(env)
        setup = SensorSetup.from_env(env)
        if setup.n_lidars < self.estimator.min_lidars:
            raise ConfigError(
                f"pose_source: {type(self.estimator).__name__} needs "
                f"{self.estimator.min_lidars} Lidars, the env has {setup.n_lidars}")
        self.estimator.reset(setup, env.unwrapped.trace.start_pose)
        self.last_estimate = None

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> NDArray[np.float32]:
        """Update the estimate from ``observation`` and let the driver act on it."""
        estimate = self.estimator.update(observation, float(info["time"]))
        self.last_estimate = np.asarray(estimate, dtype=np.float64).copy()
        seen = {"pose": self.last_estimate.copy(), "time": info["time"]}
        return self.driver.act(observation, seen)
