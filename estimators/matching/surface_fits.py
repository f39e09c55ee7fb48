"""The lines the ``icp`` estimator pairs a scan with: the curves fitted through the previous
scan's returns, with the curve's midpoint added between neighbouring returns where it bends.

A query point pairs with the tangent of its nearest reference return's fitted curve (anchor
and normal, :func:`estimators.matching.scan_matching.fit_local_curves`). On a convex surface
the tangent runs in front of the surface, so a query point a distance ``d`` along it lies
behind the line by ``d^2 / 2R`` (radius ``R``): every pair on a small cylinder seen with few
returns pulls the same way, and the pulls add up scan after scan (sideways in a turn among
cylinders, where half the Lidar's beams are lost most of all). Between two neighbouring
returns whose curve bulges off their chord by more than :data:`MAX_SAGITTA`, a reference
point on the curve at the middle (the cubic Hermite curve through both anchors along their
tangents) halves the distance ``d`` from a query point between them to the nearest tangent,
and the pull falls with ``d^2``. Flat walls get no midpoints: their pairs are those of the
fitted curves alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import fit_local_curves

#: [m] the neighbours of a return are sought within this distance (``fit_local_curves``'s).
NEIGHBOUR_RADIUS = 0.5
#: [m] the most the curve between two neighbouring returns may bulge off their chord without
#: a midpoint: a quarter of the 2 cm range noise of the Lidars the defaults suit.
MAX_SAGITTA = 0.005


def curve_midpoints(points: NDArray[np.float64], normals: NDArray[np.float64],
                    valid: NDArray[np.bool_], anchors: NDArray[np.float64],
                    neighbours: NDArray[np.int64]) -> tuple[NDArray[np.float64],
                                                             NDArray[np.float64]]:
    """Midpoints (M, 2) [m] and their unit normals (M, 2) of the curves between each of
    ``points`` (N, 2) and its ``neighbours`` (N, j) (``N`` where missing), both with a fitted
    curve (``valid``, ``normals``, ``anchors`` (N, 2) [m]), once per pair, where the cubic
    Hermite curve through both anchors along their tangents bulges more than
    :data:`MAX_SAGITTA` off their chord."""
    n = len(points)
    rows = np.repeat(np.arange(n), neighbours.shape[1])
    others = neighbours.ravel()
    kept = others < n
    rows, others = rows[kept], others[kept]
    kept = valid[rows] & valid[others]
    low, high = np.minimum(rows[kept], others[kept]), np.maximum(rows[kept], others[kept])
    pairs = np.unique(low * n + high)
    first, second = pairs // n, pairs % n
    start, chord = anchors[first], anchors[second] - anchors[first]
    length = np.hypot(chord[:, 0], chord[:, 1])[:, None]

    def tangents(rows: NDArray[np.int64]) -> NDArray[np.float64]:
        along = np.column_stack([normals[rows, 1], -normals[rows, 0]])
        return along * np.sign(np.einsum("ij,ij->i", along, chord))[:, None]

    t0, t1 = tangents(first), tangents(second)
    # the Hermite curve's offset at its middle: length (t0 - t1) / 8, its sagitta
    bulge = length * (t0 - t1) / 8.0
    bent = np.hypot(bulge[:, 0], bulge[:, 1]) > MAX_SAGITTA
    middle = start[bent] + 0.5 * chord[bent] + bulge[bent]
    slope = 1.5 * chord[bent] - 0.25 * length[bent] * (t0[bent] + t1[bent])
    middle_normals = np.column_stack([-slope[:, 1], slope[:, 0]])
    middle_normals /= np.hypot(middle_normals[:, 0], middle_normals[:, 1])[:, None]
    return middle, middle_normals


def surface_reference(points: NDArray[np.float64], k: int, max_k: int) -> PointToLineReference:
    """Reference over ``points`` (N, 2) [m] whose lines are the curves fitted through each
    point's ``k`` nearest neighbours within :data:`NEIGHBOUR_RADIUS`, grown up to ``max_k``
    along noisy walls (:func:`estimators.matching.scan_matching.fit_local_curves`, denoised
    anchors), plus the midpoints of those curves between each point and its two nearest
    neighbours where they bend (:func:`curve_midpoints`)."""
    reference = PointToLineReference(points)
    normals, valid, anchors = fit_local_curves(reference.points, reference.search_tree, k,
                                               NEIGHBOUR_RADIUS, max_k)
    _, index = reference.search_tree.query(reference.points, k=min(3, len(points)),
                                           distance_upper_bound=NEIGHBOUR_RADIUS)
    middle, middle_normals = curve_midpoints(reference.points, normals, valid, anchors,
                                             index[:, 1:])
    if not len(middle):
        reference.normals, reference.valid_normals, reference.anchors = normals, valid, anchors
        return reference
    return PointToLineReference(np.vstack([reference.points, middle]),
                                np.vstack([normals, middle_normals]),
                                np.concatenate([valid, np.ones(len(middle), bool)]),
                                np.vstack([anchors, middle]))
