"""Scan-to-local-map odometry on the simulated two-Lidar car, the two-Lidar merge, the
correlative search, and parameter errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver
from estimators import SensorSetup, make
from estimators.matching.correlative import correlative_search
from estimators.matching.scan_matching import (
    LikelihoodField,
    scans_to_car_points,
    voxel_downsample,
)
from estimators.odometry.local_map import LocalMapOdometry
from lidar_env import lidars_with_noise
from lidar_env.core.errors import ConfigError
from lidar_env.core.se2 import compose, relative, transform_points
from lidar_env.sensors.lidar import Lidar
from lidar_env.world.polygons import segment_distances
from lidar_env.world.world import World


def _distance_to_world(world, points: np.ndarray) -> np.ndarray:
    """Distance [m] of world points to the nearest wall or cylinder (the oracle)."""
    nearest = np.full(len(points), np.inf)
    if len(world.segments):
        nearest = np.minimum(nearest, segment_distances(points, world.segments).min(axis=1))
    if len(world.circles):
        centre = np.linalg.norm(points[:, None, :] - world.circles[None, :, :2], axis=-1)
        nearest = np.minimum(nearest, np.abs(centre - world.circles[None, :, 2]).min(axis=1))
    return nearest


def test_both_lidars_merge_onto_the_world_through_their_mounts():
    noiseless = {"lidars": lidars_with_noise(range_noise_std=0.0, dropout_prob=0.0)}
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight", config=noiseless)
    observation, info = env.reset(seed=1)
    setup = SensorSetup.from_env(env)
    points = scans_to_car_points(observation, setup)
    world_points = transform_points(info["pose"], points)
    assert len(points) > 100
    # Noise-free scans: every merged point lies on a primitive (float32 ranges: < 1 mm).
    assert np.max(_distance_to_world(env.unwrapped.world, world_points)) < 1e-3
    # Each lidar alone contributes points: the rear one is not dropped or mis-mounted.
    rear_only = {"lidar_1": np.full(360, setup.max_range), "lidar_2": observation["lidar_2"]}
    rear = transform_points(info["pose"], scans_to_car_points(rear_only, setup))
    assert 0 < len(rear) < len(points)
    assert np.max(_distance_to_world(env.unwrapped.world, rear)) < 1e-3


CORNER_LIDARS = [
    {"mount": (0.35, 0.2, np.pi / 4), "fov": 1.5 * np.pi, "n_beams": 271, "max_range": 10.0},
    {"mount": (-0.35, -0.2, -0.75 * np.pi), "fov": 1.5 * np.pi, "n_beams": 271, "max_range": 6.0},
    {"mount": (0.4, 0.0, 0.0), "fov": np.pi, "n_beams": 91, "max_range": 15.0},
]


def test_lidars_of_their_own_geometry_merge_onto_the_world():
    config = {"lidars": lidars_with_noise({"lidars": CORNER_LIDARS}, range_noise_std=0.0)}
    env = gym.make("DualLidar-v0", world="closed_to_open", config=config)
    observation, info = env.reset(seed=1)
    setup = SensorSetup.from_env(env)
    points = transform_points(info["pose"], scans_to_car_points(observation, setup))
    pairs = list(zip(setup.keys, setup.sensors, strict=True))
    hits = sum(int(np.sum(observation[k] < s.max_range)) for k, s in pairs)
    assert len(points) > 100 and len(points) <= hits
    assert np.max(_distance_to_world(env.unwrapped.world, points)) < 1e-3
    for k in range(3):  # each Lidar alone lands on the world through its own mount and beams
        alone = {key: (observation[key] if j == k else np.full(s.n_beams, s.max_range))
                 for j, (key, s) in enumerate(pairs)}
        part = transform_points(info["pose"], scans_to_car_points(alone, setup))
        assert len(part) > 10
        assert np.max(_distance_to_world(env.unwrapped.world, part)) < 1e-3


def test_lidar_odometry_tracks_a_car_with_two_270_degree_corner_lidars():
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn",
                   config={"lidars": lidars_with_noise({"lidars": CORNER_LIDARS[:2]},
                                                       range_noise_std=0.01)})
    truth, estimator = _drive_with_odometry(env, max_steps=60)
    path = np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))
    end = relative(truth[-1], estimator.pose)
    assert path > 5.0
    assert np.hypot(end[0], end[1]) < 0.005 * path and abs(end[2]) < np.radians(0.5)


def _drive_with_odometry(env, max_steps: int | None = None):
    """True poses (N, 3) of a scripted drive and the ``lidar_odometry`` that followed it."""
    observation, info = env.reset(seed=0)
    driver = PurePursuitDriver()
    driver.reset(env)
    estimator = make("lidar_odometry")
    estimator.reset(SensorSetup.from_env(env), info["pose"])
    estimator.update(observation, info["time"])
    truth = [info["pose"]]
    terminated = truncated = False
    while not (terminated or truncated) and (max_steps is None or len(truth) <= max_steps):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        estimator.update(observation, info["time"])
        truth.append(info["pose"])
    return np.array(truth), estimator


@pytest.mark.slow
@pytest.mark.parametrize(("world", "trace"), [("open_cylinders", "right_turn")])
def test_drift_on_the_simulated_car_stays_small(world: str, trace: str):
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"lidars": lidars_with_noise(range_noise_std=0.01)})
    truth, estimator = _drive_with_odometry(env)
    travelled = np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))
    end = relative(truth[-1], estimator.pose)
    assert travelled > 10.0
    assert np.hypot(end[0], end[1]) < 0.005 * travelled  # the 0.5 % target
    assert abs(end[2]) < np.radians(0.5)


def test_correlative_search_finds_a_pose_far_from_the_guess():
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight")
    observation, info = env.reset(seed=2)
    setup = SensorSetup.from_env(env)
    points = scans_to_car_points(observation, setup)
    field = LikelihoodField(transform_points(info["pose"], points), resolution=0.05)
    guess = compose(info["pose"], [0.3, -0.25, np.radians(15.0)])
    found, score = correlative_search(field, points, guess, 0.5, np.radians(20.0))
    error = relative(info["pose"], found)
    assert np.hypot(error[0], error[1]) <= 0.05 * np.sqrt(2)  # one grid cell
    assert abs(error[2]) <= np.radians(1.0)  # one heading step
    assert score > 0.8


@pytest.mark.parametrize(("times", "settings"), [
    ([0.0, 0.1, 0.2, 3.2, 3.3, 3.4], {}),  # over a 3 s gap (ACES, 613 s)
    ([0.0, 0.1, 0.2, 0.3, 0.4, 0.5], {"max_turn_rate": np.radians(900.0)}),  # a car that can
])
def test_a_turn_beyond_the_motion_model_and_search_window_is_found(times, settings):
    # One 360-beam Lidar at the car's origin: turning the car in place by k degrees rolls its
    # scan by k beams, so the true headings are known exactly. An 80-degree turn between two
    # scans lies far outside the 30-degree search window around the constant-velocity guess
    # (0 here); the scan after it, standing still again, lies 80 degrees from the new guess
    # (ACES, 613 s: a 78-degree turn over a 3 s gap was lost). The search reaches it where the
    # car can have turned that far: over a gap in the scans, or at a max_turn_rate that allows
    # 80 degrees in 0.1 s.
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight")
    observation, _ = env.reset(seed=3)
    env_setup = SensorSetup.from_env(env)
    setup = SensorSetup(np.zeros((1, 3)), env_setup.beam_angles, env_setup.max_range)
    ranges = observation["lidar_1"].astype(np.float64)
    turn = 80
    headings = [0, 0, 0, turn, turn, turn]
    estimator = LocalMapOdometry(**settings)
    estimator.reset(setup, np.zeros(3))
    for t, heading in zip(times, headings, strict=True):
        estimator.update({"lidar_1": np.roll(ranges, -heading)}, t)
    trajectory = estimator.trajectory
    np.testing.assert_allclose(
        np.degrees(trajectory[:, 2]), headings, atol=1.0, err_msg="headings [deg]"
    )
    assert np.max(np.hypot(trajectory[:, 0], trajectory[:, 1])) < 0.05
    assert estimator.fallbacks + estimator.far_searches >= 1


def test_a_turn_no_car_makes_between_two_scans_is_not_taken() -> None:
    # the same 80-degree roll 0.1 s after the last scan: 800 deg/s, beyond max_turn_rate
    # (1.5 rad/s); no search turns the car that far, and the match stays poor and flagged
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight")
    observation, _ = env.reset(seed=3)
    env_setup = SensorSetup.from_env(env)
    setup = SensorSetup(np.zeros((1, 3)), env_setup.beam_angles, env_setup.max_range)
    ranges = observation["lidar_1"].astype(np.float64)
    estimator = LocalMapOdometry()
    estimator.reset(setup, np.zeros(3))
    for t, heading in enumerate([0, 0, 0, 80]):
        estimator.update({"lidar_1": np.roll(ranges, -heading)}, 0.1 * t)
    assert abs(np.degrees(estimator.trajectory[-1, 2])) < 40.0
    assert estimator.poor_matches == [3]


def _corridor_drive(
    n_scans: int, rng: np.random.Generator, noise: float = 0.01
) -> tuple[SensorSetup, np.ndarray, list[dict[str, np.ndarray]]]:
    """Drive down a 5 m wide, 40 m long corridor from x = 1 m at 0.1 m per scan with one
    360-beam Lidar (10 m range, ``noise`` [m] of range noise): its setup, true poses (n, 3)
    and scans.
    Once the start wall falls out of range (x > ~10 m) nothing in view fixes the motion along
    the corridor."""
    corners = np.array([(0.0, -2.5), (40.0, -2.5), (40.0, 2.5), (0.0, 2.5)])
    world = World(segments=np.hstack([corners, np.roll(corners, -1, axis=0)]))
    lidar = Lidar(noise_std=noise)
    truth = np.column_stack([1.0 + 0.1 * np.arange(n_scans), np.zeros((n_scans, 2))])
    scans = [{"lidar_1": lidar.scan(world, pose[None], rng)[0].astype(np.float64)}
             for pose in truth]
    return SensorSetup(np.zeros((1, 3)), lidar.beam_angles, lidar.max_range), truth, scans


def _replay(estimator: LocalMapOdometry, setup: SensorSetup, start: np.ndarray,
            scans: list[dict[str, np.ndarray]], stamps: np.ndarray) -> np.ndarray:
    """The estimator's trajectory (n, 3) over ``scans`` stamped ``stamps`` [s]."""
    estimator.reset(setup, start)
    for scan, t in zip(scans, stamps, strict=True):
        estimator.update(scan, float(t))
    return estimator.trajectory


