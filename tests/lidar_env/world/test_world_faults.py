"""World geometry under hostile input: named ``MapError``s for
self-intersecting polygons, oversized, complex or mistyped images and arguments, usable
bounds for a flat world, and image tracing that keeps every pixel."""

from __future__ import annotations

import numpy as np
import pymunk
import pytest

from lidar_env.core.errors import MapError
from lidar_env.world.occupancy_image import MAX_IMAGE_PIXELS
from lidar_env.world.world import World

STAR = [(np.cos(a), np.sin(a)) for a in np.pi / 2 + np.arange(5) * 4 * np.pi / 5]


@pytest.mark.parametrize(
    "polygon",
    [[(0, 0), (1, 1), (1, 0), (0, 1)], [(0, 0), (2, 1), (2, 0), (0, 2)], STAR],
    ids=["bowtie", "uneven bowtie", "pentagram"],
)
def test_self_intersecting_polygons_are_refused_by_name(polygon):
    with pytest.raises(MapError, match=r"polygons\[0\]: expected a simple polygon, got edges"):
        World(polygons=[polygon])


def test_simple_polygons_touching_or_concave_still_build_and_agree_with_pymunk():
    concave = [(0, 0), (4, 0), (4, 4), (2, 1), (0, 4)]
    world = World(polygons=[concave], bounds=(-1, -1, 5, 5))
    space = world.build_space()
    points = np.random.default_rng(0).uniform(-1, 5, (400, 2))
    inside = world.contains(points)
    queries = [space.point_query_nearest(tuple(p), 0, pymunk.ShapeFilter()) for p in points]
    hit = np.array([query is not None and query.distance < 0 for query in queries])
    assert inside.any() and (~inside).any()
    assert np.array_equal(inside, hit)


def test_a_world_of_one_straight_wall_gets_drawable_bounds():
    world = World(segments=[[0.0, 0.0, 5.0, 0.0]])
    xmin, ymin, xmax, ymax = world.bounds
    assert (xmin, xmax) == (0.0, 5.0) and ymin < 0.0 < ymax
    image = world.to_image(0.1)
    assert image.shape == (10, 50) and image.any()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"circles": "abc"}, r"circles: expected numbers of shape \(N, 3\)"),
        ({"circles": [[1, 2, 3], [1, 2]]}, r"circles: expected numbers of shape \(N, 3\)"),
        ({"circles": [[1 + 1j, 2, 3]]}, "circles: expected real numbers"),
        ({"segments": [[0, 0, "x", 1]]}, r"segments: expected numbers of shape \(N, 4\)"),
        ({"polygons": [[(0, 0), (1, "a"), (1, 1)]]}, r"polygons\[0\]: expected numbers"),
    ],
)
def test_mistyped_geometry_is_named(kwargs, message):
    with pytest.raises(MapError, match=message):
        World(**kwargs)


@pytest.mark.parametrize(
    ("image", "resolution", "message"),
    [
        (np.eye(8), "0.05", "resolution: expected a positive pixel size .m., got str '0.05'"),
        (np.eye(8), None, "resolution: expected a positive pixel size"),
        (np.eye(8) + 1j, 0.05, "image: expected real pixel values, got complex"),
        (np.zeros((2001, 2000)), 0.05, f"image: expected at most {MAX_IMAGE_PIXELS} pixels"),
    ],
)
def test_bad_images_and_resolutions_are_named(image, resolution, message):
    with pytest.raises(MapError, match=message):
        World.from_image(image, resolution)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("tolerance", [0.0, 0.5])
def test_traced_speckle_rasterises_back_to_the_same_pixels(seed, tolerance):
    """Independent oracle: every pixel centre inside the traced polygons (even-odd) is exactly
    an occupied pixel, diagonal neighbours and holes included."""
    rng = np.random.default_rng(seed)
    image = rng.random((37, 53)) < rng.uniform(0.05, 0.6)
    world = World.from_image(image, 0.1, tolerance=tolerance)
    np.testing.assert_array_equal(world.to_image(0.1) > 0, image)
