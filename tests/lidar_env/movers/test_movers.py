"""Moving obstacles: the crowd never overlaps anything, is seeded, seen exactly by
the Lidars (pymunk oracle) and ends the episode on contact."""

import inspect
import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pymunk
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env import lidars_with_noise
from lidar_env.core.errors import ConfigError
from lidar_env.rendering.renderer import MOVER_COLOUR
from lidar_env.sensors.lidar import pymunk_cast_rays
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout
from lidar_env.vehicle.car import Car, drive_arc, drive_arc_among_movers
from lidar_env.world.world import World

NOISELESS = {"lidars": lidars_with_noise(range_noise_std=0.0)}


def _crowd_env(world, movers, seed=0, **config):
    env = gym.make("DualLidar-v0", world=world, config={"moving_obstacles": movers, **config})
    observation, info = env.reset(seed=seed)
    return env, observation, info


def _pairwise_gaps(positions, radius):
    d = np.hypot(*(positions[:, None, :] - positions[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    return d - 2 * radius


@pytest.mark.parametrize(("world", "movers"), [
    ("open_cylinders", 20), ("hallway", 10), ("closed_to_open", 12), ("random", 8)])
def test_movers_never_overlap_walls_obstacles_or_each_other_over_a_long_rollout(world, movers):
    env, _, _ = _crowd_env(world, movers, seed=3)
    crowd, scene = env.unwrapped.crowd, env.unwrapped.world
    radius, dt = crowd.radius, env.unwrapped.config.control_dt
    space = scene.build_space()  # pymunk's swept query is the independent oracle
    xmin, ymin, xmax, ymax = scene.bounds
    rng = np.random.default_rng(0)
    walked, changes = 0.0, 0
    for _ in range(2000):
        before, waypoints = crowd.positions.copy(), crowd.waypoints.copy()
        crowd.step(scene, dt, rng)
        after, velocities = crowd.positions, crowd.velocities
        for p, q in zip(before, after, strict=True):  # the whole swept disc, not only the ends
            assert space.segment_query_first(tuple(p), tuple(q), radius,
                                             pymunk.ShapeFilter()) is None
        assert np.all(scene.clearance(after) > radius)
        assert np.all((after[:, 0] - radius > xmin) & (after[:, 0] + radius < xmax))
        assert np.all((after[:, 1] - radius > ymin) & (after[:, 1] + radius < ymax))
        # closest approach of every pair over the step (both move linearly)
        d0 = before[:, None, :] - before[None, :, :]
        dv = velocities[:, None, :] - velocities[None, :, :]
        vv = np.maximum(np.sum(dv * dv, axis=2), 1e-300)
        t = np.clip(-np.sum(d0 * dv, axis=2) / vv, 0.0, dt)
        closest = np.hypot(*(d0 + dv * t[..., None]).transpose(2, 0, 1))
        np.fill_diagonal(closest, np.inf)
        assert closest.min() > 2 * radius
        walked += float(np.sum(np.hypot(*(after - before).T)))
        changes += int(np.sum(np.any(crowd.waypoints != waypoints, axis=1)))
    # they really walk (not standing still to stay safe) and keep picking new waypoints
    assert walked / (2000 * dt * movers) > 0.5 * np.mean(crowd.speeds)
    assert changes > 5 * movers


def test_same_seed_gives_the_same_crowd_and_scans_bit_for_bit_other_seeds_differ():
    def rollout(seed):
        env, observation, info = _crowd_env("open_cylinders", 15, seed=seed,
                                            lidars=lidars_with_noise(range_noise_std=0.02))
        record = [observation["lidar_1"], info["moving_obstacles"]]
        for _ in range(80):
            observation, reward, terminated, truncated, info = env.step(
                np.array([0.4, 0.2], dtype=np.float32))
            record += [observation["lidar_1"], observation["lidar_2"],
                       info["moving_obstacles"], [reward]]
            if terminated or truncated:
                break
        return np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in record])

    first, second, other = rollout(5), rollout(5), rollout(6)
    assert first.tobytes() == second.tobytes()
    assert len(first) != len(other) or first.tobytes() != other.tobytes()


def _mover_rollout(seed, steps=60):
    """Scans, poses and movers of a seeded random-action drive among 10 movers."""
    env = gym.make("DualLidar-v0", world="random",
                   config={"moving_obstacles": 10,
                           "lidars": lidars_with_noise(range_noise_std=0.05, dropout_prob=0.1)})
    observation, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    record = [observation["lidar_1"], info["moving_obstacles"]]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
        record += [observation["lidar_2"], info["pose"], info["moving_obstacles"], [reward]]
        if terminated or truncated:
            break
    return np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in record])


