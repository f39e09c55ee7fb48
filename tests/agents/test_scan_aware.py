"""The scan-aware driver: its corridor geometry, and braking for a pedestrian it only sees."""

import math

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.driver import make_driver
from agents.evaluate import drive_episode
from agents.scan_aware import ScanAwareDriver
from lidar_env import lidars_with_noise


def test_free_arc_is_the_arc_length_from_the_nose_to_the_first_return_in_the_corridor():
    driver = ScanAwareDriver(side_margin=0.2)  # car 0.8 x 0.5 m: corridor half width 0.45 m
    straight = np.array([[2.0, 0.0], [1.5, 0.6], [-1.0, 0.0]])  # ahead, beside, behind
    assert driver.free_arc(straight, 0.0) == pytest.approx(1.6)
    for curvature in (1.0, -1.0):  # a quarter turn of radius 1 m, left and right
        point = np.array([[1.0, 1.0 / curvature]])
        assert driver.free_arc(point, curvature) == pytest.approx(math.pi / 2 - 0.4)
        outside = np.array([[0.0, -3.0 / curvature]])  # beside the car, away from the turn
        assert driver.free_arc(outside, curvature) == driver.reach + 0.3
    assert driver.free_arc(np.array([[0.2, 0.2]]), 0.0) == 0.0  # against the body: stop
    assert driver.free_arc(np.array([[0.2, 0.4]]), 0.0) == driver.reach + 0.3  # beside: go on
    braking = ScanAwareDriver(side_margin=0.2, back_off=False)  # the shipped model's expert
    assert braking.free_arc(np.array([[0.2, 0.4]]), 0.0) == 0.0  # it stops for that too


def test_scan_points_put_each_return_in_the_car_frame_from_its_mount():
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight",
                   config={"lidars": lidars_with_noise(range_noise_std=0.0)})
    observation, info = env.reset(seed=0)
    driver = ScanAwareDriver()
    driver.reset(env)
    points = driver.scan_points(observation, float(info["pose"][2]))
    world = env.unwrapped.world
    x, y, heading = info["pose"]
    c, s = math.cos(heading), math.sin(heading)
    in_world = np.column_stack([x + c * points[:, 0] - s * points[:, 1],
                                y + s * points[:, 0] + c * points[:, 1]])
    assert len(points) > 100
    assert np.abs(world.clearance(in_world)).max() < 1e-3  # every return lies on a surface


@pytest.mark.parametrize(("name", "collides"), [("scripted", True), ("scan_aware", False)])
def test_it_stops_for_a_pedestrian_standing_on_the_trace_which_pure_pursuit_hits(name,
                                                                                  collides):
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight",
                   config={"moving_obstacles": 1, "mover_speed_range": (0.0, 0.0),
                           "max_episode_time": 8.0})
    observation, info = env.reset(seed=0)
    x, y, heading = info["pose"]
    env.unwrapped.crowd.positions[0] = (x + 3.0 * math.cos(heading), y + 3.0 * math.sin(heading))
    observation = env.unwrapped._observe()  # the scans with the pedestrian where it now stands
    driver = make_driver(name)
    driver.reset(env)
    terminated = truncated = False
    while not (terminated or truncated):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
    assert info["collision"] == collides
    if not collides:  # it waited just short of the pedestrian, until the time ran out
        gap = math.hypot(*(env.unwrapped.crowd.positions[0] - info["pose"][:2])) - 0.4 - 0.25
        assert truncated and 0.2 < gap < 0.5


def test_without_movers_it_drives_like_pure_pursuit():
    env = gym.make("DualLidar-v0", world="hallway", trace="zigzag")
    episode = drive_episode(env, make_driver("scan_aware"), seed=0)
    reference = drive_episode(env, make_driver("scripted"), seed=0)
    assert episode.success and reference.success
    assert episode.time <= reference.time + 3.0


@pytest.mark.parametrize(("name", "collides"), [("scripted", True), ("scan_aware", False)])
def test_it_backs_off_from_a_pedestrian_walking_at_it_which_pure_pursuit_hits(name, collides):
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="straight",
                   config={"moving_obstacles": 1, "mover_speed_range": (1.0, 1.0),
                           "mover_model": "waypoints", "max_episode_time": 5.0})
    observation, info = env.reset(seed=0)
    x, y, heading = info["pose"]
    ahead = np.array([math.cos(heading), math.sin(heading)])
    crowd = env.unwrapped.crowd
    crowd.positions[0] = (x, y) + 3.5 * ahead  # on the trace, walking straight at the car
    crowd.waypoints[0] = (x, y) - 1.0 * ahead
    crowd._needs[:] = False
    observation = env.unwrapped._observe()
    driver = make_driver(name)
    driver.reset(env)
    terminated = truncated = False
    backed = 0.0
    while not (terminated or truncated):
        action = driver.act(observation, info)
        backed = min(backed, float(action[0]))
        observation, _, terminated, truncated, info = env.step(action)
    assert info["collision"] == collides
    if not collides:  # the pedestrian stopped at its waypoint, where the car had stood
        assert backed < -0.3 and truncated
