"""Maps from estimated poses: the log-odds occupancy grid (``occupancy``), obstacle detection and
tracking (``obstacles``) and map scores against the true world (``map_scoring``). It imports
``estimators.base`` and ``lidar_env`` only. The env draws a grid as a
``lidar_env.rendering.renderer.OccupancyMap`` (bounds, resolution, probabilities), never by
importing this package.
"""

from estimators.mapping.map_scoring import score_cylinders, score_occupancy
from estimators.mapping.obstacles import detect_obstacles
from estimators.mapping.occupancy import OccupancyGrid
from estimators.mapping.tracking import ObstacleTracker

__all__ = ["ObstacleTracker", "OccupancyGrid", "detect_obstacles", "score_cylinders",
           "score_occupancy"]
