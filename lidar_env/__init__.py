"""duallidar's environment: a car with planar Lidars (two by default, 1 to 8) in a 2-D pymunk
world, built-in or the user's own (a World, an image, a ROS map_server map).

``import lidar_env`` registers ``DualLidar-v0`` (also reachable as
``gym.make("lidar_env:DualLidar-v0")`` without importing first).
"""

import gymnasium

from lidar_env.config import EnvConfig, lidars_with_noise
from lidar_env.env import DualLidarEnv
from lidar_env.lidar_config import LidarConfig
from lidar_env.ros_map import save_ros_map
from lidar_env.traces import TRACE_NAMES, Trace, make_trace
from lidar_env.world import World
from lidar_env.worlds import WORLD_NAMES, make_world

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
