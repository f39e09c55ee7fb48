"""duallidar's environment: a car with planar Lidars (two by default, 1 to 8) in a 2-D pymunk
world, built-in or the user's own (a World, an image, a ROS map_server map).

``import lidar_env`` registers ``DualLidar-v0`` (also reachable as
``gym.make("lidar_env:DualLidar-v0")`` without importing first). The subpackages, from the
bottom up, each importing only those before it: :mod:`.core` (SE(2) maths, the exception
hierarchy, time checks: what every package of the project uses), :mod:`.routes` (trace seeds
and waypoint routes), :mod:`.world` (world geometry, built-in worlds, images and ROS maps),
:mod:`.sensors` (the Lidars and their compiled ray caster), :mod:`.vehicle` (the car and its
action), :mod:`.movers` (pedestrians), :mod:`.rendering`; above them the env itself
(:mod:`.env`, its :mod:`.config`, :mod:`.scenes` and :mod:`.env_views`) and the batched env
(:mod:`.vector`). Nothing here imports ``estimators`` or ``agents``.
"""

from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import gymnasium

from lidar_env.config import EnvConfig, lidars_with_noise
from lidar_env.core.kernel_cache import drop_stale_caches
from lidar_env.env import DualLidarEnv
from lidar_env.moved_modules import install as _install_moved_modules
from lidar_env.routes import TRACE_NAMES, Trace, make_trace
from lidar_env.sensors import LidarConfig
from lidar_env.world import WORLD_NAMES, World, make_world, save_ros_map

_install_moved_modules()
drop_stale_caches(Path(__file__).resolve().parent.parent, "lidar_env", ("lidar_env",))

try:
    __version__ = version("duallidar")
except PackageNotFoundError:  # run from a source tree that was never installed
    __version__ = "0+unknown"

if "DualLidar-v0" not in gymnasium.registry:
    gymnasium.register("DualLidar-v0", entry_point="lidar_env.env:DualLidarEnv",
                       vector_entry_point="lidar_env.vector.env:DualLidarVectorEnv")

__all__ = [
    "TRACE_NAMES",
    "WORLD_NAMES",
    "DualLidarEnv",
    "EnvConfig",
    "LidarConfig",
    "Trace",
    "World",
    "lidars_with_noise",
    "make_trace",
    "make_world",
    "save_ros_map",
]
