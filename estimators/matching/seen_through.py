"""Which reference points a scan sees through from a pose: the ray consistency test of
occupancy-grid scan matching, for judging where a scan was taken after a blind stretch.

A beam that ends well beyond a reference point along its bearing says that point is not
where the pose puts it. Placed short of where it was taken (along a corridor, which fits its
walls about as well anywhere), a scan sees through the walls the car has driven past; at the
true pose it sees through none. Bearings are binned (:data:`BEARING_BIN`); bins without a
return (no echo) judge nothing, and points nearer the car than :data:`NEAREST_JUDGED` are
not judged. Scan points in their car frame, reference points and poses in the reference
frame; distances [m], angles [rad].
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: [rad] bearing bins a scan's nearest returns are taken over (two 1-degree beams).
BEARING_BIN = math.radians(2.0)
#: [m] a reference point counts as seen through where every return of the scan in its
#: bearing bin lies at least this far behind it (the map's and the scan's noise, and the
#: car-frame origin standing in for each Lidar's mount).
SEEN_THROUGH_MARGIN = 0.3
#: [m] reference points nearer the car than this are not judged (a Lidar's mount a few
#: decimetres off the car's origin turns their bearings by tens of degrees).
NEAREST_JUDGED = 1.0
#: Seen-through reference points a place may have over the fewest and still count as free
#: of contradiction (a thin post between two beams, a stray return).
SEEN_THROUGH_SLACK = 3
#: Poses judged at once by :func:`seen_through_counts` (bounds its arrays to a few MB).
COUNT_CHUNK = 256
_BINS = int(round(2.0 * math.pi / BEARING_BIN))


def bearing_bins(points: FloatArray) -> NDArray[np.int64]:
    """The :data:`BEARING_BIN` index of each car-frame point (..., 2)."""
    return ((np.arctan2(points[..., 1], points[..., 0]) + math.pi) / BEARING_BIN).astype(
        np.int64) % _BINS


def nearest_by_bearing(points: FloatArray) -> FloatArray:
    """The nearest range [m] of the car-frame ``points`` (M, 2) in each bearing bin, inf
    where a bin holds none."""
    nearest = np.full(_BINS, np.inf)
    np.minimum.at(nearest, bearing_bins(points), np.hypot(points[:, 0], points[:, 1]))
    return nearest


def seen_through_counts(reference_points: FloatArray, query_points: FloatArray,
                        poses: FloatArray, nearest: FloatArray | None = None
                        ) -> NDArray[np.int64]:
    """(P,) how many ``reference_points`` (N, 2) the scan's ``query_points`` (M, 2) see
    through with the car at each of ``poses`` (P, 3): points at least
    :data:`NEAREST_JUDGED` from the car whose bearing bin holds returns, all at least
    :data:`SEEN_THROUGH_MARGIN` farther. ``nearest``: :func:`nearest_by_bearing` of
    ``query_points``, where already taken."""
    if nearest is None:
        nearest = nearest_by_bearing(query_points)
    counts = np.zeros(len(poses), dtype=np.int64)
    for first in range(0, len(poses), COUNT_CHUNK):
        chunk = poses[first:first + COUNT_CHUNK]
        c, s = np.cos(chunk[:, 2:]), np.sin(chunk[:, 2:])
        dx = reference_points[None, :, 0] - chunk[:, :1]
        dy = reference_points[None, :, 1] - chunk[:, 1:2]
        local = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)
        distance = np.hypot(local[..., 0], local[..., 1])
        behind = nearest[bearing_bins(local)]
        counts[first:first + COUNT_CHUNK] = np.count_nonzero(
            (distance >= NEAREST_JUDGED) & np.isfinite(behind)
            & (behind > distance + SEEN_THROUGH_MARGIN), axis=1)
    return counts


def seen_through_count(reference_points: FloatArray, query_points: FloatArray,
                       pose: FloatArray) -> int:
    """:func:`seen_through_counts` at one ``pose`` (3,)."""
    return int(seen_through_counts(reference_points, query_points, pose[None])[0])
