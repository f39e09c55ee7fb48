"""Two-Lidar fusion: the four-node graph (paper Fig. 4) and windowed pose graphs by weighted
least squares. Oracle: edges generated from known car poses and mounts."""

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from estimators.base import LIDAR_KEYS, Sensor, SensorSetup, default_beam_angles
from estimators.evaluation.metrics import evaluate
from estimators.matching.rotation_pc import motion_from_sensor_match
from estimators.odometry.edge_consensus import fuse_from_consensus
from estimators.odometry.sensor_graph import (
    SensorEdge,
    fuse_car_motion,
    optimize_poses,
    predict_edges,
)
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import compose, relative
from lidar_env.sensors.lidar import Lidar
from lidar_env.world.world import World

MOUNTS = np.array([[0.25, 0.05, 0.1], [-0.25, -0.1, -0.4]])


def four_edges(motion: np.ndarray, rng: np.random.Generator | None = None) -> list[SensorEdge]:
    """The four matches 1→3, 2→4, 1→4, 2→3 a car moving by ``motion`` produces."""
    edges = []
    for i, j in ((0, 0), (1, 1), (0, 1), (1, 0)):
        z = relative(MOUNTS[i], compose(motion, MOUNTS[j]))
        if rng is not None:
            z = z + rng.normal(0.0, [0.005, 0.005, 0.002])
        edges.append(SensorEdge(0, i, 1, j, z, 1.0))
    return edges


@pytest.mark.parametrize("motion", [[0.15, 0.0, 0.0], [0.1, -0.05, 0.3], [-0.2, 0.1, -1.2]])
def test_exact_edges_give_the_true_car_motion(motion) -> None:
    motion = np.array(motion)
    estimate = fuse_car_motion(MOUNTS, four_edges(motion))
    np.testing.assert_allclose(estimate, motion, atol=1e-6)


def test_cross_edge_alone_constrains_all_three_dof() -> None:
    motion = np.array([0.12, 0.03, 0.2])
    edge = four_edges(motion)[2]  # lidar 1 at t-1 -> lidar 2 at t
    np.testing.assert_allclose(
        predict_edges(np.stack([np.zeros(3), motion]), MOUNTS, [edge])[0], edge.pose, atol=1e-12
    )
    np.testing.assert_allclose(fuse_car_motion(MOUNTS, [edge]), motion, atol=1e-6)


def test_confidence_weights_the_edges_like_a_weighted_mean() -> None:
    # Identity mounts and pure translation: the weighted least-squares answer is the weighted mean.
    mounts = np.zeros((2, 3))
    edges = [
        SensorEdge(0, 0, 1, 0, np.array([0.10, 0.0, 0.0]), 0.9),
        SensorEdge(0, 1, 1, 1, np.array([0.13, 0.0, 0.0]), 0.3),
    ]
    estimate = fuse_car_motion(mounts, edges, robust_scale=1e6)
    np.testing.assert_allclose(estimate, [(0.9 * 0.10 + 0.3 * 0.13) / 1.2, 0.0, 0.0], atol=1e-6)


def test_one_wrong_match_does_not_drag_the_others() -> None:
    motion = np.array([0.15, 0.02, 0.05])
    edges = four_edges(motion)
    bad = edges[3]
    edges[3] = SensorEdge(
        0, bad.source_sensor, 1, bad.target_sensor, bad.pose + [0.4, -0.3, 0.2], 1
    )
    estimate = fuse_car_motion(MOUNTS, edges)
    assert np.hypot(*(estimate[:2] - motion[:2])) < 0.01
    plain = fuse_car_motion(MOUNTS, edges, robust_scale=1e6)
    assert np.hypot(*(plain[:2] - motion[:2])) > 0.05  # the robust loss is what saves it


