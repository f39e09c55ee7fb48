"""Built-in worlds (the paper's Fig. 7 surroundings) and random worlds."""

import numpy as np
import pytest

from lidar_env.routes.traces import TRACE_NAMES
from lidar_env.world.built_in import (
    LAYOUT_CLEARANCE,
    PAPER_TRACES,
    WORLD_NAMES,
    built_in_layout,
    make_scene,
    make_world,
)

BUILT_IN = [name for name in WORLD_NAMES if name != "random"]


def test_the_paper_pairs_worlds_with_traces():
    assert PAPER_TRACES["open_cylinders"] == "right_turn"
    assert PAPER_TRACES["hallway"] == "zigzag"
    assert PAPER_TRACES["closed_to_open"] == "zigzag"


@pytest.mark.parametrize("name", BUILT_IN)
@pytest.mark.parametrize("trace", TRACE_NAMES)
def test_every_default_trace_fits_its_world_at_full_size(name, trace):
    layout = built_in_layout(name)
    scene = make_scene(name, trace)
    assert scene.trace.length == pytest.approx(layout.lengths[trace], abs=1e-2)
    assert np.min(scene.world.clearance(scene.trace.waypoints)) >= LAYOUT_CLEARANCE
    xmin, ymin, xmax, ymax = scene.world.bounds
    assert np.all((scene.trace.waypoints >= (xmin, ymin)) & (scene.trace.waypoints <= (xmax, ymax)))
    assert 20.0 <= max(xmax - xmin, ymax - ymin) <= 45.0


def _free_width(world, x, y_range=(-20, 20)):
    """Free distance [m] across the world along the vertical line at ``x`` through y = 0."""
    ys = np.linspace(*y_range, 8001)
    blocked = np.flatnonzero(world.clearance(np.stack([np.full_like(ys, x), ys], 1)) <= 0)
    centre = np.argmin(np.abs(ys))
    above, below = blocked[blocked > centre], blocked[blocked < centre]
    top = ys[above[0]] if len(above) else ys[-1]
    bottom = ys[below[-1]] if len(below) else ys[0]
    return top - bottom


def test_hallway_is_closed_narrow_at_both_ends_and_broad_in_the_middle():
    world = make_world("hallway")
    start, middle, end = (_free_width(world, x) for x in (4.0, 20.0, 36.0))
    assert start == pytest.approx(5.0, abs=0.05) and end == pytest.approx(5.0, abs=0.05)
    assert middle > 2.5 * start
    assert len(world.circles) == 0  # plain walls: few features


def test_open_cylinders_is_open_ground_with_many_single_cylinders():
    world = make_world("open_cylinders")
    assert len(world.walls) == 0 and len(world.polygons) == 0
    assert len(world.circles) >= 50


def test_closed_to_open_widens_from_a_corridor_into_a_hall():
    world = make_world("closed_to_open")
    assert _free_width(world, 5.0) == pytest.approx(5.0, abs=0.05)
    assert _free_width(world, 30.0) > 20.0
    assert len(world.circles) + len(world.polygons) >= 5  # some features in the hall


@pytest.mark.parametrize("trace", ["zigzag", "loop", "out_and_back"])
def test_random_worlds_come_from_the_generator_and_keep_the_trace_clear(trace):
    worlds = []
    for seed in (0, 0, 1):
        scene = make_scene("random", trace, np.random.default_rng(seed))
        worlds.append(scene)
        assert np.min(scene.world.clearance(scene.trace.waypoints)) >= LAYOUT_CLEARANCE
        assert len(scene.world.walls) >= 4  # the room, at least
    np.testing.assert_array_equal(worlds[0].world.circles, worlds[1].world.circles)
    np.testing.assert_array_equal(worlds[0].trace.waypoints, worlds[1].trace.waypoints)
    assert not np.array_equal(worlds[0].trace.waypoints, worlds[2].trace.waypoints)


def test_bad_names_and_a_missing_generator_are_readable():
    with pytest.raises(ValueError, match="unknown world 'maze': expected one of open_cylinders, "
                                         "hallway, closed_to_open, random"):
        make_world("maze")
    with pytest.raises(ValueError, match="unknown trace 'lap'"):
        make_scene("hallway", "lap")
    with pytest.raises(TypeError, match="world 'random' needs a numpy.random.Generator, got int"):
        make_scene("random", "straight", 3)
