"""Trace seeds: exact geometry, projection against a brute-force oracle, fitting to a world."""

import math

import numpy as np
import pytest

from lidar_env.routes.trace_geometry import WAYPOINT_SPACING
from lidar_env.routes.traces import (
    RIGHT_TURN_RADIUS,
    TRACE_NAMES,
    TraceFitError,
    build_trace,
    make_trace,
)
from lidar_env.world.world import World


@pytest.mark.parametrize("seed", TRACE_NAMES)
def test_every_seed_has_the_requested_length_and_dense_waypoints(seed):
    start = (2.0, -1.0, 0.7)
    trace = build_trace(seed, start, 25.0)
    assert trace.length == pytest.approx(25.0, abs=1e-3)
    steps = np.hypot(*np.diff(trace.waypoints, axis=0).T)
    assert steps.max() <= WAYPOINT_SPACING + 1e-9
    np.testing.assert_allclose(trace.start_pose, start)
    # headings agree with the direction the waypoints actually run in
    direction = np.arctan2(*np.diff(trace.waypoints, axis=0)[:, ::-1].T)
    mid = 0.5 * (trace.headings[1:] + trace.headings[:-1])
    np.testing.assert_allclose(np.angle(np.exp(1j * (direction - mid))), 0.0, atol=1e-3)


def test_straight_and_right_turn_end_where_geometry_says():
    straight = build_trace("straight", (1.0, 2.0, math.pi / 2), 10.0)
    np.testing.assert_allclose(straight.end_pose, (1.0, 12.0, math.pi / 2), atol=1e-12)
    turn = build_trace("right_turn", (0.0, 0.0, 0.0), 20.0)
    leg = (20.0 - 0.5 * math.pi * RIGHT_TURN_RADIUS) / 2
    expected = (leg + RIGHT_TURN_RADIUS, -(leg + RIGHT_TURN_RADIUS), -math.pi / 2)
    np.testing.assert_allclose(turn.end_pose, expected, atol=1e-9)


def test_zigzag_swings_both_ways_and_returns_to_its_axis():
    trace = build_trace("zigzag", (0.0, 0.0, 0.0), 30.0)
    lateral = trace.waypoints[:, 1]
    assert lateral.max() > 1.0 and lateral.min() < -1.0
    assert abs(lateral.max() + lateral.min()) < 1e-6  # symmetric about the start axis
    np.testing.assert_allclose(trace.end_pose[1:], (0.0, 0.0), atol=1e-9)
    turns = np.diff(np.sign(np.round(trace.headings, 6)))
    assert np.count_nonzero(turns) >= 6  # several legs, not one bend


def test_projection_matches_a_brute_force_oracle():
    trace = build_trace("zigzag", (0.0, 0.0, 0.3), 20.0)
    rng = np.random.default_rng(1)
    dense = np.linspace(0, trace.length, 200_001)
    oracle_points = np.stack([trace.point_at(s) for s in dense[::50]])
    for point in rng.uniform((-1, -3), (18, 8), size=(20, 2)):
        projection = trace.project(point)
        distances = np.hypot(*(oracle_points - point).T)
        assert abs(projection.cross_track_error) == pytest.approx(distances.min(), abs=2e-3)
        foot = trace.point_at(projection.arc_position)
        assert np.hypot(*(foot - point)) == pytest.approx(abs(projection.cross_track_error))
        assert projection.progress == pytest.approx(projection.arc_position / trace.length)


def test_cross_track_error_is_positive_on_the_left():
    trace = build_trace("straight", (0.0, 0.0, 0.0), 10.0)
    assert trace.project((3.0, 0.5)).cross_track_error == pytest.approx(0.5)
    assert trace.project((3.0, -0.5)).cross_track_error == pytest.approx(-0.5)
    np.testing.assert_allclose(trace.lookahead((3.0, -0.5), 1.5), (4.5, 0.0))


def test_a_window_keeps_the_projection_on_the_current_leg():
    trace = build_trace("zigzag", (0.0, 0.0, 0.0), 30.0)
    point = trace.point_at(10.0) + (0.0, 0.05)
    near = trace.project(point, near=10.0)
    assert near.arc_position == pytest.approx(10.0, abs=0.1)
    far = trace.project(point, near=20.0, window=2.0)
    assert 18.0 - WAYPOINT_SPACING <= far.arc_position <= 22.0 + WAYPOINT_SPACING


def test_fitting_shrinks_a_trace_to_clear_a_wall():
    wall = World(segments=[[12.0, -5.0, 12.0, 5.0]], bounds=(-2, -6, 30, 6), name="wall")
    trace = make_trace("straight", (0.0, 0.0, 0.0), 20.0, wall, clearance=0.77)
    assert trace.length < 12.0 - 0.77
    assert np.min(wall.clearance(trace.waypoints)) >= 0.77
    roomy = make_trace("straight", (0.0, 0.0, 0.0), 10.0, wall, clearance=0.77)
    assert roomy.length == pytest.approx(10.0)


def test_fitting_shrinks_bends_before_length():
    corridor = World(segments=[[-1, 1.6, 40, 1.6], [-1, -1.6, 40, -1.6]], bounds=(-2, -3, 41, 3))
    trace = make_trace("zigzag", (0.0, 0.0, 0.0), 30.0, corridor, clearance=0.77)
    assert trace.length == pytest.approx(30.0, abs=1e-2)
    assert np.min(corridor.clearance(trace.waypoints)) >= 0.77
    assert np.max(np.abs(trace.waypoints[:, 1])) < 1.6 - 0.77 + 1e-9


def test_an_impossible_fit_says_where_it_is_tight():
    box = World(segments=[[1.0, -1, 1.0, 1]], bounds=(-2, -2, 30, 2), name="box")
    with pytest.raises(TraceFitError, match=r"trace 'straight' .* does not fit in world 'box'"):
        make_trace("straight", (0.0, 0.0, 0.0), 20.0, box, clearance=0.77)


def test_unknown_seed_and_bad_arguments_are_readable():
    with pytest.raises(ValueError, match="unknown trace 'zig': expected one of straight, "
                                         "right_turn, zigzag, loop, out_and_back"):
        build_trace("zig", (0, 0, 0), 10.0)
    with pytest.raises(ValueError, match="start_pose: expected 3 finite numbers"):
        build_trace("straight", (0, 0), 10.0)
    with pytest.raises(ValueError, match="length: expected a positive trace length"):
        build_trace("straight", (0, 0, 0), -1.0)


@pytest.mark.parametrize("seed", ["zigzag", "loop"])
def test_points_at_is_point_at_bit_for_bit(seed: str) -> None:
    trace = build_trace(seed, (0.5, -1.0, 0.3), 20.0)
    arcs = np.random.default_rng(3).uniform(-5.0, trace.length + 5.0, 200)  # past both ends
    arcs[:3] = (0.0, trace.length, -0.0)
    expected = np.stack([trace.point_at(float(s)) for s in arcs])
    np.testing.assert_array_equal(trace.points_at(arcs), expected)
