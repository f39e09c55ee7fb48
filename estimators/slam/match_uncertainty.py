"""How uncertain a verified loop match is: the information of its point-to-line ICP Hessian
(:func:`match_information`), and how far it could move and fit as well (:func:`score_spread`:
the spread of the near-best poses around it on the likelihood field), a covariance the loop
edge adds to the Hessian's.

The ICP Hessian says how sharply the
point-to-line cost rises at the match, as if its residuals were independent noise. Where few
surfaces fix a direction (a pillar or two, the end of a shelf, a corner), their errors do not
average out: a pillar seen from another side, or the end face of a shelf seen from the other
end, shifts the match by a pillar's width along that direction while the Hessian still claims
centimetres. The likelihood field tells such a direction apart: moving the scan along it leaves
its score nearly unchanged. Following Olson ("Real-time correlative scan matching", ICRA 2009:
the covariance of a match from the score over the search window), the spread is the second
moment, about the match, of the poses within a window around it whose mean score is at least
``ratio`` times the window's best: a few millimetres where walls cross, a pillar's width along
an aisle of pillars.

Frames: the reference place's frame for poses and points' placement; the covariance is
returned in the pose graph's residual coordinates (the match pose's own frame). Distances [m],
angles [rad].
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from estimators.matching.point_to_line import PointToLineReference, point_to_line_jacobian
from estimators.matching.scan_matching import LikelihoodField
from lidar_env.core.se2 import transform_points


class MatchNoise(Protocol):
    """What :func:`match_information` reads of the loop-closure settings
    (:class:`~estimators.slam.loop_closure.LoopClosureParams`)."""

    inlier_distance: float  # [m] pairs nearer than this count
    effective_points: float  # independent points a registration is worth
    point_sigma: float  # [m] one point's residual noise

#: [m] standard deviation along a direction the near-best translations fill up to the window's
#: edge (unbounded: an aisle's axis), as :func:`match_information`'s
#: floor: no information.
UNBOUNDED_SIGMA = 10.0


def score_spread(
    field: LikelihoodField,
    points: NDArray[np.float64],
    pose: NDArray[np.float64],
    reach: float,
    turn: float,
    angular_step: float,
    ratio: float,
    sigmas: float = 0.0,
) -> NDArray[np.float64]:
    """``(3, 3)`` second moment of the offsets ``(dx, dy, dtheta)`` from ``pose`` (3,) whose
    mean score of ``points`` (M, 2, query frame) on ``field`` is near the best: at least
    ``ratio`` times it, or within ``sigmas`` standard errors of it (its points' scores' standard
    deviation over the square root of their count: a match on a handful of points is no
    sharper than that). Translations within ``reach`` [m] per axis on the field's cells,
    headings within ``turn`` [rad] in ``angular_step`` steps; where near-best translations
    reach the edge of that window, the direction they fill (their main axis: an aisle's)
    gets ``UNBOUNDED_SIGMA`` on top. Translations are turned into ``pose``'s frame. Zeros
    without points."""
    if len(points) == 0:
        return np.zeros((3, 3))
    n = int(round(reach / field.resolution))
    n_turn = int(round(turn / angular_step))
    turns = angular_step * np.arange(-n_turn, n_turn + 1)
    steps = np.arange(-n, n + 1)
    shape = np.array(field.grid.shape)
    scores = np.empty((len(turns), len(steps), len(steps)))
    for k, dtheta in enumerate(turns):
        placed = transform_points(pose + np.array([0.0, 0.0, dtheta]), points)
        # a shift by whole cells moves every point's cell by the same count
        cells = np.floor((placed - field.origin) / field.resolution).astype(np.int64)
        x = cells[:, 0, None, None] + steps[None, :, None]
        y = cells[:, 1, None, None] + steps[None, None, :]
        inside = (x >= 0) & (x < shape[0]) & (y >= 0) & (y < shape[1])
        values = field.grid[np.clip(x, 0, shape[0] - 1), np.clip(y, 0, shape[1] - 1)]
        scores[k] = np.where(inside, values, 0.0).mean(axis=0)
    best = scores.max()
    k_best = np.unravel_index(np.argmax(scores), scores.shape)
    placed = transform_points(pose + np.array([0.0, 0.0, turns[k_best[0]]]), points)
    placed += field.resolution * steps[np.array(k_best[1:])]
    # the best mean's sampling error: its points' scores spread over so few of them
    noise = field.score(placed).std() / np.sqrt(len(points))
    near = np.argwhere(scores >= best - max((1.0 - ratio) * best, sigmas * noise))
    offsets = np.column_stack(
        [
            field.resolution * steps[near[:, 1]],
            field.resolution * steps[near[:, 2]],
            turns[near[:, 0]],
        ]
    )
    moment = offsets.T @ offsets / len(offsets)
    if np.any(np.abs(near[:, 1:] - n) == n):
        _, axes = np.linalg.eigh(moment[:2, :2])
        moment[:2, :2] += UNBOUNDED_SIGMA**2 * np.outer(axes[:, -1], axes[:, -1])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    to_local = np.eye(3)
    to_local[:2, :2] = [[c, -s], [s, c]]
    return to_local.T @ moment @ to_local


def match_information(
    reference: PointToLineReference,
    points: NDArray[np.float64],
    pose: NDArray[np.float64],
    params: MatchNoise,
) -> NDArray[np.float64]:
    """``(3, 3)`` information of a registration: the point-to-line Gauss-Newton Hessian over
    the inlier pairs at ``pose``, ``mean(J^T J) * effective_points / point_sigma^2``; small
    along directions the scene leaves free (a corridor's axis), large across them.

    Expressed in the pose graph's residual coordinates (the pose's own frame): the Hessian
    over a reference-frame perturbation ``(dx, dy, dtheta)`` is rotated by ``R(theta)``."""
    world = transform_points(pose, points)
    pairs = reference.correspond(world, params.inlier_distance)
    if len(pairs.index) == 0:
        return 1e-2 * np.eye(3)
    jacobian = point_to_line_jacobian(world[pairs.index], pose[:2], pairs.normals)
    hessian = jacobian.T @ jacobian / len(jacobian) * params.effective_points
    hessian /= params.point_sigma**2
    to_local = np.eye(3)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    to_local[:2, :2] = [[c, -s], [s, c]]
    hessian = to_local.T @ hessian @ to_local
    # A floor (sigma 10 m / 10 rad) keeps the matrix invertible in a degenerate scene without
    # adding information the scan does not hold.
    return hessian + 1e-2 * np.eye(3)