def _corridor_end_error(
    estimator: LocalMapOdometry, seed: int = 0, noise: float = 0.01
) -> np.ndarray:
    """Final pose error (3,) [m, rad] after 15 m of the corridor at 10 Hz, ``noise`` [m] of
    range noise."""
    setup, truth, scans = _corridor_drive(151, np.random.default_rng(seed), noise)
    trajectory = _replay(estimator, setup, truth[0], scans, 0.1 * np.arange(len(truth)))
    return relative(truth[-1], trajectory[-1])


@pytest.mark.slow
def test_a_featureless_corridor_is_crossed_at_the_speed_seen_before_it():
    # The along-axis error after ~5 m of featureless corridor (x = 10..16 m) is what the
    # motion model brings into it. Noisy wall normals must not pass for information along the
    # axis (with 5-neighbour normals the map drags the car back by most of a metre), and the
    # speed carried in is averaged over several increments rather than taken from the last
    # (which a single run may get right by luck: compare the RMS over a few).
    def along_axis_rms(**parameters: int) -> float:
        errors = [_corridor_end_error(LocalMapOdometry(**parameters), seed) for seed in range(4)]
        assert np.all(np.abs(np.array(errors)[:, 1:]) < [0.01, np.radians(0.1)])
        return float(np.sqrt(np.mean([error[0] ** 2 for error in errors])))

    default = along_axis_rms()
    assert default < 0.05
    assert along_axis_rms(velocity_window=1) > 1.5 * default
    assert along_axis_rms(normal_neighbours=5) > 0.5


