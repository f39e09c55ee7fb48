"""Where the car drives: the paper's trace seeds (``straight``, ``right_turn``, ``zigzag``, plus
``loop`` and ``out_and_back``) in :mod:`.traces`, the user's waypoint routes in
:mod:`.user_traces`, and the geometry they share (constant-curvature pieces laid into dense
waypoints, the :class:`Trace` type, projection onto it) in :mod:`.trace_geometry`.

It imports only :mod:`lidar_env.core`.
"""

from lidar_env.routes.trace_geometry import Trace
from lidar_env.routes.traces import TRACE_NAMES, TraceFitError, build_trace, make_trace
from lidar_env.routes.user_traces import user_trace, waypoint_trace

__all__ = ["TRACE_NAMES", "Trace", "TraceFitError", "build_trace", "make_trace", "user_trace",
           "waypoint_trace"]
