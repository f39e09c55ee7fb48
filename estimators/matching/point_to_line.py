"""The point-to-line geometry ICP iterates on (Censi 2008): robust IRLS weights, the Jacobian of
point-to-line residuals, the closed-form Gauss-Newton step, and :class:`PointToLineReference`,
a reference scan with a normal at each point that pairs query points with the lines through
their nearest points.

    sum_i rho(n_i . (R(theta) p_i + t - q_i))                                   (Censi eq. 5)

Shared by :mod:`estimators.matching.icp`, :mod:`estimators.matching.curve_refinement` and loop
closure.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.matching.nearest import PointIndex
from estimators.matching.normal_equations import fresh_neighbours, point_to_line_system
from estimators.matching.scan_matching import (
    estimate_normals,
    fit_local_curves,
)
from lidar_env.core import EstimatorInputError, UnknownNameError

#: Robust losses by name: weight of a residual r at scale c (IRLS weights).
LOSSES: tuple[str, ...] = ("cauchy", "huber", "squared")


def robust_weights(residuals: NDArray[np.float64], loss: str, scale: float) -> NDArray[np.float64]:
    """IRLS weights ``rho'(r) / r`` of ``residuals`` [m] for ``loss`` at ``scale`` [m]."""
    if loss == "cauchy":
        return 1.0 / (1.0 + (residuals / scale) ** 2)
    if loss == "huber":
        magnitude = np.abs(residuals)
        return np.where(magnitude <= scale, 1.0, scale / np.maximum(magnitude, 1e-12))
    if loss == "squared":
        return np.ones_like(residuals)
    raise UnknownNameError(f"unknown loss {loss!r}: expected one of {', '.join(LOSSES)}")


