"""DualLidar-v0: API conformance, determinism, physics and bad input."""

import importlib.util
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

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env import lidars_with_noise
from lidar_env.core import se2
from lidar_env.scenes import StartPoseError
from lidar_env.vehicle.car import Car
from lidar_env.world.built_in import WORLD_NAMES, make_world

NOISELESS = {"lidars": lidars_with_noise(range_noise_std=0.0)}


@pytest.mark.parametrize("world", WORLD_NAMES)
def test_gymnasium_and_sb3_checkers_pass_without_warnings(world, monkeypatch):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    # gymnasium's render check also opens the "human" window: headless SDL, if pygame is there
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    has_pygame = importlib.util.find_spec("pygame") is not None
    env = gym.make("DualLidar-v0", world=world, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=not has_pygame)
        sb3_checker.check_env(env.unwrapped, warn=True)
    env.close()


def _rollout(env, seed, steps=60):
    """Observations, rewards and poses of ``steps`` seeded random actions."""
    observation, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    record = [observation["lidar_1"], observation["lidar_2"], info["pose"]]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
        record += [observation["lidar_1"], observation["lidar_2"], info["pose"], [reward]]
        if terminated or truncated:
            break
    return np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in record])


NOISY = {"lidars": lidars_with_noise(range_noise_std=0.05, dropout_prob=0.1)}


@pytest.mark.parametrize("trace", [None, "loop", "out_and_back"])
def test_same_seed_gives_bit_identical_rollouts_and_other_seeds_differ(trace):
    env = gym.make("DualLidar-v0", world="random", trace=trace, config=NOISY)
    first, second, other = _rollout(env, 7), _rollout(env, 7), _rollout(env, 8)
    assert first.tobytes() == second.tobytes()
    assert len(first) != len(other) or first.tobytes() != other.tobytes()


def test_rollouts_are_bit_identical_across_processes():
    # a fresh interpreter that has not imported lidar_env: the "module:id" form registers it
    script = (
        "import gymnasium as gym, numpy as np, sys\n"
        + inspect.getsource(_rollout)
        + f"env = gym.make('lidar_env:DualLidar-v0', world='random', config={NOISY!r})\n"
        "sys.stdout.write(_rollout(env, 7).tobytes().hex())\n"
    )
    here = _rollout(gym.make("DualLidar-v0", world="random", config=NOISY), 7)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            check=True, timeout=120)
    assert result.stdout == here.tobytes().hex()


def test_pickled_env_continues_identically():
    env = gym.make("DualLidar-v0", world="hallway", config=NOISY)
    env.reset(seed=3)
    for _ in range(5):
        env.step(np.array([0.8, 0.1], dtype=np.float32))
    env.unwrapped.space  # noqa: B018 - a built pymunk space must not break pickling
    clone = pickle.loads(pickle.dumps(env))
    action = np.array([0.5, -0.2], dtype=np.float32)
    for _ in range(5):
        a, b = env.step(action), clone.step(action)
        np.testing.assert_array_equal(a[0]["lidar_1"], b[0]["lidar_1"])
        np.testing.assert_array_equal(a[4]["pose"], b[4]["pose"])
        assert a[1] == b[1]


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec_steps_both_sensors(mode):
    envs = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode=mode,
                        world="closed_to_open")
    try:
        observations, infos = envs.reset(seed=[1, 2])
        assert observations["lidar_1"].shape == (2, 360)
        observations, rewards, _, _, infos = envs.step(np.full((2, 2), 0.5, dtype=np.float32))
        assert observations["lidar_2"].shape == (2, 360) and rewards.shape == (2,)
        assert infos["pose"].shape == (2, 3)
    finally:
        envs.close()


def test_observation_matches_pymunk_ray_queries_from_the_reported_lidar_poses():
    env = gym.make("DualLidar-v0", world="closed_to_open", config=NOISELESS)
    observation, info = env.reset(seed=0, options={"start": (16.0, 3.0, 0.4)})
    for _ in range(3):
        observation, *_, info = env.step(np.array([0.7, 0.5], dtype=np.float32))
    space = make_world("closed_to_open").build_space()  # obstacles only
    max_range = env.unwrapped.config.max_range
    for key, (x, y, heading) in zip(("lidar_1", "lidar_2"), info["lidar_poses"], strict=True):
        for i in range(0, 360, 7):
            angle = heading + 2 * math.pi * i / 360
            end = (x + max_range * math.cos(angle), y + max_range * math.sin(angle))
            hit = space.segment_query_first((x, y), end, 0.0, pymunk.ShapeFilter())
            expected = max_range if hit is None else hit.alpha * max_range
            assert observation[key][i] == pytest.approx(expected, abs=1e-5)