def test_a_car_that_stops_dead_and_starts_again_is_followed():
    # Stop and go down the corridor, 5 scans at 1.5 m/s (10 Hz), then 5 standing, four times;
    # along the axis only the start wall 1-7 m behind pins the pose (a few dozen returns), so
    # the 5 mm constant-velocity prior would hold a stop for a scan or two and lag by ~12 cm;
    # widened after a large miss, the wall corrects it.
    corners = np.array([(0.0, -2.5), (40.0, -2.5), (40.0, 2.5), (0.0, 2.5)])
    world = World(segments=np.hstack([corners, np.roll(corners, -1, axis=0)]))
    lidar = Lidar(noise_std=0.01)
    steps = np.tile(np.r_[np.full(5, 0.15), np.zeros(5)], 4)
    truth = np.column_stack([1.0 + np.r_[0.0, np.cumsum(steps)], np.zeros((len(steps) + 1, 2))])
    rng = np.random.default_rng(0)
    scans = [{"lidar_1": lidar.scan(world, pose[None], rng)[0].astype(np.float64)}
             for pose in truth]
    setup = SensorSetup(np.zeros((1, 3)), lidar.beam_angles, lidar.max_range)
    trajectory = _replay(LocalMapOdometry(), setup, truth[0], scans, 0.1 * np.arange(len(truth)))
    errors = np.array([relative(true, estimate) for true, estimate in zip(truth, trajectory,
                                                                            strict=True)])
    assert np.abs(errors[:, 0]).max() < 0.03  # constant sigma: 0.12 m behind at the stops
    assert np.abs(errors[:, 1:]).max() < 0.01


