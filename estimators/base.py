"""The estimator interface: a small stateful core that turns scans into car poses.

An estimator sees only the scans and the known sensor geometry (:class:`SensorSetup`),
never the ground truth. Timing, metrics and files belong to the pipeline that drives it
(:mod:`estimators.evaluation.scoring`, :mod:`estimators.leaderboard.cli`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Observation keys of the main and the offset Lidar, in that order.
LIDAR_KEYS: tuple[str, ...] = ("lidar_1", "lidar_2")


def default_beam_angles(n_beams: int) -> NDArray[np.float64]:
    """Beam ``i`` points at ``2 pi i / n`` [rad], CCW from the sensor's forward axis."""
    return 2.0 * np.pi * np.arange(n_beams) / n_beams


@dataclass(frozen=True)
class SensorSetup:
    """What an estimator may know about the sensors: their mounts and beam geometry.

    Attributes:
        mounts: ``(K, 3)`` pose of each Lidar in the car frame (x [m] forward, y [m] left,
            heading [rad]); row ``k`` belongs to observation key ``LIDAR_KEYS[k]``.
        beam_angles: ``(n,)`` beam directions [rad] in the sensor frame, CCW from forward.
        max_range: [m]; readings ``>= max_range`` (or non-finite) are "no return".
        world_aligned: scans are rotated into world orientation (the paper's simplification:
            heading is then known and only translation is estimated).
    """

    mounts: NDArray[np.float64]
    beam_angles: NDArray[np.float64]
    max_range: float
    world_aligned: bool = False

    def __post_init__(self) -> None:
        mounts = np.atleast_2d(np.asarray(self.mounts, dtype=np.float64))
        if mounts.ndim != 2 or mounts.shape[1] != 3 or len(mounts) not in (1, 2):
            raise ValueError(f"mounts: expected shape (1, 3) or (2, 3), got {mounts.shape}")
        angles = np.asarray(self.beam_angles, dtype=np.float64)
        if angles.ndim != 1 or len(angles) < 3:
            raise ValueError(f"beam_angles: expected a 1-D array of >= 3, got {angles.shape}")
        if not np.isfinite(self.max_range) or self.max_range <= 0:
            raise ValueError(f"max_range: expected a positive finite number, got {self.max_range}")
        object.__setattr__(self, "mounts", mounts)
        object.__setattr__(self, "beam_angles", angles)
        object.__setattr__(self, "max_range", float(self.max_range))

    @property
    def n_lidars(self) -> int:
        return len(self.mounts)

    @property
    def keys(self) -> tuple[str, ...]:
        return LIDAR_KEYS[: self.n_lidars]

    @classmethod
    def from_env(cls, env: Any) -> SensorSetup:
        """Read the sensor geometry of a ``DualLidar-v0`` env (wrapped or not)."""
        config = env.unwrapped.config
        return cls(
            mounts=np.asarray(config.lidar_mounts, dtype=np.float64),
            beam_angles=default_beam_angles(config.n_beams),
            max_range=config.max_range,
            world_aligned=config.scan_frame == "world",
        )

    def check_observation(self, observation: Mapping[str, Any]) -> dict[str, NDArray[np.float64]]:
        """Validate the scans of one observation; return them as float64 arrays.

        Non-finite readings are a readable error, not a silent NaN in the estimate.
        """
        scans: dict[str, NDArray[np.float64]] = {}
        for key in self.keys:
            if key not in observation:
                raise KeyError(f"observation lacks {key!r}: expected keys {', '.join(self.keys)}")
            scan = np.asarray(observation[key], dtype=np.float64)
            if scan.shape != self.beam_angles.shape:
                raise ValueError(
                    f"{key}: expected a scan of shape {self.beam_angles.shape}, got {scan.shape}"
                )
            if not np.all(np.isfinite(scan)):
                raise ValueError(f"{key}: scan holds NaN or inf; expected finite ranges [m]")
            if np.any(scan < 0):
                raise ValueError(f"{key}: scan holds negative ranges; expected ranges >= 0 [m]")
            scans[key] = scan
        return scans


@dataclass
class Estimator(ABC):
    """Base class: ``reset(setup, initial_pose)``, then ``update(observation, t) -> pose``.

    ``trajectory[k]`` is the estimated car pose (x [m], y [m], heading [rad]) at the k-th
    observation; the first observation gets ``initial_pose``. Subclasses implement
    :meth:`_start` (first scans) and :meth:`_step` (every later scans, returning the new pose).
    """

    #: Lidars the estimator needs; a pipeline skips it (no failure) on a setup with fewer.
    min_lidars: ClassVar[int] = 1
    setup: SensorSetup | None = field(default=None, init=False, repr=False)
    _poses: list[NDArray[np.float64]] = field(default_factory=list, init=False, repr=False)
    _times: list[float] = field(default_factory=list, init=False, repr=False)

    def reset(
        self, setup: SensorSetup | ArrayLike, initial_pose: ArrayLike = (0.0, 0.0, 0.0)
    ) -> None:
        """Start a new trajectory. ``setup`` may be a :class:`SensorSetup` or bare mounts (K, 3)
        (then 360 beams over 360 degrees and a 10 m max range are assumed)."""
        if not isinstance(setup, SensorSetup):
            setup = SensorSetup(np.asarray(setup, dtype=np.float64), default_beam_angles(360), 10.0)
        pose = np.asarray(initial_pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"initial_pose: expected 3 finite numbers (x, y, heading), got {pose}")
        self.setup = setup
        self._poses = []
        self._times = []
        self._initial_pose = pose.copy()
        self._reset_state()

    def update(self, observation: Mapping[str, Any], t: float) -> NDArray[np.float64]:
        """Feed the scans taken at time ``t`` [s]; return the car pose estimate (3,)."""
        if self.setup is None:
            raise RuntimeError("call reset(setup, initial_pose) before update()")
        scans = self.setup.check_observation(observation)
        if not self._poses:
            self._start(scans, t)
            pose = self._initial_pose.copy()
        else:
            pose = np.asarray(self._step(scans, t), dtype=np.float64)
        self._poses.append(pose)
        self._times.append(float(t))
        return pose.copy()

    @property
    def trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` estimated car poses, one per observation so far."""
        return np.array(self._poses, dtype=np.float64).reshape(-1, 3)

    @property
    def times(self) -> NDArray[np.float64]:
        """``(N,)`` observation times [s]."""
        return np.array(self._times, dtype=np.float64)

    @property
    def pose(self) -> NDArray[np.float64]:
        """The latest pose estimate (3,)."""
        return self._poses[-1].copy() if self._poses else self._initial_pose.copy()

    def _reset_state(self) -> None:  # noqa: B027 - optional hook, empty by design
        """Clear per-trajectory state (override when there is some)."""

    @abstractmethod
    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        """Take the first scans (keyed by ``setup.keys``)."""

    @abstractmethod
    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> ArrayLike:
        """Take the next scans; return the new car pose in the trajectory's frame."""
