"""Closed-form hand-eye calibration on SE(2): the pose of Lidar k in Lidar 1's frame from the
two Lidars' own motions.

Two sensors rigidly on one body move by ``A_i`` (Lidar 1) and ``B_i`` (Lidar k, each in its own
frame) over the same interval ``i``; the mount ``X`` (Lidar k in Lidar 1) satisfies
``A_i X = X B_i``. In the plane the rotations commute, so the yaw increments of ``A_i`` and
``B_i`` are equal for every ``X`` (they check the data, they cannot give the mount's heading);
the translation part

    (R(a_i) - I) t_X - R(phi) t_B_i = -t_A_i                                  (hand-eye, SE(2))

is linear in ``(t_x, t_y, cos phi, sin phi)``: one least-squares solve gives the heading
``phi`` of the mount from how the two sensors' translations turn, then Gauss-Newton on
``(t_x, t_y, phi)`` polishes it with robust (Cauchy) weights.

Observability: ``(R(a) - I)^T (R(a) - I) = 2 (1 - cos a) I``, so the lever arm ``t_X`` is seen
only through rotation, both of its components alike; a drive without rotation gives the
heading (from any translation) and no lever arm at all. :func:`solve_hand_eye` reports a
parameter whose standard deviation (from the residuals) exceeds its limit as unobservable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.matching.point_to_line import robust_weights
from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import relative, wrap_angle

#: Mount parameters in the order of every (3,) array here.
PARAMETERS: tuple[str, ...] = ("x", "y", "heading")
#: A parameter whose 1-sigma exceeds this is unobservable: [m], [m], [rad].
DEFAULT_MAX_STD = np.array([0.02, 0.02, np.radians(1.0)])
#: Intervals [scan steps] between the paired poses: short ones are precise, long ones turn more.
DEFAULT_WINDOWS: tuple[int, ...] = (1, 3, 10, 30)
#: Robust scale [m] of the residuals: a few times the per-interval odometry error.
LOSS_SCALE = 0.02


@dataclass(frozen=True)
class HandEyeSolution:
    """The mount of Lidar k in Lidar 1's frame from motion alone.

    Attributes:
        mount: ``(3,)`` (x [m], y [m], heading [rad]); unobservable entries hold the guess.
        std: ``(3,)`` 1-sigma [m, m, rad] from the residuals (``inf`` when unobservable).
        unobservable: names (of :data:`PARAMETERS`) the drive could not determine.
        residual_rms: [m] RMS of the translation residuals.
        yaw_mismatch_rms: [rad] RMS difference of the two sensors' yaw increments (0 for a rigid
            mount and perfect odometry; large means failed odometry or unsynchronised clocks).
        intervals: number of motion pairs used.
    """

    mount: NDArray[np.float64]
    std: NDArray[np.float64]
    unobservable: tuple[str, ...]
    residual_rms: float
    yaw_mismatch_rms: float
    intervals: int


def interval_motions(poses: ArrayLike, windows: tuple[int, ...] = DEFAULT_WINDOWS
                     ) -> NDArray[np.float64]:
    """``(M, 3)`` relative motions ``poses[i]^-1 poses[i + w]`` for every ``w`` in ``windows``."""
    poses = np.asarray(poses, dtype=np.float64)
    rows = [relative(poses[i], poses[i + w]) for w in windows for i in range(len(poses) - w)]
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def _linear_system(a: NDArray, b: NDArray, phi: float) -> tuple[NDArray, NDArray]:
    """Residuals (2M,) of the hand-eye equation and their Jacobian (2M, 3) at ``(t, phi)``=0."""
    cos_a, sin_a = np.cos(a[:, 2]), np.sin(a[:, 2])
    c, s = np.cos(phi), np.sin(phi)
    rotated = np.column_stack([c * b[:, 0] - s * b[:, 1], s * b[:, 0] + c * b[:, 1]])
    jacobian = np.zeros((2 * len(a), 3))
    jacobian[0::2, 0], jacobian[0::2, 1] = cos_a - 1.0, -sin_a
    jacobian[1::2, 0], jacobian[1::2, 1] = sin_a, cos_a - 1.0
    jacobian[0::2, 2], jacobian[1::2, 2] = rotated[:, 1], -rotated[:, 0]
    return (a[:, :2] - rotated).reshape(-1), jacobian


def _initial_heading(a: NDArray, b: NDArray, weights: NDArray) -> float:
    """The closed-form least-squares solve in ``(t_x, t_y, cos phi, sin phi)``; its heading."""
    cos_a, sin_a = np.cos(a[:, 2]), np.sin(a[:, 2])
    design = np.zeros((2 * len(a), 4))
    design[0::2, :2] = np.column_stack([cos_a - 1.0, -sin_a])
    design[1::2, :2] = np.column_stack([sin_a, cos_a - 1.0])
    design[0::2, 2:] = np.column_stack([-b[:, 0], b[:, 1]])
    design[1::2, 2:] = np.column_stack([-b[:, 1], -b[:, 0]])
    w = np.repeat(np.sqrt(weights), 2)
    solution, *_ = np.linalg.lstsq(design * w[:, None], -a[:, :2].reshape(-1) * w, rcond=None)
    return float(np.arctan2(solution[3], solution[2]))


def solve_hand_eye(
    motions_1: ArrayLike,
    motions_k: ArrayLike,
    guess: ArrayLike = (0.0, 0.0, 0.0),
    max_std: ArrayLike = DEFAULT_MAX_STD,
    iterations: int = 10,
) -> HandEyeSolution:
    """Solve ``A_i X = X B_i`` for the mount ``X`` (see the module docstring).

    Args:
        motions_1: ``(M, 3)`` motions of Lidar 1 in its own frame (x [m], y [m], yaw [rad]).
        motions_k: ``(M, 3)`` motions of Lidar k over the same intervals, in its own frame.
        guess: ``(3,)`` the mount used for parameters the motions cannot determine.
        max_std: ``(3,)`` largest 1-sigma [m, m, rad] a parameter may have to count as known.
        iterations: Gauss-Newton iterations after the closed-form start.
    """
    a, b = np.asarray(motions_1, dtype=np.float64), np.asarray(motions_k, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape or len(a) < 3:
        raise EstimatorInputError(f"motions: expected two (M >= 3, 3) arrays of equal shape, "
                                  f"got {a.shape} and {b.shape}")
    guess = np.asarray(guess, dtype=np.float64)
    limits = np.asarray(max_std, dtype=np.float64)
    weights = np.ones(len(a))
    phi = _initial_heading(a, b, weights)
    # The lever arm is solved only where the rotations make it observable.
    lever = guess[:2].copy()
    for _ in range(iterations):
        residuals, jacobian = _linear_system(a, b, phi)
        residuals = residuals + (jacobian[:, :2] @ lever)
        w2 = np.repeat(weights, 2)
        normal = (jacobian * w2[:, None]).T @ jacobian
        step = _damped_solve(normal, -(jacobian * w2[:, None]).T @ residuals)
        lever, phi = lever + step[:2], float(wrap_angle(phi + step[2]))
        per_pair = np.hypot(*(residuals + jacobian @ step).reshape(-1, 2).T)
        weights = robust_weights(per_pair, "cauchy", LOSS_SCALE)
    residuals, jacobian = _linear_system(a, b, phi)
    residuals = residuals + jacobian[:, :2] @ lever
    std = _standard_deviations(jacobian, residuals, np.repeat(weights, 2))
    unknown = std > limits
    mount = np.where(unknown, guess, np.r_[lever, phi])
    return HandEyeSolution(
        mount=mount, std=np.where(unknown, np.inf, std),
        unobservable=tuple(p for p, u in zip(PARAMETERS, unknown, strict=True) if u),
        residual_rms=float(np.sqrt(np.mean(residuals**2) * 2)),
        yaw_mismatch_rms=float(np.sqrt(np.mean(wrap_angle(a[:, 2] - b[:, 2]) ** 2))),
        intervals=len(a))


def batch_standard_error(samples: ArrayLike, center: ArrayLike) -> NDArray[np.float64]:
    """``(3,)`` standard error [m, m, rad] of a mean from ``(B, 3)`` solutions over B disjoint
    time blocks of one drive (batch means): unlike the residuals' sigma it keeps the errors
    that are correlated within a block (odometry drift, the same walls seen step after step).
    Headings are taken relative to ``center``; a robust spread (1.4826 MAD) lets one bad block
    pass; ``inf`` with fewer than 3 blocks."""
    samples = np.asarray(samples, dtype=np.float64).reshape(-1, 3)
    if len(samples) < 3:
        return np.full(3, np.inf)
    offsets = samples - np.asarray(center, dtype=np.float64)
    offsets[:, 2] = wrap_angle(offsets[:, 2])
    spread = 1.4826 * np.median(np.abs(offsets - np.median(offsets, axis=0)), axis=0)
    return spread / np.sqrt(len(samples) - 1)


def block_solutions(poses_1: ArrayLike, poses_k: ArrayLike, guess: ArrayLike, blocks: int = 6,
                    windows: tuple[int, ...] = DEFAULT_WINDOWS) -> NDArray[np.float64]:
    """``(B', 3)`` hand-eye mounts from each of ``blocks`` contiguous stretches of the two
    trajectories (``(N, 3)`` each); stretches too short or without the rotation to observe
    the whole mount are left out."""
    solutions = []
    for index in np.array_split(np.arange(len(poses_1)), blocks):
        if len(index) < max(windows) + 3:
            continue
        a = interval_motions(np.asarray(poses_1)[index], windows)
        b = interval_motions(np.asarray(poses_k)[index], windows)
        solution = solve_hand_eye(a, b, guess)
        if not solution.unobservable:
            solutions.append(solution.mount)
    return np.array(solutions, dtype=np.float64).reshape(-1, 3)


def _damped_solve(normal: NDArray, gradient: NDArray) -> NDArray:
    """Solve ``normal d = gradient``; directions without information get no step."""
    values, vectors = np.linalg.eigh(normal)
    keep = values > 1e-9 * max(values.max(), 1e-300)
    inverse = np.where(keep, 1.0 / np.where(keep, values, 1.0), 0.0)
    return vectors @ (inverse * (vectors.T @ gradient))


def _standard_deviations(jacobian: NDArray, residuals: NDArray, weights: NDArray) -> NDArray:
    """1-sigma of each parameter: ``sigma^2 (J^T W J)^-1`` with ``sigma^2`` from the weighted
    residuals (``inf`` along directions without information)."""
    normal = (jacobian * weights[:, None]).T @ jacobian
    dof = max(int(np.sum(weights > 0.5)) - 3, 1)
    sigma2 = float(np.sum(weights * residuals**2)) / dof
    values, vectors = np.linalg.eigh(normal)
    floor = 1e-12 * max(values.max(), 1e-300)
    # 1e30 stands for "no information" (inf would turn 0 * inf into NaN in the product).
    variance = (vectors**2) @ np.where(values > floor, sigma2 / np.maximum(values, floor), 1e30)
    return np.sqrt(variance)