def test_a_regular_clock_tightens_the_motion_prior_and_a_jittery_one_does_not():
    # The same scans, taken every 0.1 m, stamped once at a steady 10 Hz and once with +-40 ms
    # of jitter. Per scan the car moves the same either way, but only the steady clock
    # vouches for it: there the constant-velocity prior may be trusted to ~5 mm and it damps
    # the step noise; a jittery clock (Intel's: bursts, stamps out of order) keeps it weak.
    rng = np.random.default_rng(0)
    setup, truth, scans = _corridor_drive(60, rng)
    regular = 0.1 * np.arange(len(truth))
    jittery = regular + rng.uniform(-0.04, 0.04, len(truth))
    noise = {}
    for name, stamps in (("regular", regular), ("jittery", jittery)):
        trajectory = _replay(LocalMapOdometry(), setup, truth[0], scans, stamps)
        noise[name] = np.std(np.diff(trajectory[10:, 0]) - 0.1)
    assert noise["regular"] < 0.85 * noise["jittery"]
    assert noise["jittery"] < 0.004  # the weak prior still leaves a well-constrained match


def test_voxel_downsample_keeps_one_point_per_cell():
    points = np.array([[0.01, 0.01], [0.02, 0.03], [0.2, 0.0], [-0.01, 0.0]])
    np.testing.assert_array_equal(voxel_downsample(points, 0.1), points[[0, 2, 3]])
    with pytest.raises(ValueError, match="voxel_size: expected a positive size"):
        voxel_downsample(points, 0.0)


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="keyframe_distance: expected a positive value"):
        LocalMapOdometry(keyframe_distance=0.0)
    with pytest.raises(ValueError, match="n_keyframes: expected an integer >= 1"):
        LocalMapOdometry(n_keyframes=0)
    with pytest.raises(ValueError, match="normal_neighbours: expected an integer >= 3"):
        LocalMapOdometry(normal_neighbours=2)
    with pytest.raises(ValueError, match=r"max_normal_neighbours: expected an integer >= 9 \("):
        LocalMapOdometry(max_normal_neighbours=5)
    with pytest.raises(ValueError, match="prediction_acceleration: expected a positive value"):
        LocalMapOdometry(prediction_acceleration=-1.0)
    with pytest.raises(ValueError, match="search_resolution: expected a positive value"):
        LocalMapOdometry(search_resolution=0.0)
    with pytest.raises(ValueError, match="velocity_window: expected an integer >= 1"):
        LocalMapOdometry(velocity_window=0)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="speed_information: expected a positive value"):
            LocalMapOdometry(speed_information=bad)
        with pytest.raises(ConfigError,
                           match="calibrated_sideslip_sigma: expected a positive value"):
            LocalMapOdometry(calibrated_sideslip_sigma=bad)
    with pytest.raises(ConfigError, match="start_speed_scans: expected an integer >= 1"):
        LocalMapOdometry(start_speed_scans=0)
    with pytest.raises(ValueError, match="min_quality: expected a share"):
        LocalMapOdometry(min_quality=1.5)
    with pytest.raises(ValueError, match="unknown loss 'l1'"):
        LocalMapOdometry(loss="l1")


