"""The exact Lidar kernel against pymunk's own ray query, its edge cases, and the noise model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lidar_env.sensors.lidar import Lidar, cast_rays, pymunk_cast_rays
from lidar_env.world.world import World

MAX_RANGE = 10.0
BEAMS = 2.0 * np.pi * np.arange(360) / 360


def pymunk_ranges(world: World, poses: np.ndarray, angles: np.ndarray, max_range: float):
    """Oracle: one ``segment_query_first`` per beam against ``world.build_space()``."""
    return pymunk_cast_rays(world.build_space(), poses, angles, max_range)


def random_free_poses(world: World, rng: np.random.Generator, count: int, margin: float = 0.05):
    """``count`` poses in ``world.bounds`` with at least ``margin`` [m] of clearance."""
    xmin, ymin, xmax, ymax = world.bounds
    poses = np.empty((0, 3))
    while len(poses) < count:
        candidates = np.column_stack(
            [rng.uniform(xmin, xmax, 4 * count), rng.uniform(ymin, ymax, 4 * count),
             rng.uniform(-np.pi, np.pi, 4 * count)]
        )
        poses = np.vstack([poses, candidates[world.clearance(candidates[:, :2]) > margin]])
    return poses[:count]


def random_world(rng: np.random.Generator) -> World:
    centres = rng.uniform(-12, 12, (30, 2))
    circles = np.column_stack([centres, rng.uniform(0.1, 1.0, 30)])
    starts = rng.uniform(-12, 12, (60, 2))
    angle = rng.uniform(0, 2 * np.pi, 60)
    length = rng.uniform(0.3, 5.0, 60)
    walls = np.column_stack([starts, starts + length[:, None] * np.column_stack(
        [np.cos(angle), np.sin(angle)])])
    # Axis-aligned walls and a non-convex polygon exercise exact horizontal/vertical geometry.
    walls = np.vstack([walls, [[-14, -14, 14, -14], [14, -14, 14, 14], [-14, 3, -9, 3]]])
    l_shape = np.array([[4, 8], [8, 8], [8, 9], [5, 9], [5, 12], [4, 12]], dtype=float)
    triangle = np.array([[-6, -8], [-3, -9], [-4, -6]], dtype=float)
    return World(circles, walls, [l_shape, triangle], bounds=(-15, -15, 15, 15))


def image_world() -> World:
    yy, xx = np.mgrid[:80, :100]
    image = np.zeros((80, 100), dtype=np.uint8)
    image[:3, :] = image[-3:, :] = image[:, :3] = image[:, -3:] = 255
    image[(yy - 40) ** 2 + (xx - 30) ** 2 < 120] = 255
    image[20:50, 60:64] = 255
    image[55:60, 40:90] = 128
    return World.from_image(image, 0.1, origin=(-5.0, -4.0))


@pytest.mark.parametrize(
    "make_world",
    [
        pytest.param(lambda rng: World(random_world(rng).circles, bounds=(-15, -15, 15, 15)),
                     id="circles"),
        pytest.param(lambda rng: World(segments=random_world(rng).walls), id="walls"),
        pytest.param(random_world, id="mixed"),
        pytest.param(lambda rng: image_world(), id="from_image"),
    ],
)
def test_matches_pymunk_ray_query(make_world) -> None:
    rng = np.random.default_rng(7)
    world = make_world(rng)
    poses = random_free_poses(world, rng, 16)
    ranges = cast_rays(world, poses, BEAMS, MAX_RANGE)
    expected = pymunk_ranges(world, poses, BEAMS, MAX_RANGE)
    assert ranges.shape == (16, 360)
    np.testing.assert_allclose(ranges, expected, rtol=0, atol=1e-6)
    assert np.mean(ranges < MAX_RANGE) > 0.2, "the scans should see plenty of obstacles"


def test_large_map_through_the_grid_matches_pymunk_and_contains() -> None:
    """A map of thousands of edges: the grid must neither miss primitives nor double-count
    polygon edges in the inside test, also for sensors outside the map."""
    rng = np.random.default_rng(4)
    image = (rng.random((120, 160)) < 0.08).astype(np.uint8)
    image[40:80, 60:100] = 255
    image[45:75, 65:95] = 0  # a room ...
    image[55:60, 75:80] = 255  # ... with an island
    world = World.from_image(image, 0.1, origin=(-3.0, 1.0))
    assert len(world.segments) > 1500 and world.grid.nx * world.grid.ny > 100
    xmin, ymin, xmax, ymax = world.bounds
    poses = np.column_stack([rng.uniform(xmin - 2, xmax + 2, 400),
                             rng.uniform(ymin - 2, ymax + 2, 400), rng.uniform(-4, 4, 400)])
    ranges = cast_rays(world, poses, BEAMS, 3.0)
    blind = np.all(ranges == 0.0, axis=1)
    np.testing.assert_array_equal(blind, world.contains(poses[:, :2]))
    assert 20 < blind.sum() < 200
    free = np.flatnonzero(world.clearance(poses[:, :2]) > 1e-3)[:12]
    np.testing.assert_allclose(
        ranges[free], pymunk_ranges(world, poses[free], BEAMS, 3.0), rtol=0, atol=1e-6
    )


@pytest.mark.parametrize(
    "angles",
    [
        pytest.param(np.random.default_rng(3).uniform(-7, 7, 200), id="unsorted-random"),
        pytest.param(np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 271), id="270-degree-fan"),
        pytest.param(BEAMS[::-1] - np.pi, id="descending-shifted"),
        pytest.param(np.array([0.3, 0.3, 1.0, 1.0]), id="duplicates"),
        pytest.param(np.array([0.3]), id="single-beam"),
        pytest.param(np.array([1e-17, -1e-17, 2 * np.pi, -2 * np.pi]), id="around-zero"),
        # narrow wedges: the caster skips cells and primitives outside them
        pytest.param(np.sort(np.random.default_rng(5).uniform(0.2, 0.9, 40)), id="narrow-random"),
        pytest.param(np.linspace(2.0, 2.0 + np.pi / 2, 91), id="90-degree-fan"),
        pytest.param(np.linspace(-np.pi / 2, np.pi / 2, 181), id="180-degree-fan"),
    ],
)
def test_general_beam_angles_match_pymunk(angles: np.ndarray) -> None:
    rng = np.random.default_rng(11)
    world = random_world(rng)
    poses = random_free_poses(world, rng, 6)
    np.testing.assert_allclose(
        cast_rays(world, poses, angles, MAX_RANGE),
        pymunk_ranges(world, poses, angles, MAX_RANGE),
        rtol=0,
        atol=1e-6,
    )


def test_beam_direction_convention() -> None:
    """Beam j points at heading + angle_j, counter-clockwise; ranges are from the sensor."""
    world = World(circles=[[5.0, 0.0, 1.0], [0.0, 3.0, 0.5]])
    ranges = cast_rays(world, [[0.0, 0.0, 0.0], [1.0, 0.0, np.pi / 2]], BEAMS, MAX_RANGE)
    assert ranges[0, 0] == pytest.approx(4.0)
    assert ranges[0, 90] == pytest.approx(2.5)
    assert ranges[0, 180] == MAX_RANGE
    # Heading +90 deg: beam 270 (-90 deg in the sensor) points along world +x.
    assert ranges[1, 270] == pytest.approx(3.0)
    assert ranges[1, 0] == MAX_RANGE


def test_beam_exactly_through_segment_end_point_hits() -> None:
    world = World(segments=[[1.0, 0.0, 3.0, 0.0], [-3.0, 1.0, -1.0, 1.0]])
    through_end, just_past_end = np.pi / 4, np.pi / 4 + 1e-9
    ranges = cast_rays(world, [0.0, -1.0, 0.0], np.array([through_end, just_past_end]), MAX_RANGE)
    np.testing.assert_allclose(ranges, [[math.sqrt(2.0), MAX_RANGE]], atol=1e-12)
    ranges = cast_rays(world, [0.0, 0.0, 0.0], np.array([3 * np.pi / 4]), MAX_RANGE)
    np.testing.assert_allclose(ranges, [[math.sqrt(2.0)]], atol=1e-12)


def test_beam_tangent_to_circle_hits_at_the_tangent_point_like_pymunk() -> None:
    world = World(circles=[[5.0, 1.0, 1.0]])
    ranges = cast_rays(world, [0.0, 0.0, 0.0], BEAMS, MAX_RANGE)
    assert ranges[0, 0] == pytest.approx(5.0)
    np.testing.assert_allclose(
        ranges, pymunk_ranges(world, np.zeros((1, 3)), BEAMS, MAX_RANGE), atol=1e-6
    )


def test_beam_along_a_wall_misses_it_like_pymunk() -> None:
    world = World(segments=[[2.0, 0.0, 5.0, 0.0]])
    ranges = cast_rays(world, [0.0, 0.0, 0.0], BEAMS, MAX_RANGE)
    assert ranges[0, 0] == MAX_RANGE
    assert pymunk_ranges(world, np.zeros((1, 3)), BEAMS[:1], MAX_RANGE)[0, 0] == MAX_RANGE


@pytest.mark.parametrize("gap", [1e-3, 1e-7, 1e-11])
def test_sensor_next_to_a_long_wall(gap: float) -> None:
    """A sensor a hair off a wall sees it on the whole half-plane and nothing beyond it."""
    world = World(segments=[[-50.0, 0.0, 50.0, 0.0]])
    poses = np.array([[0.3, gap, 0.1], [0.3, -gap, -2.0]])
    ranges = cast_rays(world, poses, BEAMS, MAX_RANGE)
    for (_, y, heading), row in zip(poses, ranges, strict=True):
        towards_wall = np.sin(heading + BEAMS) * -np.sign(y)
        hits = towards_wall > 1e-6
        np.testing.assert_allclose(row[hits], np.abs(y) / towards_wall[hits], rtol=1e-9)
        assert np.all(row[towards_wall < -1e-6] == MAX_RANGE)


def test_sensor_next_to_a_circle_matches_pymunk() -> None:
    world = World(circles=[[0.0, 0.0, 1.0]])
    poses = np.array([[1.0 + 1e-9, 0.0, 0.3], [0.0, -1.0 - 1e-6, 2.0]])
    np.testing.assert_allclose(
        cast_rays(world, poses, BEAMS, MAX_RANGE),
        pymunk_ranges(world, poses, BEAMS, MAX_RANGE),
        atol=1e-6,
    )


def test_primitive_straddling_the_angle_wrap_is_seen_on_both_sides() -> None:
    """A wall crossing the beam-0 direction (and the +-pi bearing cut) is seen by all beams."""
    world = World(segments=[[3.0, -1.0, 3.0, 1.0], [-3.0, -1.0, -3.0, 1.0]])
    for heading in (0.0, np.pi, -np.pi, 1e-13, 2 * np.pi - 1e-13):
        ranges = cast_rays(world, [0.0, 0.0, heading], BEAMS, MAX_RANGE)[0]
        expected = pymunk_ranges(world, np.array([[0.0, 0.0, heading]]), BEAMS, MAX_RANGE)[0]
        np.testing.assert_allclose(ranges, expected, atol=1e-9)
        assert np.sum(ranges < MAX_RANGE) == 2 * 37  # atan(1/3) = 18.4 deg: 18 beams + centre


def test_sensor_inside_an_obstacle_or_on_a_wall_reads_zero() -> None:
    world = World(
        circles=[[0.0, 0.0, 1.0]],
        segments=[[5.0, -1.0, 5.0, 1.0]],
        polygons=[np.array([[10.0, 0.0], [12.0, 0.0], [11.0, 2.0]])],
    )
    poses = np.array([[0.5, 0.0, 0.0], [5.0, 0.25, 1.0], [11.0, 1.0, 0.0], [3.0, 0.0, 0.0]])
    ranges = cast_rays(world, poses, BEAMS, MAX_RANGE)
    assert np.all(ranges[:3] == 0.0)
    assert ranges[3, 0] == pytest.approx(2.0) and ranges[3, 180] == pytest.approx(2.0)


def test_max_range_cut_off() -> None:
    world = World(circles=[[14.5, 0.0, 1.0]], segments=[[0, -20, 0, 20]])
    ranges = cast_rays(world, [3.0, 0.0, 0.0], BEAMS, MAX_RANGE)[0]
    assert ranges[0] == MAX_RANGE, "the circle's surface is 10.5 m away"
    assert ranges[180] == pytest.approx(3.0)
    assert ranges[120] == pytest.approx(6.0)
    np.testing.assert_array_equal(cast_rays(world, [3.0, 0.0, 0.0], BEAMS, 2.5)[0], 2.5)


def test_accepts_arrays_and_a_single_pose() -> None:
    world = random_world(np.random.default_rng(0))
    pose = np.array([0.5, 0.5, 0.2])
    from_arrays = cast_rays((world.circles, world.segments), pose, BEAMS, MAX_RANGE)
    assert from_arrays.shape == (1, 360) and from_arrays.dtype == np.float64
    np.testing.assert_array_equal(from_arrays, cast_rays(world, pose[None], BEAMS, MAX_RANGE))


@pytest.mark.parametrize(
    ("args", "error", "message"),
    [
        ((np.zeros((2, 2)), BEAMS, 10.0), ValueError, r"sensor_poses: expected finite \(K, 3\)"),
        (([[0, 0, np.nan]], BEAMS, 10.0), ValueError, "sensor_poses: expected finite"),
        ((np.zeros(3), np.zeros((3, 3)), 10.0), ValueError, "beam_angles: expected a non-empty"),
        ((np.zeros(3), [], 10.0), ValueError, "beam_angles: expected a non-empty"),
        ((np.zeros(3), BEAMS, 0.0), ValueError, "max_range: expected a positive"),
        ((np.zeros(3), BEAMS, np.inf), ValueError, "max_range: expected a positive"),
    ],
)
def test_bad_inputs_are_readable_errors(args, error, message) -> None:
    world = World(circles=[[3.0, 0.0, 1.0]])
    with pytest.raises(error, match=message):
        cast_rays(world, *args)


def test_bad_geometry_argument() -> None:
    with pytest.raises(TypeError, match=r"expected a World or a \(circles"):
        cast_rays([[1, 2, 3]], np.zeros(3), BEAMS, 10.0)
    with pytest.raises(ValueError, match="circles"):
        cast_rays((np.zeros((2, 2)), ()), np.zeros(3), BEAMS, 10.0)


# ---------------------------------------------------------------------- the Lidar model
def test_lidar_beam_angles_and_noiseless_scan() -> None:
    lidar = Lidar(n_beams=90, max_range=8.0)
    np.testing.assert_allclose(lidar.beam_angles, np.deg2rad(np.arange(0, 360, 4)))
    world = random_world(np.random.default_rng(1))
    poses = random_free_poses(world, np.random.default_rng(2), 2)
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    scan = lidar.scan(world, poses, rng)
    assert scan.dtype == np.float32 and scan.shape == (2, 90)
    np.testing.assert_allclose(scan, cast_rays(world, poses, lidar.beam_angles, 8.0), atol=1e-5)
    assert rng.bit_generator.state == state, "a noiseless scan must not consume randomness"


def test_lidar_hit_just_below_max_range_stays_a_hit_in_float32() -> None:
    world = World(circles=[[10.5 - 1e-7, 0.0, 0.5]])
    scan = Lidar(n_beams=4, max_range=10.0).scan(world, [0.0, 0.0, 0.0], np.random.default_rng())
    assert scan[0, 0] < 10.0


def test_lidar_noise_statistics_and_determinism() -> None:
    world = World(segments=[[-30, 5, 30, 5], [-30, -5, 30, -5]])
    lidar = Lidar(n_beams=720, max_range=10.0, noise_std=0.05)
    poses = np.tile([0.0, 0.0, 0.0], (40, 1))
    exact = cast_rays(world, poses, lidar.beam_angles, 10.0)
    scan = lidar.scan(world, poses, np.random.default_rng(42))
    hits = exact < 10.0
    error = scan[hits] - exact[hits]
    assert abs(error.mean()) < 4 * 0.05 / math.sqrt(error.size)
    assert error.std() == pytest.approx(0.05, rel=0.03)
    assert np.all(scan[~hits] == 10.0), "noise is added to hits only"
    assert np.all((scan >= 0) & (scan <= 10.0)) and np.all(scan[hits] < 10.0)
    np.testing.assert_array_equal(scan, lidar.scan(world, poses, np.random.default_rng(42)))
    assert not np.array_equal(scan, lidar.scan(world, poses, np.random.default_rng(43)))


def test_lidar_dropout_rate() -> None:
    corridor = World(segments=[[-9, 3, 9, 3], [-9, -3, 9, -3]])
    lidar = Lidar(n_beams=360, max_range=10.0, dropout_prob=0.2)
    poses = np.tile([0.0, 0.0, 0.0], (50, 1))
    scan = lidar.scan(corridor, poses, np.random.default_rng(0))
    exact = cast_rays(corridor, poses, lidar.beam_angles, 10.0)
    hits = exact < 10.0
    dropped = scan[hits] == 10.0
    n = hits.sum()
    assert abs(dropped.mean() - 0.2) < 4 * math.sqrt(0.2 * 0.8 / n)
    np.testing.assert_allclose(scan[hits][~dropped], exact[hits][~dropped], atol=1e-5)


def documented_scan(lidar: Lidar, world: World, poses: np.ndarray, rng: np.random.Generator):
    """Oracle: :meth:`Lidar.scan`'s documented pipeline written out in numpy, step by step."""
    ranges = cast_rays(world, poses, lidar.beam_angles, lidar.max_range)
    hit = ranges < lidar.max_range
    if lidar.noise_std > 0:
        ranges = np.where(hit, ranges + rng.normal(0.0, lidar.noise_std, ranges.shape), ranges)
    largest_float32_hit = float(np.nextafter(np.float32(lidar.max_range), np.float32(0.0)))
    ranges = np.where(hit, np.clip(ranges, 0.0, largest_float32_hit), ranges)
    if lidar.dropout_prob > 0:
        ranges = np.where(rng.random(ranges.shape) < lidar.dropout_prob, lidar.max_range, ranges)
    return ranges.astype(np.float32)


