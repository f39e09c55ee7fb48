"""Moving obstacles: a crowd of pedestrians (circles) walking between free waypoints
(:class:`Crowd`, :mod:`.crowd`) and its compiled geometry and motion (:mod:`.kernels`).

It imports :mod:`lidar_env.core` and :mod:`lidar_env.world`.
"""

from lidar_env.movers.crowd import MOVER_MODELS, Crowd, car_circles

__all__ = ["MOVER_MODELS", "Crowd", "car_circles"]
