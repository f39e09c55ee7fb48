"""The occupancy grid: exact cells on synthetic scenes, the inverse sensor model, the helpers."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import SensorSetup, default_beam_angles
from estimators.mapping.map_figure import occupancy_to_rgb
from estimators.mapping.occupancy import OccupancyGrid, logit, sensor_poses
from estimators.mapping.run_maps import from_estimator_run

MISS, HIT = logit(0.4), logit(0.7)


def cells_where(mask: np.ndarray) -> set[tuple[int, int]]:
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(mask), strict=True)}


def crossed_cells(grid: OccupancyGrid, start: np.ndarray, end: np.ndarray,
                  clear_radius: float = np.inf) -> set[tuple[int, int]]:
    """Oracle (slab test): the cells (row, col) in which the segment spends a positive length
    and whose centre is within ``clear_radius`` [cells] of its line."""
    (c0, r0), (c1, r1) = grid.to_grid_coordinates(np.array([start, end]))
    rows, cols = np.meshgrid(np.arange(grid.shape[0]), np.arange(grid.shape[1]), indexing="ij")
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = np.sort([(cols - c0) / (c1 - c0), (cols + 1 - c0) / (c1 - c0)], axis=0)
        tr = np.sort([(rows - r0) / (r1 - r0), (rows + 1 - r0) / (r1 - r0)], axis=0)
    if c1 == c0:
        tc = np.where((cols <= c0) & (c0 < cols + 1), [[[-np.inf]], [[np.inf]]], np.nan)
    if r1 == r0:
        tr = np.where((rows <= r0) & (r0 < rows + 1), [[[-np.inf]], [[np.inf]]], np.nan)
    enter = np.maximum(np.maximum(tc[0], tr[0]), 0.0)
    leave = np.minimum(np.minimum(tc[1], tr[1]), 1.0)
    along = np.array([c1 - c0, r1 - r0]) / np.hypot(c1 - c0, r1 - r0)
    centre_distance = np.abs(along[0] * (rows + 0.5 - r0) - along[1] * (cols + 0.5 - c0))
    return cells_where((leave > enter) & (centre_distance <= clear_radius))


def test_square_room_marks_exactly_the_wall_cells_and_the_free_cells_between():
    # 1 m cells, 10 x 10 room; the sensor sits in the centre of cell (row 4, col 5) and its four
    # beams (forward = +x, then CCW) stop 0.2 m inside the cells of the walls they face.
    grid = OccupancyGrid((0.0, 0.0, 10.0, 10.0), resolution=1.0)
    pose = np.array([5.5, 5.5, 0.0])  # row = floor(10 - 5.5) = 4, col = 5
    ranges = np.array([4.3, 4.3, 5.3, 5.3])  # to x = 9.8, y = 9.8, x = 0.2, y = 0.2
    grid.integrate(ranges, np.array([0, np.pi / 2, np.pi, 3 * np.pi / 2]), pose, max_range=20.0)
    assert cells_where(grid.occupied()) == {(4, 9), (0, 5), (4, 0), (9, 5)}
    free = {(4, c) for c in range(1, 9)} | {(r, 5) for r in range(1, 9)}
    assert cells_where(grid.free()) == free
    assert np.allclose(grid.log_odds[grid.occupied()], HIT)
    assert np.allclose(grid.log_odds[grid.free()], MISS)  # the shared start cell only once


@pytest.mark.parametrize("clear_radius", [0.5, 1.0])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_each_beam_frees_exactly_the_cells_it_crosses_and_hits_its_end_cell(seed, clear_radius):
    rng = np.random.default_rng(seed)
    grid = OccupancyGrid((-3.0, -2.0, 4.0, 5.0), resolution=0.1, clear_radius=clear_radius)
    for _ in range(20):
        grid.log_odds[:] = 0.0
        pose = np.array([*rng.uniform([-3, -2], [4, 5]), rng.uniform(-np.pi, np.pi)])
        angle, length = rng.uniform(-np.pi, np.pi), rng.uniform(0.05, 4.0)
        end = pose[:2] + length * np.array([np.cos(pose[2] + angle), np.sin(pose[2] + angle)])
        grid.integrate([length], [angle], pose, max_range=5.0)
        # the last free_margin (one cell) before a return is left alone, as the surface may
        # reach into it
        free_end = pose[:2] + max(length - grid.resolution, 0.0) * (end - pose[:2]) / length
        crossed = crossed_cells(grid, pose[:2], free_end, clear_radius)
        end_col, end_row = np.floor(grid.to_grid_coordinates(end)[0]).astype(int)
        inside = 0 <= end_row < grid.shape[0] and 0 <= end_col < grid.shape[1]
        hit = {(int(end_row), int(end_col))} if inside else set()
        assert cells_where(grid.occupied()) == hit
        assert cells_where(grid.free()) == crossed - hit


def test_a_beam_clipping_a_cell_corner_leaves_it_unknown():
    # line y = x - 0.1 clips the corner x in [1, 1.1] of the cell x, y in [1, 2] x [0, 1]
    # (row 2, col 1), 0.64 cells from its centre: by default it is not cleared (the rim cell of
    # a round obstacle that tangential beams clip), with clear_radius >= 0.71 it is
    for clear_radius, cleared in ((0.5, False), (0.75, True)):
        grid = OccupancyGrid((0.0, 0.0, 3.0, 3.0), resolution=1.0, clear_radius=clear_radius)
        grid.integrate([3.0], [np.pi / 4], [0.5, 0.4, 0.0], max_range=3.0)
        assert grid.free()[2, 1] == cleared
        assert grid.free()[2, 0] and grid.free()[1, 1]  # the cells it runs through
    with pytest.raises(ValueError, match="clear_radius: expected a distance >= 0"):
        OccupancyGrid((0.0, 0.0, 1.0, 1.0), clear_radius=-1.0)


def test_max_range_beams_only_free_space_up_to_max_range():
    grid = OccupancyGrid((0.0, 0.0, 10.0, 1.0), resolution=0.5)
    grid.integrate([7.0], [0.0], [0.25, 0.25, 0.0], max_range=3.0)
    assert not grid.occupied().any()
    assert cells_where(grid.free()) == {(1, c) for c in range(7)}  # x in [0, 3.25]


def test_the_free_margin_before_a_return_is_left_unknown():
    grid = OccupancyGrid((0.0, 0.0, 2.0, 0.1), resolution=0.1, free_margin=0.25)
    grid.integrate([1.0], [0.0], [0.05, 0.05, 0.0], max_range=5.0)  # return at x = 1.05
    assert cells_where(grid.occupied()) == {(0, 10)}
    assert cells_where(grid.free()) == {(0, c) for c in range(9)}  # up to x = 0.8
    assert grid.log_odds[0, 9] == 0.0
    with pytest.raises(ValueError, match="free_margin: expected a distance >= 0"):
        OccupancyGrid((0.0, 0.0, 1.0, 1.0), free_margin=-0.1)


def test_hits_outrank_misses_within_one_observation_and_probabilities_are_clamped():
    grid = OccupancyGrid((0.0, 0.0, 4.0, 1.0), resolution=1.0)
    # the first beam ends in cell col 2, the second passes through it in the same call
    grid.integrate([2.0, 3.0], [0.0, 0.0], [0.5, 0.5, 0.0], max_range=5.0)
    assert grid.log_odds[0, 2] == pytest.approx(HIT)
    for _ in range(50):
        grid.integrate([2.0], [0.0], [0.5, 0.5, 0.0], max_range=5.0)
    assert grid.probabilities()[0, 2] == pytest.approx(0.97)
    assert grid.probabilities()[0, 0] == pytest.approx(0.12)
    assert grid.probabilities()[0, 3] == pytest.approx(0.7)  # only the first call's long beam


def test_beams_leaving_the_grid_are_clipped_and_returns_outside_are_ignored():
    grid = OccupancyGrid((0.0, 0.0, 2.0, 2.0), resolution=1.0)
    grid.integrate([5.0], [0.0], [-1.5, 0.5, 0.0], max_range=10.0)  # starts and ends outside
    assert cells_where(grid.free()) == {(1, 0), (1, 1)}
    assert not grid.occupied().any()


def test_from_estimator_run_places_each_lidar_at_car_pose_compose_mount():
    setup = SensorSetup(np.array([[0.5, 0.0, np.pi / 2], [-0.5, 0.0, 0.0]]),
                        default_beam_angles(4), max_range=10.0)
    trajectory = np.array([[2.02, 2.02, np.pi / 2]])
    # car facing +y: lidar_1 sits 0.5 m ahead of it facing -x, lidar_2 0.5 m behind facing +y
    assert np.allclose(sensor_poses(trajectory, setup)[0],
                       [[2.02, 2.52, -np.pi], [2.02, 1.52, np.pi / 2]])
    observation = {"lidar_1": [1.0, 10, 10, 10], "lidar_2": [1.0, 10, 10, 10]}
    grid = from_estimator_run(trajectory, [observation], setup, resolution=0.1,
                              bounds=(0.0, 0.0, 4.0, 4.0))
    hits = grid.cell_centres()[grid.occupied()]
    assert np.allclose(np.sort(hits, axis=0), [[1.05, 2.55], [2.05, 2.55]])


def test_occupancy_to_rgb_greys_and_resamples():
    grid = OccupancyGrid((0.0, 0.0, 2.0, 1.0), resolution=1.0)
    grid.integrate([1.2], [0.0], [0.5, 0.5, 0.0], max_range=5.0)
    rgb = occupancy_to_rgb(grid)
    assert rgb.shape == (1, 2, 3) and rgb.dtype == np.uint8
    assert np.allclose(rgb[0, :, 0], [255 * 0.6, 255 * 0.3], atol=0.51)  # free, occupied
    wide = occupancy_to_rgb(grid, bounds=(-1.0, 0.0, 2.0, 1.0), resolution=0.5)
    assert wide.shape == (2, 6, 3)
    assert np.all(wide[:, :2] == 128) and np.all(wide[:, 2:4] == rgb[0, 0])


def test_bad_input_is_a_readable_error():
    with pytest.raises(ValueError, match="xmax > xmin"):
        OccupancyGrid((1.0, 0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="resolution: expected a positive"):
        OccupancyGrid((0.0, 0.0, 1.0, 1.0), resolution=0.0)
    with pytest.raises(ValueError, match="p_min < 0.5 < p_max"):
        OccupancyGrid((0.0, 0.0, 1.0, 1.0), p_hit=0.3)
    grid = OccupancyGrid((0.0, 0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match=r"ranges: expected shape \(n,\) or \(K, n\)"):
        grid.integrate(np.ones(3), np.zeros(4), [0, 0, 0], 5.0)
    with pytest.raises(ValueError, match="sensor_pose: expected shape"):
        grid.integrate(np.ones((2, 4)), np.zeros(4), [0, 0, 0], 5.0)
    with pytest.raises(ValueError, match="finite ranges"):
        grid.integrate([np.nan], [0.0], [0, 0, 0], 5.0)
    with pytest.raises(ValueError, match="threshold"):
        grid.occupied(1.5)
    setup = SensorSetup(np.zeros((1, 3)), default_beam_angles(4), 10.0)
    with pytest.raises(ValueError, match="one per trajectory row"):
        from_estimator_run(np.zeros((2, 3)), [{"lidar_1": np.ones(4)}], setup)