@pytest.mark.parametrize(
    ("noise_std", "dropout_prob"), [(0.0, 0.0), (0.05, 0.0), (0.0, 0.3), (0.5, 0.3)]
)
def test_lidar_scan_is_the_documented_pipeline_bit_for_bit(noise_std, dropout_prob) -> None:
    """The fused kernel draws the same numbers in the same order as the numpy pipeline; a
    noise of 0.5 m also drives hits near a wall below 0 and near max_range above it."""
    world = random_world(np.random.default_rng(7))
    poses = random_free_poses(world, np.random.default_rng(8), 30, margin=0.01)
    lidar = Lidar(n_beams=360, max_range=6.0, noise_std=noise_std, dropout_prob=dropout_prob)
    rng, oracle_rng = np.random.default_rng(9), np.random.default_rng(9)
    scan = lidar.scan(world, poses, rng)
    expected = documented_scan(lidar, world, poses, oracle_rng)
    assert scan.dtype == np.float32 and scan.shape == (30, 360)
    np.testing.assert_array_equal(scan, expected)
    assert rng.bit_generator.state == oracle_rng.bit_generator.state, "same numbers consumed"


def test_lidar_scan_returns_a_new_array_every_call() -> None:
    world = World(circles=[[3.0, 0.0, 1.0]])
    lidar = Lidar(n_beams=8, noise_std=0.1)
    rng = np.random.default_rng(0)
    first = lidar.scan(world, np.zeros(3), rng)
    kept = first.copy()
    second = lidar.scan(world, np.zeros(3), rng)
    assert not np.shares_memory(first, second)
    np.testing.assert_array_equal(first, kept)