def _aisle_drive(rng: np.random.Generator) -> tuple[SensorSetup, np.ndarray,
                                                      list[dict[str, np.ndarray]]]:
    """A TurtleBot's 3.5 m, 360-beam Lidar (1.5 cm range noise) at 5 Hz and 0.22 m/s down a
    2.5 m wide aisle between two rows of 4 m shelf units set end to end, 0-2 cm apart (nearly
    invisible joints), from 1 m before the aisle's closed end wall: its setup, true poses and
    scans. Past the first 3.5 m, the joints and the walls' noise are all that is seen along
    the aisle."""
    units = []
    for y0, y1 in ((-2.25, -1.25), (1.25, 2.25)):
        for k in range(8):
            gap = rng.uniform(0.0, 0.01, 2)
            corners = np.array([(4 * k + gap[0], y0), (4 * k + 4 - gap[1], y0),
                                (4 * k + 4 - gap[1], y1), (4 * k + gap[0], y1)])
            units.append(np.hstack([corners, np.roll(corners, -1, axis=0)]))
    world = World(segments=np.vstack([*units, [[0.0, -1.25, 0.0, 1.25]]]))
    lidar = Lidar(max_range=3.5, noise_std=0.015)
    truth = np.column_stack([1.0 + 0.044 * np.arange(600), np.zeros((600, 2))])
    scans = [{"lidar_1": lidar.scan(world, pose[None], rng)[0].astype(np.float64)}
             for pose in truth]
    return SensorSetup(np.zeros((1, 3)), lidar.beam_angles, lidar.max_range), truth, scans


@pytest.mark.slow
def test_a_shelf_aisle_seen_through_a_few_joints_is_crossed_near_the_car_s_speed():
    # Along the aisle a match is pinned by a handful of returns (the joints, the wall normals'
    # noise). Fed back whole, each step's noise walked the speed, backwards at times: final
    # errors of 3.6-43 m over 26 m (median 24 m over these seeds); moved only in proportion to
    # what pins it, the speed holds (0.9-8 m, median 1.2 m).
    errors = []
    for seed in range(5):
        setup, truth, scans = _aisle_drive(np.random.default_rng(seed))
        trajectory = _replay(LocalMapOdometry(), setup, truth[0], scans,
                             0.2 * np.arange(len(truth)))
        errors.append(relative(truth[-1], trajectory[-1]))
    errors = np.array(errors)
    assert np.median(np.abs(errors[:, 0])) < 3.0
    assert np.all(np.abs(errors[:, 1:]) < [0.01, np.radians(0.5)])


def test_each_scan_s_match_information_is_kept_for_the_last_scan():
    # Midway down a 5 m wide, 40 m long corridor, its ends beyond the 8 m range: the side
    # walls pin y with a point's worth per return squarely facing it, x hardly at all (only
    # through the walls' noise).
    corners = np.array([(0.0, -2.5), (40.0, -2.5), (40.0, 2.5), (0.0, 2.5)])
    world = World(segments=np.hstack([corners, np.roll(corners, -1, axis=0)]))
    lidar = Lidar(noise_std=0.01, max_range=8.0)
    truth = np.column_stack([20.0 + 0.1 * np.arange(4), np.zeros((4, 2))])
    rng = np.random.default_rng(0)
    scans = [{"lidar_1": lidar.scan(world, pose[None], rng)[0].astype(np.float64)}
             for pose in truth]
    setup = SensorSetup(np.zeros((1, 3)), lidar.beam_angles, lidar.max_range)
    estimator = LocalMapOdometry()
    _replay(estimator, setup, truth[0], scans, 0.1 * np.arange(len(truth)))
    information = estimator.scan_information
    assert information.shape == (3, 3)
    np.testing.assert_allclose(information, information.T, atol=1e-9)
    assert np.linalg.eigvalsh(information)[0] >= -1e-9
    assert information[1, 1] > 50  # dozens of returns face y squarely
    assert information[0, 0] < 0.05 * information[1, 1]  # the corridor's axis is (nearly) free
