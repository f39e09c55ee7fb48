"""Robot presets: real robots' bodies, speed limits and Lidars, from their makers' spec sheets.

``EnvConfig.from_dict({"robot": "turtlebot3_burger", "max_speed": 0.1})`` starts from a
preset and applies the other keys over it, so any value of a preset can be overridden. Each
preset sets the body (``car_length`` x ``car_width`` [m], the footprint's bounding box), the
speed and yaw-rate limits, the control period (one step per Lidar scan, at the Lidar's scan
rate) and the Lidars (mount, beams, field of view, ``min_range`` .. ``max_range``, noise).
The spec table with the sources is ``docs/robots.md``; a test checks every preset against it.

Modelling choices shared by the presets:

* The car frame's origin is the centre of the footprint's bounding box, and the robot turns
  about it (the env's unicycle model). TurtleBot3's LDS sits at the centre of its base's box,
  so its mount is (0, 0, 0).
* Range noise is Gaussian with one standard deviation for every range: the spec's accuracy
  bound taken as 1 sigma (LDS-01: +-15 mm, the bound below 0.5 m; its +-5 % beyond 0.5 m is
  not modelled; UST-10LX: +-40 mm).
* ``paper_car`` is the env's default, the paper's 0.8 x 0.5 m car with two 360-beam 10 m
  Lidars 0.5 m apart; choosing it changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from lidar_env.core.errors import ConfigError
from lidar_env.sensors.lidar_config import LidarConfig


@dataclass(frozen=True)
class RobotPreset:
    """One robot: the :class:`~lidar_env.config.EnvConfig` values it sets (units in comments)."""

    name: str
    description: str
    car_length: float  # [m] along the robot's x (forward) axis
    car_width: float  # [m] along its y (left) axis
    max_speed: float  # [m/s]
    max_yaw_rate: float  # [rad/s]
    control_dt: float  # [s] one step per scan: 1 / the Lidar's scan rate
    physics_substeps: int  # [-] collision checks per step (<= ~4 cm of travel apart)
    lidars: tuple[LidarConfig, ...]

    def changes(self) -> dict[str, Any]:
        """The preset as ``EnvConfig`` keyword changes."""
        return {"car_length": self.car_length, "car_width": self.car_width,
                "max_speed": self.max_speed, "max_yaw_rate": self.max_yaw_rate,
                "control_dt": self.control_dt, "physics_substeps": self.physics_substeps,
                "lidars": self.lidars}


def _lds01() -> tuple[LidarConfig, ...]:
    """ROBOTIS LDS-01 at the centre of a TurtleBot3's base: 360 beams of 1 degree, 0.12-3.5 m."""
    return (LidarConfig((0.0, 0.0, 0.0), n_beams=360, max_range=3.5, min_range=0.12,
                        range_noise_std=0.015),)


#: [rad] UST-10LX field of view: 270 degrees.
UST_10LX_FOV = 1.5 * math.pi

ROBOTS: dict[str, RobotPreset] = {preset.name: preset for preset in (
    RobotPreset(
        "paper_car", "the paper's car: 0.8 x 0.5 m, two 360-degree 10 m Lidars 0.5 m apart",
        0.8, 0.5, 1.5, 1.5, 0.1, 4,
        (LidarConfig((0.25, 0.0, 0.0)), LidarConfig((-0.25, 0.0, 0.0), where="lidars[1]"))),
    RobotPreset(
        "turtlebot3_burger", "ROBOTIS TurtleBot3 Burger with its LDS-01 (5 Hz)",
        0.138, 0.178, 0.22, 2.84, 0.2, 4, _lds01()),
    RobotPreset(
        "turtlebot3_waffle_pi", "ROBOTIS TurtleBot3 Waffle Pi with its LDS-01 (5 Hz)",
        0.281, 0.306, 0.26, 1.82, 0.2, 4, _lds01()),
    RobotPreset(
        "f1tenth", "an F1TENTH-class 1/10 race car with a Hokuyo UST-10LX (40 Hz, 270 deg)",
        0.58, 0.31, 20.0, 4.0, 0.025, 12,
        (LidarConfig((0.1, 0.0, 0.0), n_beams=1081, fov=UST_10LX_FOV, max_range=10.0,
                     min_range=0.06, range_noise_std=0.04),)),
)}
#: Preset names, the default first.
ROBOT_NAMES: tuple[str, ...] = tuple(ROBOTS)


def robot_preset(name: Any) -> RobotPreset:
    """The preset called ``name``, or a ``ConfigError`` listing the presets."""
    if not isinstance(name, str) or name not in ROBOTS:
        raise ConfigError(f"robot: expected one of {', '.join(ROBOT_NAMES)}, got {name!r:.60}")
    return ROBOTS[name]
