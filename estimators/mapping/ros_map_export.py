"""Save the mapper's occupancy grid as a ROS map_server map (PGM + YAML).

The file format lives in :mod:`lidar_env.world.ros_map`; this module only places an
:class:`~estimators.mapping.occupancy.OccupancyGrid` in it: the grid's lower-left corner
``(xmin, ymin)`` becomes the map origin (yaw 0), its cells (row 0 at max y) the pixels, cells
never observed (probability 0.5) "unknown". A map built from estimated poses can then be loaded
with :meth:`lidar_env.world.world.World.from_ros_map` and driven again.
"""

from __future__ import annotations

import os
from pathlib import Path

from estimators.mapping.occupancy import OccupancyGrid
from lidar_env.world import save_ros_map


def save_grid_as_ros_map(
    grid: OccupancyGrid,
    yaml_path: str | os.PathLike,
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> tuple[Path, Path]:
    """Write ``grid`` as ``<yaml_path stem>.pgm`` + ``yaml_path``; return both paths. Cells above
    ``occupied_thresh`` are occupied, below ``free_thresh`` free, the rest unknown."""
    xmin, ymin, _, _ = grid.bounds
    return save_ros_map(yaml_path, grid.probabilities(), grid.resolution, (xmin, ymin, 0.0),
                        occupied_thresh, free_thresh)
