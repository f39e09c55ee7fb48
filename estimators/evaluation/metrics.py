"""Trajectory metrics: the paper's eq. 11 and the direction-aware errors it lacks.

Both trajectories are ``(N, 3)`` car poses (x [m], y [m], heading [rad]) sampled at the same
instants. They share the start pose (the estimator is reset to the true start), so by default
nothing is aligned; ``align="se2"`` first applies the rigid 2-D motion that best maps the
estimated positions onto the true ones (Umeyama 1991 without scale), as ``evo_ape -a`` does.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import compose, relative, wrap_angle

#: Steps of the true car shorter than this [m] are left out of eq. 11, which divides by the
#: true step length and is undefined for a car standing still. 1 cm is the range noise of a
#: cheap Lidar (and a fifth of the default image pixel): below it the ratio measures the
#: noise floor of any Lidar estimator, not its skill.
DEFAULT_MIN_STEP = 0.01

ALIGNMENTS: tuple[str, ...] = ("none", "se2")


def _check_trajectories(
    estimated: ArrayLike, truth: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    est = np.asarray(estimated, dtype=np.float64)
    true = np.asarray(truth, dtype=np.float64)
    for name, poses in (("estimated", est), ("truth", true)):
        if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) < 2:
            raise EstimatorInputError(
                f"{name}: expected poses of shape (N, 3), N >= 2; got {poses.shape}")
        if not np.all(np.isfinite(poses)):
            raise EstimatorInputError(f"{name}: expected finite poses, got NaN or inf")
    if est.shape != true.shape:
        raise EstimatorInputError(
            f"estimated and truth: expected equal numbers of poses, got {len(est)} and {len(true)}"
        )
    return est, true


def eq11_error(
    estimated: ArrayLike, truth: ArrayLike, min_step: float = DEFAULT_MIN_STEP
) -> float:
    """The paper's eq. 11 exactly as printed [%]: the mean relative error of the per-step
    displacement *length*, ``|(|dp_est| - |dp_true|)| / |dp_true| * 100``, over the steps
    whose true length is at least ``min_step`` [m]. NaN if no step qualifies.

    It ignores direction: an estimate going backwards at the right speed scores 0 %.
    """
    est, true = _check_trajectories(estimated, truth)
    estimated_steps = np.linalg.norm(np.diff(est[:, :2], axis=0), axis=1)  # sqrt(rx^2 + ry^2)
    true_steps = np.linalg.norm(np.diff(true[:, :2], axis=0), axis=1)  # delta real
    scored = true_steps >= min_step
    if not np.any(scored):
        return float("nan")
    # eq. 11
    relative_errors = np.abs(estimated_steps[scored] - true_steps[scored]) / true_steps[scored]
    return float(np.mean(relative_errors) * 100.0)


def accuracy(eq11_percent: float) -> float:
    """Table I's "accuracy" [%]: ``max(0, 100 - eq. 11)``.

    Eq. 11 as printed is an error (0 % is perfect), yet Table I calls 91.10 % the best
    result, so the table must report its complement; floored at 0 because eq. 11 is unbounded.
    """
    return float(max(0.0, 100.0 - eq11_percent)) if np.isfinite(eq11_percent) else float("nan")


def align_se2(estimated: ArrayLike, truth: ArrayLike) -> NDArray[np.float64]:
    """``estimated`` moved by the rigid 2-D motion (no scale) that minimises the squared
    position error to ``truth`` (Umeyama 1991); headings turn with it."""
    est, true = _check_trajectories(estimated, truth)
    est_mean, true_mean = est[:, :2].mean(axis=0), true[:, :2].mean(axis=0)
    covariance = (true[:, :2] - true_mean).T @ (est[:, :2] - est_mean)
    u, _, vt = np.linalg.svd(covariance)
    sign = np.diag([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rotation = u @ sign @ vt
    angle = np.arctan2(rotation[1, 0], rotation[0, 0])
    translation = true_mean - rotation @ est_mean
    return compose(np.array([*translation, angle]), est)


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Scores of one estimated trajectory against the truth.

    Attributes:
        eq11_error_percent: eq. 11 as printed [%] (0 is perfect).
        accuracy_percent: Table I's accuracy, ``max(0, 100 - eq. 11)`` [%].
        ate_rmse_m: RMSE of the position error [m] (after ``alignment``).
        heading_rmse_deg: RMSE of the heading error [deg] (after ``alignment``).
        rpe_translation_rmse_m: RMSE of the per-step relative pose error, translation [m].
        rpe_rotation_rmse_deg: the same, rotation [deg].
        drift_percent: end-point position error over the true distance travelled [%].
        distance_m: true distance travelled [m].
        n_poses: poses compared.
        n_steps_scored: steps long enough to enter eq. 11.
        alignment: ``"none"`` or ``"se2"``.
    """

    eq11_error_percent: float
    accuracy_percent: float
    ate_rmse_m: float
    heading_rmse_deg: float
    rpe_translation_rmse_m: float
    rpe_rotation_rmse_deg: float
    drift_percent: float
    distance_m: float
    n_poses: int
    n_steps_scored: int
    alignment: str

    def as_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


def _rms(values: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(values**2)))


def evaluate(
    estimated: ArrayLike,
    truth: ArrayLike,
    min_step: float = DEFAULT_MIN_STEP,
    align: str = "none",
) -> TrajectoryMetrics:
    """All metrics of ``estimated`` (N, 3) against ``truth`` (N, 3), same instants.

    ``min_step`` [m] applies to eq. 11 only; ``align`` is ``"none"`` (default: trajectories
    share the start pose) or ``"se2"`` and applies to ATE, heading RMSE and drift (RPE and
    eq. 11 compare steps and do not depend on it).
    """
    if align not in ALIGNMENTS:
        raise ConfigError(f"unknown align {align!r}: expected one of {', '.join(ALIGNMENTS)}")
    if not np.isfinite(min_step) or min_step <= 0:
        raise ConfigError(f"min_step: expected a positive number [m], got {min_step!r}")
    est, true = _check_trajectories(estimated, truth)
    eq11 = eq11_error(est, true, min_step)
    true_steps = np.linalg.norm(np.diff(true[:, :2], axis=0), axis=1)
    distance = float(true_steps.sum())
    compared = align_se2(est, true) if align == "se2" else est
    position_errors = np.linalg.norm(compared[:, :2] - true[:, :2], axis=1)
    heading_errors = wrap_angle(compared[:, 2] - true[:, 2])
    # RPE: the true step seen from the estimated step, (true_k^-1 true_k+1)^-1 (est_k^-1 est_k+1)
    step_errors = relative(relative(true[:-1], true[1:]), relative(est[:-1], est[1:]))
    return TrajectoryMetrics(
        eq11_error_percent=eq11,
        accuracy_percent=accuracy(eq11),
        ate_rmse_m=_rms(position_errors),
        heading_rmse_deg=float(np.rad2deg(_rms(heading_errors))),
        rpe_translation_rmse_m=_rms(np.linalg.norm(step_errors[:, :2], axis=1)),
        rpe_rotation_rmse_deg=float(np.rad2deg(_rms(step_errors[:, 2]))),
        drift_percent=float(position_errors[-1] / distance * 100.0) if distance > 0 else np.nan,
        distance_m=distance,
        n_poses=len(true),
        n_steps_scored=int(np.sum(true_steps >= min_step)),
        alignment=align,
    )
