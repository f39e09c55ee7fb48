"""The estimator interface: a small stateful core that turns scans into car poses.

An estimator sees only the scans and the known sensor geometry (:class:`SensorSetup`),
never the ground truth. Timing, metrics and files belong to the pipeline that drives it
(:mod:`estimators.evaluation.scoring`, :mod:`estimators.leaderboard.cli`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.health import MIN_RETURNS, Health, Observations, ScanScreen, moved
from lidar_env.core import EstimatorInputError, ResetNeededError, check_time

#: Observation keys ``lidar_1 .. lidar_8``; sensor ``k`` of a setup reads ``LIDAR_KEYS[k]``.
LIDAR_KEYS: tuple[str, ...] = tuple(f"lidar_{k}" for k in range(1, 9))

#: Most Lidars a :class:`SensorSetup` (and the env) carries.
MAX_LIDARS: int = len(LIDAR_KEYS)
#: Relative gap of ``n * angle_increment`` to 2 pi below which a LaserScan's beams make one full
#: turn (float32 keeps about 7 digits).
FULL_TURN_TOLERANCE = 1e-6


def default_beam_angles(n_beams: int) -> NDArray[np.float64]:
    """Beam ``i`` points at ``2 pi i / n`` [rad], CCW from the sensor's forward axis."""
    return 2.0 * np.pi * np.arange(n_beams) / n_beams


@dataclass(frozen=True, eq=False)
class Sensor:
    """One planar Lidar as an estimator knows it, and as a ROS ``sensor_msgs/LaserScan``
    describes it (:attr:`angle_min`, :attr:`angle_increment`, :attr:`range_min`,
    :attr:`range_max`, :attr:`frame`).

    Attributes:
        mount: ``(3,)`` pose in the car frame (x [m] forward, y [m] left, heading [rad]).
        beam_angles: ``(n,)`` beam directions [rad] in the sensor frame, CCW from forward.
        max_range: [m]; readings ``>= max_range`` (or non-finite) are "no return".
        index: position in the setup (0 for ``lidar_1``), used to name it in errors.
        range_min: [m] readings below it are invalid (the env and the bag reader report them
            as ``max_range``), in ``[0, max_range)``.
        frame: the sensor's frame name (``header.frame_id``); empty: ``lidar_<index + 1>``.
    """

    mount: NDArray[np.float64]
    beam_angles: NDArray[np.float64]
    max_range: float
    index: int = 0
    range_min: float = 0.0
    frame: str = ""

    def __post_init__(self) -> None:
        name = f"sensor {self.index} ({LIDAR_KEYS[self.index]})" if (
            0 <= self.index < MAX_LIDARS) else f"sensor {self.index}"
        mount = np.asarray(self.mount, dtype=np.float64)
        if mount.shape != (3,) or not np.all(np.isfinite(mount)):
            raise EstimatorInputError(
                f"mount of {name}: expected 3 finite numbers (x [m], y [m], heading [rad]), "
                f"got {np.asarray(self.mount).tolist()!r}")
        angles = np.asarray(self.beam_angles, dtype=np.float64)
        if angles.ndim != 1 or len(angles) < 3:
            raise EstimatorInputError(
                f"beam_angles of {name}: expected a 1-D array of >= 3 angles [rad], "
                f"got shape {angles.shape}")
        if not np.all(np.isfinite(angles)):
            bad = int(np.argmin(np.isfinite(angles)))
            raise EstimatorInputError(f"beam_angles of {name}: expected finite angles [rad], "
                                      f"got {angles[bad]} at beam {bad}")
        max_range = self.max_range
        if isinstance(max_range, bool) or not isinstance(max_range, (int, float, np.number)) or (
                not np.isfinite(max_range) or max_range <= 0):
            raise EstimatorInputError(
                f"max_range of {name}: expected a positive finite number [m], got {max_range!r}")
        low = self.range_min
        if isinstance(low, bool) or not isinstance(low, (int, float, np.number)) or (
                not np.isfinite(low) or not 0 <= low < max_range):
            raise EstimatorInputError(
                f"range_min of {name}: expected a number in [0, max_range) = [0, {max_range:g}) "
                f"[m], got {low!r}")
        if not isinstance(self.frame, str):
            raise EstimatorInputError(f"frame of {name}: expected a frame name, got "
                                      f"{type(self.frame).__name__}")
        object.__setattr__(self, "mount", mount)
        object.__setattr__(self, "beam_angles", angles)
        object.__setattr__(self, "max_range", float(max_range))
        object.__setattr__(self, "range_min", float(low))
        object.__setattr__(self, "frame", self.frame or f"lidar_{self.index + 1}")

    @classmethod
    def from_laser_scan(cls, mount: ArrayLike, angle_min: float, angle_increment: float,
                        n_beams: int, range_min: float, range_max: float, frame: str = "",
                        index: int = 0) -> Sensor:
        """The sensor of a ``sensor_msgs/LaserScan`` header: beam ``i`` at ``angle_min + i
        angle_increment`` [rad] (one full turn of beams gets the exact ``2 pi i / n`` steps),
        ``range_min`` .. ``range_max`` [m], ``frame`` its ``frame_id``, at ``mount``."""
        for what, value in (("angle_min", angle_min), ("angle_increment", angle_increment)):
            if not np.isfinite(value):
                raise EstimatorInputError(f"{what}: expected a finite angle [rad], got {value}")
        if angle_increment == 0 or n_beams < 3:
            raise EstimatorInputError(f"LaserScan: expected >= 3 beams a non-zero "
                                      f"angle_increment apart, got {n_beams} beams of "
                                      f"{angle_increment}")
        if abs(n_beams * angle_increment - 2 * np.pi) <= FULL_TURN_TOLERANCE * 2 * np.pi:
            angles = float(angle_min) + default_beam_angles(n_beams)
        else:
            angles = float(angle_min) + float(angle_increment) * np.arange(n_beams)
        return cls(mount, angles, range_max, index, range_min, frame)

    @property
    def angle_min(self) -> float:
        """[rad] direction of beam 0 (the LaserScan's ``angle_min``)."""
        return float(self.beam_angles[0])

    @property
    def angle_increment(self) -> float:
        """[rad] mean step between beams (the LaserScan's ``angle_increment``)."""
        return float((self.beam_angles[-1] - self.beam_angles[0]) / (self.n_beams - 1))

    @property
    def range_max(self) -> float:
        """[m] the LaserScan's ``range_max``: :attr:`max_range`."""
        return self.max_range

    @property
    def n_beams(self) -> int:
        return len(self.beam_angles)


