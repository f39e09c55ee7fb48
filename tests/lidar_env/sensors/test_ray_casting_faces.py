"""Back-face culling (``lidar_env.sensors.edge_facing``): each polygon edge's free side is found
right, an edge whose side changes along it (crossed, touched, a wall) stays two-sided, and skipping
the edges that face away leaves every range of :meth:`LidarLayout.scan` bit for bit as it was."""

import math

import numpy as np
import pytest

from lidar_env.sensors.edge_facing import edge_facing
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout, cast_packed, fresh_seen, readings
from lidar_env.world.world import World

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])  # counter-clockwise


def facing(world: World) -> np.ndarray:
    return edge_facing(world.segments, len(world.walls), tuple(world.grid))


def test_the_free_side_is_outside_a_polygon_and_inside_its_hole() -> None:
    hole = 0.5 + 0.5 * SQUARE  # inside the square: free under the even-odd rule
    world = World(segments=[[5.0, 5.0, 6.0, 6.0]], polygons=[SQUARE, hole[::-1]])
    codes = facing(world)
    assert codes[0] == 0  # a wall is two-sided
    edges = world.segments[1:]
    for edge, code in zip(edges, codes[1:], strict=True):
        mid = 0.5 * (edge[:2] + edge[2:])
        left = np.array([-(edge[3] - edge[1]), edge[2] - edge[0]]) / math.dist(edge[:2], edge[2:])
        free = mid + 1e-3 * code * left
        filled = mid - 1e-3 * code * left
        assert code in (-1, 1)
        assert not world.contains(free[None])[0] and world.contains(filled[None])[0]
    # a counter-clockwise outline has its free side on the right, a clockwise one on the left
    assert np.all(codes[1:5] == -1) and np.all(codes[5:] == -1)
    assert np.all(facing(World(polygons=[SQUARE[::-1]])) == 1)


def test_edges_whose_side_changes_along_them_stay_two_sided() -> None:
    crossing = World(polygons=[SQUARE, SQUARE + (1.0, 1.0)])  # overlapping: even-odd flips
    codes = facing(crossing)
    crossed = [1, 2, 4, 7]  # the edges the other square crosses
    assert np.all(codes[crossed] == 0)
    assert np.all(codes[np.setdiff1d(np.arange(8), crossed)] != 0)
    side_by_side = World(polygons=[SQUARE, SQUARE + (2.0, 0.5)])  # an edge touches the other
    assert facing(side_by_side)[1] == 0 and facing(side_by_side)[7] == 0
    corner = World(polygons=[SQUARE, SQUARE + (2.0, 2.0)])  # touching at a corner only
    assert np.all(facing(corner) != 0)


def random_polygons(rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """Star-shaped polygons of 3 to 9 vertices in a 20 m square, some of them overlapping."""
    polygons = []
    for _ in range(count):
        k = rng.integers(3, 10)
        angles = (np.arange(k) + rng.uniform(0.0, 0.8, k)) * 2 * np.pi / k
        radii = rng.uniform(0.3, 2.0, k)
        centre = rng.uniform(-10, 10, 2)
        polygon = centre + radii[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        polygons.append(polygon if rng.random() < 0.5 else polygon[::-1])
    return polygons


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_skipping_edges_that_face_away_changes_no_range(seed: int) -> None:
    rng = np.random.default_rng(seed)
    world = World(circles=[[3.0, 3.0, 0.5]], segments=[[-8.0, -8.0, -4.0, -7.0]],
                  polygons=random_polygons(rng, 40), bounds=(-12, -12, 12, 12))
    codes = facing(world)
    assert np.count_nonzero(codes) > 0.5 * len(world.polygon_edges)
    layout = LidarLayout.exact([LidarConfig((0.0, 0.0, 0.0), 360),
                          LidarConfig((0.0, 0.0, 1.0), 91, np.pi / 2, 6.0)])
    beams, params = layout._packed
    poses = np.column_stack([rng.uniform(-12, 12, (300, 2)), rng.uniform(-4, 4, 300)])
    for pose in poses:
        sensors = np.array([pose, pose + (0.1, 0.0, 0.5)])
        args = (world.circles, world.segments, len(world.walls), tuple(world.grid), sensors,
                beams, params, np.empty((0, 3)), np.empty(0))
        culled = cast_packed(*args, fresh_seen(world.circles, world.segments), 1, codes).copy()
        plain = cast_packed(*args, fresh_seen(world.circles, world.segments), 1,
                            np.empty(0, dtype=np.int64)).copy()
        np.testing.assert_array_equal(culled, plain)
        out = np.empty(len(plain), np.float32)
        np.testing.assert_array_equal(np.concatenate(layout.scan(world, sensors, rng)),
                                      readings(plain, params, np.empty(0), np.empty(0), out))