def test_info_lidar_poses_are_the_mounts_composed_with_the_car_pose():
    env = gym.make("DualLidar-v0", config={"lidars": [{"mount": [0.3, 0.1, 0.2]},
                                                      {"mount": [-0.2, 0, -0.1]}]})
    env.reset(seed=0)
    *_, info = env.step(np.array([1.0, 1.0], dtype=np.float32))
    mounts = env.unwrapped.config.mounts_array
    np.testing.assert_allclose(info["lidar_poses"], se2.compose(info["pose"], mounts), atol=1e-12)


def test_world_frame_scans_are_sensor_scans_rotated_by_the_heading():
    quarter = {"start": (20.0, -3.0, math.pi / 2), "trace": "straight"}
    sensor = gym.make("DualLidar-v0", world="hallway", config=NOISELESS)
    world = gym.make("DualLidar-v0", world="hallway", config={**NOISELESS, "scan_frame": "world"})
    a, _ = sensor.reset(seed=0, options=quarter)
    b, _ = world.reset(seed=0, options=quarter)
    # heading +90 deg: world beam i looks where sensor beam i - 90 looks
    np.testing.assert_allclose(b["lidar_1"], np.roll(a["lidar_1"], 90), atol=1e-5)


def test_unicycle_motion_is_an_exact_arc():
    env = gym.make("DualLidar-v0", world="closed_to_open", config={"max_episode_time": 1000.0})
    _, info = env.reset(seed=0, options={"start": (27.0, 0.0, 0.0), "trace": "straight"})
    start = info["pose"]
    turn = np.array([1.0, 1.0], dtype=np.float32)  # 1.5 m/s at 1.5 rad/s: a 1 m radius circle
    steps = round(2 * math.pi / 1.5 / 0.1)
    _, _, _, _, info = env.step(turn)
    centre = start[:2] + (0.0, 1.0)
    assert np.hypot(*(info["pose"][:2] - centre)) == pytest.approx(1.0, abs=1e-12)
    for _ in range(steps - 1):
        *_, info = env.step(turn)
    exact = se2.compose(start, (math.sin(1.5 * steps * 0.1), 1 - math.cos(1.5 * steps * 0.1),
                               1.5 * steps * 0.1))
    np.testing.assert_allclose(info["pose"], exact, atol=1e-9)


def test_collision_kernel_agrees_with_pymunk_shape_queries():
    world = make_world("closed_to_open")
    space = world.build_space()
    car = Car(0.8, 0.5, world.circles, world.segments)
    body = car.add_to_space(space)
    shape = next(iter(body.shapes))
    rng = np.random.default_rng(5)
    checked = touching = 0
    while checked < 1500:
        pose = np.array([*rng.uniform((14, -15), (40, 15)), rng.uniform(-math.pi, math.pi)])
        # near obstacles only, and not swallowed whole by a box (pymunk sees that, edges don't)
        if np.min(world.clearance(pose[None, :2])) > 1.0 or world.contains(pose[None, :2])[0]:
            continue
        car.place(pose)
        car.sync_body()
        oracle = any(q.shape is not shape for q in space.shape_query(shape))
        assert car.collides_at(pose) == oracle, pose
        checked += 1
        touching += oracle
    assert 100 < touching < 1400  # both outcomes were exercised


def test_driving_into_a_wall_terminates_with_the_car_stopped_just_short_of_it():
    env = gym.make("DualLidar-v0", world="hallway", trace="right_turn")
    env.reset(seed=0)  # starts at (12, 4) heading east; keep straight instead of turning right
    for _ in range(200):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and not truncated and info["collision"]
    assert reward < -env.unwrapped.config.collision_penalty + 1.0
    space = env.unwrapped.space
    car = env.unwrapped.car
    car_shape = next(iter(car.body.shapes))
    assert not [q for q in space.shape_query(car_shape) if q.shape is not car_shape]
    substep = 1.5 * 0.1 / 4  # [m] at full speed
    assert car.collides_at(se2.compose(info["pose"], (substep, 0.0, 0.0)))
    assert info["pose"][0] > 29.0  # it got to the sloping far wall