def point_to_line_jacobian(
    world_points: NDArray[np.float64], position: NDArray[np.float64], normals: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``(M, 3)`` derivative of ``n . (R(theta) p + t)`` w.r.t. the pose ``(x, y, theta)``,
    evaluated at the mapped points ``world_points = R p + t`` with ``t = position``."""
    lever = world_points - position
    return np.column_stack(
        [normals[:, 0], normals[:, 1], normals[:, 1] * lever[:, 0] - normals[:, 0] * lever[:, 1]]
    )


def gauss_newton_step(
    jacobian: NDArray[np.float64],
    residuals: NDArray[np.float64],
    weights: NDArray[np.float64],
    prior_information: NDArray[np.float64] | None = None,
    prior_offset: NDArray[np.float64] | None = None,
    min_information: float = 0.0,
) -> NDArray[np.float64]:
    """Pose increment (3,) minimising ``sum w (r + J d)^2 + (d - e)^T L (d - e)`` over ``d``,
    with ``L = prior_information`` ((3, 3), or (3,) for its diagonal) and ``e = prior_offset``
    (prior pose minus current).

    With ``min_information`` > 0 and a prior, directions in which the data carry less
    information than that many fully weighted points facing that way (a corridor's axis) are
    left to the prior alone (Zhang, Kaess and Singh, "On degeneracy of optimization-based
    state estimation problems", ICRA 2016): the data's weak pull there comes from noisy
    normals and the nearest-neighbour bias towards "no motion", not from evidence. Rotation
    is scaled by the points' RMS lever arm to compare it with translation.
    """
    weighted = jacobian * weights[:, None]
    lever = float(np.sqrt(np.mean(jacobian[:, 2] ** 2))) if len(jacobian) else 0.0
    return solve_normal_equations(weighted.T @ jacobian, -weighted.T @ residuals, lever,
                                  prior_information, prior_offset, min_information)


def solve_normal_equations(
    hessian: NDArray[np.float64],
    gradient: NDArray[np.float64],
    lever: float,
    prior_information: NDArray[np.float64] | None = None,
    prior_offset: NDArray[np.float64] | None = None,
    min_information: float = 0.0,
) -> NDArray[np.float64]:
    """The step of :func:`gauss_newton_step` from the data's normal equations: ``hessian``
    ``J^T W J`` (3, 3), ``gradient`` ``-J^T W r`` (3,) and ``lever``, the RMS of the Jacobian's
    rotation column [m] (0 stands for 1)."""
    if min_information > 0 and prior_information is not None:
        scale = np.array([1.0, 1.0, lever or 1.0])
        values, vectors = np.linalg.eigh(hessian / np.outer(scale, scale))
        kept = vectors[:, values >= min_information]
        projection = kept @ kept.T
        hessian = np.outer(scale, scale) * (projection @ (hessian / np.outer(scale, scale))
                                            @ projection)
        gradient = scale * (projection @ (gradient / scale))
    if prior_information is not None:
        information = np.asarray(prior_information, dtype=np.float64)
        information = np.diag(information) if information.ndim == 1 else information
        hessian = hessian + information
        gradient = gradient + information @ prior_offset
    # A tiny damping keeps degenerate geometry (one wall) solvable; it moves nothing that the
    # data constrain.
    hessian = hessian + 1e-9 * np.eye(3)
    return np.linalg.solve(hessian, gradient)


@dataclass(frozen=True)
class Correspondences:
    """Pairs for the query points ``index``: the line through ``anchors`` with unit ``normals``."""

    index: NDArray[np.intp]
    anchors: NDArray[np.float64]
    normals: NDArray[np.float64]


class PointToLineReference:
    """Reference points (world or any fixed frame) with a k-d tree, paired point-to-line.

    With ``normals`` (M, 2) given, a query point's line passes through its nearest reference
    point (or that point's ``anchors`` row, a denoised position of it) along that point's
    normal (rows of ``valid_normals`` false fall back to the line
    through the two nearest points). Without, the line runs through the two nearest reference
    points (Censi's PL-ICP); when the second lies beyond the pairing distance, or a stored normal
    is not valid, the pair is point-to-point (the normal points from the reference point to
    the query point).
    """

    def __init__(
        self,
        points: ArrayLike,
        normals: NDArray[np.float64] | None = None,
        valid_normals: NDArray[np.bool_] | None = None,
        anchors: NDArray[np.float64] | None = None,
    ) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 2 or len(self.points) < 2:
            raise EstimatorInputError(
                f"reference points: expected shape (N >= 2, 2), got {self.points.shape}"
            )
        self.search_tree = PointIndex(self.points)
        self.normals = normals
        self.valid_normals = (
            valid_normals
            if valid_normals is not None or normals is None
            else np.ones(len(self.points), bool)
        )
        self.anchors = self.points if anchors is None else np.asarray(anchors, dtype=np.float64)
        if self.anchors.shape != self.points.shape:
            raise EstimatorInputError(
                f"anchors: expected the points' shape {self.points.shape}, got "
                f"{self.anchors.shape}"
            )
        self._neighbours: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]] | (
            None) = None

    #: The attributes :attr:`kernel_arrays` holds that may be set after construction (the
    #: curve fits set them on a built reference).
    _KERNEL_INPUTS = frozenset({"normals", "valid_normals", "anchors"})

    def __setattr__(self, name: str, value: object) -> None:
        super().__setattr__(name, value)
        if name in self._KERNEL_INPUTS:
            self.__dict__.pop("kernel_arrays", None)  # built again at its next use

    @cached_property
    def kernel_arrays(self) -> tuple[object, ...]:
        """The reference as the kernels of :mod:`estimators.matching.normal_equations` take
        it, built once (again after ``normals``, ``valid_normals`` or ``anchors`` are set):
        the k-d tree's arrays, the points, the contiguous normals (the points where none are
        stored), the valid flags, the contiguous anchors and whether normals are stored."""
        has_normals = self.normals is not None
        return (*self.search_tree.arrays, self.points,
                np.ascontiguousarray(self.normals if has_normals else self.points,
                                     dtype=np.float64),
                self.valid_normals if has_normals else np.ones(len(self.points), bool),
                np.ascontiguousarray(self.anchors), has_normals)

    def neighbours_for(
        self, query: NDArray[np.float64],
        given: tuple[NDArray[np.float64], NDArray[np.int64]] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """``kept`` and ``near`` (:func:`estimators.matching.nearest.search_near`) for the
        query points ``query`` (M, 2), updated in place by the kernels: ``given``, else those
        the last iterations on this reference left, row by row (fresh past their rows): all
        of them when they were of the same array (the same object: ICP takes a float64 array
        as it is, where ``np.asarray`` copies one whose dtype is another instance, as numba's
        are), else another scan's, whose rows mostly lie near the same beams. ICP of one scan
        from several starts, again without some of its points, or of the next scan then
        skips the searches the kept points answer and starts the others near their answer;
        the pairs stay the same bit for bit, as the kept points are this reference's wherever
        the query stood."""
        last = self._neighbours
        if given is not None:
            last = (query, *given)
        elif last is None or last[0] is not query or len(last[1]) != len(query):
            kept, near = fresh_neighbours(len(query))
            if last is not None:  # another scan's rows: seeds near the same beams' points
                rows = min(len(query), len(last[1]))
                kept[:rows], near[:rows] = last[1][:rows], last[2][:rows]
            last = (query, kept, near)
        self._neighbours = last
        return last[1], last[2]

    @classmethod
    def with_estimated_normals(
        cls, points: ArrayLike, k: int = 5, denoise: bool = False, max_k: int | None = None
    ) -> PointToLineReference:
        """Reference whose normals come from each point's ``k`` nearest neighbours
        (:func:`estimators.matching.scan_matching.estimate_normals`), found in its own k-d tree
        (:class:`estimators.matching.nearest.PointIndex`). With ``denoise``, lines pass
        through each point moved onto the curve fitted through its neighbours, with that
        curve's normal (:func:`estimators.matching.scan_matching.fit_local_curves`): pairs
        then carry the reference's range noise averaged over ``k`` readings rather than one
        reading's. With ``max_k``, neighbourhoods that do not form a line are refitted through
        up to that many points (noisy walls; see
        :func:`estimators.matching.scan_matching.estimate_normals`)."""
        reference = cls(points)
        if denoise:
            reference.normals, reference.valid_normals, reference.anchors = fit_local_curves(
                reference.points, reference.search_tree, k, max_k=max_k
            )
        else:
            reference.normals, reference.valid_normals = estimate_normals(
                reference.points, reference.search_tree, k, max_k=max_k
            )
        return reference

    def correspond(
        self, world_points: NDArray[np.float64], max_distance: float
    ) -> Correspondences:
        """Pairs for the points ``(M, 2)`` whose nearest reference point is within
        ``max_distance`` [m]."""
        if self.normals is None:
            return self._censi_pairs(world_points, np.arange(len(world_points)), max_distance)
        # Stored normals need only the nearest neighbour: half the k-d tree work.
        distances, nearest = self.search_tree.query(world_points, distance_upper_bound=max_distance)
        index = np.flatnonzero(np.isfinite(distances))
        nearest = nearest[index]
        stored = self.valid_normals[nearest]
        pairs = Correspondences(index[stored], self.anchors[nearest[stored]],
                                self.normals[nearest[stored]])
        if np.all(stored):
            return pairs
        censi = self._censi_pairs(world_points, index[~stored], max_distance)
        return Correspondences(
            np.concatenate([pairs.index, censi.index]),
            np.concatenate([pairs.anchors, censi.anchors]),
            np.concatenate([pairs.normals, censi.normals]),
        )

    def _censi_pairs(
        self, world_points: NDArray[np.float64], candidates: NDArray[np.intp], max_distance: float
    ) -> Correspondences:
        """Lines through the two nearest reference points of ``world_points[candidates]``."""
        distances, neighbours = self.search_tree.query(
            world_points[candidates], k=2, distance_upper_bound=max_distance
        )
        found = np.isfinite(distances[:, 0])
        index, neighbours = candidates[found], neighbours[found]
        nearest = neighbours[:, 0]
        has_line = np.isfinite(distances[found, 1])
        second = np.where(has_line, neighbours[:, 1], nearest)
        along = self.points[second] - self.points[nearest]
        length = np.hypot(along[:, 0], along[:, 1])
        has_line &= length > 1e-9
        normals = np.column_stack([-along[:, 1], along[:, 0]]) / np.maximum(length, 1e-12)[:, None]
        first = self.points[nearest]
        # No line: point-to-point, linearised along the current offset.
        offset = world_points[index[~has_line]] - first[~has_line]
        offset_length = np.maximum(np.hypot(offset[:, 0], offset[:, 1]), 1e-12)
        normals[~has_line] = offset / offset_length[:, None]
        return Correspondences(index, first, normals)

    def normal_equations(
        self, query_points: NDArray[np.float64], pose: NDArray[np.float64], max_distance: float,
        loss: str, scale: float,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], int, float, NDArray[np.float64]]:
        """One compiled ICP iteration of ``query_points`` (M, 2) at ``pose`` (3,): the pairs
        :meth:`correspond` makes within ``max_distance`` [m], summed into ``J^T W J`` (3, 3)
        and ``-J^T W r`` (3,) with ``loss`` at ``scale``; also the number of pairs, the RMS
        lever of the rotation column (see :func:`solve_normal_equations`) and every query
        point's residual [m] (NaN where unpaired)
        (:func:`estimators.matching.normal_equations.point_to_line_system`)."""
        residuals = np.empty(len(query_points))
        hessian, gradient, count, rotation_squares = point_to_line_system(
            *self.kernel_arrays, np.ascontiguousarray(query_points, dtype=np.float64),
            np.asarray(pose, dtype=np.float64), float(max_distance), LOSSES.index(loss),
            float(scale), residuals, *self.neighbours_for(query_points),
        )
        lever = float(np.sqrt(rotation_squares / count)) if count else 0.0
        return hessian, gradient, count, lever, residuals
