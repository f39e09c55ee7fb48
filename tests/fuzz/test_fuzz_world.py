"""Fuzz: map images and arrays, and World geometry."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lidar_env.world.world import World
from tests.fuzz.conftest import named_or_result

dtypes = st.sampled_from([np.bool_, np.uint8, np.int16, np.float32, np.float64, np.complex128])
images = hnp.arrays(dtypes, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=24))
numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5),
                    st.just("0.5"), st.none(), st.booleans())


@given(image=images, resolution=numbers)
def test_from_image_names_the_problem_or_keeps_every_pixel(image, resolution):
    world = named_or_result(lambda: World.from_image(image, resolution))
    if world is None:
        return
    occupied = image.astype(np.float64) > 0
    np.testing.assert_array_equal(world.to_image(float(resolution)) > 0, occupied)


@given(image=hnp.arrays(np.bool_, st.tuples(st.integers(1, 30), st.integers(1, 30))))
def test_boolean_maps_trace_back_to_themselves(image):
    world = named_or_result(lambda: World.from_image(image, 0.1))
    if world is not None:
        np.testing.assert_array_equal(world.to_image(0.1) > 0, image)
    else:
        assert image.all()  # the one refusal: no free pixel at all


coordinate = st.one_of(st.floats(-20, 20), st.sampled_from([np.nan, np.inf, -np.inf, 1e300]),
                       st.just("x"))
rows = st.lists(st.lists(coordinate, min_size=2, max_size=5), max_size=4)


@settings(max_examples=settings().max_examples * 2)
@given(circles=rows, segments=rows, polygons=st.lists(rows, max_size=3))
def test_world_geometry_is_named_or_consistent(circles, segments, polygons):
    world = named_or_result(lambda: World(circles=circles, segments=segments, polygons=polygons))
    if world is None:
        return
    xmin, ymin, xmax, ymax = world.bounds
    assert np.all(np.isfinite(world.bounds)) and xmin < xmax and ymin < ymax
    points = np.random.default_rng(0).uniform((xmin, ymin), (xmax, ymax), (50, 2))
    inside = world.contains(points)
    assert inside.shape == (50,)
    world.build_space()