def test_crowd_is_bit_identical_across_processes():
    script = ("import gymnasium as gym, numpy as np, sys\n"
              "from lidar_env import lidars_with_noise\n" + inspect.getsource(_mover_rollout)
              + "sys.stdout.write(_mover_rollout(4).tobytes().hex())\n")
    result = subprocess.run([sys.executable, "-c", "import lidar_env\n" + script],
                            capture_output=True, text=True, check=True, timeout=300)
    assert result.stdout == _mover_rollout(4).tobytes().hex()


def test_pickled_env_with_movers_continues_identically():
    env, _, _ = _crowd_env("hallway", 8, seed=2, lidars=lidars_with_noise(range_noise_std=0.03))
    for _ in range(20):
        env.step(np.array([0.6, 0.1], dtype=np.float32))
    env.unwrapped.space  # noqa: B018 - a built space with mover bodies must not break pickling
    clone = pickle.loads(pickle.dumps(env))
    action = np.array([0.5, -0.2], dtype=np.float32)
    for _ in range(20):
        a, b = env.step(action), clone.step(action)
        np.testing.assert_array_equal(a[0]["lidar_1"], b[0]["lidar_1"])
        np.testing.assert_array_equal(a[4]["moving_obstacles"], b[4]["moving_obstacles"])
        assert a[1] == b[1] and a[2] == b[2]
        if a[2] or a[3]:
            break


def _space_with_movers(world, movers):
    space = world.build_space()
    for x, y, radius in movers:
        space.add(pymunk.Circle(space.static_body, float(radius), offset=(float(x), float(y))))
    return space


def test_env_scans_match_pymunk_ray_queries_with_the_movers_as_circles():
    env, observation, info = _crowd_env("open_cylinders", 30, seed=1, **NOISELESS)
    cfg, seen = env.unwrapped.config, 0
    for step in range(40):
        if step % 8 == 0:
            movers = info["moving_obstacles"]
            space = _space_with_movers(env.unwrapped.world, movers[:, [0, 1, 4]])
            static = env.unwrapped.world.build_space()
            for k, lidar in enumerate(cfg.lidars):
                pose = info["lidar_poses"][k:k + 1]
                oracle = pymunk_cast_rays(space, pose, lidar.beam_angles, lidar.max_range)[0]
                np.testing.assert_allclose(observation[f"lidar_{k + 1}"], oracle, atol=1e-5)
                without = pymunk_cast_rays(static, pose, lidar.beam_angles, lidar.max_range)[0]
                seen += int(np.sum(oracle < without - 1e-6))  # beams stopped by a mover
        observation, _, terminated, truncated, info = env.step(
            np.array([0.3, 0.0], dtype=np.float32))
        if terminated or truncated:
            break
    assert seen > 20


def test_layout_scan_with_movers_matches_pymunk_and_reads_zero_inside_a_mover():
    world = World(circles=[[4.0, 0.0, 0.5]], segments=[[-6, -6, 6, -6], [6, -6, 6, 6]])
    rng = np.random.default_rng(0)
    movers = np.column_stack([rng.uniform(-5, 5, (25, 2)), rng.uniform(0.1, 0.6, 25)])
    lidars = [LidarConfig((0.0, 0.0, 0.0), 360), LidarConfig((0.0, 0.0, 1.0), 181, math.pi)]
    layout = LidarLayout.exact(lidars)
    space = _space_with_movers(world, movers)
    free = np.array([[x, y] for x, y in rng.uniform(-5, 5, (400, 2))
                     if np.all(np.hypot(*(movers[:, :2] - (x, y)).T) > movers[:, 2] + 0.05)
                     and world.clearance([[x, y]])[0] > 0.05])
    for x, y in free[:10]:
        poses = np.array([[x, y, 0.3], [x, y, 1.3]])
        scans = layout.scan(world, poses, rng, movers)
        for k, lidar in enumerate(lidars):
            oracle = pymunk_cast_rays(space, poses[k], lidar.beam_angles, lidar.max_range)[0]
            np.testing.assert_allclose(scans[k], oracle, atol=1e-5)
    inside = np.array([[*movers[0, :2], 0.0], [*movers[0, :2], 0.0]])
    assert all(np.all(scan == 0.0) for scan in layout.scan(world, inside, rng, movers))
    empty = layout.scan(world, poses, rng, np.zeros((0, 3)))
    assert all(np.array_equal(a, b) for a, b in zip(empty, layout.scan(world, poses, rng),
                                                     strict=True))


