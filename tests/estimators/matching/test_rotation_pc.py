"""Rotation-aware phase correlation: pairwise matches and the pc_rot / pc_rot_icp estimators.
Oracle: scans cast by the env's Lidar from known poses."""

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver
from estimators.base import SensorSetup, default_beam_angles
from estimators.evaluation.metrics import evaluate
from estimators.matching.curve_refinement import PRIOR_INFORMATION, CurveReference
from estimators.matching.rotation_pc import RotationPhaseCorrelation, ScanMatcher
from estimators.odometry.motion_prior import MIN_PREDICTION_SIGMA, prediction_information
from lidar_env import lidars_with_noise
from lidar_env.core.se2 import compose, relative, wrap_angle
from lidar_env.sensors.lidar import Lidar
from lidar_env.world.world import World

ANGLES = default_beam_angles(360)
MOUNTS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])


def room(rng: np.random.Generator) -> World:
    walls = [[-8, -8, 8, -8], [8, -8, 8, 8], [8, 8, -8, 8], [-8, 8, -8, -8]]
    centres = rng.uniform(-7, 7, (40, 2))
    centres = centres[np.hypot(*centres.T) > 3.0][:12]
    return World(np.column_stack([centres, rng.uniform(0.15, 0.5, len(centres))]), walls)


def scans_at(world: World, poses: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return Lidar(noise_std=0.01).scan(world, poses, rng).astype(np.float64)


@pytest.mark.parametrize("icp_iterations", [0, 5])
def test_match_recovers_relative_sensor_pose(icp_iterations) -> None:
    rng = np.random.default_rng(2)
    matcher = ScanMatcher(10.0, image_size=200, icp_iterations=icp_iterations)
    errors = []
    for _ in range(8):
        world = room(rng)
        first = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi)])
        second = compose(first, [*rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.3, 0.3)])
        a, b = scans_at(world, np.stack([first, second]), rng)
        match = matcher.match(matcher.prepare(a, ANGLES), matcher.prepare(b, ANGLES))
        errors.append(relative(relative(first, second), match.pose))
        assert 0.0 < match.confidence <= 1.0
    errors = np.abs(np.array(errors))
    translation, heading = np.hypot(errors[:, 0], errors[:, 1]), np.degrees(errors[:, 2])
    if icp_iterations:  # the refinement reaches the millimetre level
        assert translation.max() < 0.01 and np.median(translation) < 0.003
        assert heading.max() < 0.1
    else:  # a 10 cm pixel and a 0.5 degree angle bin, refined to a fraction
        assert translation.max() < 0.05 and heading.max() < 1.0


def test_cross_sensor_match_sees_the_mount_offset() -> None:
    """lidar_1 at t-1 against lidar_2 at t: the matcher must report mount⁻¹ ⊕ Δ ⊕ mount."""
    rng = np.random.default_rng(4)
    world = room(rng)
    car_before = np.array([0.3, -0.2, 0.4])
    motion = np.array([0.1, 0.0, 0.05])
    car_after = compose(car_before, motion)
    scans = scans_at(
        world, np.stack([compose(car_before, MOUNTS[0]), compose(car_after, MOUNTS[1])]), rng
    )
    matcher = ScanMatcher(10.0, image_size=200, icp_iterations=5)
    match = matcher.match(matcher.prepare(scans[0], ANGLES), matcher.prepare(scans[1], ANGLES))
    expected = compose(compose(-MOUNTS[0], motion), MOUNTS[1])  # mounts have no heading
    np.testing.assert_allclose(match.pose[:2], expected[:2], atol=0.005)
    assert abs(wrap_angle(match.pose[2] - expected[2])) < np.radians(0.2)


