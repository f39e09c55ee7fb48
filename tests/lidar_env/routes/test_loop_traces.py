"""The loop-closure seeds: a closed ``loop`` and ``out_and_back``, and closed-trace progress."""

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents import PurePursuitDriver
from lidar_env import lidars_with_noise
from lidar_env.core import se2
from lidar_env.routes.trace_geometry import WAYPOINT_SPACING
from lidar_env.routes.traces import (
    LOOP_ASPECT,
    LOOP_CORNER_RADIUS,
    OUT_AND_BACK_OFFSET,
    OUT_AND_BACK_RADIUS,
    Trace,
    build_trace,
)
from lidar_env.world.built_in import WORLD_NAMES

BUILT_IN = [name for name in WORLD_NAMES if name != "random"]


@pytest.mark.parametrize("length", [40.0, 25.0, 6.0])
@pytest.mark.parametrize("start", [(0.0, 0.0, 0.0), (3.0, -7.0, 2.9), (-1.0, 4.0, -2.0)])
def test_a_loop_ends_at_its_start_pose(start, length):
    trace = build_trace("loop", start, length)
    assert trace.closed
    np.testing.assert_allclose(se2.relative(trace.start_pose, trace.end_pose), 0.0, atol=1e-9)
    # counter-clockwise: exactly one turn to the left, never to the right
    assert trace.headings[-1] - trace.headings[0] == pytest.approx(2 * math.pi, abs=1e-9)
    assert np.all(np.diff(trace.headings) >= 0.0)
    np.testing.assert_allclose(trace.point_at(trace.length + 1.0), trace.point_at(1.0))


@pytest.mark.parametrize("length", [40.0, 10.0])
def test_the_loop_encloses_the_area_of_its_rounded_rectangle(length):
    trace = build_trace("loop", (2.0, 1.0, 0.4), length)
    radius = min(LOOP_CORNER_RADIUS, length / (4 * math.pi))
    short = (length - 2 * math.pi * radius) / (2 * (1 + LOOP_ASPECT))
    long = LOOP_ASPECT * short
    expected = (long + 2 * radius) * (short + 2 * radius) - (4 - math.pi) * radius**2
    x, y = trace.waypoints.T
    shoelace = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)  # > 0: counter-clockwise
    # chords cut the corners: (pi / 6) spacing^2 in all, whatever the radius
    assert expected - WAYPOINT_SPACING**2 < shoelace <= expected


@pytest.mark.parametrize(("length", "scale"), [(40.0, 1.0), (15.0, None)])
def test_out_and_back_returns_beside_its_start_facing_back(length, scale):
    start = (1.0, -2.0, 0.5)
    trace = build_trace("out_and_back", start, length)
    assert not trace.closed
    angle = math.acos((OUT_AND_BACK_OFFSET / OUT_AND_BACK_RADIUS + 2) / 4)
    if scale is None:  # short: the turn-around shrinks to half the length
        scale = length / (2 * OUT_AND_BACK_RADIUS * (math.pi + 4 * angle))
    expected = se2.compose(start, (0.0, OUT_AND_BACK_OFFSET * scale, math.pi))
    np.testing.assert_allclose(se2.relative(expected, trace.end_pose), 0.0, atol=1e-9)
    # the way back runs along the way out: every point of the last quarter is offset from it
    quarter = len(trace.waypoints) // 4
    out, back = trace.waypoints[:quarter], trace.waypoints[-quarter:]
    gaps = np.min(np.hypot(*(back[:, None] - out[None]).transpose(2, 0, 1)), axis=1)
    np.testing.assert_allclose(gaps, OUT_AND_BACK_OFFSET * scale, atol=1e-3)


def _left_of(trace: Trace, arc: float, offset: float) -> np.ndarray:
    """The point ``offset`` [m] left of the trace at ``arc`` [m] (any lap)."""
    heading = np.interp(arc % trace.length, trace.arc, trace.headings)
    return trace.point_at(arc) + offset * np.array([-math.sin(heading), math.cos(heading)])


def test_tracked_projection_counts_two_laps_through_the_seam():
    trace = build_trace("loop", (5.0, 5.0, 1.0), 30.0)
    tracked = 0.0
    for arc in np.arange(0.0, 2 * trace.length, 0.1):
        projection = trace.project(_left_of(trace, arc, 0.2), near=tracked)
        tracked = projection.arc_position
        # on the corners the chords lean off the tangent by spacing / (2 radius): mm shifts
        assert tracked == pytest.approx(arc, abs=5e-3)
        assert projection.cross_track_error == pytest.approx(0.2, abs=1e-3)
    assert projection.progress == pytest.approx(2.0 - 0.1 / trace.length, abs=1e-4)


