"""seen_through: points lying in space a scan saw as free."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.odometry.free_space import seen_through
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World

FULL = 2 * np.pi * np.arange(360) / 360
FRONT = np.linspace(-np.pi / 2, np.pi / 2, 181)  # a 180-degree Lidar, beam 0 to the right
BOX = World(segments=[[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]])


def _bounded(ranges: np.ndarray, max_range: float, full: bool, window: int = 3) -> np.ndarray:
    """Brute force: each no-return reading with a return within ``window`` beams bounded by
    the nearer of the nearest returns on either side."""
    n, out = len(ranges), ranges.copy()
    for j in np.flatnonzero(ranges >= max_range):
        nearest = []
        for side in (-1, 1):
            for d in range(1, window + 1):
                k = (j + side * d) % n if full else j + side * d
                if 0 <= k < n and ranges[k] < max_range:
                    nearest.append(ranges[k])
                    break
        if nearest:
            out[j] = min(nearest)
    return out


def _oracle(point: np.ndarray, pose: np.ndarray, ranges: np.ndarray, angles: np.ndarray,
            max_range: float, margin: float) -> bool:
    """Brute force: the nearest beam by angle (within the field of view) and its neighbours,
    no-return readings among returns bounded by them."""
    ranges = _bounded(ranges, max_range, len(angles) == 360)
    dx, dy = point - pose[:2]
    distance = math.hypot(dx, dy)
    if distance + margin >= max_range:
        return False
    bearing = math.atan2(dy, dx) - pose[2]
    gaps = np.abs((angles - bearing + np.pi) % (2 * np.pi) - np.pi)
    j = int(np.argmin(gaps))
    n = len(angles)
    full = n == 360
    spacing = 2 * np.pi / n if full else (angles[-1] - angles[0]) / (n - 1)
    if gaps[j] > 0.5 * spacing + 1e-12:
        return False  # outside the field of view
    neighbours = [(j + o) % n if full else j + o for o in (-1, 0, 1)]
    if any(k < 0 or k >= n for k in neighbours):
        return False
    return all(min(ranges[k], max_range) > distance + margin for k in neighbours)


def test_a_static_scene_is_not_seen_through_by_a_later_scan() -> None:
    rng = np.random.default_rng(0)
    world = World(circles=[[2.0, 1.0, 0.3]], segments=BOX.walls)
    first, second = np.array([0.0, 0.0, 0.0]), np.array([0.3, 0.1, 0.2])
    ranges = cast_rays(world, first, FULL, 10.0)[0] + 0.01 * rng.standard_normal(360)
    points = first[:2] + np.column_stack([ranges * np.cos(FULL), ranges * np.sin(FULL)])
    later = cast_rays(world, second, FULL, 10.0)[0] + 0.01 * rng.standard_normal(360)
    assert not seen_through(points, second[None], [later], [FULL], [10.0]).any()


def test_a_point_in_front_of_a_wall_is_seen_through_one_behind_it_is_not() -> None:
    pose = np.array([0.0, 0.0, 0.0])
    ranges = cast_rays(BOX, pose, FULL, 10.0)[0]
    points = np.array([[2.0, 0.0], [5.5, 0.0], [4.9, 0.0], [0.0, -3.0]])
    flags = seen_through(points, pose[None], [ranges], [FULL], [10.0])
    np.testing.assert_array_equal(flags, [True, False, False, True])


def test_dropped_beams_among_returns_do_not_see_through_the_wall_they_miss() -> None:
    pose = np.array([0.0, 0.0, 0.0])
    ranges = cast_rays(BOX, pose, FULL, 10.0)[0]
    dropped = ranges.copy()
    dropped[np.arange(360) % 8 < 4] = 10.0  # half the beams return nothing, in bursts of 4
    wall = np.array([[5.3, y] for y in np.linspace(-3.0, 3.0, 13)])  # just behind the wall
    assert not seen_through(wall, pose[None], [dropped], [FULL], [10.0]).any()
    inside = np.array([[4.0, y] for y in np.linspace(-3.0, 3.0, 13)])  # in front of it
    assert seen_through(inside, pose[None], [dropped], [FULL], [10.0]).all()


def test_the_open_is_seen_free_up_to_the_max_range() -> None:
    pose = np.array([0.0, 0.0, 0.0])
    ranges = np.full(360, 10.0)  # nothing in range
    ranges[170:190] = 2.0  # but one object behind the car
    points = np.array([[6.0, 0.0], [0.0, 6.0], [-6.0, 0.0]])
    flags = seen_through(points, pose[None], [ranges], [FULL], [10.0])
    np.testing.assert_array_equal(flags, [True, True, False])


def test_a_narrow_lidar_says_nothing_behind_it() -> None:
    pose = np.array([0.0, 0.0, 0.0])
    ranges = cast_rays(BOX, pose, FRONT, 10.0)[0]
    flags = seen_through(np.array([[2.0, 0.0], [-2.0, 0.0], [1.0, 1.5], [0.0, 2.0]]), pose[None],
                         [ranges], [FRONT], [10.0])
    np.testing.assert_array_equal(flags, [True, False, True, False])  # edge: no neighbour


def test_any_sensor_suffices() -> None:
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, np.pi]])
    scans = [cast_rays(BOX, p, FRONT, 10.0)[0] for p in poses]
    flags = seen_through(np.array([[2.0, 0.0], [-2.0, 0.0]]), poses, scans, [FRONT] * 2,
                         [10.0] * 2)
    np.testing.assert_array_equal(flags, [True, True])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), full=st.booleans(),
       heading=st.floats(-np.pi, np.pi), margin=st.floats(0.0, 0.5))
def test_matches_the_brute_force_oracle(seed: int, full: bool, heading: float,
                                        margin: float) -> None:
    rng = np.random.default_rng(seed)
    angles = FULL if full else FRONT
    pose = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), heading])
    ranges = rng.uniform(0.0, 12.0, len(angles))  # beyond 10 m: no return
    points = rng.uniform(-9, 9, (200, 2))
    flags = seen_through(points, pose[None], [ranges], [angles], [10.0], margin)
    expected = [_oracle(p, pose, ranges, angles, 10.0, margin) for p in points]
    # the kernel's bearing is good to 2e-6 rad: half-way between two beams either is nearest
    bearings = np.arctan2(points[:, 1] - pose[1], points[:, 0] - pose[0]) - pose[2] - angles[0]
    spacing = angles[1] - angles[0]
    clear = np.abs((bearings / spacing) % 1.0 - 0.5) * spacing > 1e-5
    np.testing.assert_array_equal(flags[clear], np.array(expected)[clear])


def _car_points(scans: list[np.ndarray], setup: object) -> np.ndarray:
    from estimators.matching.scan_matching import scans_to_car_points

    return scans_to_car_points(dict(zip(setup.keys, scans, strict=True)), setup)  # type: ignore[attr-defined]


@pytest.mark.parametrize("path", ["crossing", "receding"])
def test_the_filter_flags_a_walker_and_nothing_static(path: str) -> None:
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter

    setup = SensorSetup([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]], FULL, 10.0)
    moving_filter = MovingPointFilter(setup)
    rng = np.random.default_rng(2)
    car = np.array([0.0, 0.0, 0.0])
    sensors = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])
    walk = np.arange(0.0, 3.0, 0.1)  # 1 m/s at 10 Hz
    # crossing 2.5 m ahead of the car; or walking straight away from it (it hides where it
    # goes, never where it was: only the points it left tell)
    places = (np.column_stack([np.full_like(walk, 2.5), walk - 2.0]) if path == "crossing"
              else np.column_stack([1.2 + walk, np.full_like(walk, 0.3)]))
    for step, (walker_x, walker_y) in enumerate(places):
        world = World(circles=[[3.0, 2.0, 0.3], [walker_x, walker_y, 0.25]],
                      segments=BOX.walls)
        scans = [s + 0.01 * rng.standard_normal(360) for s in cast_rays(world, sensors, FULL,
                                                                          10.0)]
        points = _car_points(scans, setup)
        observation = dict(zip(setup.keys, scans, strict=True))
        moving, stale = moving_filter.classify(points, car, observation, [])
        on_walker = np.abs(np.hypot(points[:, 0] - walker_x, points[:, 1] - walker_y)
                           - 0.25) < 0.05
        if step >= 5:  # half a second of history: the walker's whole visible side
            assert moving[on_walker].mean() > (0.9 if path == "crossing" else 0.8)
        assert not moving[~on_walker].any()
        assert stale == []
        moving_filter.remember(car, observation, points)



def test_a_scan_judges_only_points_where_its_beams_lie_close_enough() -> None:
    """``resolution``: at 1-degree beams (1.75 cm apart per metre) and 0.1 m, points out to
    5.7 m are judged, farther ones not (the beams could straddle a thin post there)."""
    from estimators.odometry.free_space import BeamGeometry

    room = World(segments=[[-12, -12, 12, -12], [12, -12, 12, 12], [12, 12, -12, 12],
                           [-12, 12, -12, -12]])
    ranges = cast_rays(room, np.zeros(3), FULL, 20.0)[0]
    points = np.array([[3.0, 0.1], [5.5, -0.2], [6.0, 0.3], [8.0, 0.05], [0.0, -9.0]])
    beams = BeamGeometry([FULL], [20.0])
    everywhere = beams.seen_through(points, np.zeros((1, 3)), [ranges], 0.2)
    near_only = beams.seen_through(points, np.zeros((1, 3)), [ranges], 0.2, 0.0, 0.1)
    np.testing.assert_array_equal(everywhere, [True] * 5)
    np.testing.assert_array_equal(near_only, [True, True, False, False, False])


def test_the_filter_clears_map_points_only_where_the_new_scan_resolves_them() -> None:
    """A map point in free space 3 m out is stale, one 8 m out (1-degree beams 14 cm apart
    there) is not, with the default ``stale_resolution`` 0.1 m; a new point in space an earlier
    scan saw through is moving at 8 m too (that test keeps the full range)."""
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter

    room = World(segments=[[-12, -12, 12, -12], [12, -12, 12, 12], [12, 12, -12, 12],
                           [-12, 12, -12, -12]])
    setup = SensorSetup([[0.0, 0.0, 0.0]], FULL, 20.0)
    car = np.zeros(3)
    empty = {setup.keys[0]: cast_rays(room, car[None], FULL, 20.0)[0]}
    moving_filter = MovingPointFilter(setup)
    far, near = np.array([[8.0, 0.05]]), np.array([[3.0, 0.05]])
    moving, stale = moving_filter.classify(far, car, empty, [near, far])
    assert stale[0].tolist() == [True] and stale[1].tolist() == [False]
    assert moving.tolist() == [False]  # no history yet
    moving_filter.remember(car, empty, np.zeros((0, 2)))
    moving, _ = moving_filter.classify(far, car, empty, [])
    assert moving.tolist() == [True]
    everywhere = MovingPointFilter(setup, stale_resolution=np.inf)
    assert everywhere.classify(far, car, empty, [far])[1][0].tolist() == [True]


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan")])
def test_a_stale_resolution_that_is_no_spacing_is_named(bad: float) -> None:
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter
    from lidar_env.core.errors import ConfigError

    with pytest.raises(ConfigError, match="stale_resolution"):
        MovingPointFilter(SensorSetup([[0.0, 0.0, 0.0]], FULL, 20.0), stale_resolution=bad)


def _walker_steps(places: np.ndarray, interval: float, room: World = BOX, jump: float = 0.0,
                  **params: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """A two-Lidar car (20 m range) standing in ``room`` beside a post while a walker (0.25 m)
    passes through ``places``, one scan every ``interval`` [s], each pose ``jump`` [m] from
    the motion model's guess: per scan, the filter's moving mask and which points lie on the
    walker."""
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter

    setup = SensorSetup([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]], FULL, 20.0)
    moving_filter = MovingPointFilter(setup, **params)
    sensors, car = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]]), np.zeros(3)
    steps = []
    for walker_x, walker_y in places:
        world = World(circles=[[3.0, 2.0, 0.3], [walker_x, walker_y, 0.25]],
                      segments=room.walls)
        scans = cast_rays(world, sensors, FULL, 20.0)
        points = _car_points(scans, setup)
        observation = dict(zip(setup.keys, scans, strict=True))
        moving, _ = moving_filter.classify(points, car, observation, [])
        on_walker = np.abs(np.hypot(points[:, 0] - walker_x, points[:, 1] - walker_y)
                           - 0.25) < 0.05
        steps.append((moving, on_walker))
        moving_filter.remember(car, observation, points, interval, jump)
    return steps


def test_a_slow_walker_walking_away_is_flagged_once_it_has_left_margin_behind() -> None:
    """At 0.3 m/s a walker leaves the 0.2 m margin behind only after 0.7 s: half a second of
    scans (``history``) never shows it moved on, the last second's (``anchor_time``) does."""
    walk = 3.0 + 0.03 * np.arange(25)  # 0.3 m/s at 10 Hz, straight away from the car
    places = np.column_stack([walk, np.full_like(walk, 0.3)])
    for anchor_time in (1.0, 0.0):
        steps = _walker_steps(places, 0.1, anchor_time=anchor_time)
        assert not any(moving[~on_walker].any() for moving, on_walker in steps)
        late = [moving[on_walker].mean() for moving, on_walker in steps[10:]]
        assert min(late) > 0.8 if anchor_time else max(late) == 0.0