def test_curve_reference_has_zero_residual_on_a_sampled_circle() -> None:
    # A cylinder of 0.3 m radius 3 m ahead, seen with 1-degree beams: points between the beams
    # lie on the curve, where a chord would put them ~1 mm off.
    ranges = np.full(360, 10.0)
    beams = np.arange(-5, 6) % 360
    centre, radius = np.array([3.0, 0.0]), 0.3
    for beam in beams:
        direction = np.array([np.cos(ANGLES[beam]), np.sin(ANGLES[beam])])
        along = direction @ centre
        ranges[beam] = along - np.sqrt(along**2 - centre @ centre + radius**2)
    reference = CurveReference(ranges, ANGLES, 10.0)
    angles = np.radians(np.linspace(-3.5, 3.5, 15)) + np.pi
    between = centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])
    index, anchors, normals = reference.correspond(between)
    residuals = np.einsum("ij,ij->i", between[index] - anchors, normals)
    assert len(index) == len(between)
    assert np.abs(residuals).max() < 2e-4


def drive(world: str, trace: str, steps: int, seed: int = 0):
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"lidars": lidars_with_noise(range_noise_std=0.01)})
    driver = PurePursuitDriver()
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    frames = [(observation, info["time"], info["pose"])]
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        frames.append((observation, info["time"], info["pose"]))
        if terminated or truncated:
            break
    return SensorSetup.from_env(env), frames


def test_pc_rot_icp_tracks_a_driven_turn_better_than_the_paper() -> None:
    setup, frames = drive("open_cylinders", "right_turn", 150)  # through the turn
    truth = np.array([pose for _, _, pose in frames])
    scores = {}
    for name in ("pc", "pc_rot", "pc_rot_icp"):
        estimator = estimators.make(name)
        estimator.reset(setup, truth[0])
        for observation, t, _ in frames:
            estimator.update(observation, t)
        scores[name] = evaluate(estimator.trajectory, truth)
    assert scores["pc_rot_icp"].accuracy_percent > 97.5
    assert scores["pc_rot_icp"].drift_percent < 0.5
    assert scores["pc_rot_icp"].heading_rmse_deg < 0.5
    assert scores["pc_rot"].accuracy_percent > scores["pc"].accuracy_percent + 5.0
    assert scores["pc_rot"].drift_percent < 0.5 * scores["pc"].drift_percent


def test_pc_rot_runs_on_the_offset_lidar_alone_and_on_a_one_lidar_setup() -> None:
    rng = np.random.default_rng(6)
    world = room(rng)
    poses = [np.array([0.0, 0.0, 0.2])]
    for _ in range(5):
        poses.append(compose(poses[-1], [0.1, 0.0, 0.03]))
    poses = np.array(poses)
    scans = [scans_at(world, compose(p, MOUNTS), rng) for p in poses]
    two = SensorSetup(MOUNTS, ANGLES, 10.0)
    one = SensorSetup(MOUNTS[1:], ANGLES, 10.0)
    for setup, key in ((two, 1), (one, 0)):
        estimator = RotationPhaseCorrelation(lidar=key, image_size=200, icp_iterations=5)
        estimator.reset(setup, poses[0])
        for k, scan in enumerate(scans):
            observation = (
                {"lidar_1": scan[1]}
                if setup is one
                else dict(zip(("lidar_1", "lidar_2"), scan, strict=True))
            )
            estimator.update(observation, 0.1 * k)
        np.testing.assert_allclose(estimator.trajectory[:, :2], poses[:, :2], atol=0.01)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: ScanMatcher(10.0, image_size=201), "even"),
        (lambda: ScanMatcher(10.0, image_size=200, resolution=0.01), "cannot hold"),
        (lambda: ScanMatcher(10.0, icp_iterations=-1), "icp_iterations"),
    ],
)
def test_bad_settings_raise_readable_errors(make, message) -> None:
    with pytest.raises(ValueError, match=message):
        make()


def test_unknown_lidar_index_is_a_readable_error() -> None:
    estimator = estimators.make("pc_rot", lidar=2)
    with pytest.raises(ValueError, match=r"lidar: expected an index in 0\.\.1"):
        estimator.reset(SensorSetup(MOUNTS, ANGLES, 10.0))


