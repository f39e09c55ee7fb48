"""One typed, validated configuration for ``DualLidar-v0``.

Units are in the field comments. ``EnvConfig.from_dict`` and ``EnvConfig.replace`` reject
unknown keys by name, so a typo never silently falls back to a default. Their key ``robot``
starts from a robot preset (:mod:`lidar_env.vehicle.presets`: the paper's car, TurtleBot3
Burger and Waffle Pi, an F1TENTH-class car), the other keys applied over it. Each Lidar carries its
own range noise and dropout; :func:`lidars_with_noise` gives a layout (the default one or a
config's) with the same noise on every Lidar.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lidar_env.core.errors import ConfigError
from lidar_env.movers import MOVER_MODELS
from lidar_env.sensors.lidar_config import LidarConfig, check_lidars
from lidar_env.vehicle.presets import ROBOT_NAMES, robot_preset

#: Valid values of :attr:`EnvConfig.scan_frame`.
SCAN_FRAMES: tuple[str, ...] = ("sensor", "world")


#: Most moving obstacles an env may hold (each costs a little per step and per beam).
MAX_MOVERS = 256
#: [m/s] fastest mover speed accepted: a sprinting person (the car's collision checks are
#: spaced for the fastest mover, so a runaway speed would need millions of them).
MAX_MOVER_SPEED = 10.0

#: Keys of earlier versions, now set per Lidar in ``lidars``.
MOVED_TO_LIDARS: tuple[str, ...] = ("lidar_mounts", "n_beams", "max_range")
#: Keys of earlier versions that set every Lidar's noise, now set per Lidar too.
NOISE_KEYS: tuple[str, ...] = ("range_noise_std", "dropout_prob")
#: The key of :meth:`EnvConfig.from_dict` and :meth:`EnvConfig.replace` that applies a preset.
ROBOT_KEY = "robot"
#: [m] half-diagonal of the paper's 0.8 x 0.5 m car: the body scale 1.
PAPER_HALF_DIAGONAL = 0.5 * math.hypot(0.8, 0.5)
#: [m] free space kept beyond the half-diagonal along a trace, at body scale 1.
TRACE_MARGIN = 0.3


def _default_lidars() -> tuple[LidarConfig, ...]:
    """The paper's two 360-degree Lidars, 0.5 m apart on the car's axis."""
    return (LidarConfig((0.25, 0.0, 0.0)), LidarConfig((-0.25, 0.0, 0.0), where="lidars[1]"))


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
          ``lidars`` holds 1 to 8 Lidars, each a
          :class:`~lidar_env.sensors.lidar_config.LidarConfig` or a dict ``{"mount": (x, y,
          heading), "n_beams", "fov", "max_range", "range_noise_std", "dropout_prob"}``; mounts lie
          within the car's half-diagonal.
        * each Lidar's ``range_noise_std`` 0.01 m (the typical 1 sigma of a cheap time-of-flight
          Lidar) and ``dropout_prob`` 0 are its own; :func:`lidars_with_noise` sets them on
          every Lidar of a layout at once.
        * ``moving_obstacles`` 0: no movers, so every result without them stays as it was. Movers
          (:mod:`lidar_env.movers.crowd`) are pedestrians: circles of ``mover_radius`` 0.25 m (a
          person's shoulders) walking at a speed drawn from ``mover_speed_range`` 0.5-1.5 m/s
          (slow to brisk walking), placed at least ``mover_clearance`` 1 m from the car.
        * ``mover_model`` "yielding": movers keep clear of the car's box where it stands, like
          real pedestrians (they never walk into it; a car that drives on can still hit them);
          "waypoints" movers ignore the car and walk into it even where it stands still, the
          harder crowd.
        * ``trace_margin`` None: 0.3 m x :attr:`body_scale`, so a smaller robot keeps a
          proportionally smaller margin (0.3 m on the paper's car, 0.07 m on a TurtleBot3
          Burger). Start clearance, corner radii of waypoint routes and the default trace's
          length in a user world scale with the body the same way.

    ``from_dict({"robot": name, ...})`` and ``replace(robot=name, ...)`` take a robot
    preset's body, speed limits, control period and Lidars first
    (:data:`lidar_env.vehicle.presets.ROBOTS`), then the other keys.
    """

    control_dt: float = 0.1  # [s] time between two actions (and two scans)
    physics_substeps: int = 4  # [-] collision checks per control step
    max_speed: float = 1.5  # [m/s] action[0] = +-1 maps to +-max_speed (reverse allowed)
    max_yaw_rate: float = 1.5  # [rad/s] action[1] = +-1 maps to +-max_yaw_rate (CCW positive)
    car_length: float = 0.8  # [m] along the car's x (forward) axis
    car_width: float = 0.5  # [m] along the car's y (left) axis
    # lidar_1 .. lidar_K: mount (x [m] forward, y [m] left, heading [rad]), beams, fov, range
    lidars: tuple[LidarConfig, ...] = field(default_factory=_default_lidars)
    scan_frame: str = "sensor"  # "sensor": beam 0 along the sensor's forward axis; "world": +x
    max_episode_time: float = 120.0  # [s] truncation time limit
    collision_penalty: float = 10.0  # [-] subtracted from the reward on the colliding step
    cross_track_penalty: float = 0.1  # [1/s] reward -= this * |cross-track error [m]| * dt
    goal_tolerance: float = 0.3  # [m] the trace is done within this arc length of its end
    trace_margin: float | None = None  # [m] beyond the half-diagonal along a trace (None: scaled)
    map_resolution: float = 0.05  # [m/px] pixel size of a world given as an array or image
    moving_obstacles: int = 0  # [-] pedestrians walking through the world (0 to MAX_MOVERS)
    mover_radius: float = 0.25  # [m] radius of each moving circle
    mover_speed_range: tuple[float, float] = (0.5, 1.5)  # [m/s] (min, max) of a mover's speed
    mover_clearance: float = 1.0  # [m] least gap between a mover and the car's box at reset
    mover_model: str = "yielding"  # "yielding": movers avoid the car; "waypoints": they ignore it
    render_size: int = 800  # [px] longest side of a rendered frame (16 to 8192)

    def __post_init__(self) -> None:
        positive = {
            "control_dt": self.control_dt,
            "max_speed": self.max_speed,
            "max_yaw_rate": self.max_yaw_rate,
            "car_length": self.car_length,
            "car_width": self.car_width,
            "max_episode_time": self.max_episode_time,
            "goal_tolerance": self.goal_tolerance,
            "map_resolution": self.map_resolution,
            "mover_radius": self.mover_radius,
        }
        for name, value in positive.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ConfigError(f"{name}: expected a positive finite number, got {value!r}")
        non_negative = {
            "collision_penalty": self.collision_penalty,
            "cross_track_penalty": self.cross_track_penalty,
            "trace_margin": 0.0 if self.trace_margin is None else self.trace_margin,
            "mover_clearance": self.mover_clearance,
        }
        for name, value in non_negative.items():
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ConfigError(f"{name}: expected a finite number >= 0, got {value!r}")
        for name, value, low in (("physics_substeps", self.physics_substeps, 1),):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ConfigError(f"{name}: expected an integer >= {low}, got {value!r}")
        size = self.render_size
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) \
                or not 16 <= size <= 8192:
            raise ConfigError(f"render_size: expected an integer in [16, 8192] pixels, got "
                              f"{size!r:.40}")
        if self.scan_frame not in SCAN_FRAMES:
            raise ConfigError(
                f"scan_frame: expected one of {', '.join(SCAN_FRAMES)}, got {self.scan_frame!r}"
            )
        movers = self.moving_obstacles
        if (isinstance(movers, bool) or not isinstance(movers, (int, np.integer))
                or not 0 <= movers <= MAX_MOVERS):
            raise ConfigError(f"moving_obstacles: expected an integer in [0, {MAX_MOVERS}], "
                              f"got {movers!r}")
        if not isinstance(self.mover_model, str) or self.mover_model not in MOVER_MODELS:
            raise ConfigError(f"mover_model: expected one of {', '.join(MOVER_MODELS)}, got "
                              f"{self.mover_model!r}")
        derived = self.trace_margin is None
        object.__setattr__(self, "_margin_derived", derived)
        if derived:
            object.__setattr__(self, "trace_margin", TRACE_MARGIN * self.body_scale)
        object.__setattr__(self, "mover_speed_range", _speed_range(self.mover_speed_range))
        object.__setattr__(self, "lidars", check_lidars(self.lidars, self.car_half_diagonal))
        object.__setattr__(self, "physics_substeps", int(self.physics_substeps))
        object.__setattr__(self, "moving_obstacles", int(movers))

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """Names of all settable fields."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_dict(cls, mapping: Mapping[str, Any] | None) -> EnvConfig:
        """Build a config from ``mapping`` (missing keys take their defaults, or the preset's
        with a ``robot`` key)."""
        return cls().replace(**dict(mapping or {}))

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with ``changes`` applied; an unknown key raises ``ConfigError`` naming them.

        ``robot=name`` applies that preset's values first; a ``trace_margin`` that was derived
        from the body is derived again from the new one."""
        moved = sorted(set(changes) & set(MOVED_TO_LIDARS))
        if moved:
            raise ConfigError(
                f"config key(s) {', '.join(map(repr, moved))} moved into 'lidars': expected "
                "config={'lidars': [{'mount': (x, y, heading), 'n_beams': 360, 'fov': 2 pi, "
                "'max_range': 10.0}, ...]}, one dict per Lidar")
        noise = sorted(set(changes) & set(NOISE_KEYS))
        if noise:
            per_lidar = " and ".join(f"config['lidars'][k][{key!r}]" for key in noise)
            keywords = ", ".join(f"{key}=..." for key in noise)
            raise ConfigError(
                f"config key(s) {', '.join(map(repr, noise))} moved into 'lidars': expected "
                f"{per_lidar} per Lidar, or the same on every Lidar with config={{'lidars': "
                f"lidar_env.lidars_with_noise(config, {keywords})}} (config: the rest of yours, "
                "or None for the default two Lidars)")
        unknown = sorted(set(changes) - set(self.keys()) - {ROBOT_KEY})
        if unknown:
            raise ConfigError(
                f"unknown config key(s) {', '.join(map(repr, unknown))}: expected some of "
                f"{ROBOT_KEY} ({', '.join(ROBOT_NAMES)}), {', '.join(self.keys())}"
            )
        if ROBOT_KEY in changes:
            changes = {**robot_preset(changes.pop(ROBOT_KEY)).changes(), **changes}
        if getattr(self, "_margin_derived", False) and "trace_margin" not in changes:
            changes["trace_margin"] = None
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The config as a plain dict (round-trips through :meth:`from_dict`)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {**fields, "lidars": [lidar.to_dict() for lidar in self.lidars],
                "mover_speed_range": list(self.mover_speed_range)}

    @property
    def n_lidars(self) -> int:
        return len(self.lidars)

    @property
    def mounts_array(self) -> np.ndarray:
        """``(K, 3)`` float64 Lidar mounts in the car frame, row ``k`` for ``lidar_{k+1}``."""
        return np.array([lidar.mount for lidar in self.lidars], dtype=np.float64)

    @property
    def lidar_mounts(self) -> tuple[tuple[float, float, float], ...]:
        """The mounts of :attr:`mounts_array` as tuples."""
        return tuple(lidar.mount for lidar in self.lidars)

    @property
    def n_beams(self) -> int:
        """Beams per scan shared by every Lidar (a ``ConfigError`` if they differ)."""
        return self._shared("n_beams")

    @property
    def max_range(self) -> float:
        """[m] shared by every Lidar (a ``ConfigError`` if they differ)."""
        return self._shared("max_range")

    def _shared(self, name: str) -> Any:
        values = {getattr(lidar, name) for lidar in self.lidars}
        if len(values) != 1:
            raise ConfigError(f"config.{name}: the Lidars differ ({sorted(values)}); "
                              f"expected per-Lidar access, config.lidars[k].{name}")
        return values.pop()

    @property
    def body_scale(self) -> float:
        """[-] the car's half-diagonal over the paper car's (1 for the default car): what
        margins, corner radii and trace lengths are scaled by."""
        return self.car_half_diagonal / PAPER_HALF_DIAGONAL

    @property
    def car_half_diagonal(self) -> float:
        """[m] radius of the circle around the car's centre that holds the whole car body."""
        return 0.5 * math.hypot(self.car_length, self.car_width)

    @property
    def trace_clearance(self) -> float:
        """[m] clearance every trace waypoint keeps from obstacles: half-diagonal + margin."""
        return self.car_half_diagonal + self.trace_margin


