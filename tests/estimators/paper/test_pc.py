"""The paper's estimators on synthetic scans of known motion, and their bad-input errors."""

from __future__ import annotations

import numpy as np
import pytest

import estimators
from estimators.base import SensorSetup, default_beam_angles
from lidar_env.core.se2 import compose
from lidar_env.sensors.lidar import cast_rays

MOUNTS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])
MAX_RANGE = 10.0
N_BEAMS = 360


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Cylinders scattered around the path and a room of walls 7-9 m away."""
    centres = rng.uniform(-6.0, 6.0, (25, 2))
    centres = centres[np.linalg.norm(centres, axis=1) > 2.0]
    circles = np.column_stack([centres, rng.uniform(0.15, 0.4, len(centres))])
    corners = np.array([[-8.0, -7.0], [9.0, -7.0], [9.0, 8.0], [-8.0, 8.0]])
    segments = np.column_stack([corners, np.roll(corners, -1, axis=0)])
    return circles, segments


def _drive(
    car_poses: np.ndarray, world_aligned: bool, seed: int = 0, noise: float = 0.01
) -> list[dict[str, np.ndarray]]:
    """Scans of both Lidars (1 cm noise) for each true car pose, as the env would give them."""
    rng = np.random.default_rng(seed)
    scene = _scene(rng)
    observations = []
    for car in car_poses:
        sensors = compose(car, MOUNTS)
        if world_aligned:
            sensors[:, 2] = 0.0
        ranges = cast_rays(scene, sensors, default_beam_angles(N_BEAMS), MAX_RANGE)
        hit = ranges < MAX_RANGE
        noisy = ranges[hit] + rng.normal(0.0, noise, hit.sum())
        ranges[hit] = np.clip(noisy, 0.0, MAX_RANGE - 1e-6)
        observations.append({"lidar_1": ranges[0], "lidar_2": ranges[1]})
    return observations


def _translation(start: np.ndarray, step: np.ndarray, n: int) -> np.ndarray:
    """``n`` car poses from ``start``, each ``step`` (x [m], y [m], world frame) further."""
    poses = np.repeat(start[None], n, axis=0)
    poses[:, :2] += np.arange(n)[:, None] * step
    return poses


def _run(name: str, observations: list, world_aligned: bool, start: np.ndarray) -> np.ndarray:
    estimator = estimators.make(name)
    setup = SensorSetup(MOUNTS, default_beam_angles(N_BEAMS), MAX_RANGE, world_aligned)
    estimator.reset(setup, start)
    for k, observation in enumerate(observations):
        estimator.update(observation, 0.1 * k)
    return estimator.trajectory


def test_registry_lists_the_paper_estimators() -> None:
    assert {"pc", "pc_offset", "pc_pg", "zero"} <= set(estimators.names())
    with pytest.raises(KeyError, match="unknown estimator 'pcc': expected one of .*pc_pg"):
        estimators.make("pcc")


@pytest.mark.parametrize("world_aligned", [True, False])
@pytest.mark.parametrize("name", ["pc", "pc_offset", "pc_pg"])
def test_translation_is_tracked_in_the_trajectory_frame(name: str, world_aligned: bool) -> None:
    """A car heading 0.6 rad that translates (without turning) 7 cm per step, partly sideways:
    the sign and frame conventions must put the estimate on the true path."""
    start = np.array([0.3, -0.2, 0.6])
    truth = _translation(start, np.array([0.06, 0.035]), 25)
    estimate = _run(name, _drive(truth, world_aligned), world_aligned, start)
    assert estimate.shape == truth.shape
    np.testing.assert_allclose(estimate[0], start)
    np.testing.assert_allclose(estimate[:, 2], start[2])
    travelled = np.linalg.norm(truth[-1, :2] - start[:2])
    end_error = np.linalg.norm(estimate[-1, :2] - truth[-1, :2])
    assert end_error < 0.15 * travelled
    steps_est, steps_true = np.diff(estimate[:, :2], axis=0), np.diff(truth[:, :2], axis=0)
    cosine = np.sum(steps_est * steps_true, axis=1) / (
        np.linalg.norm(steps_est, axis=1) * np.linalg.norm(steps_true, axis=1)
    )
    assert np.median(cosine) > 0.95


def test_zero_stays_at_the_initial_pose() -> None:
    start = np.array([1.0, 2.0, 0.3])
    truth = _translation(start, np.array([0.1, 0.0]), 4)
    estimate = _run("zero", _drive(truth, False), False, start)
    np.testing.assert_allclose(estimate, np.repeat(start[None], 4, axis=0))


def test_pose_graph_beats_a_single_lidar_here() -> None:
    """Averaging the two cross-Lidar estimates (eq. 10) should not be worse than one Lidar."""
    start = np.array([0.0, 0.0, 0.0])
    truth = _translation(start, np.array([0.08, 0.0]), 30)
    observations = _drive(truth, True, seed=5)
    errors = {
        name: np.linalg.norm(_run(name, observations, True, start)[:, :2] - truth[:, :2], axis=1)
        for name in ("pc", "pc_pg")
    }
    assert np.sqrt(np.mean(errors["pc_pg"] ** 2)) < np.sqrt(np.mean(errors["pc"] ** 2))


@pytest.mark.parametrize("size", [401, 0, -2])
def test_bad_image_size_is_an_error_at_make(size: int) -> None:
    with pytest.raises(ValueError, match="size: expected a positive even integer"):
        estimators.make("pc", image_size=size)


def test_bad_setup_and_scans_are_readable_errors() -> None:
    setup = SensorSetup(MOUNTS, default_beam_angles(N_BEAMS), MAX_RANGE)
    estimator = estimators.make("pc", resolution=0.01)
    with pytest.raises(ValueError, match="cannot hold max_range"):
        estimator.reset(setup)
    with pytest.raises(ValueError, match="lidar: expected 0 .* or 1"):
        estimators.make("pc", lidar=2)
    single = SensorSetup(MOUNTS[:1], default_beam_angles(N_BEAMS), MAX_RANGE)
    with pytest.raises(ValueError, match="pc_pg needs 2 Lidars"):
        estimators.make("pc_pg").reset(single)
    with pytest.raises(ValueError, match="lidar 1 requested but the setup has 1"):
        estimators.make("pc_offset").reset(single)
    estimator = estimators.make("pc")
    estimator.reset(setup)
    scans = {"lidar_1": np.full(N_BEAMS, 5.0), "lidar_2": np.full(N_BEAMS, 5.0)}
    with pytest.raises(ValueError, match=r"lidar_1: expected a scan of shape \(360,\)"):
        estimator.update({**scans, "lidar_1": np.full(300, 5.0)}, 0.0)
    bad = np.full(N_BEAMS, 5.0)
    bad[3] = np.nan
    with pytest.raises(ValueError, match="lidar_2: scan holds NaN or inf"):
        estimator.update({**scans, "lidar_2": bad}, 0.0)
