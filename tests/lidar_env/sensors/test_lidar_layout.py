"""K Lidars of their own geometry (``config["lidars"]``, ``lidar_env.sensors.lidar_layout``): the
documented beam directions, agreement with pymunk's ray queries for a 270-degree Lidar,
bit-identity with ``Lidar.scan`` for identical Lidars, and the env checks for K = 1 and 3."""

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env import lidars_with_noise
from lidar_env.core import se2
from lidar_env.sensors.lidar import Lidar, pymunk_cast_rays
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout, scan_layout_body_kernel
from lidar_env.world.built_in import make_world
from lidar_env.world.world import World

CORNERS = [{"mount": (0.35, 0.2, math.pi / 4), "fov": 1.5 * math.pi, "n_beams": 271},
           {"mount": (-0.35, -0.2, -0.75 * math.pi), "fov": 1.5 * math.pi, "n_beams": 271}]
THREE = [{"mount": (0.35, 0.0, 0.0), "fov": math.pi, "n_beams": 181, "max_range": 20.0},
         {"mount": (0.0, 0.2, math.pi / 2), "fov": math.pi / 2, "n_beams": 91, "max_range": 6.0},
         {"mount": (-0.3, 0.0, math.pi), "n_beams": 120, "range_noise_std": 0.0}]
ONE = [{"mount": (0.4, 0.0, 0.0), "fov": math.pi, "n_beams": 181}]


def test_beam_angles_are_centred_on_the_forward_axis():
    wide = LidarConfig((0, 0, 0), n_beams=271, fov=1.5 * math.pi)
    assert wide.beam_angles[0] == pytest.approx(-0.75 * math.pi)  # beam 0 at -135 degrees
    assert wide.beam_angles[-1] == pytest.approx(0.75 * math.pi)
    assert wide.beam_angles[135] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.diff(wide.beam_angles) > 0)  # CCW
    full = LidarConfig((0, 0, 0), n_beams=360)
    np.testing.assert_array_equal(full.beam_angles, Lidar(360).beam_angles)


def test_a_270_degree_lidar_agrees_with_pymunk_ray_queries():
    world = make_world("closed_to_open")
    space = world.build_space()
    lidar = LidarConfig((0.35, 0.2, math.pi / 4), n_beams=271, fov=1.5 * math.pi, max_range=8.0)
    layout = LidarLayout.exact([lidar])
    rng = np.random.default_rng(0)
    for pose in ([16.0, 3.0, 0.4], [5.0, 1.0, -2.0], [24.0, -2.0, 3.0]):
        sensor = se2.compose(np.array(pose), np.array(lidar.mount))[None, :]
        (scan,) = layout.scan(world, sensor, rng)
        oracle = pymunk_cast_rays(space, sensor, lidar.beam_angles, lidar.max_range)[0]
        assert scan.shape == (271,) and np.any(scan < 8.0)
        np.testing.assert_allclose(scan, oracle, atol=1e-5)  # float32 readings


def test_identical_lidars_scan_bit_for_bit_like_the_single_lidar_model():
    world = World(circles=[[3.0, 0.5, 0.7], [-2.0, 2.0, 1.0]],
                  segments=[[-5.0, -3.0, 6.0, -3.0]], bounds=(-6, -4, 7, 4))
    poses = np.array([[0.0, 0.0, 0.3], [0.5, -0.2, 2.0]])
    lidar = Lidar(360, 6.0, noise_std=0.05, dropout_prob=0.2)
    layout = LidarLayout([LidarConfig((0, 0, 0), 360, max_range=6.0, range_noise_std=0.05,
                                      dropout_prob=0.2)] * 2)
    single = lidar.scan(world, poses, np.random.default_rng(4))
    packed = layout.scan(world, poses, np.random.default_rng(4))
    assert single.tobytes() == np.stack(packed).tobytes()


def test_each_lidar_keeps_its_own_range_noise_and_length():
    env = gym.make("DualLidar-v0", world="hallway", config={"lidars": THREE})
    observation, info = env.reset(seed=1)
    assert [observation[k].shape for k in ("lidar_1", "lidar_2", "lidar_3")] == [
        (181,), (91,), (120,)]
    assert info["lidar_poses"].shape == (3, 3)
    assert observation in env.observation_space
    assert env.observation_space["lidar_2"].high.max() == pytest.approx(6.0)
    np.testing.assert_allclose(info["lidar_poses"],
                               se2.compose(info["pose"], env.unwrapped.config.mounts_array),
                               atol=1e-12)
    # lidar_3 is noiseless: its hits equal the exact cast from the reported pose
    space = env.unwrapped.world.build_space()
    third = env.unwrapped.config.lidars[2]
    exact = pymunk_cast_rays(space, info["lidar_poses"][2:], third.beam_angles, third.max_range)
    np.testing.assert_allclose(observation["lidar_3"], exact[0], atol=1e-5)


def _rollout(env, seed, steps=30):
    observation, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    record = [info["pose"], *observation.values()]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
        record += [info["pose"], [reward], *observation.values()]
        if terminated or truncated:
            break
    return np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in record])