def test_after_a_jump_the_last_scans_are_judged_only_where_beams_are_dense() -> None:
    """A pose that landed far from the motion model's guess may be off; the far points of the
    scans before it then stop marking what moved on for ``history`` scans."""
    far = 7.0 + 0.03 * np.arange(25)  # walking away 7 m out: 1-degree beams 12 cm apart
    places = np.column_stack([far, np.full_like(far, 0.3)])
    hall = World(segments=[[-12, -12, 12, -12], [12, -12, 12, 12], [12, 12, -12, 12],
                           [-12, 12, -12, -12]])
    steady = _walker_steps(places, 0.1, hall)
    assert min(moving[on].mean() for moving, on in steady[10:]) > 0.5  # 4 beams on it
    jumpy = _walker_steps(places, 0.1, hall, jump=0.06)  # each pose 6 cm from the guess
    assert not any(moving.any() for moving, _ in jumpy)


@pytest.mark.parametrize("name", ["radius", "history", "anchor_time", "max_anchor_scans",
                                  "anchor_spacing", "anchor_break", "map_clearance",
                                  "map_support"])
def test_a_filter_setting_out_of_range_is_named(name: str) -> None:
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter
    from lidar_env.core.errors import ConfigError

    for bad in (-1, float("nan")):
        with pytest.raises(ConfigError, match=name):
            MovingPointFilter(SensorSetup([[0.0, 0.0, 0.0]], FULL, 20.0), **{name: bad})