def test_time_limit_truncates():
    env = gym.make("DualLidar-v0", config={"max_episode_time": 0.5})
    env.reset(seed=0)
    ends = [env.step(np.zeros(2, dtype=np.float32))[2:4] for _ in range(5)]
    assert ends[-1] == (False, True) and all(end == (False, False) for end in ends[:-1])


def test_reward_is_progress_and_clipped_actions_act_like_the_limit():
    config = {**NOISELESS, "cross_track_penalty": 0.0}
    env = gym.make("DualLidar-v0", world="hallway", trace="straight", config=config)
    env.reset(seed=0)
    _, reward, *_, info = env.step(np.array([5.0, 0.0], dtype=np.float32))
    assert reward == pytest.approx(0.15) and info["arc_position"] == pytest.approx(0.15)


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (np.zeros(3, dtype=np.float32), r"action: expected shape \(2,\).*got shape \(3,\)"),
        (np.zeros((1, 2), dtype=np.float32), r"got shape \(1, 2\)"),
        (np.array([np.nan, 0.0], dtype=np.float32), "action: expected finite values"),
        (np.array([0.0, np.inf], dtype=np.float32), "action: expected finite values"),
    ],
)
def test_bad_actions_raise(action, message):
    env = gym.make("DualLidar-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(action)


def test_bad_names_options_and_start_poses_raise():
    with pytest.raises(ValueError, match="unknown world 'moon': expected one of open_cylinders"):
        gym.make("DualLidar-v0", world="moon")
    with pytest.raises(ValueError, match="unknown trace 'lap': expected one of straight"):
        gym.make("DualLidar-v0", trace="lap")
    env = gym.make("DualLidar-v0", world="hallway")
    with pytest.raises(ValueError, match="unknown trace 'zig'"):
        env.reset(options={"trace": "zig"})
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) 'seed': expected some of "
                                         "world, trace, start"):
        env.reset(options={"seed": 3})
    with pytest.raises(StartPoseError, match=r"start pose \(20, 6.9, 0\) puts the 0.8 m x "
                                             r"0.5 m car into an obstacle of world 'hallway'"):
        env.reset(options={"start": (20.0, 6.9, 0.0)})
    with pytest.raises(ValueError, match=r"options\['start'\]: expected 3 finite numbers"):
        env.reset(options={"start": (1.0, 2.0)})
    with pytest.raises(StartPoseError):
        gym.make("DualLidar-v0", world="closed_to_open").reset(
            options={"start": (26.0, 5.0, 0.0)}  # inside a box
        )
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        gym.make("DualLidar-v0").unwrapped.step(np.zeros(2, dtype=np.float32))


def test_space_holds_the_obstacles_and_the_car_at_its_pose():
    env = gym.make("DualLidar-v0", world="closed_to_open")
    env.reset(seed=0)
    *_, info = env.step(np.array([1.0, 0.3], dtype=np.float32))
    space = env.unwrapped.space
    world = env.unwrapped.world
    assert isinstance(space, pymunk.Space)
    kinematic = [b for b in space.bodies if b.body_type == pymunk.Body.KINEMATIC]
    assert len(kinematic) == 1
    assert tuple(kinematic[0].position) == tuple(info["pose"][:2])
    assert kinematic[0].angle == info["pose"][2]
    assert len(space.static_body.shapes) >= len(world.circles) + len(world.segments)


def test_stepping_after_the_episode_ended_is_refused_until_reset() -> None:
    from lidar_env.core.errors import ResetNeededError

    env = gym.make("DualLidar-v0", world="hallway", config={"max_episode_time": 0.2})
    env.reset(seed=0)
    forward = np.array([1.0, 0.0], dtype=np.float32)
    assert env.step(forward)[3] is False
    assert env.step(forward)[3] is True  # truncated at 0.2 s
    with pytest.raises(ResetNeededError, match="call reset"):
        env.unwrapped.step(forward)
    env.reset(seed=0)
    assert np.all(np.isfinite(env.step(forward)[4]["pose"]))


@pytest.mark.parametrize("action", ["forward", ["a", None], None, [1.0, 2.0, 3.0]])
def test_bad_actions_are_a_config_error_naming_the_action(action) -> None:
    from lidar_env.core.errors import ConfigError

    env = gym.make("DualLidar-v0", world="hallway")
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="action: expected"):
        env.unwrapped.step(action)