def lidars_with_noise(
    config: EnvConfig | Mapping[str, Any] | None = None,
    *,
    range_noise_std: float | None = None,
    dropout_prob: float | None = None,
) -> list[dict[str, Any]]:
    """The Lidars of ``config`` (None: the default two) with the same noise on every one.

    Args:
        config: an :class:`EnvConfig` or a dict of its fields; only its ``lidars`` are used
            (the default layout where it sets none).
        range_noise_std: [m] std of the Gaussian noise on each hit, >= 0; None keeps each
            Lidar's own (0.01 m unless set).
        dropout_prob: probability in [0, 1) that a beam reads ``max_range``; None keeps each
            Lidar's own (0 unless set).

    Returns:
        A new ``lidars`` list, one dict of :class:`~lidar_env.sensors.lidar_config.LidarConfig`'s
        fields per Lidar, in ``config``'s order.

    Example (every default Lidar noiseless, world-aligned scans)::

        config = {"scan_frame": "world", "lidars": lidars_with_noise(range_noise_std=0.0)}
        env = gym.make("DualLidar-v0", config=config)
    """
    if isinstance(config, EnvConfig):
        lidars = config.lidars
    elif config is None or isinstance(config, Mapping):
        lidars = EnvConfig.from_dict(config).lidars
    else:
        raise ConfigError(f"config: expected an EnvConfig, a dict or None, "
                          f"got {type(config).__name__}")
    noise = {"range_noise_std": range_noise_std, "dropout_prob": dropout_prob}
    changes = {name: value for name, value in noise.items() if value is not None}
    return [dataclasses.replace(lidar, **changes).to_dict() for lidar in lidars]


def _speed_range(value: Any) -> tuple[float, float]:
    """``value`` as (min, max) [m/s] with 0 <= min <= max <= :data:`MAX_MOVER_SPEED`."""
    expected = (f"mover_speed_range: expected (min, max) [m/s] with 0 <= min <= max <= "
                f"{MAX_MOVER_SPEED:g}")
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ConfigError(f"{expected}, got {value!r}")
    numbers = []
    for v in value:
        numeric = not isinstance(v, bool) and isinstance(v, (int, float, np.number))
        if not numeric or not math.isfinite(v):
            raise ConfigError(f"{expected}, got {value!r}")
        numbers.append(float(v))
    low, high = numbers
    if low < 0 or low > high or high > MAX_MOVER_SPEED:
        raise ConfigError(f"{expected}, got min {low:g} and max {high:g}")
    return low, high
