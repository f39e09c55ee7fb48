"""Top-down pictures of an episode, drawn with numpy: the env's :class:`Renderer`, the
colours every figure of the project shares, and PNG files (:mod:`.renderer`).

It imports :mod:`lidar_env.core` and :mod:`lidar_env.world`.
"""

from lidar_env.rendering.renderer import (
    CAR_COLOUR,
    LIDAR_COLOURS,
    MAP_ALPHA,
    MOVER_COLOUR,
    OBSTACLE,
    TRACE_COLOUR,
    TRAJECTORY_COLOURS,
    OccupancyMap,
    Renderer,
    occupancy_to_rgb,
    raster_shape,
    tile_frames,
    write_png,
)

__all__ = ["CAR_COLOUR", "LIDAR_COLOURS", "MAP_ALPHA", "MOVER_COLOUR", "OBSTACLE", "TRACE_COLOUR",
           "TRAJECTORY_COLOURS", "OccupancyMap", "Renderer", "occupancy_to_rgb", "raster_shape",
           "tile_frames", "write_png"]