def test_projection_near_the_seam_looks_both_ways_and_stays_in_its_window():
    trace = build_trace("loop", (0.0, 0.0, 0.0), 30.0)
    length = trace.length
    behind = _left_of(trace, length - 0.5, -0.1)  # just before the end = just behind the start
    assert trace.project(behind, near=0.3).arc_position == pytest.approx(-0.5, abs=1e-6)
    assert trace.project(behind, near=length - 0.3).arc_position == pytest.approx(
        length - 0.5, abs=1e-6)
    ahead = _left_of(trace, 0.5, 0.1)
    assert trace.project(ahead, near=length - 0.3).arc_position == pytest.approx(
        length + 0.5, abs=1e-6)
    assert trace.project(ahead).arc_position == pytest.approx(0.5, abs=1e-6)  # global: [0, L]
    # across the seam the window still holds: a point half a lap away is not reached
    far = trace.project(_left_of(trace, length / 2, 0.0), near=0.0, window=2.0)
    assert -2.0 - WAYPOINT_SPACING <= far.arc_position <= 2.0 + WAYPOINT_SPACING
    # a window wider than the loop sees every point on two laps: the lap nearest ``near`` wins
    wide = trace.project(_left_of(trace, 1.0, 0.1), near=3 * length - 2.0, window=10 * length)
    assert wide.arc_position == pytest.approx(3 * length + 1.0, abs=1e-6)
    # the windowed answer is the global one, shifted by whole laps, when it lies in the window
    rng = np.random.default_rng(4)
    for arc in rng.uniform(-length, 2 * length, size=30):
        point = _left_of(trace, arc, rng.uniform(-0.5, 0.5))
        windowed = trace.project(point, near=arc + rng.uniform(-1.0, 1.0))
        whole = trace.project(point)
        laps = (windowed.arc_position - whole.arc_position) / length
        assert laps == pytest.approx(round(laps), abs=1e-9)
        assert windowed.cross_track_error == pytest.approx(whole.cross_track_error, abs=1e-12)


def test_a_closed_trace_must_close():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match=r"closed trace 'bent': expected the last waypoint to "
                                         r"meet the first .* got a gap of 1.41421 m"):
        Trace("bent", points, np.zeros(3), closed=True)


def test_the_env_counts_the_lap_not_the_distance_to_the_start():
    config = {"lidars": lidars_with_noise(range_noise_std=0.0), "cross_track_penalty": 0.0}
    env = gym.make("DualLidar-v0", world="hallway", trace="loop", config=config)
    _, info = env.reset(seed=0)
    assert info["arc_position"] == 0.0
    back = np.array([-1.0, 0.0], dtype=np.float32)  # 0.15 m per step, straight back
    total = 0.0
    for _ in range(10):  # backing over the seam is no lap, and earns no lap's reward
        _, reward, terminated, _, info = env.step(back)
        total += reward
        assert not terminated
    assert info["arc_position"] == pytest.approx(-1.5, abs=1e-9)
    assert info["progress"] == pytest.approx(-1.5 / env.unwrapped.trace.length)
    assert total == pytest.approx(-1.5, abs=1e-9)


@pytest.mark.parametrize("world", BUILT_IN)
def test_the_scripted_driver_drives_one_lap_of_the_loop(world):
    env = gym.make("DualLidar-v0", world=world, trace="loop")
    observation, info = env.reset(seed=0)
    driver = PurePursuitDriver()
    driver.reset(env)
    arcs, total = [info["arc_position"]], 0.0
    while True:
        observation, reward, terminated, truncated, info = env.step(driver.act(observation, info))
        arcs.append(info["arc_position"])
        total += reward
        if terminated or truncated:
            break
    trace, config = env.unwrapped.trace, env.unwrapped.config
    assert terminated and not info["collision"]
    assert np.all(np.diff(arcs) > 0.0)  # through the seam without a jump
    assert trace.length - config.goal_tolerance <= arcs[-1] < trace.length
    assert total == pytest.approx(arcs[-1], abs=0.05)  # reward = arc gained (- tiny penalty)
    # it drove the lap: the arc covered is the distance driven (~ speed x time), and it stopped
    # short of the start by the goal tolerance at most (+ one step's travel, + cross-track)
    assert info["time"] * driver.speed == pytest.approx(arcs[-1], rel=0.03)
    gap = np.hypot(*(info["pose"][:2] - trace.start_pose[:2]))
    assert gap <= config.goal_tolerance + 0.15 + abs(info["cross_track_error"])


@pytest.mark.parametrize("trace", ["loop", "out_and_back"])
def test_gymnasium_checker_passes_on_the_new_seeds(trace):
    env = gym.make("DualLidar-v0", world="closed_to_open", trace=trace)
    check_env(env.unwrapped, skip_render_check=True)
