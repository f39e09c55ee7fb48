"""TUM trajectory files: round trip, and readable by evo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimators.evaluation.tum import read_tum, write_tum


def _trajectory() -> tuple[np.ndarray, np.ndarray]:
    times = 0.1 * np.arange(20)
    poses = np.column_stack(
        [np.linspace(0, 3, 20), np.sin(np.linspace(0, 2, 20)), np.linspace(-3.1, 3.1, 20)]
    )
    return times, poses


def test_round_trip(tmp_path: Path) -> None:
    times, poses = _trajectory()
    path = tmp_path / "est.tum"
    write_tum(path, times, poses)
    read_times, read_poses = read_tum(path)
    np.testing.assert_allclose(read_times, times, atol=1e-9)
    np.testing.assert_allclose(read_poses, poses, atol=1e-8)


def test_evo_reads_the_file(tmp_path: Path) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    times, poses = _trajectory()
    path = tmp_path / "est.tum"
    write_tum(path, times, poses)
    trajectory = file_interface.read_tum_trajectory_file(str(path))
    np.testing.assert_allclose(trajectory.timestamps, times, atol=1e-9)
    np.testing.assert_allclose(trajectory.positions_xyz[:, :2], poses[:, :2], atol=1e-8)
    # evo's quaternions are (w, x, y, z); yaw about +z is the heading
    w, x, y, z = trajectory.orientations_quat_wxyz.T
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y**2 + z**2))
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - poses[:, 2]))), 0.0, atol=1e-8)


def test_non_planar_or_malformed_files_are_readable_errors(tmp_path: Path) -> None:
    path = tmp_path / "bad.tum"
    path.write_text("0 1 2 0.5 0 0 0 1\n")
    with pytest.raises(ValueError, match="planar"):
        read_tum(path)
    path.write_text("0 1 2 0 0 0 1\n")
    with pytest.raises(ValueError, match="expected 8 columns"):
        read_tum(path)
    with pytest.raises(ValueError, match=r"times: expected shape \(20,\)"):
        write_tum(path, np.zeros(3), _trajectory()[1])