@dataclass(frozen=True, init=False, eq=False)
class SensorSetup:
    """What an estimator may know about the sensors: K Lidars (1..8), each with its own mount,
    beam geometry and max range.

    Build it either from sensors, ``SensorSetup(sensors=(Sensor(mount, angles, max_range),
    ...))``, or, when every Lidar shares one beam geometry (the env's default and a CARMEN
    log), from bare arrays: ``SensorSetup(mounts (K, 3), beam_angles (n,), max_range)``.

    Attributes:
        sensors: one :class:`Sensor` per Lidar; sensor ``k`` reads observation key
            ``LIDAR_KEYS[k]``.
        world_aligned: scans are rotated into world orientation (the paper's simplification:
            heading is then known and only translation is estimated).
    """

    sensors: tuple[Sensor, ...]
    world_aligned: bool

    def __init__(
        self,
        mounts: ArrayLike | None = None,
        beam_angles: ArrayLike | None = None,
        max_range: float | None = None,
        world_aligned: bool = False,
        *,
        sensors: Sequence[Sensor] | None = None,
    ) -> None:
        if sensors is None:
            sensors = _uniform_sensors(mounts, beam_angles, max_range)
        elif mounts is not None or beam_angles is not None or max_range is not None:
            raise EstimatorInputError(
                "SensorSetup: expected either sensors= or (mounts, beam_angles, max_range), "
                "got both")
        sensors = tuple(sensors)
        if not 1 <= len(sensors) <= MAX_LIDARS:
            raise EstimatorInputError(
                f"sensors: expected 1 to {MAX_LIDARS} Lidars, got {len(sensors)}")
        checked = []
        for k, sensor in enumerate(sensors):
            if not isinstance(sensor, Sensor):
                raise EstimatorInputError(
                    f"sensors[{k}]: expected a Sensor, got {type(sensor).__name__}")
            checked.append(sensor if sensor.index == k else Sensor(
                sensor.mount, sensor.beam_angles, sensor.max_range, k, sensor.range_min,
                sensor.frame if sensor.frame != f"lidar_{sensor.index + 1}" else ""))
        object.__setattr__(self, "sensors", tuple(checked))
        object.__setattr__(self, "world_aligned", bool(world_aligned))
        object.__setattr__(self, "_mounts", np.stack([s.mount for s in checked]))

    @property
    def n_lidars(self) -> int:
        return len(self.sensors)

    @property
    def keys(self) -> tuple[str, ...]:
        return LIDAR_KEYS[: self.n_lidars]

    @property
    def mounts(self) -> NDArray[np.float64]:
        """``(K, 3)`` pose of each Lidar in the car frame; row ``k`` reads ``keys[k]``."""
        return self._mounts.copy()

    @property
    def uniform(self) -> bool:
        """Every Lidar has the same beam angles and max range."""
        first = self.sensors[0]
        return all(s.max_range == first.max_range and np.array_equal(s.beam_angles,
                                                                     first.beam_angles)
                   for s in self.sensors[1:])

    @property
    def beam_angles(self) -> NDArray[np.float64]:
        """``(n,)`` beam directions [rad] shared by every Lidar (an error if they differ)."""
        self._require_uniform("beam_angles")
        return self.sensors[0].beam_angles

    @property
    def max_range(self) -> float:
        """[m] shared by every Lidar (an error if they differ)."""
        self._require_uniform("max_range")
        return self.sensors[0].max_range

    def _require_uniform(self, name: str) -> None:
        if not self.uniform:
            raise EstimatorInputError(
                f"setup.{name}: the {self.n_lidars} Lidars differ in beam geometry; "
                f"expected per-sensor access, setup.sensors[k].{name}")

    @classmethod
    def from_env(cls, env: Any) -> SensorSetup:
        """Read the sensor geometry of a ``DualLidar-v0`` env (wrapped or not)."""
        config = env.unwrapped.config
        sensors = [Sensor(lidar.mount, lidar.beam_angles, lidar.max_range, k, lidar.min_range)
                   for k, lidar in enumerate(config.lidars)]
        return cls(sensors=sensors, world_aligned=config.scan_frame == "world")

    def check_observation(self, observation: Mapping[str, Any]) -> dict[str, NDArray[np.float64]]:
        """Validate the scans of one observation; return them as float64 arrays.

        Non-finite readings are a readable error, not a silent NaN in the estimate.
        """
        scans: dict[str, NDArray[np.float64]] = {}
        for key, sensor in zip(self.keys, self.sensors, strict=True):
            if not isinstance(observation, Mapping) or key not in observation:
                raise EstimatorInputError(
                    f"observation lacks {key!r}: expected a mapping with keys "
                    f"{', '.join(self.keys)}, got {type(observation).__name__}")
            try:
                scan = np.asarray(observation[key], dtype=np.float64)
            except (TypeError, ValueError) as error:
                raise EstimatorInputError(
                    f"{key}: expected an array of ranges [m], got {observation[key]!r:.60}"
                ) from error
            if scan.shape != sensor.beam_angles.shape:
                raise EstimatorInputError(
                    f"{key}: expected a scan of shape {sensor.beam_angles.shape}, got {scan.shape}"
                )
            if scan.size and not 0.0 <= scan.min() <= scan.max() < np.inf:  # NaN fails both
                if not np.all(np.isfinite(scan)):
                    raise EstimatorInputError(
                        f"{key}: scan holds NaN or inf; expected finite ranges [m]")
                raise EstimatorInputError(
                    f"{key}: scan holds negative ranges; expected ranges >= 0 [m]")
            scans[key] = scan
        return scans