def test_points_beside_a_moving_one_stay_out_of_the_map_unless_the_map_knows_them() -> None:
    """A walker's points the filter missed lie beside those it caught: they stay out of the
    keyframe; a wall point as near, which the map already holds, stays in."""
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter

    moving_filter = MovingPointFilter(SensorSetup([[0.0, 0.0, 0.0]], FULL, 20.0))
    world = np.array([[3.0, 0.0], [3.0, 0.1], [3.0, 0.2],  # caught
                      [3.0, 0.35], [3.05, -0.2],  # missed, within map_clearance (0.3 m)
                      [3.2, 0.3],  # a wall point as near, the map holds one 5 cm off
                      [3.0, 0.9], [6.0, 0.0]])  # static, farther out
    moving = np.array([True, True, True, False, False, False, False, False])
    known = [np.array([[3.25, 0.3]]), np.array([[9.0, 9.0]])]
    keep = moving_filter.mappable(world, moving, known)
    assert keep.tolist() == [False, False, False, False, False, True, True, True]
    assert moving_filter.mappable(world, moving, []).tolist()[5] is False  # no map: out
    nothing = np.zeros(len(world), dtype=np.bool_)
    assert moving_filter.mappable(world, nothing, known).all()
    off = MovingPointFilter(SensorSetup([[0.0, 0.0, 0.0]], FULL, 20.0), map_clearance=0.0)
    assert off.mappable(world, moving, known).tolist() == (~moving).tolist()
