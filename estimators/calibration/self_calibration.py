"""Extrinsic self-calibration: the mounts of Lidars 2..K relative to Lidar 1 from one drive,
with no ground truth and no wheel odometry.

1. Each Lidar's own odometry: a registered estimator (``lidar_odometry`` by default) run on
   that Lidar alone, as if it sat at the car's origin, gives the sensor's own trajectory.
2. Hand-eye on SE(2) (:mod:`estimators.calibration.hand_eye`): the mount from the two
   sensors' motions over the same intervals, with its uncertainty and what it cannot observe.
3. Refinement (:mod:`estimators.calibration.alignment`): where the Lidars' views overlap,
   aligning their simultaneous scans measures the mount directly, starting from step 2.

The car frame stays the user's: Lidar 1 keeps its configured mount, and
:meth:`Calibration.setup` places Lidar k at ``mount_1 (+) X_k``.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import Sensor, SensorSetup
from estimators.calibration.alignment import Alignment, align_scans
from estimators.calibration.hand_eye import (
    DEFAULT_MAX_STD,
    DEFAULT_WINDOWS,
    PARAMETERS,
    HandEyeSolution,
    batch_standard_error,
    block_solutions,
    interval_motions,
    solve_hand_eye,
)
from estimators.registry import make
from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import compose, relative


class UnobservableMountError(EstimatorInputError):
    """A mount was asked for whose parameters the calibration drive could not determine."""


class NoOverlapWarning(UserWarning):
    """Two Lidars' scans share too little of the world to refine the mount by alignment."""


class InconsistentMotionWarning(UserWarning):
    """Two Lidars' own odometries turn by different amounts: they do not move as one body."""


#: [rad] RMS difference of two rigidly mounted Lidars' yaw increments above which their
#: odometry (or their clocks) cannot be trusted for hand-eye calibration.
MAX_YAW_MISMATCH = 0.01


@dataclass(frozen=True)
class MountEstimate:
    """Lidar k's pose in Lidar 1's frame, as the drive determined it.

    Attributes:
        key: the Lidar's observation key (``lidar_2`` ...).
        value: ``(3,)`` (x [m], y [m], heading [rad]); unobservable entries hold the guess and
            are not estimates (use :meth:`known` / :attr:`unobservable`).
        std: ``(3,)`` 1-sigma [m, m, rad]; ``inf`` for unobservable entries.
        unobservable: names of :data:`PARAMETERS` the drive could not determine.
        source: ``"hand-eye"`` or ``"scan alignment"`` (where the final numbers come from).
        hand_eye: the motion-only solution.
        alignment: the scan-alignment refinement, or ``None`` when not run.
    """

    key: str
    value: NDArray[np.float64]
    std: NDArray[np.float64]
    unobservable: tuple[str, ...]
    source: str
    hand_eye: HandEyeSolution
    alignment: Alignment | None

    def known(self) -> NDArray[np.float64]:
        """The mount (3,); raises :class:`UnobservableMountError` when part of it is unknown."""
        if self.unobservable:
            raise UnobservableMountError(
                f"{self.key}: the drive does not determine {', '.join(self.unobservable)} of "
                "the mount (a drive without rotation cannot give the lever arm from motion; "
                "overlapping views can): drive with turns, or give them")
        return self.value.copy()

    def describe(self) -> str:
        """One line: each parameter with its 1-sigma, or ``unobservable``."""
        scale = (1.0, 1.0, 180.0 / np.pi)
        units = ("m", "m", "deg")
        parts = [f"{name} unobservable" if name in self.unobservable else
                 f"{name} {v * s:+.4f} +- {e * s:.4f} {u}"
                 for name, v, e, s, u in zip(PARAMETERS, self.value, self.std, scale, units,
                                             strict=True)]
        return f"{self.key} in lidar_1: " + ", ".join(parts) + f"  [{self.source}]"


@dataclass(frozen=True)
class Calibration:
    """Every Lidar's mount relative to Lidar 1 (``mounts[0]`` is Lidar 2)."""

    mounts: tuple[MountEstimate, ...]
    odometry: dict[str, NDArray[np.float64]]

    def setup(self, configured: SensorSetup) -> SensorSetup:
        """``configured`` with Lidars 2..K re-mounted at ``mount_1 (+) X_k`` (Lidar 1 and every
        beam geometry as configured); raises if a mount is not fully determined."""
        base = configured.sensors[0]
        sensors = [base] + [Sensor(compose(base.mount, m.known()), s.beam_angles, s.max_range)
                            for m, s in zip(self.mounts, configured.sensors[1:], strict=True)]
        return SensorSetup(sensors=sensors, world_aligned=configured.world_aligned)


def sensor_odometry(scans: ArrayLike, sensor: Sensor, times: ArrayLike,
                    estimator: str = "lidar_odometry") -> NDArray[np.float64]:
    """``(N, 3)`` trajectory of one Lidar in its own first frame, from its scans alone."""
    model = make(estimator)
    model.reset(SensorSetup(sensors=[Sensor(np.zeros(3), sensor.beam_angles, sensor.max_range)]))
    for ranges, t in zip(np.asarray(scans), np.asarray(times), strict=True):
        model.update({"lidar_1": ranges}, float(t))
    return model.trajectory


