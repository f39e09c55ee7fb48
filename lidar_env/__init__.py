"""duallidar's environment: a car with two planar Lidars in a 2-D pymunk world.

``import lidar_env`` registers ``DualLidar-v0`` (also reachable as
``gym.make("lidar_env:DualLidar-v0")`` without importing first).
"""

import gymnasium

from lidar_env.config import EnvConfig
from lidar_env.env import DualLidarEnv
from lidar_env.traces import TRACE_NAMES, Trace, make_trace
from lidar_env.world import World
from lidar_env.worlds import WORLD_NAMES, make_world

if "DualLidar-v0" not in gymnasium.registry:
    gymnasium.register("DualLidar-v0", entry_point="lidar_env.env:DualLidarEnv")

__all__ = [
    "TRACE_NAMES",
    "WORLD_NAMES",
    "DualLidarEnv",
    "EnvConfig",
    "Trace",
    "World",
    "make_trace",
    "make_world",
]
