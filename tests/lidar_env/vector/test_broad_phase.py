"""The batched env's collision broad phase (:func:`lidar_env.vector.kernel.obstacles_within`)
picks, through the world's grid, exactly the obstacles a scan of all of them picks; a move with
none picked (:func:`lidar_env.vector.kernel.drive_clear_arc`) ends where ``drive_arc`` ends it, bit
for bit; and the batched env stays bit-identical to single envs in a cluttered world of many grid
cells."""

from __future__ import annotations

import numpy as np

from lidar_env.vector.kernel import drive_clear_arc, obstacles_within
from lidar_env.vehicle.car import drive_arc
from lidar_env.world.primitive_grid import segment_distance2
from lidar_env.world.world import World
from tests.lidar_env.vector.test_identity import assert_same, pair, wall_seeking_actions

#: [m] the cluttered world's side and the half width of its clear band around y = SIDE / 2.
SIDE, CLEAR = 30.0, 1.5


def cluttered_world(seed: int) -> World:
    """A SIDE x SIDE room of 250 circles and 250 short walls (some across grid cells), none
    within CLEAR of the line y = SIDE / 2, where the trace starts."""
    rng = np.random.default_rng(seed)

    def off_the_band(count: int, margin: float) -> np.ndarray:
        points = rng.uniform(0.0, SIDE, (4 * count, 2))
        return points[np.abs(points[:, 1] - SIDE / 2) > CLEAR + margin][:count]

    centres = off_the_band(250, 0.4)
    circles = np.column_stack([centres, rng.uniform(0.05, 0.4, len(centres))])
    starts = off_the_band(250, 2.0)
    angles, lengths = rng.uniform(0.0, np.pi, len(starts)), rng.uniform(0.2, 2.0, len(starts))
    ends = starts + lengths[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    return World(circles, np.hstack([starts, ends]), bounds=(0.0, 0.0, SIDE, SIDE))


def test_the_grid_picks_the_same_obstacles_as_a_scan_of_all() -> None:
    world = cluttered_world(0)
    circles, segments, grid = world.circles, world.segments, tuple(world.grid)
    assert grid[3] * grid[4] > 20  # many cells, so the pick really culls
    seen = (np.zeros(len(circles), np.int64), np.zeros(len(segments), np.int64))
    stamp = np.ones(1, np.int64)
    near_circles, near_segments = np.zeros((len(circles), 3)), np.zeros((len(segments), 4))
    rng = np.random.default_rng(1)
    for x, y, reach in zip(rng.uniform(-2.0, SIDE + 2.0, 400), rng.uniform(-2.0, SIDE + 2.0, 400),
                           rng.uniform(0.1, 4.0, 400), strict=True):
        got_circles, got_segments = obstacles_within(x, y, reach, circles, segments, grid, seen,
                                                     stamp, near_circles, near_segments)
        close = np.hypot(circles[:, 0] - x, circles[:, 1] - y) <= circles[:, 2] + reach + 1e-9
        far = np.hypot(circles[:, 0] - x, circles[:, 1] - y) > circles[:, 2] + reach - 1e-9
        distances = np.array([segment_distance2(x, y, s) for s in segments])
        # each pick once; every obstacle surely within reach picked, none surely beyond it
        picked = {tuple(row) for row in got_circles}
        assert len(picked) == len(got_circles)
        assert {tuple(row) for row in circles[close & ~far]} <= picked
        assert picked <= {tuple(row) for row in circles[close]}
        assert sorted(map(tuple, got_segments)) == sorted(
            map(tuple, segments[distances <= reach * reach]))


def test_a_move_with_no_obstacle_near_ends_where_drive_arc_ends_it() -> None:
    rng = np.random.default_rng(5)
    no_circles, no_segments = np.empty((0, 3)), np.empty((0, 4))
    yaw_rates = np.concatenate([rng.uniform(-1.5, 1.5, 300), rng.uniform(-2e-9, 2e-9, 100),
                                np.zeros(20)])
    for yaw_rate in yaw_rates:
        pose = np.array([rng.uniform(-50.0, 50.0), rng.uniform(-50.0, 50.0),
                         rng.uniform(-np.pi, np.pi)])
        speed, substeps = rng.uniform(-1.5, 1.5), int(rng.integers(1, 9))
        expected = pose.copy()
        hit = drive_arc(expected, speed, yaw_rate, 0.1, substeps, 0.25, 0.15, no_circles,
                        no_segments)
        assert drive_clear_arc(pose, speed, yaw_rate, 0.1, substeps) is hit is False
        np.testing.assert_array_equal(pose.view(np.uint64), expected.view(np.uint64))


def test_batched_steps_in_a_cluttered_world_are_bit_identical_to_single_envs() -> None:
    trace = np.array([[2.0, SIDE / 2], [SIDE - 2.0, SIDE / 2]])
    batched, reference = pair(4, world=cluttered_world(2), trace=trace,
                              config={"max_episode_time": 8.0})
    got, expected = batched.reset(seed=4), reference.reset(seed=4)
    assert_same(got[0], expected[0], "reset observation")
    rng, steer, collisions = np.random.default_rng(3), np.zeros(4), 0
    for t in range(200):
        actions = wall_seeking_actions(rng, steer)
        got, expected = batched.step(actions), reference.step(actions)
        assert_same(got[0], expected[0], f"step {t} observation")
        assert_same(got[4], expected[4], f"step {t} info")
        for index in (1, 2, 3):
            np.testing.assert_array_equal(got[index], expected[index], f"step {t}")
        collisions += int(got[4]["collision"].sum())
    assert collisions >= 5, collisions
