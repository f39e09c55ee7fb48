"""What a registration found (:class:`MatchResult`): the type ICP returns and the searches
that choose among matches (``scan_recovery``) compare."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class MatchResult:
    """A registration: ``pose`` (3,) of the query frame in the reference frame; ``quality`` is
    the share of query points within ``inlier_distance`` of their line (0 = no overlap,
    1 = every point explained); ``rmse`` [m] over those inliers; ``information`` (3, 3) the
    points' ``J^T W J`` at ``pose`` over those pairs (x, y [m], heading [rad]; one point squarely
    facing a direction adds 1 to it), None where not computed."""

    pose: NDArray[np.float64]
    quality: float
    rmse: float
    iterations: int
    converged: bool
    information: NDArray[np.float64] | None = None