def test_a_mover_walking_into_the_standing_car_terminates_the_episode():
    env, _, info = _crowd_env("open_cylinders", 1, seed=0, mover_speed_range=(1.0, 1.0),
                              mover_model="waypoints")
    crowd, car = env.unwrapped.crowd, env.unwrapped.car
    x, y, heading = info["pose"]
    ahead = np.array([math.cos(heading), math.sin(heading)])
    crowd.positions[0] = (x, y) + 1.2 * ahead  # 0.55 m from the car's nose
    crowd.waypoints[0] = (x, y) - 2.0 * ahead  # straight through the car
    crowd._needs[:] = False
    still = np.zeros(2, dtype=np.float32)
    steps, terminated = 0, False
    while not terminated and steps < 20:
        _, reward, terminated, truncated, info = env.step(still)
        steps += 1
    assert terminated and not truncated and info["collision"] and reward < -5
    assert steps == 6  # 0.55 m at 1 m/s: the sixth step's substeps meet it
    np.testing.assert_array_equal(info["pose"], car.pose)
    assert info["moving_obstacles"][0, 2:4] == pytest.approx(-ahead)


def test_the_car_driving_into_a_standing_mover_stops_just_short_of_it():
    env, _, info = _crowd_env("open_cylinders", 1, seed=0, mover_speed_range=(0.0, 0.0))
    crowd, car = env.unwrapped.crowd, env.unwrapped.car
    x, y, heading = info["pose"]
    crowd.positions[0] = (x + 2.0 * math.cos(heading), y + 2.0 * math.sin(heading))
    for _ in range(30):
        _, _, terminated, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and info["collision"]
    gap = math.hypot(*(crowd.positions[0] - car.pose[:2])) - car.half_length - crowd.radius
    assert 0.0 < gap <= 1.5 * 0.1 / 4 + 1e-9  # within one substep of the mover


def test_moving_mover_collision_kernel_checks_every_substep():
    pose = np.zeros(3)
    no_circles, no_segments = np.zeros((0, 3)), np.zeros((0, 4))
    # a mover crossing the car's path between the step's ends: only the substeps see it
    mover, velocity = np.array([[0.5, -1.0, 0.2]]), np.array([[0.0, 20.0]])
    assert drive_arc_among_movers(pose.copy(), 0.0, 0.0, 0.1, 8, 0.4, 0.25, no_circles,
                                  no_segments, mover, velocity)
    assert not drive_arc_among_movers(pose.copy(), 0.0, 0.0, 0.1, 8, 0.4, 0.25, no_circles,
                                      no_segments, mover + [[0, 0, 0]], -velocity)
    a, b = pose.copy(), pose.copy()
    far = np.array([[50.0, 50.0, 0.3]])
    assert not drive_arc_among_movers(a, 1.2, 0.7, 0.1, 4, 0.4, 0.25, no_circles, no_segments,
                                      far, np.zeros((1, 2)))
    assert not drive_arc(b, 1.2, 0.7, 0.1, 4, 0.4, 0.25, no_circles, no_segments)
    np.testing.assert_array_equal(a, b)
    car = Car(0.8, 0.5, no_circles, no_segments)
    assert car.substeps_for(1.0, 0.0, 0.1, 4, other_speed=40.0) > car.substeps_for(
        1.0, 0.0, 0.1, 4)


