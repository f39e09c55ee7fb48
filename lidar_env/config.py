"""One typed, validated configuration for ``DualLidar-v0``.

Units are in the field comments. ``EnvConfig.from_dict`` and ``EnvConfig.replace`` reject
unknown keys by name, so a typo never silently falls back to a default.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Valid values of :attr:`EnvConfig.scan_frame`.
SCAN_FRAMES: tuple[str, ...] = ("sensor", "world")


def _default_mounts() -> tuple[tuple[float, float, float], ...]:
    return ((0.25, 0.0, 0.0), (-0.25, 0.0, 0.0))


@dataclass(frozen=True)
class EnvConfig:
    """Physical and episode parameters of the env (frozen; build a changed copy with ``replace``).

    Defaults and why:
        * ``control_dt`` 0.1 s: one control step per scan of a 10 Hz Lidar, the usual rate of
          planar Lidars.
        * ``physics_substeps`` 4: the car moves at most ``max_speed * control_dt / 4`` = 3.75 cm
          between collision checks, far less than the thinnest wall, so it cannot tunnel.
        * ``max_speed`` 1.5 m/s and ``max_yaw_rate`` 1.5 rad/s: a small indoor robot car; the
          tightest turn at full speed has a 1 m radius.
        * car 0.8 m x 0.5 m with the two Lidars 0.5 m apart on its axis (the paper's "unchangeable
          offset"), 360 beams over 360 degrees and 10 m range (the paper's 360 readings per round).
        * ``range_noise_std`` 0.01 m: the typical 1 sigma of a cheap time-of-flight Lidar.
    """

    control_dt: float = 0.1  # [s] time between two actions (and two scans)
    physics_substeps: int = 4  # [-] collision checks per control step
    max_speed: float = 1.5  # [m/s] action[0] = +-1 maps to +-max_speed (reverse allowed)
    max_yaw_rate: float = 1.5  # [rad/s] action[1] = +-1 maps to +-max_yaw_rate (CCW positive)
    car_length: float = 0.8  # [m] along the car's x (forward) axis
    car_width: float = 0.5  # [m] along the car's y (left) axis
    # (2, 3) pose of lidar_1 and lidar_2 in the car frame: x [m] forward, y [m] left, heading [rad]
    lidar_mounts: tuple[tuple[float, float, float], ...] = field(default_factory=_default_mounts)
    n_beams: int = 360  # [-] beams per scan, evenly spread over 360 degrees
    max_range: float = 10.0  # [m] a beam that hits nothing reads exactly max_range
    range_noise_std: float = 0.01  # [m] std of the Gaussian noise added to each hit
    dropout_prob: float = 0.0  # [-] probability that a beam reads max_range regardless
    scan_frame: str = "sensor"  # "sensor": beam 0 along the sensor's forward axis; "world": +x
    max_episode_time: float = 120.0  # [s] truncation time limit
    collision_penalty: float = 10.0  # [-] subtracted from the reward on the colliding step
    cross_track_penalty: float = 0.1  # [1/s] reward -= this * |cross-track error [m]| * dt
    goal_tolerance: float = 0.3  # [m] the trace is done within this arc length of its end
    trace_margin: float = 0.3  # [m] free space kept beyond the car's half-diagonal along a trace

    def __post_init__(self) -> None:
        positive = {
            "control_dt": self.control_dt,
            "max_speed": self.max_speed,
            "max_yaw_rate": self.max_yaw_rate,
            "car_length": self.car_length,
            "car_width": self.car_width,
            "max_range": self.max_range,
            "max_episode_time": self.max_episode_time,
            "goal_tolerance": self.goal_tolerance,
        }
        for name, value in positive.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name}: expected a positive finite number, got {value!r}")
        non_negative = {
            "range_noise_std": self.range_noise_std,
            "collision_penalty": self.collision_penalty,
            "cross_track_penalty": self.cross_track_penalty,
            "trace_margin": self.trace_margin,
        }
        for name, value in non_negative.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
        for name, value, low in (("physics_substeps", self.physics_substeps, 1),
                                 ("n_beams", self.n_beams, 3)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")
        if not isinstance(self.dropout_prob, (int, float)) or not 0 <= self.dropout_prob < 1:
            raise ValueError(
                f"dropout_prob: expected a number in [0, 1), got {self.dropout_prob!r}"
            )
        if self.scan_frame not in SCAN_FRAMES:
            raise ValueError(
                f"scan_frame: expected one of {', '.join(SCAN_FRAMES)}, got {self.scan_frame!r}"
            )
        mounts = np.asarray(self.lidar_mounts, dtype=np.float64)
        if mounts.shape != (2, 3) or not np.all(np.isfinite(mounts)):
            raise ValueError(
                f"lidar_mounts: expected (2, 3) finite car-frame poses (x, y, heading), "
                f"got shape {mounts.shape}"
            )
        object.__setattr__(self, "lidar_mounts", tuple(tuple(float(v) for v in m) for m in mounts))
        for name in ("physics_substeps", "n_beams"):
            object.__setattr__(self, name, int(getattr(self, name)))

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Names of all settable fields."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_dict(cls, mapping: Mapping[str, Any] | None) -> EnvConfig:
        """Build a config from ``mapping`` (missing keys take their defaults)."""
        return cls().replace(**dict(mapping or {}))

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with ``changes`` applied; an unknown key raises ``ValueError`` naming all keys."""
        unknown = sorted(set(changes) - set(self.keys()))
        if unknown:
            raise ValueError(
                f"unknown config key(s) {', '.join(map(repr, unknown))}: expected some of "
                f"{', '.join(self.keys())}"
            )
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The config as a plain dict (round-trips through :meth:`from_dict`)."""
        return dataclasses.asdict(self)

    @property
    def mounts_array(self) -> np.ndarray:
        """``(2, 3)`` float64 Lidar mounts in the car frame."""
        return np.asarray(self.lidar_mounts, dtype=np.float64)

    @property
    def car_half_diagonal(self) -> float:
        """[m] radius of the circle around the car's centre that holds the whole car body."""
        return 0.5 * math.hypot(self.car_length, self.car_width)

    @property
    def trace_clearance(self) -> float:
        """[m] clearance every trace waypoint keeps from obstacles: half-diagonal + margin."""
        return self.car_half_diagonal + self.trace_margin