def test_curve_reference_needs_three_returns() -> None:
    with pytest.raises(ValueError, match="at least 3 returns"):
        CurveReference(np.full(360, 10.0), ANGLES, 10.0)


@pytest.mark.parametrize("name", ["pc_rot", "pc_rot_icp", "pc_fusion"])
def test_world_aligned_scans_are_refused_with_a_readable_error(name) -> None:
    setup = SensorSetup(MOUNTS, ANGLES, 10.0, world_aligned=True)
    with pytest.raises(ValueError, match="expected sensor-frame scans"):
        estimators.make(name).reset(setup)


def test_the_offset_lidar_variant_declares_it_needs_two_lidars() -> None:
    import estimators

    assert estimators.make("pc_rot").min_lidars == 1
    assert estimators.make("pc_rot", lidar=1).min_lidars == 2


def corridor_scans(car_before, car_after, mount, rng):
    """Sensor-frame scans from ``mount`` on a car at two poses in a featureless corridor
    (walls y = +-2.5 m, ends far beyond the range)."""
    walls = [[-50, -2.5, 50, -2.5], [-50, 2.5, 50, 2.5]]
    world = World(np.zeros((0, 3)), walls)
    return scans_at(world, np.stack([compose(car_before, mount), compose(car_after, mount)]), rng)


@pytest.mark.parametrize("heading", [0.5, -0.8])
def test_corridor_prior_about_the_car_centre_ignores_its_heading_error(heading) -> None:
    # Along a corridor the scans leave the translation open and the prior decides it. A
    # prediction of the car's motion is surest of where the car's centre goes: its heading
    # error (here 0.03 rad) must not move that along the corridor -- but about a sensor 0.4 m
    # from the centre it moves the sensor by 12 mm.
    rng = np.random.default_rng(5)
    mount = np.array([0.4, 0.0, 0.0])
    car_before = np.array([0.0, 0.3, heading])
    motion = np.array([0.1, 0.0, 0.05])
    scans = corridor_scans(car_before, compose(car_before, motion), mount, rng)
    matcher = ScanMatcher(10.0, image_size=200, icp_iterations=5)
    earlier, later = (matcher.prepare(scan, ANGLES) for scan in scans)
    predicted = motion + [0.0, 0.0, 0.03]
    prior = relative(mount, compose(predicted, mount))
    car_centre = -mount[:2]  # in the sensor frame (the mount has no heading)

    def along_error(pivot) -> float:
        match = matcher.refine(earlier, later, [prior], prior, pivot)
        car_motion = compose(compose(mount, match.pose), [-mount[0], -mount[1], 0.0])
        world_after = compose(car_before, car_motion)
        return float(world_after[0] - compose(car_before, motion)[0])

    assert abs(along_error(car_centre)) < 0.002
    assert abs(along_error(None)) > 0.005  # held about the sensor, the heading error leaks in


def test_prediction_information_grows_with_the_scan_rate_within_its_bounds() -> None:
    information = [prediction_information(dt)[0] for dt in (0.2, 0.1, 0.05)]
    assert information[1] == pytest.approx(16 * information[0])  # sigma ~ dt^2
    assert prediction_information(10.0)[0] == pytest.approx(PRIOR_INFORMATION[0])
    assert prediction_information(1e-3)[0] == pytest.approx((0.01 / MIN_PREDICTION_SIGMA) ** 2)
    assert prediction_information(0.1)[2] == pytest.approx(PRIOR_INFORMATION[2])
    # A clock jittering by 5 ms at 1 m/s adds 5 mm: the 10 Hz prediction is half as sure.
    jittery = prediction_information(0.1, speed=1.0, jitter=0.005)[0]
    assert jittery == pytest.approx(information[1] / 4)
    with pytest.raises(ValueError, match="dt"):
        prediction_information(0.0)
    with pytest.raises(ValueError, match="jitter"):
        prediction_information(0.1, speed=1.0, jitter=-0.01)