def test_window_with_extra_edges_beats_chaining_consecutive_matches() -> None:
    rng = np.random.default_rng(7)
    truth = [np.zeros(3)]
    for _ in range(5):
        truth.append(compose(truth[-1], [0.15, 0.0, 0.05]))
    truth = np.array(truth)
    chained_errors, window_errors = [], []
    for _ in range(20):
        edges = []
        for a in range(len(truth)):
            for b in range(a + 1, min(a + 4, len(truth))):
                for i in range(2):
                    for j in range(2):
                        z = relative(compose(truth[a], MOUNTS[i]), compose(truth[b], MOUNTS[j]))
                        noise = rng.normal(0.0, [0.01, 0.01, 0.005])
                        edges.append(SensorEdge(a, i, b, j, z + noise, 1.0))
        chained = [np.zeros(3)]
        for edge in edges:
            if (
                edge.target_node == edge.source_node + 1
                and edge.source_sensor == edge.target_sensor == 0
            ):
                chained.append(compose(chained[-1], motion_from_sensor_match(MOUNTS[0], edge.pose)))
        chained = np.array(chained)
        solved = optimize_poses(chained, MOUNTS, edges)
        chained_errors.append(np.hypot(*(chained[-1, :2] - truth[-1, :2])))
        window_errors.append(np.hypot(*(solved[-1, :2] - truth[-1, :2])))
    assert np.mean(window_errors) < 0.5 * np.mean(chained_errors)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_fixed": 2}, "n_fixed"),
        ({"edges": [SensorEdge(0, 0, 2, 0, np.zeros(3), 1.0)]}, "nodes outside"),
        ({"edges": [SensorEdge(0, 0, 1, 2, np.zeros(3), 1.0)]}, "sensors outside"),
        ({"edges": [SensorEdge(0, 0, 1, 0, np.zeros(3), 0.0)]}, "confidences"),
        ({"edges": []}, "at least one edge"),
        ({"sigma_heading": -1.0}, "positive"),
    ],
)
def test_bad_graphs_raise_readable_errors(kwargs, message) -> None:
    arguments = {"car_poses": np.zeros((2, 3)), "mounts": MOUNTS, "edges": four_edges(np.zeros(3))}
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=message):
        optimize_poses(**arguments)


def scan_drive(world: World, mounts: np.ndarray, poses: np.ndarray, rng: np.random.Generator):
    """The setup, noisy (1 cm) 360-beam scans from ``mounts`` at every car pose, and the poses."""
    lidar = Lidar(noise_std=0.01)
    observations = [
        dict(zip(LIDAR_KEYS, lidar.scan(world, compose(pose, mounts), rng), strict=False))
        for pose in poses
    ]
    return SensorSetup(mounts, default_beam_angles(360), 10.0), observations, poses


def drive_in_room(steps: int, motion: np.ndarray, n_lidars: int = 2):
    """Noisy scans of a car moving by ``motion`` per scan through a room of cylinders."""
    rng = np.random.default_rng(21)
    walls = [[-8, -8, 8, -8], [8, -8, 8, 8], [8, 8, -8, 8], [-8, 8, -8, -8]]
    centres = rng.uniform(-7, 7, (60, 2))
    centres = centres[np.hypot(*centres.T) > 3.5][:14]
    world = World(np.column_stack([centres, rng.uniform(0.15, 0.5, len(centres))]), walls)
    mounts = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])[:n_lidars]
    poses = [np.array([-1.0, -0.5, 0.3])]
    for _ in range(steps):
        poses.append(compose(poses[-1], motion))
    return scan_drive(world, mounts, np.array(poses), rng)


@pytest.mark.parametrize(("n_lidars", "window"), [(2, 2), (1, 2), (2, 4)])
def test_fusion_estimator_follows_a_curve_to_millimetres_per_step(n_lidars, window) -> None:
    setup, observations, truth = drive_in_room(40, np.array([0.1, 0.0, 0.04]), n_lidars)
    estimator = estimators.make("pc_fusion", window=window)
    estimator.reset(setup, truth[0])
    for k, observation in enumerate(observations):
        estimator.update(observation, 0.1 * k)
    scores = evaluate(estimator.trajectory, truth)
    assert scores.accuracy_percent > 98.0
    assert scores.drift_percent < 0.5
    assert scores.heading_rmse_deg < 0.2


def test_fusion_estimator_standing_still_does_not_drift() -> None:
    setup, observations, truth = drive_in_room(30, np.zeros(3))
    estimator = estimators.make("pc_fusion")
    estimator.reset(setup, truth[0])
    for k, observation in enumerate(observations):
        estimator.update(observation, 0.1 * k)
    errors = estimator.trajectory - truth
    assert np.abs(errors[:, :2]).max() < 0.003
    assert np.abs(errors[:, 2]).max() < np.radians(0.1)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"window": 0}, "window"),
        ({"keyframe_distance": 0.0}, "keyframe_distance"),
        ({"icp_iterations": 0}, "icp_iterations"),
        ({"velocity_window": 0.0}, "velocity_window"),
    ],
)
def test_bad_fusion_settings_raise_readable_errors(params, message) -> None:
    with pytest.raises(ValueError, match=message):
        estimators.make("pc_fusion", **params)


