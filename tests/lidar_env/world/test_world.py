"""World geometry: construction, pymunk space, point queries, and image round trips."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pymunk
import pytest

from lidar_env.world.polygons import (
    _ear_clip,
    _is_convex,
    convex_pieces,
    even_odd_inside,
    segment_distances,
    signed_area,
)
from lidar_env.world.world import OBSTACLE_COLLISION_TYPE, World

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


def boundary_pixels(occupied: np.ndarray) -> np.ndarray:
    """Pixels with a 4-neighbour of the other kind (image edges count as free)."""
    padded = np.pad(occupied, 1)
    centre = padded[1:-1, 1:-1]
    return (
        (centre != padded[:-2, 1:-1])
        | (centre != padded[2:, 1:-1])
        | (centre != padded[1:-1, :-2])
        | (centre != padded[1:-1, 2:])
    )


def blob_image(rng: np.random.Generator, shape: tuple[int, int] = (90, 120)) -> np.ndarray:
    """Random discs and rectangles, a border wall, and a hole with an island inside."""
    image = np.zeros(shape, dtype=np.uint8)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    for _ in range(8):
        r, c = rng.integers(10, shape[0] - 10), rng.integers(10, shape[1] - 10)
        radius = rng.integers(2, 9)
        image[(yy - r) ** 2 + (xx - c) ** 2 < radius**2] = rng.integers(1, 256)
    image[:2, :] = image[-2:, :] = image[:, :2] = image[:, -2:] = 255
    image[30:60, 80:110] = 255
    image[36:54, 86:104] = 0
    image[42:47, 92:97] = 7
    return image


# ---------------------------------------------------------------------- construction
def test_arrays_and_bounds() -> None:
    world = World(
        circles=[[5.0, 5.0, 1.0]],
        segments=[[-1.0, 0.0, -1.0, 3.0]],
        polygons=[np.vstack([SQUARE, SQUARE[:1]])],  # a repeated closing vertex is dropped
        name="demo",
    )
    assert world.name == "demo"
    assert world.circles.dtype == np.float64 and world.circles.shape == (1, 3)
    assert len(world.polygons) == 1 and world.polygons[0].shape == (4, 2)
    assert world.segments.shape == (5, 4), "segments are the wall plus the 4 polygon edges"
    np.testing.assert_array_equal(world.segments[0], [-1.0, 0.0, -1.0, 3.0])
    assert world.bounds == (-1.0, 0.0, 6.0, 6.0)
    assert World(circles=[[0, 0, 1]], bounds=(-5, -5, 5, 5)).bounds == (-5.0, -5.0, 5.0, 5.0)
    assert World(bounds=(0, 0, 1, 1)).n_primitives == 0


def test_arrays_are_read_only_copies() -> None:
    circles = np.array([[0.0, 0.0, 1.0]])
    square = np.vstack([SQUARE[:2], SQUARE[1:2], SQUARE[2:]])  # a repeated vertex
    world = World(circles, polygons=[square])
    assert circles.flags.writeable, "the caller's array is left alone"
    assert len(world.polygons[0]) == 4, "repeated vertices make no zero-length edges"
    with pytest.raises(ValueError, match="read-only"):
        world.circles[0, 2] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        world.segments[0, 0] = 5.0


def test_pickles_cheaply() -> None:
    world = World.from_image(blob_image(np.random.default_rng(0)), 0.1)
    world.clearance([[1.0, 1.0]])  # builds the grid, which is not pickled
    data = pickle.dumps(world)
    clone = pickle.loads(data)
    np.testing.assert_array_equal(clone.segments, world.segments)
    assert clone.bounds == world.bounds and clone.name == world.name
    assert len(data) < 2 * world.segments.nbytes + 10_000
    assert not clone.segments.flags.writeable
    points = np.random.default_rng(1).uniform(0, 12, (50, 2))
    np.testing.assert_array_equal(clone.clearance(points), world.clearance(points))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"circles": [[0, 0]]}, r"circles: expected shape \(N, 3\), got \(1, 2\)"),
        ({"circles": [[0, 0, -1]]}, r"circles\[0\]: expected a positive radius, got -1"),
        ({"circles": [[0, np.nan, 1]]}, "circles: expected finite values"),
        ({"segments": [[0, 0, 1]]}, r"segments: expected shape \(N, 4\)"),
        ({"segments": [[1, 1, 1, 1]]}, r"segments\[0\]: expected two distinct end points"),
        ({"polygons": [[[0, 0], [1, 1]]]}, r"polygons\[0\]: expected >= 3 distinct vertices"),
        ({"polygons": [[[0, 0], [1, 1], [2, 2]]]}, r"polygons\[0\]: expected a non-zero area"),
        ({"polygons": [np.zeros((3, 3))]}, r"polygons\[0\]: expected shape \(k, 2\)"),
        ({"polygons": SQUARE}, "wrap a single polygon in a list"),
        ({}, "bounds: expected .* for a world without obstacles"),
        ({"circles": [[0, 0, 1]], "bounds": (1, 0, 0, 1)}, "bounds: expected finite"),
        ({"circles": [[0, 0, 1]], "bounds": (0, 0, 1)}, "bounds: expected finite"),
    ],
)
def test_bad_geometry_is_a_readable_error(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        World(**kwargs)


# ---------------------------------------------------------------------- pymunk space
def test_build_space_shapes() -> None:
    concave = np.array([[10, 0], [14, 0], [14, 4], [12, 1], [10, 4]], dtype=float)
    world = World(
        circles=[[5.0, 5.0, 1.0]], segments=[[-1.0, 0.0, -1.0, 3.0]], polygons=[SQUARE, concave]
    )
    space = world.build_space()
    assert space is not world.build_space(), "every call builds a fresh space"
    shapes = space.shapes
    assert all(s.body is space.static_body for s in shapes)
    assert all(s.collision_type == OBSTACLE_COLLISION_TYPE for s in shapes)
    assert sum(isinstance(s, pymunk.Circle) for s in shapes) == 1
    assert sum(isinstance(s, pymunk.Segment) for s in shapes) == len(world.segments)
    polys = [s for s in shapes if isinstance(s, pymunk.Poly)]
    # The square is one convex piece; the concave polygon's pieces cover exactly its area.
    assert sum(p.area for p in polys) == pytest.approx(4.0 + 16.0 - 0.5 * 4 * 3)
    probe = np.random.default_rng(0).uniform(-2, 16, (500, 2))
    inside_pieces = [
        any(p.point_query(tuple(q)).distance < -1e-9 for p in polys) for q in probe
    ]
    polygons_only = World(polygons=[SQUARE, concave])
    margin = np.abs(polygons_only.clearance(probe)) > 1e-6
    np.testing.assert_array_equal(
        np.array(inside_pieces)[margin], polygons_only.contains(probe)[margin]
    )


@pytest.mark.parametrize("split", [convex_pieces, _ear_clip])
def test_convex_pieces_cover_a_star_exactly(split) -> None:
    angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    radii = np.where(np.arange(24) % 2 == 0, 3.0, 1.0)
    star = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])[::-1]  # clockwise
    pieces = split(star)
    star_world = World(polygons=[star])
    assert sum(abs(signed_area(p)) for p in pieces) == pytest.approx(
        abs(signed_area(star)), rel=1e-12
    )
    probe = np.random.default_rng(1).uniform(-3, 3, (2000, 2))
    in_pieces = np.zeros(len(probe), dtype=bool)
    for piece in pieces:
        assert _is_convex(piece)
        assert len(piece) >= 3 and abs(signed_area(piece)) > 1e-9
        in_pieces |= World(polygons=[piece]).contains(probe)
    np.testing.assert_array_equal(in_pieces, star_world.contains(probe))


def test_degenerate_pieces_from_the_decomposition_are_dropped(monkeypatch) -> None:
    """Whatever pymunk's decomposition returns, slivers (repeated or collinear vertices, as
    pymunk 7.3.1 gives on a star) never reach World: the cover stays exact and buildable."""
    from pymunk import autogeometry

    real = autogeometry.convex_decomposition

    def with_slivers(polyline, tolerance):
        pieces = list(real(polyline, tolerance))
        a, b = pieces[0][0], pieces[0][1]
        return [*pieces, [a, (a + b) / 2, b], [a, a, b], [a, b, b, a]]

    monkeypatch.setattr(autogeometry, "convex_decomposition", with_slivers)
    l_shape = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [0, 3]], dtype=float)
    pieces = convex_pieces(l_shape)
    assert sum(abs(signed_area(p)) for p in pieces) == pytest.approx(6.0, rel=1e-12)
    for piece in pieces:
        assert _is_convex(piece) and abs(signed_area(piece)) > 1e-9
    World(polygons=[l_shape]).build_space()


def test_nested_polygons_stay_hollow_in_the_space() -> None:
    outer = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float)
    inner = np.array([[1, 1], [9, 1], [9, 9], [1, 9]], dtype=float)
    space = World(polygons=[outer, inner]).build_space()
    assert not any(isinstance(s, pymunk.Poly) for s in space.shapes)
    assert space.point_query((5.0, 5.0), 0.0, pymunk.ShapeFilter()) == []


def segments_meet_box(segments: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) True where a segment meets the closed box ``[lo, hi]`` (Liang-Barsky clipping)."""
    start, delta = segments[:, :2], segments[:, 2:] - segments[:, :2]
    t0, t1 = np.zeros(len(segments)), np.ones(len(segments))
    ok = np.ones(len(segments), dtype=bool)
    for axis in (0, 1):
        for p, q in ((-delta[:, axis], start[:, axis] - lo[axis]),
                     (delta[:, axis], hi[axis] - start[:, axis])):
            ok &= ~((p == 0) & (q < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = q / p
            t0 = np.where(p < 0, np.maximum(t0, r), t0)
            t1 = np.where(p > 0, np.minimum(t1, r), t1)
    return ok & (t0 <= t1)


def test_grid_lists_primitives_in_the_cells_they_touch() -> None:
    """Circles: exactly the cells their bounding box touches. Segments: every cell they pass
    through, and none outside their bounding box."""
    rng = np.random.default_rng(9)
    starts = rng.uniform(-20, 20, (300, 2))
    walls = np.vstack([np.hstack([starts, starts + rng.normal(0, 3, (300, 2))]),
                       [[-20, -20, 20, 20], [-20, 20, 19, -19]]])  # long diagonals
    circles = np.column_stack([rng.uniform(-20, 20, (100, 2)), rng.uniform(0.1, 2, 100)])
    world = World(circles, walls, [SQUARE + 30.0])
    grid = world.grid
    assert grid.nx * grid.ny > 50
    assert grid.segment_start[-1] == len(grid.segment_ids)
    segment_lo = np.minimum(world.segments[:, :2], world.segments[:, 2:])
    segment_hi = np.maximum(world.segments[:, :2], world.segments[:, 2:])
    for cell in rng.choice(grid.nx * grid.ny, 80, replace=False):
        ix, iy = cell % grid.nx, cell // grid.nx
        lo = np.array([grid.x0 + ix * grid.cell, grid.y0 + iy * grid.cell])
        hi = lo + grid.cell
        circles_touching = np.all((circles[:, :2] - circles[:, 2:] < hi)
                                  & (circles[:, :2] + circles[:, 2:] >= lo), axis=1)
        listed = grid.circle_ids[grid.circle_start[cell] : grid.circle_start[cell + 1]]
        np.testing.assert_array_equal(np.sort(listed), np.flatnonzero(circles_touching))
        listed = set(grid.segment_ids[grid.segment_start[cell] : grid.segment_start[cell + 1]])
        passing = set(np.flatnonzero(segments_meet_box(world.segments, lo, hi)))
        in_box = set(np.flatnonzero(np.all((segment_lo <= hi) & (segment_hi >= lo), axis=1)))
        assert passing <= listed <= in_box
    diagonal = len(world.walls) - 2
    cells_listing_diagonal = np.count_nonzero(grid.segment_ids == diagonal)
    assert cells_listing_diagonal < 4 * max(grid.nx, grid.ny), "not its whole bounding box"


# ---------------------------------------------------------------------- point queries
def test_contains_even_odd_holes_circles_and_walls() -> None:
    outer = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=float)
    hole = np.array([[2, 2], [8, 2], [8, 8], [2, 8]], dtype=float)
    island = np.array([[4, 4], [6, 4], [6, 6], [4, 6]], dtype=float)
    world = World(
        circles=[[20.0, 0.0, 1.0]], segments=[[30, 0, 30, 5]], polygons=[outer, hole, island]
    )
    points = [[1, 1], [3, 3], [5, 5], [20.5, 0.2], [21.5, 0], [30, 2], [-1, 5]]
    np.testing.assert_array_equal(
        world.contains(points), [True, False, True, True, False, False, False]
    )


def test_contains_matches_a_numpy_crossing_count() -> None:
    rng = np.random.default_rng(2)
    world = World.from_image(blob_image(rng), 0.1)
    points = rng.uniform(-0.5, 12.5, (3000, 2))
    expected = even_odd_inside(points, world.polygon_edges)
    np.testing.assert_array_equal(world.contains(points), expected)
    assert 0.1 < expected.mean() < 0.9


def test_clearance_and_contains_on_a_large_map_match_brute_force() -> None:
    """The grid's ring search must find the nearest surface also far from everything, in holes,
    and outside the map."""
    rng = np.random.default_rng(12)
    image = blob_image(rng, (150, 200))
    image[rng.random(image.shape) < 0.04] = 255  # speckle: thousands of edges
    world = World(
        circles=[[2.0, 14.0, 0.5], [30.0, -5.0, 1.0]],
        segments=[[-4.0, -4.0, 3.0, -2.0], [1.0, 1.0, 1.5, 1.0]],
        polygons=World.from_image(image, 0.1).polygons,
    )
    points = np.vstack([rng.uniform(-5, 25, (1500, 2)), [[200.0, -300.0], [10.0, 7.5]]])
    circle_sdf = np.hypot(*(points[:, None, :] - world.circles[None, :, :2]).transpose(2, 0, 1))
    circle_sdf -= world.circles[:, 2]
    wall = segment_distances(points, world.walls).min(axis=1)
    edge = segment_distances(points, world.polygon_edges).min(axis=1)
    odd = even_odd_inside(points, world.polygon_edges)
    expected = np.minimum(np.minimum(circle_sdf.min(axis=1), wall), np.where(odd, -edge, edge))
    np.testing.assert_allclose(world.clearance(points), expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(world.contains(points), odd | (circle_sdf.min(axis=1) < 0))
    assert world.grid.nx * world.grid.ny > 100


def test_clearance_matches_pymunk_nearest_point_query() -> None:
    """Oracle: pymunk's signed nearest-shape distance, on convex polygons (one piece each)."""
    rng = np.random.default_rng(3)
    triangle = np.array([[6, -3], [9, -2], [7, 1]], dtype=float)
    world = World(
        circles=np.column_stack([rng.uniform(-8, 8, (6, 2)), rng.uniform(0.3, 1.5, 6)]),
        segments=[[-9, -9, 9, -7], [-9, 9, -2, 2]],
        polygons=[SQUARE, triangle],
    )
    space = world.build_space()
    points = rng.uniform(-10, 10, (400, 2))
    expected = [
        space.point_query_nearest(tuple(p), 100.0, pymunk.ShapeFilter()).distance for p in points
    ]
    np.testing.assert_allclose(world.clearance(points), expected, atol=1e-9)
    assert np.any(world.clearance(points) < 0)


def test_clearance_of_an_empty_world_is_infinite_and_bad_points_fail() -> None:
    world = World(bounds=(0, 0, 1, 1))
    assert np.all(np.isinf(world.clearance([[0.5, 0.5]])))
    with pytest.raises(ValueError, match=r"points: expected shape \(N, 2\)"):
        world.clearance([[1, 2, 3]])
    with pytest.raises(ValueError, match="points: expected finite"):
        world.contains([[np.nan, 0]])


# ---------------------------------------------------------------------- images
def test_from_image_pixel_convention() -> None:
    image = np.zeros((4, 5), dtype=np.uint8)
    image[0, 4] = 255  # top-right pixel
    world = World.from_image(image, resolution=0.5, origin=(10.0, 20.0))
    assert world.bounds == (10.0, 20.0, 12.5, 22.0)
    assert len(world.polygons) == 1
    vertices = world.polygons[0]
    np.testing.assert_allclose(vertices.min(axis=0), [12.0, 21.5])
    np.testing.assert_allclose(vertices.max(axis=0), [12.5, 22.0])
    assert world.contains([[12.25, 21.75], [10.25, 20.25]]).tolist() == [True, False]


def test_image_round_trip_differs_only_on_boundary_pixels() -> None:
    image = blob_image(np.random.default_rng(5))
    occupied = image > 0
    for tolerance in (0.0, 0.5):
        world = World.from_image(image, 0.05, origin=(-1.0, 2.0), tolerance=tolerance)
        back = world.to_image(0.05)
        assert back.shape == image.shape and back.dtype == np.uint8
        assert set(np.unique(back)) <= {0, 255}
        differ = (back > 0) != occupied
        assert not np.any(differ & ~boundary_pixels(occupied))
        if tolerance == 0.0:
            assert not np.any(differ), "unsimplified outlines run exactly along pixel edges"
    # contains() agrees at every pixel centre off the boundary: the walled room's free
    # interior is a hole and the island in it is solid again.
    rows, cols = np.nonzero(~boundary_pixels(occupied))
    centres = np.column_stack([-1.0 + (cols + 0.5) * 0.05, 2.0 + (90 - rows - 0.5) * 0.05])
    np.testing.assert_array_equal(world.contains(centres), occupied[rows, cols])
    assert not occupied[38, 88] and occupied[44, 94]


def test_to_image_draws_circles_and_thin_walls() -> None:
    world = World(circles=[[5.0, 5.0, 2.0], [1.0, 1.0, 0.01]], segments=[[0.0, 9.0, 10.0, 8.0]])
    res = 0.05
    image = world.to_image(res, bounds=(0, 0, 10, 10))
    assert image.shape == (200, 200)
    circle = image[60:140, 60:140] > 0
    assert abs(circle.sum() * res**2 - math.pi * 4.0) < 2 * math.pi * 2.0 * res
    row, col = 200 - 1 - int(1.0 / res), int(1.0 / res)
    assert image[row, col] == 255, "a circle smaller than a pixel still marks its pixel"
    wall_columns = np.flatnonzero(image[:40].any(axis=0))
    np.testing.assert_array_equal(wall_columns, np.arange(200))  # drawn unbroken
    with pytest.raises(ValueError, match="resolution: expected a positive pixel size"):
        world.to_image(0.0)


def test_from_image_reads_png_and_pgm(tmp_path) -> None:
    from PIL import Image

    image = blob_image(np.random.default_rng(8), (40, 50))
    expected = World.from_image(image, 0.1).to_image(0.1)
    for suffix in ("png", "pgm"):
        path = tmp_path / f"map.{suffix}"
        Image.fromarray(image).save(path)
        world = World.from_image(path, 0.1)
        assert world.name == "map"
        np.testing.assert_array_equal(world.to_image(0.1), expected)
    deep = (image > 0).astype(np.uint16) * np.uint16(1000)  # 16-bit map
    Image.fromarray(deep).save(tmp_path / "deep.png")
    deep_world = World.from_image(tmp_path / "deep.png", 0.1)
    np.testing.assert_array_equal(deep_world.to_image(0.1), expected)
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG not really an image")
    with pytest.raises(ValueError, match="corrupt.png: expected a readable image file"):
        World.from_image(corrupt, 0.1)


@pytest.mark.parametrize(
    ("image", "kwargs", "message"),
    [
        (np.zeros((3, 3, 3)), {}, r"image: expected a 2-D occupancy array, got shape \(3, 3, 3\)"),
        (np.zeros((0, 4)), {}, "image: expected a non-empty image"),
        (np.ones((4, 4)), {}, "image: expected some free"),
        (-np.ones((4, 4)), {}, "image: expected finite pixel values >= 0"),
        (np.array([["a", "b"]]), {}, "image: expected numeric pixel values"),
        (np.zeros((4, 4)), {"resolution": -1.0}, "resolution: expected a positive pixel size"),
        (np.zeros((4, 4)), {"tolerance": 2.0}, r"tolerance: expected a value in \[0, 0.5\]"),
    ],
)
def test_from_image_bad_input(image, kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        World.from_image(image, **{"resolution": 0.1, **kwargs})


def test_from_image_all_free_is_an_empty_world() -> None:
    world = World.from_image(np.zeros((10, 20)), 0.5)
    assert world.n_primitives == 0 and world.bounds == (0.0, 0.0, 10.0, 5.0)