def test_env_observations_kept_across_steps_are_not_overwritten() -> None:
    """Users (estimators, replay buffers) keep observations: a later step must not change them."""
    gym = pytest.importorskip("gymnasium")
    import lidar_env  # noqa: F401 - registers DualLidar-v0

    env = gym.make("DualLidar-v0", world="closed_to_open")
    observation, _ = env.reset(seed=0)
    kept = [observation]
    copies = [{key: scan.copy() for key, scan in observation.items()}]
    for _ in range(3):
        observation, *_ = env.step(np.array([1.0, 0.5], dtype=np.float32))
        kept.append(observation)
        copies.append({key: scan.copy() for key, scan in observation.items()})
    for observation, copy in zip(kept, copies, strict=True):
        for key in ("lidar_1", "lidar_2"):
            np.testing.assert_array_equal(observation[key], copy[key])
    assert not np.array_equal(kept[0]["lidar_1"], kept[-1]["lidar_1"]), "the car moved"


def test_lidar_integer_parameters_scan_like_floats() -> None:
    world = World(circles=[[3.0, 0.0, 1.0]])
    as_int = Lidar(n_beams=16, max_range=10, noise_std=0, dropout_prob=0)
    rng = np.random.default_rng(0)
    assert isinstance(as_int.max_range, float) and as_int == Lidar(n_beams=16, max_range=10.0)
    np.testing.assert_array_equal(
        as_int.scan(world, np.zeros(3), rng), Lidar(16, 10.0).scan(world, np.zeros(3), rng)
    )


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"n_beams": 0}, "n_beams: expected a positive integer"),
        ({"n_beams": 2.5}, "n_beams: expected a positive integer"),
        ({"max_range": -1.0}, "max_range: expected a positive"),
        ({"noise_std": -0.1}, "noise_std: expected a finite number >= 0"),
        ({"dropout_prob": 1.5}, r"dropout_prob: expected a probability in \[0, 1\]"),
    ],
)
def test_lidar_bad_parameters(params, message) -> None:
    with pytest.raises(ValueError, match=message):
        Lidar(**params)


def test_lidar_needs_a_generator_when_random() -> None:
    world = World(circles=[[3.0, 0.0, 1.0]])
    with pytest.raises(TypeError, match="rng: expected a numpy.random.Generator, got int"):
        Lidar(noise_std=0.1).scan(world, np.zeros(3), 42)
