"""Which side of a surface two scans saw it from: a match that lays one scan's view of a thin
object (a shelf, a partition, a pillar) onto another scan's view of its far side.

A Lidar sees a surface only from the side its beams come from. Where a query scan, placed at a
candidate pose, lies on a reference point, the surface through that point (its normal ``n``)
must have been seen from the same side by both: ``n . (o_query - r)`` and ``n . (o_ref - r)``
have the same sign, ``o`` being the sensors' origins. Two rows of posts or the two faces of a
0.6 m shelf seen from aisles on either side fit each other shifted by the object's depth; the
match then pairs most points with surfaces seen from the other side, which a true revisit
never does.

Frames: reference points, their viewpoints and the pose are in the reference's frame; the
query's points in its own. Distances [m], angles [rad].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimators.matching.point_to_line import PointToLineReference
from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import transform_points


def far_side_share(reference: PointToLineReference, viewpoints: NDArray[np.float64],
                   points: NDArray[np.float64], pose: NDArray[np.float64], max_distance: float,
                   min_incidence: float = 0.1, min_pairs: int = 10) -> float:
    """Of the query's ``points`` (M, 2) placed at ``pose`` (3,) within ``max_distance`` of a
    reference point, the share whose surface the query sees from the other side than the
    reference scan did (``viewpoints`` (N, 2): where each reference point was seen
    from). Pairs seen by either sensor within ``arcsin(min_incidence)`` (about 6 deg) of the
    surface's plane, and reference points without a normal, are not counted; 0 with fewer
    than ``min_pairs`` counted pairs (too few to tell a thin object's far side from the
    rim of a post seen from another angle)."""
    normals = reference.normals
    if normals is None or len(viewpoints) != len(reference.points):
        raise EstimatorInputError(f"far_side_share: expected a reference with normals and "
                                  f"{len(reference.points)} viewpoints, got {len(viewpoints)}")
    world = transform_points(pose, points)
    distances, nearest = reference.search_tree.query(world, distance_upper_bound=max_distance)
    nearest = nearest[np.isfinite(distances)]
    nearest = nearest[reference.valid_normals[nearest]]
    if len(nearest) == 0:
        return 0.0
    surface, normal = reference.points[nearest], normals[nearest]
    sides = []
    for origin in (viewpoints[nearest], pose[None, :2]):
        sight = origin - surface
        sides.append(np.einsum("ij,ij->i", normal, sight)
                     / np.maximum(np.hypot(sight[:, 0], sight[:, 1]), 1e-9))
    counted = (np.abs(sides[0]) > min_incidence) & (np.abs(sides[1]) > min_incidence)
    if counted.sum() < min_pairs:
        return 0.0
    return float(np.mean(np.sign(sides[0][counted]) != np.sign(sides[1][counted])))
