"""Refine a Lidar's mount by aligning its scans with Lidar 1's scans of the same instants.

Two Lidars on one car scan the same walls at the same time from two viewpoints: point-to-line
ICP of Lidar k's scan onto Lidar 1's scan (:func:`estimators.matching.icp.register`) measures
the pose of Lidar k in Lidar 1's frame, the mount itself, at every step where their views
overlap. The per-step measurements are combined by their ICP information (``J^T W J / s^2`` of
the point-to-line residuals), after dropping steps whose match explains too few points or lies
far from the others; the reported 1-sigma is the larger of the information's and the
batch-means error over time blocks (steps share the same walls, so their errors are not
independent). A direction the walls do
not constrain (a long featureless corridor) shows as a parameter without information.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import Sensor
from estimators.calibration.hand_eye import DEFAULT_MAX_STD, PARAMETERS, batch_standard_error
from estimators.matching.icp import ICPParams, register
from estimators.matching.point_to_line import (
    PointToLineReference,
    point_to_line_jacobian,
    robust_weights,
)
from estimators.matching.scan_matching import scan_to_points
from lidar_env.core.se2 import transform_points, wrap_angle

#: Steps aligned at most (evenly spread over the drive).
MAX_STEPS = 60
#: Share of Lidar k's points a match must explain to count as overlapping views.
MIN_QUALITY = 0.4
#: Fewest overlapping steps to trust the alignment.
MIN_STEPS = 5
#: Steps further than this many robust sigmas from the median are dropped.
OUTLIER_SIGMAS = 4.0
#: Time blocks whose mean alignments give the batch-means standard error.
BATCHES = 6
#: ICP settings: the defaults, with room to converge from a start tens of cm off.
ALIGNMENT_ICP = ICPParams(max_iterations=50)


@dataclass(frozen=True)
class Alignment:
    """Lidar k's mount in Lidar 1's frame from simultaneous scans.

    Attributes:
        mount: ``(3,)`` (x [m], y [m], heading [rad]); unobservable entries hold the start.
        std: ``(3,)`` 1-sigma [m, m, rad] (``inf`` when unobservable).
        unobservable: names of :data:`PARAMETERS` the scans do not constrain.
        steps: overlapping steps used.
        median_quality: median share of Lidar k's points explained by Lidar 1's scan.
    """

    mount: NDArray[np.float64]
    std: NDArray[np.float64]
    unobservable: tuple[str, ...]
    steps: int
    median_quality: float

    @property
    def overlapping(self) -> bool:
        return self.steps >= MIN_STEPS


def _information(reference: PointToLineReference, points: NDArray, pose: NDArray,
                 params: ICPParams) -> NDArray:
    """ICP information (3, 3) [1/m^2, ..] of one converged match."""
    world = transform_points(pose, points)
    pairs = reference.correspond(world, params.inlier_distance)
    moved = world[pairs.index]
    residuals = np.einsum("ij,ij->i", moved - pairs.anchors, pairs.normals)
    jacobian = point_to_line_jacobian(moved, pose[:2], pairs.normals)
    weights = robust_weights(residuals, params.loss, params.loss_scale)
    sigma2 = max(float(np.sum(weights * residuals**2) / max(np.sum(weights) - 3, 1)), 1e-8)
    return (jacobian * weights[:, None]).T @ jacobian / sigma2


def align_scans(
    scans_1: ArrayLike,
    scans_k: ArrayLike,
    sensor_1: Sensor,
    sensor_k: Sensor,
    start: ArrayLike,
    max_std: ArrayLike = DEFAULT_MAX_STD,
    params: ICPParams = ALIGNMENT_ICP,
) -> Alignment:
    """Align ``scans_k`` (N, n_k) onto ``scans_1`` (N, n_1), taken at the same N instants, from
    ``start`` (3,) (pose of Lidar k in Lidar 1's frame); see the module docstring."""
    scans_1, scans_k = np.asarray(scans_1), np.asarray(scans_k)
    start = np.asarray(start, dtype=np.float64)
    steps = np.unique(np.linspace(0, len(scans_1) - 1, min(MAX_STEPS, len(scans_1))).astype(int))
    poses, informations, qualities = [], [], []
    for step in steps:
        reference_points = scan_to_points(scans_1[step], sensor_1.beam_angles, sensor_1.max_range)
        query = scan_to_points(scans_k[step], sensor_k.beam_angles, sensor_k.max_range)
        if len(reference_points) < 10 or len(query) < 10:
            qualities.append(0.0)
            continue
        reference = PointToLineReference.with_estimated_normals(reference_points)
        match = register(reference, query, start, params)
        qualities.append(match.quality)
        if match.converged and match.quality >= MIN_QUALITY:
            poses.append(match.pose)
            informations.append(_information(reference, query, match.pose, params))
    median_quality = float(np.median(qualities)) if qualities else 0.0
    if len(poses) < MIN_STEPS:
        return Alignment(start.copy(), np.full(3, np.inf), PARAMETERS, len(poses), median_quality)
    return _combine(np.array(poses), np.array(informations), start, np.asarray(max_std),
                    median_quality)


def _combine(poses: NDArray, informations: NDArray, start: NDArray, limits: NDArray,
             median_quality: float) -> Alignment:
    poses = poses.copy()
    poses[:, 2] = start[2] + wrap_angle(poses[:, 2] - start[2])
    median = np.median(poses, axis=0)
    spread = 1.4826 * np.median(np.abs(poses - median), axis=0) + np.array([1e-4, 1e-4, 1e-5])
    keep = np.all(np.abs(poses - median) <= OUTLIER_SIGMAS * spread, axis=1)
    poses, informations = poses[keep], informations[keep]
    total = informations.sum(axis=0)
    values, vectors = np.linalg.eigh(total)
    known = values > 1e-9 * values.max()
    inverse = (vectors * np.where(known, 1.0 / np.where(known, values, 1.0), 0.0)) @ vectors.T
    mount = inverse @ np.einsum("nij,nj->i", informations, poses)
    # Directions without information keep the start (the combination gives them 0).
    free = vectors[:, ~known]
    mount = mount + free @ (free.T @ start)
    info_std = np.sqrt(np.where(np.diag(inverse) > 0, np.diag(inverse), np.inf))
    info_std[np.any(np.abs(free) > 1e-6, axis=1)] = np.inf
    batches = [batch.mean(axis=0) for batch in np.array_split(poses, min(BATCHES, len(poses)))]
    std = np.maximum(info_std, batch_standard_error(batches, mount))
    unknown = std > limits
    return Alignment(np.where(unknown, start, mount), np.where(unknown, np.inf, std),
                     tuple(p for p, u in zip(PARAMETERS, unknown, strict=True) if u),
                     len(poses), median_quality)
