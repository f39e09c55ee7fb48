"""The static world the car drives in, in metres: :class:`World` (circles, walls and polygons,
built from shapes, a grayscale matrix, an image or a ROS ``map_server`` map) in :mod:`.world`,
its polygon geometry (:mod:`.polygons`), the spatial grid its queries use
(:mod:`.primitive_grid`), occupancy images (:mod:`.occupancy_image`) and ROS maps
(:mod:`.ros_map`); the paper's built-in worlds (:mod:`.built_in`), the feature-density family
(:mod:`.feature_worlds`) and the worlds a user brings (:mod:`.user_worlds`).

It imports :mod:`lidar_env.core` and :mod:`lidar_env.routes` (a built-in world is laid out
around its trace).
"""

from lidar_env.world.built_in import PAPER_TRACES, WORLD_NAMES, Scene, make_scene, make_world
from lidar_env.world.feature_worlds import FEATURE_WORLDS, feature_world_name, parse_world_name
from lidar_env.world.ros_map import RosMap, read_ros_map, save_ros_map
from lidar_env.world.world import World

__all__ = ["FEATURE_WORLDS", "PAPER_TRACES", "WORLD_NAMES", "RosMap", "Scene", "World",
           "feature_world_name", "make_scene", "make_world", "parse_world_name", "read_ros_map",
           "save_ros_map"]
