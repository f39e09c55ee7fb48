"""The planar Lidars: one Lidar's settings (:class:`LidarConfig`, :mod:`.lidar_config`), the
exact analytic ray caster (:mod:`.ray_casting`, with beam wedges in :mod:`.beam_wedge` and
edge facing in :mod:`.edge_facing`), K Lidars scanned in one compiled call
(:class:`LidarLayout`, :mod:`.lidar_layout` and its kernels in :mod:`.layout_kernels`), and a
standalone :class:`Lidar` of plain arrays in, arrays out (:mod:`.lidar`).

It imports :mod:`lidar_env.core` and :mod:`lidar_env.world`.
"""

from lidar_env.sensors.lidar import Lidar, cast_rays, pymunk_cast_rays
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout

__all__ = ["Lidar", "LidarConfig", "LidarLayout", "cast_rays", "pymunk_cast_rays"]