@pytest.mark.parametrize("world", ["open_cylinders", "random"])
def test_check_env_passes_with_movers(world):
    env = gym.make("DualLidar-v0", world=world, config={"moving_obstacles": 6},
                   render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_info_reports_the_movers_and_no_movers_is_an_empty_array():
    _, _, info = _crowd_env("hallway", 0)
    assert info["moving_obstacles"].shape == (0, 5)
    assert info["moving_obstacles"].dtype == np.float64
    env, _, info = _crowd_env("hallway", 7, mover_radius=0.3)
    state = info["moving_obstacles"]
    assert state.shape == (7, 5) and state.dtype == np.float64
    assert np.all(state[:, 4] == 0.3) and np.all(state[:, 2:4] == 0.0)  # standing at reset
    lo, hi = env.unwrapped.config.mover_speed_range
    _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
    speeds = np.hypot(*info["moving_obstacles"][:, 2:4].T)
    assert np.all(speeds <= hi + 1e-12) and np.any(speeds > 0.0)
    np.testing.assert_array_equal(info["moving_obstacles"][:, :2], env.unwrapped.crowd.positions)


def test_movers_spawn_clear_of_the_car_by_the_clearance():
    for seed in range(5):
        env, _, info = _crowd_env("closed_to_open", 15, seed=seed, mover_clearance=2.0)
        car = env.unwrapped.car
        x, y, heading = info["pose"]
        c, s = math.cos(heading), math.sin(heading)
        for mx, my, *_, radius in info["moving_obstacles"]:
            lx, ly = c * (mx - x) + s * (my - y), -s * (mx - x) + c * (my - y)
            gap = math.hypot(max(abs(lx) - car.half_length, 0), max(abs(ly) - car.half_width, 0))
            assert gap - radius >= 2.0


def test_space_and_rendering_show_the_movers():
    env = gym.make("DualLidar-v0", config={"moving_obstacles": 5}, render_mode="rgb_array")
    _, info = env.reset(seed=0)
    frame = env.render()
    assert np.any(np.all(frame == MOVER_COLOUR, axis=-1))
    circles = [s for s in env.unwrapped.space.shapes
               if isinstance(s, pymunk.Circle) and s.body.body_type == pymunk.Body.KINEMATIC]
    positions = sorted(tuple(s.body.position) for s in circles)
    assert positions == sorted(map(tuple, info["moving_obstacles"][:, :2]))
    plain = gym.make("DualLidar-v0", render_mode="rgb_array")
    plain.reset(seed=0)
    assert not np.any(np.all(plain.render() == MOVER_COLOUR, axis=-1))


@pytest.mark.parametrize(("config", "message"), [
    ({"moving_obstacles": -1}, "moving_obstacles: expected an integer"),
    ({"moving_obstacles": 2.5}, "moving_obstacles: expected an integer"),
    ({"moving_obstacles": True}, "moving_obstacles: expected an integer"),
    ({"moving_obstacles": "3"}, "moving_obstacles: expected an integer"),
    ({"mover_speed_range": (1.5, 0.5)}, "mover_speed_range: expected (min, max)"),
    ({"mover_speed_range": (-0.5, 0.5)}, "mover_speed_range: expected (min, max)"),
    ({"mover_speed_range": 1.0}, "mover_speed_range: expected (min, max)"),
    ({"mover_speed_range": (0.5, 1e6)}, "mover_speed_range: expected (min, max)"),
    ({"mover_speed_range": (0.1, float("nan"))}, "mover_speed_range: expected (min, max)"),
    ({"mover_radius": 0.0}, "mover_radius: expected a positive"),
    ({"mover_radius": -0.2}, "mover_radius: expected a positive"),
    ({"mover_clearance": -1.0}, "mover_clearance: expected a finite number >= 0"),
])
def test_bad_mover_settings_are_config_errors_naming_the_key(config, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        gym.make("DualLidar-v0", config=config)


def test_a_world_too_crowded_for_the_movers_says_how_many_fit():
    env = gym.make("DualLidar-v0", world="hallway",
                   config={"moving_obstacles": 60, "mover_radius": 1.2})
    with pytest.raises(ConfigError, match=r"moving_obstacles: placed \d+ of 60 movers"):
        env.reset(seed=0)


mover_values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 300),
                         st.tuples(st.floats(-1, 1e6), st.floats(-1, 1e6)),
                         st.sampled_from([None, True, "2", [], [0.5], (0.0, 0.0)]))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(config=st.dictionaries(
    st.sampled_from(["moving_obstacles", "mover_radius", "mover_speed_range",
                     "mover_clearance"]), mover_values, max_size=3))
def test_any_mover_settings_are_a_config_error_or_step_finitely(config):
    config = {"moving_obstacles": 3, **config}
    try:
        env = gym.make("DualLidar-v0", world="hallway", config=config)
        env.reset(seed=0)
        for _ in range(3):
            _, reward, terminated, _, info = env.step(np.array([1.0, 0.3], dtype=np.float32))
            assert np.isfinite(reward) and np.all(np.isfinite(info["moving_obstacles"]))
            if terminated:
                break
    except ConfigError:
        pass


