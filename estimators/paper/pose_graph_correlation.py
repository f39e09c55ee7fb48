"""The paper's pose-graph correlation (section III.D, eq. 10): one motion from two Lidars.

Our reading of the four-node loop (the paper's Fig. 4 is not in the text we have):

* Nodes: ``P1`` the main Lidar in the past scan, ``P2`` the offset Lidar in the past scan,
  ``P3`` the main Lidar in the present scan, ``P4`` the offset Lidar in the present scan.
  ``P1`` is "presumed ground truth": the origin the motion is measured from.
* Edges, written ``xi_ij = P_j - P_i`` (translation from node i to node j, in one fixed frame):
  ``xi21 = -o_past`` and ``xi43 = -o_present`` are the two "ground truth factors": the known
  mount offset ``o`` from the main to the offset Lidar, at the past and the present scan.
  ``xi14`` and ``xi32`` are measured by phase correlation *across* the two Lidars: past main
  scan against present offset scan, and present main scan against past offset scan.
* Around the loop ``P1 -> P4 -> P3 -> P2 -> P1`` exact edges sum to zero
  (``xi14 + xi43 + xi32 + xi21 = 0``, the "loop-closing" constraint). With the motion
  ``d = P3 - P1``: ``xi14 = d + o_present`` and ``xi32 = o_past - d``, so
  ``(xi14 - xi32) / 2 = d + (o_present - o_past) / 2``.
* Eq. 10 subtracts the error vector ``[rx, ry]`` from that average. We read ``[rx, ry]`` as
  the error the average carries by construction, ``(o_present - o_past) / 2 = (xi21 - xi43)/2``,
  computed from the two ground-truth factors. It vanishes when the offset keeps its direction
  between the two scans (the paper's car only translates), and corrects the average when the
  car turns and the estimator knows by how much. With this reading eq. 10 is exact for exact
  edges: ``xi_12->34 = d``.
* What the loop buys: any error common to both cross estimates (the paper presumes "the
  estimations are in a same error vector") cancels in the difference, and a large
  loop-closure residual ``xi14 + xi43 + xi32 + xi21`` (the sum of the two estimates' errors)
  flags an inconsistent pair.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError


@dataclass(frozen=True)
class PoseGraphCorrelation:
    """Result of :func:`pose_graph_correlation`; all vectors (2,) [m] in the common frame.

    Attributes:
        motion: ``xi_12->34`` (eq. 10): the main Lidar's translation ``P3 - P1``.
        error: ``[rx, ry]``, the correction eq. 10 subtracts.
        loop_residual: ``xi14 + xi43 + xi32 + xi21``; zero for consistent estimates.
    """

    motion: NDArray[np.float64]
    error: NDArray[np.float64]
    loop_residual: NDArray[np.float64]


def _vector(value: ArrayLike, name: str) -> NDArray[np.float64]:
    try:
        vector = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        vector = np.empty(0)
    # math.isfinite on the two numbers: np.isfinite's call costs more than the check
    if vector.shape != (2,) or not (math.isfinite(vector[0]) and math.isfinite(vector[1])):
        raise ConfigError(f"{name}: expected 2 finite numbers (x [m], y [m]), got {value!r}")
    return vector


def pose_graph_correlation(
    xi14: ArrayLike, xi32: ArrayLike, offset_past: ArrayLike, offset_present: ArrayLike
) -> PoseGraphCorrelation:
    """Fuse the two cross-Lidar estimates of the four-node loop (eq. 10).

    Args:
        xi14: ``P4 - P1`` [m]: present offset Lidar seen from the past main Lidar.
        xi32: ``P2 - P3`` [m]: past offset Lidar seen from the present main Lidar.
        offset_past: ``P2 - P1`` [m]: main -> offset Lidar at the past scan (known mount).
        offset_present: ``P4 - P3`` [m]: main -> offset Lidar at the present scan.
    All in one frame (the frame the motion is wanted in); see the module docstring.
    """
    xi14, xi32 = _vector(xi14, "xi14"), _vector(xi32, "xi32")
    xi21 = -_vector(offset_past, "offset_past")
    xi43 = -_vector(offset_present, "offset_present")
    error = (xi21 - xi43) / 2.0
    motion = (xi14 - xi32) / 2.0 - error  # eq. 10
    return PoseGraphCorrelation(motion, error, xi14 + xi43 + xi32 + xi21)
