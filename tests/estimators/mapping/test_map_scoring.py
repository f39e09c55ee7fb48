"""Map scores on hand-built maps with known precision and recall; visibility; cylinders."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import SensorSetup, default_beam_angles
from estimators.mapping.map_figure import occupancy_to_rgb, save_map_figure
from estimators.mapping.map_scoring import (
    observable_cylinders,
    return_agreement,
    score_cylinders,
    score_occupancy,
    true_occupancy,
    visible_cells,
)
from estimators.mapping.occupancy import OccupancyGrid, bounds_around
from estimators.mapping.run_maps import evaluate_run_map, from_estimator_run, map_truth
from estimators.paths import SHARED_DATA
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World

RADISH = SHARED_DATA / "radish"


def hand_built_pair() -> tuple[np.ndarray, np.ndarray]:
    """A 10 x 10 truth with a 6-cell wall in row 2, and a map that has 4 of those cells, the
    cell just below a fifth (1 off), and 2 cells far from everything."""
    truth = np.zeros((10, 10), np.uint8)
    truth[2, 2:8] = 255
    occupied = np.zeros((10, 10), bool)
    occupied[2, 2:6] = True  # exact
    occupied[3, 6] = True  # one cell off the wall cell (2, 6)
    occupied[7, 1] = occupied[8, 8] = True  # far off
    return occupied, truth


def test_scores_without_tolerance_are_plain_cell_counts():
    occupied, truth = hand_built_pair()
    scores = score_occupancy(occupied, truth, tolerance_cells=0)
    assert scores.precision == pytest.approx(4 / 7)
    assert scores.recall == pytest.approx(4 / 6)
    assert scores.iou == pytest.approx(4 / 9)  # |A and B| / |A or B| = 4 / (7 + 6 - 4)
    assert (scores.n_map, scores.n_truth) == (7, 6)


def test_one_cell_tolerance_forgives_the_offset_cell_only():
    occupied, truth = hand_built_pair()
    scores = score_occupancy(occupied, truth, tolerance_cells=1)
    assert scores.precision == pytest.approx(5 / 7)
    # truth cells within one cell of a map cell: columns 2..7 (col 7 touches (3, 6))
    assert scores.recall == pytest.approx(6 / 6)
    assert scores.iou == pytest.approx(1 / (7 / 5 + 1 - 1))


def test_recall_counts_only_the_evaluated_cells():
    occupied, truth = hand_built_pair()
    evaluated = np.zeros_like(occupied)
    evaluated[:, :4] = True  # only truth cells (2, 2) and (2, 3) are evaluated
    scores = score_occupancy(occupied, truth, tolerance_cells=0, evaluated=evaluated)
    assert scores.recall == 1.0 and scores.n_truth == 2
    assert scores.precision == pytest.approx(4 / 7)  # precision still sees every map cell


def test_empty_map_scores_nan_precision_and_zero_iou():
    _, truth = hand_built_pair()
    scores = score_occupancy(np.zeros((10, 10), bool), truth)
    assert np.isnan(scores.precision) and scores.recall == 0.0 and scores.iou == 0.0


def test_true_occupancy_holds_every_boundary_point_and_nothing_far_from_one():
    world = World(circles=[[1.03, 0.97, 0.4]], segments=[[2.0, -1.0, 3.3, 1.17]],
                  polygons=[[[-1.5, -1.2], [-0.4, -0.9], [-1.1, 0.6]]], bounds=(-2, -2, 4, 2))
    grid = OccupancyGrid(world.bounds, 0.1)
    true = true_occupancy(world, grid)
    image = world.to_image(0.1) > 0
    assert np.all(true >= image)
    # oracle 1: dense points on every circle and segment fall in true cells
    t = np.linspace(0.0, 1.0, 20001)
    cx, cy, r = world.circles[0]
    boundary = [np.column_stack([cx + r * np.cos(2 * np.pi * t), cy + r * np.sin(2 * np.pi * t)])]
    boundary += [np.outer(1 - t, seg[:2]) + np.outer(t, seg[2:]) for seg in world.segments]
    cells = np.floor(grid.to_grid_coordinates(np.vstack(boundary))).astype(int)
    assert true[cells[:, 1], cells[:, 0]].all()
    # oracle 2: each added cell's square meets a boundary: its centre is within half a
    # diagonal of one
    centres = grid.cell_centres()[true & ~image]
    to_circle = np.abs(np.hypot(centres[:, 0] - cx, centres[:, 1] - cy) - r)
    points = np.vstack(boundary[1:])
    to_segment = np.min(np.hypot(*(centres[:, None] - points[None]).T), axis=0)
    assert np.all(np.minimum(to_circle, to_segment) <= 0.1 / np.sqrt(2) + 1e-3)
    # the rim: cells whose centre is outside the disc but which the disc reaches into
    assert np.sum(true & ~image) > 20


def test_visible_cells_are_the_near_faces_seen_from_the_sensor():
    # a 2 m x 2 m box seen from the left: only its left face (x = 4) is visible
    box = np.array([[4.0, -1.0], [6.0, -1.0], [6.0, 1.0], [4.0, 1.0]])
    world = World(polygons=[box], bounds=(0.0, -3.0, 8.0, 3.0))
    grid = OccupancyGrid(world.bounds, 0.1)
    dense = default_beam_angles(3600)
    visible = visible_cells(world, [[1.0, 0.0, 0.0]], dense, grid, max_range=10.0)
    centres = grid.cell_centres()[visible]
    assert visible.sum() >= 20 and np.all(centres[:, 0] < 4.2)
    assert np.ptp(centres[:, 1]) > 1.8  # the whole face, top to bottom
    # out of range: nothing visible
    assert not visible_cells(world, [[1.0, 0.0, 0.0]], dense, grid, max_range=2.5).any()


def test_visible_cells_are_only_those_a_beam_hit():
    # a 10 m wall 5.05 m ahead (mid-cell) seen by 3 beams 20 degrees apart: three cells, not
    # the whole wall
    world = World(segments=[[5.05, -5.0, 5.05, 5.0]], bounds=(0.0, -6.0, 6.0, 6.0))
    grid = OccupancyGrid(world.bounds, 0.1)
    angles = np.radians([-20.0, 0.0, 20.0])
    visible = visible_cells(world, [[0.0, 0.0, 0.0]], angles, grid, max_range=10.0)
    expected = np.floor(grid.to_grid_coordinates(
        np.column_stack([np.full(3, 5.05), 5.05 * np.tan(angles)]))).astype(int)
    assert visible.sum() == 3
    assert visible[expected[:, 1], expected[:, 0]].all()
    # a heading turns the beams with the sensor: the same beams at heading 20 degrees
    turned = visible_cells(world, [[0.0, 0.0, np.radians(20.0)]], angles[:2], grid, 10.0)
    assert turned.sum() == 2 and turned[expected[1:, 1], expected[1:, 0]].all()


def test_cylinder_scores_match_one_to_one_and_count_only_observable_ones():
    true = np.array([[0.0, 0.0, 0.3], [5.0, 0.0, 0.3], [0.0, 5.0, 0.3]])
    detected = np.array([[0.03, 0.04, 0.3], [5.0, 0.1, 0.3], [0.05, 0.0, 0.3], [9.0, 9.0, 0.3]])
    scores = score_cylinders(detected, true, observable=[True, True, False])
    assert scores.recall == 1.0 and scores.n_matched == 2
    assert scores.precision == pytest.approx(2 / 4)  # duplicate and far one unmatched
    assert scores.mean_error == pytest.approx((0.05 + 0.1) / 2)
    assert scores.max_error == pytest.approx(0.1)
    assert score_cylinders(detected[:1], true).recall == pytest.approx(1 / 3)
    with pytest.raises(ValueError, match=r"observable: expected shape \(3,\)"):
        score_cylinders(detected, true, observable=[True])


def test_observable_cylinders_need_enough_returns():
    world = World(circles=[[2.0, 0.0, 0.3], [9.5, 0.0, 0.1], [-4.0, 0.0, 0.2]],
                  segments=[[-3.0, -1.0, -3.0, 1.0]])  # the wall hides the third one
    observable = observable_cylinders(world, [[0.0, 0.0, 0.0]], default_beam_angles(360), 10.0,
                                      min_points=5)
    assert list(observable) == [True, False, False]


def test_true_pose_run_maps_the_world_and_finds_its_cylinders(tmp_path):
    world = World(circles=[[3.0, 2.0, 0.3], [5.0, -2.0, 0.4], [8.0, 1.5, 0.25]],
                  segments=[[-1.0, -4.0, 11.0, -4.0], [11.0, -4.0, 11.0, 4.0]],
                  bounds=(-2.0, -5.0, 12.0, 5.0))
    setup = SensorSetup(np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]]),
                        default_beam_angles(360), 10.0)
    rng = np.random.default_rng(3)
    trajectory = np.column_stack([np.linspace(0.0, 8.0, 60), np.full(60, -0.5), np.zeros(60)])
    observations = []
    for car in trajectory:
        sensors = car + setup.mounts
        ranges = cast_rays(world, sensors, setup.beam_angles, setup.max_range)
        ranges = np.where(ranges < 10.0, ranges + rng.normal(0, 0.01, ranges.shape), ranges)
        observations.append(dict(zip(setup.keys, ranges, strict=True)))
    truth = map_truth(world, trajectory, setup, resolution=0.05)
    result = evaluate_run_map(truth, trajectory, observations, setup)
    assert result.map_scores.iou >= 0.9
    assert result.cylinder_scores.recall == 1.0
    assert result.cylinder_scores.max_error <= 0.05
    # a map from a trajectory shifted by 0.3 m scores clearly worse
    shifted = trajectory + [0.3, 0.0, 0.0]
    worse = evaluate_run_map(truth, shifted, observations, setup)
    assert worse.map_scores.iou < result.map_scores.iou - 0.3
    # returns agree with the map of consistent poses, even rigidly shifted ones, not with a
    # map whose heading drifts by 5 degrees over the run
    consistent = return_agreement(result.grid, trajectory, observations, setup)
    assert consistent >= 0.95
    assert return_agreement(worse.grid, shifted, observations, setup) >= 0.95
    drifted = trajectory + np.column_stack([np.zeros((60, 2)), np.linspace(0, 0.087, 60)])
    drifted_grid = from_estimator_run(drifted, observations, setup, bounds=world.bounds)
    assert return_agreement(drifted_grid, drifted, observations, setup) < consistent - 0.1
    figure = save_map_figure(tmp_path / "maps.png",
                             {"true": world.to_image(0.05), "true poses": result.grid},
                             world.bounds, trajectories={"truth": trajectory})
    assert figure.stat().st_size > 1000
    assert occupancy_to_rgb(result.grid).shape == (*result.grid.shape, 3)
    with pytest.raises(ValueError, match="one per trajectory row"):
        evaluate_run_map(truth, trajectory[:5], observations, setup)
    with pytest.raises(ValueError, match=r"true_trajectory: expected shape \(N, 3\)"):
        map_truth(world, trajectory[:, :2], setup)


@pytest.mark.parametrize("resolution", [0.025, 0.05, 0.1])
def test_cylinders_driven_past_are_mapped_at_every_resolution(resolution):
    # eight cylinders of radius 0.2-0.45 m on both sides of a 12 m straight drive, 1 cm noise:
    # at true poses the map holds the visible faces of all of them at any cell size (every
    # crossed cell cleared, the rims cleared by tangential beams left 0.93 at 10 cm)
    xs = np.arange(1.0, 12.0, 1.5)
    circles = np.column_stack([xs, np.where(np.arange(len(xs)) % 2, 1.5, -2.5),
                               np.linspace(0.2, 0.45, len(xs))])
    world = World(circles=circles, bounds=(-1.0, -5.0, 14.0, 4.0))
    setup = SensorSetup(np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]]),
                        default_beam_angles(360), 10.0)
    rng = np.random.default_rng(1)
    trajectory = np.column_stack([np.linspace(0.0, 12.0, 100), np.full(100, -0.5),
                                  np.zeros(100)])
    observations = []
    for car in trajectory:
        ranges = cast_rays(world, car + setup.mounts, setup.beam_angles, setup.max_range)
        ranges = np.where(ranges < 10.0, ranges + rng.normal(0, 0.01, ranges.shape), ranges)
        observations.append(dict(zip(setup.keys, ranges, strict=True)))
    truth = map_truth(world, trajectory, setup, resolution)
    scores = evaluate_run_map(truth, trajectory, observations, setup).map_scores
    assert scores.recall >= 0.95 and scores.precision >= 0.99
    # the evaluated cells are on the faces, never deep inside a cylinder
    centres = OccupancyGrid(world.bounds, resolution).cell_centres()[truth.visible]
    depth = np.max(circles[:, 2] - np.hypot(*(centres[:, None] - circles[None, :, :2]).T).T,
                   axis=1)
    assert len(centres) > 0 and np.all(depth <= 2 * resolution)


def test_mismatched_shapes_and_bad_tolerance_are_readable_errors():
    occupied, truth = hand_built_pair()
    with pytest.raises(ValueError, match="expected the same shape"):
        score_occupancy(occupied[:5], truth)
    with pytest.raises(ValueError, match="tolerance_cells: expected an integer >= 0"):
        score_occupancy(occupied, truth, tolerance_cells=-1)
    with pytest.raises(ValueError, match="at least one map"):
        save_map_figure("unused.png", {}, (0.0, 0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="bounds: expected"):
        save_map_figure("unused.png", {"true": truth})


@pytest.mark.parametrize("world_name", ["open_cylinders", "hallway", "closed_to_open"])
def test_true_pose_maps_of_the_built_in_worlds_reach_the_issue_targets(world_name):
    import gymnasium as gym

    import lidar_env  # noqa: F401  (registers DualLidar-v0)
    from agents.scripted import PurePursuitDriver

    env = gym.make("DualLidar-v0", world=world_name)
    observation, info = env.reset(seed=0)
    driver = PurePursuitDriver()
    driver.reset(env)
    observations, poses = [observation], [info["pose"]]
    for _ in range(1000):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        poses.append(info["pose"])
        if terminated or truncated:
            break
    setup = SensorSetup.from_env(env)
    truth = map_truth(env.unwrapped.world, np.array(poses), setup)
    result = evaluate_run_map(truth, np.array(poses), observations, setup)
    assert result.map_scores.iou >= 0.9
    if result.cylinder_scores is not None:
        assert result.cylinder_scores.recall >= 0.95
        assert result.cylinder_scores.max_error <= 0.05


@pytest.mark.realdata
@pytest.mark.skipif(not (RADISH / "aces-corrected.log.gz").exists(),
                    reason=f"needs the Radish ACES log at {RADISH / 'aces-corrected.log.gz'}")
def test_real_aces_returns_agree_with_the_map_of_slam_poses_and_not_with_drifted_ones():
    from estimators.datasets.carmen import load_log
    from estimators.datasets.real_log import setup_from_log

    log = load_log(RADISH / "aces-corrected.log.gz")
    setup = setup_from_log(log)  # one 180-beam SICK, returns up to 50 m
    observations = [{"lidar_1": scan.ranges} for scan in log.scans]
    slam = log.logged_poses()
    drifted = slam.copy()
    drifted[:, 2] += np.linspace(0.0, np.radians(10.0), len(slam))  # 10 degrees over the log

    def agreement(poses: np.ndarray) -> float:
        grid = from_estimator_run(poses, observations, setup, resolution=0.1,
                                  bounds=bounds_around(poses[:, :2], 10.0))
        return return_agreement(grid, poses, observations, setup)

    consistent = agreement(slam)
    assert consistent >= 0.9
    assert agreement(drifted) < consistent - 0.2