@pytest.mark.parametrize("lidars", [ONE, THREE, CORNERS], ids=["K=1", "K=3", "corners"])
def test_env_checks_determinism_and_pickle_for_other_layouts(lidars):
    config = {"lidars": lidars_with_noise({"lidars": lidars}, dropout_prob=0.05)}
    env = gym.make("DualLidar-v0", world="closed_to_open", config=config)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    first, second = _rollout(env, 5), _rollout(env, 5)
    assert first.tobytes() == second.tobytes()
    env.reset(seed=2)
    env.step(np.array([0.5, 0.1], dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    action = np.array([0.6, -0.3], dtype=np.float32)
    for _ in range(3):
        a, b = env.step(action), clone.step(action)
        for key in a[0]:
            np.testing.assert_array_equal(a[0][key], b[0][key])


@pytest.mark.parametrize("lidars", [ONE, THREE], ids=["K=1", "K=3"])
def test_make_vec_stacks_every_lidar(lidars):
    envs = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="sync",
                        world="hallway", config={"lidars": lidars})
    try:
        observations, _ = envs.reset(seed=[1, 2])
        assert sorted(observations) == [f"lidar_{k + 1}" for k in range(len(lidars))]
        for k, lidar in enumerate(lidars):
            assert observations[f"lidar_{k + 1}"].shape == (2, lidar["n_beams"])
        _, rewards, _, _, infos = envs.step(np.full((2, 2), 0.5, dtype=np.float32))
        assert infos["lidar_poses"].shape == (2, len(lidars), 3) and rewards.shape == (2,)
    finally:
        envs.close()


def test_rgb_rendering_draws_lidars_of_different_lengths():
    env = gym.make("DualLidar-v0", world="hallway", config={"lidars": THREE},
                   render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.dtype == np.uint8


@pytest.mark.parametrize("lidars", [
    [LidarConfig((sx * 0.35, sy * 0.2, math.atan2(sy, sx)), 91, math.pi / 2, 8.0)
     for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))],
    [LidarConfig((0.35, 0.0, 0.0), 181, math.pi, 8.0)],
], ids=["4 x 90", "1 x 180"])
def test_narrow_lidars_on_a_traced_map_agree_with_pymunk(lidars) -> None:
    # the caster skips cells and primitives outside each wedge and edges facing away: none of
    # that may lose a hit
    image = np.zeros((200, 200), dtype=np.uint8)
    image[:4], image[-4:], image[:, :4], image[:, -4:] = 255, 255, 255, 255
    rows, cols = np.ogrid[:200, :200]
    for r, c, radius in ((50, 60, 9), (120, 140, 14), (150, 40, 6), (90, 100, 4)):
        image[(rows - r) ** 2 + (cols - c) ** 2 < radius**2] = 255
    image[30:36, 100:170] = 255
    world = World.from_image(image, 0.05)
    space = world.build_space()
    layout = LidarLayout.exact(lidars)
    rng = np.random.default_rng(2)
    cars = np.column_stack([rng.uniform(1.0, 9.0, (60, 2)), rng.uniform(-np.pi, np.pi, 60)])
    sensors = np.stack([se2.compose(cars, np.array(lidar.mount)) for lidar in lidars], axis=1)
    free = np.all(world.clearance(sensors[..., :2].reshape(-1, 2)).reshape(60, -1) > 0.05,
                  axis=1)
    assert free.sum() >= 20
    for poses in sensors[free][:20]:
        for scan, lidar, pose in zip(layout.scan(world, poses, rng), lidars, poses, strict=True):
            oracle = pymunk_cast_rays(space, pose, lidar.beam_angles, lidar.max_range)[0]
            np.testing.assert_allclose(scan, oracle, atol=1e-5)  # float32 readings


def test_the_packed_scan_is_the_arrays_kernel_bit_for_bit() -> None:
    # LidarLayout.scan packs world, beams, car and draws into two arrays once per world and
    # draws in place; the arrays kernel takes them one by one and draws afresh
    lidars = [LidarConfig((0.3, 0.1, 0.4), 200, 4.0, 7.0, 0.02, 0.0, self_occlusion=True),
              LidarConfig((-0.3, 0.0, math.pi), 91, math.pi / 2, range_noise_std=0.0,
                          dropout_prob=0.1)]
    layout = LidarLayout(lidars, (0.8, 0.5))
    world = make_world("closed_to_open")
    assert layout.pack(world) is layout.pack(world)  # packed once
    rng, reference_rng = np.random.default_rng(5), np.random.default_rng(5)
    beams, params = layout._packed
    for car in [(3.0, 0.0, 0.2), (10.0, 4.0, -2.0), (15.0, -3.0, 1.0)]:
        sensors = np.stack([se2.compose(np.array(car), np.array(lidar.mount)) for lidar in lidars])
        movers = np.array([[car[0] + 2.0, car[1], 0.25]])
        total = params[-1, 1].astype(int)
        draws = reference_rng.standard_normal(total), reference_rng.random(total)
        expected = scan_layout_body_kernel(
            world.circles, world.segments, len(world.walls), tuple(world.grid), sensors, beams,
            params, *draws, movers, layout._car(car))
        got = layout.scan(world, sensors, rng, movers, car)
        assert np.concatenate(got).tobytes() == expected.tobytes()
