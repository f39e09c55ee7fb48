"""Planar trajectories in the TUM format (``t x y z qx qy qz qw`` per line), as ``evo`` reads.

A planar pose (x [m], y [m], heading [rad]) becomes ``z = 0`` and the quaternion of a
rotation by ``heading`` about +z: ``(0, 0, sin(heading/2), cos(heading/2))``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import EstimatorInputError, LogFormatError
from lidar_env.core.se2 import wrap_angle

#: Largest z [m] or roll/pitch quaternion component accepted as planar when reading.
PLANAR_TOLERANCE = 1e-6


def write_tum(path: str | Path, times: ArrayLike, poses: ArrayLike) -> None:
    """Write ``times`` (N,) [s] and planar ``poses`` (N, 3) to ``path`` in TUM format."""
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise EstimatorInputError(f"poses: expected shape (N, 3), got {poses.shape}")
    if times.shape != (len(poses),):
        raise EstimatorInputError(f"times: expected shape ({len(poses)},), got {times.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(poses))):
        raise EstimatorInputError("times and poses: expected finite values, got NaN or inf")
    half = poses[:, 2] / 2.0
    zeros = np.zeros(len(poses))
    rows = np.column_stack([times, poses[:, :2], zeros, zeros, zeros, np.sin(half), np.cos(half)])
    np.savetxt(path, rows, fmt="%.9f", header="t x y z qx qy qz qw")


def read_tum(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Read a planar TUM file; return ``times`` (N,) [s] and ``poses`` (N, 3).

    Lines starting with ``#`` are comments. Raises ``ValueError`` for a line that is not 8
    numbers or a pose that leaves the plane (z or roll/pitch beyond ``PLANAR_TOLERANCE``).
    """
    rows = np.loadtxt(path, comments="#", ndmin=2)
    if rows.size == 0:
        raise LogFormatError(f"{path}: expected TUM lines 't x y z qx qy qz qw', found none")
    if rows.shape[1] != 8:
        raise LogFormatError(
            f"{path}: expected 8 columns 't x y z qx qy qz qw', got {rows.shape[1]}")
    t, x, y, z, qx, qy, qz, qw = rows.T
    norm = np.sqrt(qx**2 + qy**2 + qz**2 + qw**2)
    if np.any(norm == 0):
        raise LogFormatError(f"{path}: expected unit quaternions, got a zero quaternion")
    off_plane = np.maximum.reduce([np.abs(z), np.abs(qx) / norm, np.abs(qy) / norm])
    if np.any(off_plane > PLANAR_TOLERANCE):
        line = int(np.argmax(off_plane > PLANAR_TOLERANCE))
        raise LogFormatError(
            f"{path}: expected a planar trajectory (z = qx = qy = 0), pose {line} leaves the plane"
        )
    heading = 2.0 * np.arctan2(qz, qw)
    return t, np.column_stack([x, y, wrap_angle(heading)])
