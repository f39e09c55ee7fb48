"""Put an estimated trajectory into a reference's frame before drawing it
(:func:`align_to_reference`).

An estimator on a real log starts at its own origin, so its map is drawn in an arbitrary
frame; beside the reference (pseudo-truth) map it looks rotated even when it is right. The
fix is the least-squares rigid motion (SE(2), no scale; Umeyama 1991 via
:func:`estimators.evaluation.metrics.align_se2`) that brings the estimated positions onto the
reference positions at the same times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import compose, inverse


@dataclass(frozen=True)
class Alignment:
    """The aligned poses ``(N, 3)`` [m, m, rad] in the reference frame, the motion applied
    (``transform``: x [m], y [m], angle [rad]), the RMS position residual [m] over the
    ``matched`` time pairs."""

    poses: NDArray[np.float64]
    transform: NDArray[np.float64]
    residual_m: float
    matched: int


def align_to_reference(times: ArrayLike, poses: ArrayLike, reference_times: ArrayLike,
                       reference_poses: ArrayLike, tolerance: float = 0.05) -> Alignment:
    """``poses`` (N, 3) at ``times`` (N,) [s] moved by the rigid motion that best fits them,
    in the least-squares sense, to ``reference_poses`` (M, 3) at ``reference_times`` (M,) [s]:
    each reference time is paired with the nearest estimate time within ``tolerance`` [s].
    Needs at least two pairs at distinct positions."""
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    reference_times = np.asarray(reference_times, dtype=np.float64)
    reference_poses = np.asarray(reference_poses, dtype=np.float64)
    for name, t, p in (("poses", times, poses), ("reference_poses", reference_times,
                                                 reference_poses)):
        if p.ndim != 2 or p.shape[1] != 3 or len(p) != len(t) or not np.all(np.isfinite(p)):
            raise EstimatorInputError(f"{name}: expected finite (N, 3) poses, one per time "
                                      f"({len(t)}), got shape {p.shape}")
    if len(times) == 0:
        raise EstimatorInputError("times: expected at least one estimated pose, got none")
    order = np.argsort(times, kind="stable")
    slot = np.clip(np.searchsorted(times[order], reference_times), 1, max(len(times) - 1, 1))
    before, after = order[slot - 1], order[np.minimum(slot, len(times) - 1)]
    nearest = np.where(np.abs(times[before] - reference_times)
                       <= np.abs(times[after] - reference_times), before, after)
    paired = np.abs(times[nearest] - reference_times) <= tolerance
    estimate, reference = poses[nearest[paired]], reference_poses[paired]
    if len(estimate) < 2 or np.ptp(reference[:, :2], axis=0).max() == 0:
        raise EstimatorInputError(
            f"times: expected at least two reference times at distinct positions within "
            f"{tolerance} s of an estimate time, got {len(estimate)} pairs")
    from estimators.evaluation.metrics import align_se2

    fitted = align_se2(estimate, reference)
    transform = compose(fitted[0], inverse(estimate[0]))
    residual = float(np.sqrt(np.mean(np.sum((fitted[:, :2] - reference[:, :2]) ** 2, axis=1))))
    return Alignment(compose(transform, poses), transform, residual, int(len(estimate)))
