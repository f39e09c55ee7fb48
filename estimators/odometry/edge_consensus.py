"""Where the four-node graph (:func:`~estimators.odometry.sensor_graph.fuse_car_motion`) is
solved from when its matches disagree.

The graph's Cauchy loss lets a wrong match count little once the solution sits with the others,
but it makes the answer depend on where the solver starts: started at a wrong match (a
correlation fooled by a corridor, refined to a fit that explains a few points more), the right
edges are the ones that count little, and the wrong one is kept. So where an edge's own car
motion lies beyond the loss's scale from the solution, the graph is also solved from that
motion, and the solution whose edges cost the least is kept. Matches that agree (every edge
within the scale) leave the first solution as it is.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.odometry.sensor_graph import SensorEdge, fuse_car_motion, predict_edges
from lidar_env.core.se2 import compose, inverse, rotate, wrap_angle

FloatArray = NDArray[np.float64]


def edge_motions(mounts: ArrayLike, edges: Sequence[SensorEdge]) -> FloatArray:
    """``(E, 3)`` the car motion each edge of a two-node graph (node 0 to node 1) implies
    alone: ``mount_i ⊕ z_ij ⊕ mount_j⁻¹``."""
    mounts = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
    source = mounts[[e.source_sensor for e in edges]]
    target = mounts[[e.target_sensor for e in edges]]
    return compose(compose(source, np.array([e.pose for e in edges])), inverse(target))


def scaled_residuals(motion: ArrayLike, mounts: ArrayLike, edges: Sequence[SensorEdge],
                     sigma_translation: float, sigma_heading: float) -> FloatArray:
    """``(E, 3)`` each edge's residual ``z⁻¹ ⊕ h(Δ)`` at the car ``motion`` Δ, in sigma units
    and scaled by the square root of its confidence (the rows of
    :func:`~estimators.odometry.sensor_graph.optimize_poses`' least squares)."""
    measured = np.array([e.pose for e in edges], dtype=np.float64).reshape(-1, 3)
    predicted = predict_edges(np.stack([np.zeros(3), np.asarray(motion, dtype=np.float64)]),
                              np.asarray(mounts, dtype=np.float64), edges)
    translation = rotate(-measured[:, 2], predicted[:, :2] - measured[:, :2])
    heading = wrap_angle(predicted[:, 2] - measured[:, 2])
    root = np.sqrt([e.confidence for e in edges])[:, None]
    return np.column_stack([translation / sigma_translation, heading / sigma_heading]) * root


def fuse_from_consensus(mounts: ArrayLike, edges: Sequence[SensorEdge], start: ArrayLike, *,
                        sigma_translation: float, sigma_heading: float,
                        robust_scale: float) -> FloatArray:
    """The car motion (3,) :func:`fuse_car_motion` finds from ``start``, or, where an edge's
    own motion (:func:`edge_motions`) lies over ``robust_scale`` sigmas from it, the solution
    from such a motion whose edges cost less (Cauchy loss of scale ``robust_scale``)."""
    weights = {"sigma_translation": sigma_translation, "sigma_heading": sigma_heading,
               "robust_scale": robust_scale}
    best = fuse_car_motion(mounts, edges, start, **weights)
    scale = np.array([sigma_translation, sigma_translation, sigma_heading])

    def apart(a: FloatArray, b: FloatArray) -> bool:
        difference = a - b
        difference[2] = wrap_angle(difference[2])
        return bool(np.linalg.norm(difference / scale) > robust_scale)

    def cost(motion: FloatArray) -> float:
        residuals = scaled_residuals(motion, mounts, edges, sigma_translation, sigma_heading)
        return float(np.sum(np.log1p(residuals**2 / robust_scale**2)))

    outlying = [m for m in edge_motions(mounts, edges) if apart(m, best)]
    if not outlying:
        return best
    best_cost = cost(best)
    tried: list[FloatArray] = [best]
    for motion in outlying:
        if not all(apart(motion, other) for other in tried):
            continue
        solved = fuse_car_motion(mounts, edges, motion, **weights)
        tried.append(motion)
        if apart(solved, best) and cost(solved) < best_cost:
            best, best_cost = solved, cost(solved)
    return best