def test_a_yielding_mover_walks_around_the_standing_car_instead_of_into_it():
    env, _, info = _crowd_env("open_cylinders", 1, seed=0, mover_speed_range=(1.0, 1.0),
                              mover_model="yielding")
    crowd = env.unwrapped.crowd
    x, y, heading = info["pose"]
    ahead = np.array([math.cos(heading), math.sin(heading)])
    crowd.positions[0] = (x, y) + 1.2 * ahead  # the same set-up as the "waypoints" test above
    crowd.waypoints[0] = (x, y) - 2.0 * ahead
    crowd._needs[:] = False
    passed = False
    for _ in range(60):
        _, _, terminated, _, info = env.step(np.zeros(2, dtype=np.float32))
        assert not terminated and not info["collision"]
        passed |= float(np.dot(crowd.positions[0] - (x, y), ahead)) < -1.0  # behind the car
    assert passed


@pytest.mark.parametrize(("world", "movers"), [("open_cylinders", 20), ("hallway", 10),
                                               ("random", 10)])
def test_yielding_movers_never_walk_into_the_car_and_still_keep_clear_of_everything(world,
                                                                                      movers):
    from lidar_env.movers.crowd import car_circles
    from lidar_env.movers.kernels import CAR_HARD_GAP

    env, _, info = _crowd_env(world, movers, seed=3, mover_model="yielding")
    crowd, scene, car = env.unwrapped.crowd, env.unwrapped.world, env.unwrapped.car
    radius, walked = crowd.radius, 0.0
    disc = car_circles(car.pose, car.half_length, car.half_width, 0.0, 0.0)
    for step in range(600):
        # drive a slow circle (the car may run into a mover), then stand: never walked into
        action = np.array([0.3, 0.4] if step < 200 else [0.0, 0.0], dtype=np.float32)
        before = crowd.positions.copy()
        _, _, terminated, _, info = env.step(action)
        if terminated:  # the car drove into a mover that could not escape: allowed, rare
            assert info["collision"] and step < 200
            break
        after = crowd.positions
        assert np.all(scene.clearance(after) > radius)
        assert _pairwise_gaps(after, radius).min() > 0.0
        walked += float(np.sum(np.hypot(*(after - before).T)))
        if step >= 200:  # standing car: the exact box, not only its covering circles
            disc = car_circles(car.pose, car.half_length, car.half_width, 0.0, 0.0)
            gaps = np.hypot(*(after[:, None, :] - disc[None, :, :2]).transpose(2, 0, 1))
            assert (gaps - disc[None, :, 4]).min() > radius + CAR_HARD_GAP - 1e-9
    else:
        assert walked / (600 * 0.1 * movers) > 0.3 * np.mean(crowd.speeds)


def test_car_circles_cover_the_car_box():
    from lidar_env.movers.crowd import car_circles

    circles = car_circles((1.0, -2.0, 0.7), 0.4, 0.25, 1.0, 0.5)
    u, v = np.meshgrid(np.linspace(-0.4, 0.4, 41), np.linspace(-0.25, 0.25, 21))
    c, s = math.cos(0.7), math.sin(0.7)
    points = np.column_stack([1.0 + c * u.ravel() - s * v.ravel(),
                              -2.0 + s * u.ravel() + c * v.ravel()])
    inside = np.hypot(*(points[:, None, :] - circles[None, :, :2]).transpose(2, 0, 1)) <= (
        circles[None, :, 4] + 1e-12)
    assert inside.any(axis=1).all()
    # each centre moves with the car's rigid motion: forward speed plus yaw rate x offset
    offsets = (circles[:, :2] - (1.0, -2.0)) @ np.array([c, s])
    np.testing.assert_allclose(circles[:, 2], 1.0 * c - 0.5 * offsets * s)
    np.testing.assert_allclose(circles[:, 3], 1.0 * s + 0.5 * offsets * c)


def test_mover_model_is_validated_and_yielding_is_the_default():
    with pytest.raises(ConfigError, match="mover_model: expected one of yielding, waypoints"):
        gym.make("DualLidar-v0", config={"mover_model": "polite"})
    assert gym.make("DualLidar-v0").unwrapped.config.mover_model == "yielding"
    a, _, _ = _crowd_env("hallway", 6, seed=2, mover_model="yielding")
    b, _, _ = _crowd_env("hallway", 6, seed=2, mover_model="yielding")
    for _ in range(40):
        for env in (a, b):
            env.step(np.array([0.5, 0.1], dtype=np.float32))
    np.testing.assert_array_equal(a.unwrapped.crowd.state, b.unwrapped.crowd.state)