def _uniform_sensors(
    mounts: ArrayLike | None, beam_angles: ArrayLike | None, max_range: float | None
) -> tuple[Sensor, ...]:
    """One :class:`Sensor` per row of ``mounts`` (K, 3), all with the same beams and range."""
    if mounts is None or beam_angles is None or max_range is None:
        raise EstimatorInputError(
            "SensorSetup: expected sensors= or all of mounts, beam_angles, max_range")
    rows = np.atleast_2d(np.asarray(mounts, dtype=np.float64))
    if rows.ndim != 2 or rows.shape[1] != 3 or not 1 <= len(rows) <= MAX_LIDARS:
        raise EstimatorInputError(
            f"mounts: expected shape (K, 3) with K in 1..{MAX_LIDARS}, got {rows.shape}")
    return tuple(Sensor(row, beam_angles, max_range, k) for k, row in enumerate(rows))


@dataclass
class Estimator(ABC):
    """Base class: ``reset(setup, initial_pose)``, then ``update(observation, t) -> pose``.

    ``trajectory[k]`` is the estimated car pose (x [m], y [m], heading [rad]) at the k-th
    observation; the first observation gets ``initial_pose``. Subclasses implement
    :meth:`_start` (first scans) and :meth:`_step` (every later scans, returning the new pose).

    Every later observation passes a screen first (:mod:`estimators.health`): a sensor whose
    scan repeats its last one exactly while another's changed (frozen) reads no return (0 m),
    and an observation left with too few returns on the sensors the estimator reads
    (:meth:`_used_sensors`) is skipped: :meth:`_step` never sees it, and its pose is the
    constant-velocity prediction from the last used ones (the last used increment per
    observation, scaled by the time step over the median one, at most twice). ``health``
    counts what the screen met (skipped and frozen scans, clock jumps, blind stretches).
    Inside :meth:`_step`, ``pose``, ``_poses`` and ``_times`` are those of the observations
    the estimator used, ``skipped_before`` the number skipped since the last of them and
    ``clock_jumped`` whether the time step before this observation is a clock jump (or scans
    lost on the way).
    """

    #: Lidars the estimator needs; a pipeline skips it (no failure) on a setup with fewer.
    min_lidars: ClassVar[int] = 1
    #: Returns an observation needs on the sensors read to be used (``estimators.health``).
    min_returns: ClassVar[int] = MIN_RETURNS
    setup: SensorSetup | None = field(default=None, init=False, repr=False)
    _poses: list[NDArray[np.float64]] = field(default_factory=list, init=False, repr=False)
    _times: list[float] = field(default_factory=list, init=False, repr=False)
    health: Health = field(default_factory=Health, init=False, repr=False)

    def reset(
        self, setup: SensorSetup | ArrayLike, initial_pose: ArrayLike = (0.0, 0.0, 0.0)
    ) -> None:
        """Start a new trajectory. ``setup`` may be a :class:`SensorSetup` or bare mounts (K, 3)
        (then 360 beams over 360 degrees and a 10 m max range are assumed)."""
        if not isinstance(setup, SensorSetup):
            setup = SensorSetup(np.asarray(setup, dtype=np.float64), default_beam_angles(360), 10.0)
        pose = np.asarray(initial_pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise EstimatorInputError(
                f"initial_pose: expected 3 finite numbers (x, y, heading), got {pose}")
        self.setup = setup
        self._poses = []
        self._times = []
        self._initial_pose = pose.copy()
        self._observations = Observations()
        self._screen = ScanScreen([sensor.max_range for sensor in setup.sensors],
                                  self._used_sensors(setup), self.min_returns)
        self.health = self._screen.health
        self.skipped_before = 0
        self.clock_jumped = False
        self._stepping = False
        self._reset_state()

    def update(self, observation: Mapping[str, Any], t: float) -> NDArray[np.float64]:
        """Feed the scans taken at time ``t`` [s]; return the car pose estimate (3,)."""
        if self.setup is None:
            raise ResetNeededError("call reset(setup, initial_pose) before update()")
        last = self._observations.last_time
        t = check_time(t, last)
        scans = self.setup.check_observation(observation)
        index = len(self._observations)
        self.clock_jumped = last is not None and self._screen.watch_clock(index, t - last)
        screened, usable = self._screen.screen([scans[key] for key in self.setup.keys],
                                               moved(self._poses))
        scans = dict(zip(self.setup.keys, screened, strict=True))
        if self._poses and not usable:
            self._screen.skip(index)
            self._skip(scans, t)
            return self._observations.skip(self._poses, t, hold=self._screen.all_frozen)
        self.skipped_before = self._screen.used_one()
        self._stepping = True
        try:
            if not self._poses:
                self._start(scans, t)
                pose = self._initial_pose.copy()
            else:
                pose = np.asarray(self._step(scans, t), dtype=np.float64)
        finally:
            self._stepping = False
        self._poses.append(pose)
        self._times.append(float(t))
        self._observations.use(len(self._poses) - 1, t)
        return pose.copy()

    def _used_sensors(self, setup: SensorSetup) -> list[int]:
        """Indices of the sensors this estimator reads (all; one for a single-Lidar method)."""
        return list(range(setup.n_lidars))

    @property
    def trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` estimated car poses, one per observation so far."""
        return self._observations.all_poses(np.array(self._poses, dtype=np.float64).reshape(-1, 3))

    @property
    def times(self) -> NDArray[np.float64]:
        """``(N,)`` observation times [s]."""
        return self._observations.times

    @property
    def pose(self) -> NDArray[np.float64]:
        """The latest pose estimate (3,) (inside :meth:`_step`: the last used one's)."""
        if not self._poses:
            return self._initial_pose.copy()
        return self._poses[-1].copy() if self._stepping else self._observations.latest(self._poses)

    def _reset_state(self) -> None:  # noqa: B027 - optional hook, empty by design
        """Clear per-trajectory state (override when there is some)."""

    def _skip(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:  # noqa: B027
        """Hook: the screened scans of an observation at ``t`` [s] skipped as unusable (an
        estimator built on another passes them on, so its inner one counts the stretch)."""

    @abstractmethod
    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        """Take the first scans (keyed by ``setup.keys``)."""

    @abstractmethod
    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> ArrayLike:
        """Take the next scans; return the new car pose in the trajectory's frame."""
