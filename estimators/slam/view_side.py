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


def far_side_pairs(reference: PointToLineReference, viewpoints: NDArray[np.float64],
                   points: NDArray[np.float64], pose: NDArray[np.float64], max_distance: float,
                   min_incidence: float = 0.1) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which of the query's ``points`` (M, 2) placed at ``pose`` (3,) are counted (M,) and,
    of those, which lie on a surface the query sees from the other side than the reference
    scan did (M,): counted are the points within ``max_distance`` of a reference point with a
    normal, seen by both sensors (``viewpoints`` (N, 2): where each reference point was seen
    from) more than ``arcsin(min_incidence)`` (about 6 deg) off the surface's plane."""
    normals = reference.normals
    if normals is None or len(viewpoints) != len(reference.points):
        raise EstimatorInputError(f"far_side_share: expected a reference with normals and "
                                  f"{len(reference.points)} viewpoints, got {len(viewpoints)}")
    world = transform_points(pose, points)
    distances, nearest = reference.search_tree.query(world, distance_upper_bound=max_distance)
    rows = np.flatnonzero(np.isfinite(distances))
    rows = rows[reference.valid_normals[nearest[rows]]]
    nearest = nearest[rows]
    counted, far = np.zeros(len(points), bool), np.zeros(len(points), bool)
    if len(rows) == 0:
        return counted, far
    surface, normal = reference.points[nearest], normals[nearest]
    sides = []
    for origin in (viewpoints[nearest], pose[None, :2]):
        sight = origin - surface
        sides.append(np.einsum("ij,ij->i", normal, sight)
                     / np.maximum(np.hypot(sight[:, 0], sight[:, 1]), 1e-9))
    seen = (np.abs(sides[0]) > min_incidence) & (np.abs(sides[1]) > min_incidence)
    counted[rows[seen]] = True
    far[rows[seen & (np.sign(sides[0]) != np.sign(sides[1]))]] = True
    return counted, far


def far_side_share(reference: PointToLineReference, viewpoints: NDArray[np.float64],
                   points: NDArray[np.float64], pose: NDArray[np.float64], max_distance: float,
                   min_incidence: float = 0.1, min_pairs: int = 10) -> float:
    """Of the query's ``points`` (M, 2) placed at ``pose`` (3,) counted by
    :func:`far_side_pairs`, the share whose surface the query sees from the other side than
    the reference scan did; 0 with fewer than ``min_pairs`` counted pairs (too few to tell a
    thin object's far side from the rim of a post seen from another angle)."""
    counted, far = far_side_pairs(reference, viewpoints, points, pose, max_distance,
                                  min_incidence)
    if counted.sum() < min_pairs:
        return 0.0
    return float(far.sum() / counted.sum())


def without_far_side(reference: PointToLineReference, viewpoints: NDArray[np.float64],
                     points: NDArray[np.float64], pose: NDArray[np.float64],
                     max_distance: float) -> NDArray[np.float64]:
    """The query's ``points`` (M, 2) less those :func:`far_side_pairs` places on a surface
    the reference saw from its other side: at ``pose`` (3,) they pair with the wrong face (a
    pillar's near side seen from across it, a pillar's width off)."""
    _, far = far_side_pairs(reference, viewpoints, points, pose, max_distance)
    return points[~far]