def calibrate(
    recording: Any,
    guess: ArrayLike | None = None,
    *,
    estimator: str = "lidar_odometry",
    refine: bool = True,
    windows: tuple[int, ...] = DEFAULT_WINDOWS,
    max_std: ArrayLike = DEFAULT_MAX_STD,
) -> Calibration:
    """Estimate the mounts of Lidars 2..K relative to Lidar 1 from a drive.

    Args:
        recording: anything with ``setup`` (a :class:`SensorSetup`), ``times`` (N,) [s] and
            ``scans`` ``{key: (N, n_k)}``: a :class:`estimators.datasets.Recording` (a bag),
            or a recorded env drive (:class:`estimators.leaderboard.records.SensorDataset`).
            Its configured mounts are not used, except as the guess when ``guess`` is None.
        guess: ``(K - 1, 3)`` poses of Lidars 2..K in Lidar 1's frame, used for what the drive
            cannot observe and to start the alignment; default: from ``recording.setup``.
        estimator: the registered estimator each Lidar's own odometry comes from.
        refine: align simultaneous scans where the views overlap (see the module docstring).
        windows: intervals [scan steps] of the hand-eye motion pairs.
        max_std: ``(3,)`` largest 1-sigma [m, m, rad] of a parameter that counts as known.
    """
    setup: SensorSetup = recording.setup
    if setup.n_lidars < 2:
        raise EstimatorInputError(
            f"recording: expected at least 2 Lidars to calibrate one against the other, got "
            f"{setup.n_lidars} ({', '.join(setup.keys)})")
    if setup.world_aligned:
        raise EstimatorInputError("recording: expected scans in each sensor's frame; "
                                  "world-aligned scans hide the sensors' headings")
    times = np.asarray(recording.times, dtype=np.float64)
    if len(times) < max(windows) + 3:
        raise EstimatorInputError(f"recording: expected at least {max(windows) + 3} scans for "
                                  f"the motion windows {windows}, got {len(times)}")
    guesses = _guesses(setup, guess)
    odometry = {key: sensor_odometry(recording.scans[key], sensor, times, estimator)
                for key, sensor in zip(setup.keys, setup.sensors, strict=True)}
    motions_1 = interval_motions(odometry[setup.keys[0]], windows)
    estimates = []
    for k in range(1, setup.n_lidars):
        key = setup.keys[k]
        solution = solve_hand_eye(motions_1, interval_motions(odometry[key], windows),
                                  guesses[k - 1], max_std)
        solution = _with_block_spread(solution, odometry[setup.keys[0]], odometry[key],
                                      windows, np.asarray(max_std, dtype=np.float64))
        if solution.yaw_mismatch_rms > MAX_YAW_MISMATCH:
            warnings.warn(
                f"{key}: its own odometry turns unlike lidar_1's (yaw increments differ by "
                f"{solution.yaw_mismatch_rms:.3f} rad RMS): not one rigid body, unsynchronised "
                "clocks, or failed odometry; the hand-eye mount is doubtful",
                InconsistentMotionWarning, stacklevel=2)
        alignment = None
        if refine:
            alignment = align_scans(recording.scans[setup.keys[0]], recording.scans[key],
                                    setup.sensors[0], setup.sensors[k], solution.mount, max_std)
            if not alignment.overlapping:
                warnings.warn(
                    f"{key}: its scans overlap too little with lidar_1's to refine the mount "
                    f"(median match quality {alignment.median_quality:.2f}, "
                    f"{alignment.steps} usable steps); the mount is from motion only",
                    NoOverlapWarning, stacklevel=2)
        estimates.append(_merge(key, solution, alignment))
    return Calibration(tuple(estimates), odometry)


def _with_block_spread(solution: HandEyeSolution, poses_1: NDArray, poses_k: NDArray,
                       windows: tuple[int, ...], limits: NDArray) -> HandEyeSolution:
    """The solution with each 1-sigma raised to the batch-means error of per-block solutions
    (the residuals' sigma treats overlapping motion pairs as independent: too small)."""
    if solution.unobservable:
        return solution
    blocks = block_solutions(poses_1, poses_k, solution.mount, windows=windows)
    if len(blocks) < 3:
        return solution
    std = np.maximum(solution.std, batch_standard_error(blocks, solution.mount))
    unknown = std > limits
    return dataclasses.replace(
        solution, std=np.where(unknown, np.inf, std),
        unobservable=tuple(p for p, u in zip(PARAMETERS, unknown, strict=True) if u))


def _guesses(setup: SensorSetup, guess: ArrayLike | None) -> NDArray[np.float64]:
    if guess is None:
        return np.array([relative(setup.mounts[0], m) for m in setup.mounts[1:]])
    guesses = np.asarray(guess, dtype=np.float64).reshape(-1, 3)
    if len(guesses) != setup.n_lidars - 1 or not np.all(np.isfinite(guesses)):
        raise EstimatorInputError(f"guess: expected {setup.n_lidars - 1} finite rows (x, y, "
                                  f"heading) for lidar_2..lidar_{setup.n_lidars}, got "
                                  f"{np.asarray(guess).tolist()!r}")
    return guesses


def _merge(key: str, solution: HandEyeSolution, alignment: Alignment | None) -> MountEstimate:
    """The alignment's numbers where it determines them, else the hand-eye's."""
    if alignment is None or not alignment.overlapping:
        return MountEstimate(key, solution.mount, solution.std, solution.unobservable,
                             "hand-eye", solution, alignment)
    from_alignment = np.isfinite(alignment.std)
    value = np.where(from_alignment, alignment.mount, solution.mount)
    std = np.where(from_alignment, alignment.std, solution.std)
    unobservable = tuple(p for p, s in zip(PARAMETERS, std, strict=True) if not np.isfinite(s))
    return MountEstimate(key, value, std, unobservable, "scan alignment", solution, alignment)