def drive_through_corridor(weave: float, seed: int):
    """Scans of a car driving 20 m at 0.1 m per scan (10 Hz) down a 5 m wide corridor whose
    only along-track features are door frames around its start: beyond x = 12.5 m nothing in
    the Lidars' 10 m range tells how far the car has gone. ``weave`` [rad per scan]: the
    amplitude of a sinusoidal turn rate (period 20 scans)."""
    rng = np.random.default_rng(seed)
    walls = [[-12, -2.5, 40, -2.5], [-12, 2.5, 40, 2.5], [-12, -2.5, -12, 2.5], [40, -2.5, 40, 2.5]]
    for x in (-6.0, -4.5, -3.0, 0.0, 1.5):
        walls += [[x, -2.5, x, -2.0], [x + 0.7, 2.5, x + 0.7, 2.0]]
    world = World(np.zeros((0, 3)), walls)
    mounts = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])
    poses = [np.array([-2.0, 0.0, 0.0])]
    for k in range(200):
        poses.append(compose(poses[-1], [0.1, 0.0, weave * np.sin(2 * np.pi * k / 20)]))
    return scan_drive(world, mounts, np.array(poses), rng)


@pytest.mark.parametrize(("weave", "limit"), [(0.0, 0.08), (0.04, 0.25)])
def test_featureless_corridor_is_crossed_at_the_speed_measured_before_it(weave, limit) -> None:
    # Along the corridor the scans say nothing for 55 scans: the estimate there is the
    # velocity the estimator measured before. From the last step alone (its match noise
    # carried 55 times), and with a prediction that bent a weaving car's path, the along-track
    # error grew by 0.16 m straight and by 1 m weaving on this drive.
    setup, observations, truth = drive_through_corridor(weave, seed=1)
    estimator = estimators.make("pc_fusion")
    estimator.reset(setup, truth[0])
    for k, observation in enumerate(observations):
        estimator.update(observation, 0.1 * k)
    along = estimator.trajectory[:, 0] - truth[:, 0]
    entry = np.argmax(truth[:, 0] > 13.0)
    assert abs(along[-1] - along[entry]) < limit


def test_fusion_refuses_lidars_of_different_max_ranges_and_runs_three_270_degree_ones() -> None:
    wide = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 271)
    mounts = [(0.35, 0.2, np.pi / 4), (-0.35, -0.2, -0.75 * np.pi), (0.0, 0.2, np.pi / 2)]
    mixed = SensorSetup(sensors=[Sensor(mounts[0], wide, 10.0), Sensor(mounts[1], wide, 6.0)])
    with pytest.raises(EstimatorInputError, match=r"one max range.*\[6.0, 10.0\]"):
        estimators.make("pc_fusion").reset(mixed)
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn", config={
        "lidars": [{"mount": m, "fov": 1.5 * np.pi, "n_beams": 271} for m in mounts]})
    observation, info = env.reset(seed=0)
    estimator = estimators.make("pc_fusion")
    estimator.reset(SensorSetup.from_env(env), info["pose"])
    estimator.update(observation, info["time"])
    for _ in range(15):
        observation, *_, info = env.step(np.array([0.8, -0.3], dtype=np.float32))
        estimator.update(observation, info["time"])
    end = relative(info["pose"], estimator.pose)
    assert np.hypot(end[0], end[1]) < 0.03 and abs(end[2]) < np.radians(0.5)


def test_a_wrong_main_match_does_not_outvote_the_three_that_agree() -> None:
    # The solver started at the main pair's match: 0.4 m off along the way (a corridor).
    motion = np.array([0.1, 0.0, 0.03])
    edges = four_edges(motion)
    wrong = motion + np.array([0.4, 0.1, 0.0])
    edges[0] = SensorEdge(0, 0, 1, 0, relative(MOUNTS[0], compose(wrong, MOUNTS[0])), 1.0)
    weights = {"sigma_translation": 0.01, "sigma_heading": 0.005, "robust_scale": 3.0}
    stuck = fuse_car_motion(MOUNTS, edges, wrong, **weights)
    assert np.linalg.norm(stuck[:2] - motion[:2]) > 0.3  # the Cauchy loss keeps its start
    estimate = fuse_from_consensus(MOUNTS, edges, wrong, **weights)
    np.testing.assert_allclose(estimate, motion, atol=0.01)  # the outlier pulls a few mm


def test_matches_that_agree_keep_the_solution_from_the_main_match() -> None:
    edges = four_edges(np.array([0.12, 0.01, 0.05]), np.random.default_rng(3))
    start = motion_from_sensor_match(MOUNTS[0], edges[0].pose)
    weights = {"sigma_translation": 0.01, "sigma_heading": 0.005, "robust_scale": 3.0}
    np.testing.assert_array_equal(fuse_from_consensus(MOUNTS, edges, start, **weights),
                                  fuse_car_motion(MOUNTS, edges, start, **weights))
