"""The car never tunnels through a wall, whatever the speed and control step."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from lidar_env.core.errors import ConfigError
from lidar_env.vehicle.car import MAX_STEP_FRACTION, Car

WALL = np.array([[2.0, -5.0, 2.0, 5.0]])  # a zero-thickness wall across the x axis at x = 2 m


@pytest.mark.parametrize(("speed", "duration"), [(40.0, 0.1), (1.5, 5.0), (300.0, 1.0)])
def test_a_fast_or_long_move_stops_at_the_wall_instead_of_jumping_it(speed, duration):
    car = Car(0.8, 0.5, np.empty((0, 3)), WALL)
    car.place((0.0, 0.0, 0.0))
    assert car.drive(speed, 0.0, duration, substeps=4)
    # stopped short of the wall, within one collision check of touching it
    front = car.pose[0] + 0.4
    assert front < 2.0
    assert 2.0 - front <= MAX_STEP_FRACTION * 0.5 + 1e-9


def test_spinning_fast_is_checked_too():
    # a post just beside the car's corner sweep: a fast turn in place must hit it
    post = np.array([[0.0, 0.42, 0.05]])
    car = Car(0.8, 0.5, post, np.empty((0, 4)))
    car.place((0.0, 0.0, 0.0))
    assert car.drive(0.0, 200.0, 0.1, substeps=4)


def test_default_motion_keeps_the_configured_substeps():
    car = Car(0.8, 0.5, np.empty((0, 3)), np.empty((0, 4)))
    # the default config (1.5 m/s, 1.5 rad/s, 0.1 s, 4 checks) is already fine enough
    assert car.substeps_for(1.5, 1.5, 0.1, 4) == 4
    assert car.substeps_for(-1.5, -1.5, 0.1, 4) == 4
    assert car.substeps_for(40.0, 0.0, 0.1, 4) == math.ceil(4.0 / (MAX_STEP_FRACTION * 0.5))


@pytest.mark.parametrize(
    ("speed", "yaw_rate", "duration", "message"),
    [
        (math.nan, 0.0, 0.1, "car speed: expected a finite value"),
        (0.0, math.inf, 0.1, "car yaw_rate: expected a finite value"),
        (1e300, 0.0, 0.1, "collision checks"),
        (1.0, 0.0, -0.1, "car duration: expected a value >= 0"),
    ],
)
def test_motion_that_cannot_be_simulated_is_rejected_by_name(speed, yaw_rate, duration, message):
    car = Car(0.8, 0.5, np.empty((0, 3)), WALL)
    car.place((0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match=message):
        car.drive(speed, yaw_rate, duration, substeps=4)
    assert np.array_equal(car.pose, [0.0, 0.0, 0.0])


@pytest.mark.parametrize("config", [{"control_dt": 5.0}, {"max_speed": 40.0}])
def test_the_env_car_stays_inside_the_hallway(config):
    env = gym.make("DualLidar-v0", world="hallway", config=config)
    env.reset(seed=0)
    world = env.unwrapped.world
    xmin, ymin, xmax, ymax = world.bounds
    collided = False
    for _ in range(40):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
        x, y, _ = info["pose"]
        assert xmin <= x <= xmax and ymin <= y <= ymax
        assert math.isfinite(reward)
        collided |= info["collision"]
        if terminated or truncated:
            break
    assert collided or terminated


def test_an_absurd_max_speed_is_named_at_the_first_step():
    env = gym.make("DualLidar-v0", world="hallway", config={"max_speed": 1e300})
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="max_speed"):
        env.step(np.array([1.0, 0.0]))
