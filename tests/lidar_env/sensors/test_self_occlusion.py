"""Car-body self-occlusion (``lidars[k]["self_occlusion"]``): a body-level Lidar sees the car's
outline as a wall except within ``housing_radius`` of its mount, checked against pymunk's ray
queries on the world plus the car's box, and the physically expected views of a corner and a
centre mount."""

import math

import gymnasium as gym
import numpy as np
import pymunk
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.core import se2
from lidar_env.core.errors import ConfigError
from lidar_env.sensors.lidar import pymunk_cast_rays
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import (
    LidarLayout,
    car_outline,
    cast_packed,
    fresh_seen,
    scan_layout_kernel,
)
from lidar_env.world.built_in import make_world

CAR = (0.8, 0.5)  # the env's default car_length, car_width [m]


def body_oracle(car_pose, sensor, angles, max_range, housing, world_space):
    """Per beam: pymunk's first world hit, or the first hit on the car's four edges (pymunk
    segments in a space of their own) beyond ``housing`` from the sensor, whichever is nearer."""
    body_space = pymunk.Space()
    hl, hw = 0.5 * CAR[0], 0.5 * CAR[1]
    corners = [se2.compose(np.asarray(car_pose), np.array([u, v, 0.0]))[:2]
               for u, v in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        body_space.add(pymunk.Segment(body_space.static_body, tuple(a), tuple(b), 0.0))
    out = pymunk_cast_rays(world_space, sensor[None, :], angles, max_range)[0]
    x, y, heading = sensor
    for j, angle in enumerate(angles):
        end = (x + max_range * math.cos(heading + angle), y + max_range * math.sin(heading + angle))
        hits = [h.alpha * max_range for h in body_space.segment_query((x, y), end, 0.0,
                                                                       pymunk.ShapeFilter())]
        beyond = [t for t in hits if t > housing]
        if beyond:
            out[j] = min(out[j], min(beyond))
    return out


def exact_scan(layout, world, sensors, car_pose):
    beams, params = layout._packed
    return cast_packed(world.circles, world.segments, len(world.walls), tuple(world.grid),
                       sensors, beams, params, np.empty((0, 3)),
                       layout._car(np.asarray(car_pose, dtype=np.float64)),
                       fresh_seen(world.circles, world.segments), 1,
                       np.empty(0, dtype=np.int64)).copy()


@pytest.mark.parametrize("mount, fov, housing", [
    ((0.35, 0.2, math.pi / 4), 1.5 * math.pi, 0.1),  # the corner 270-degree Lidar
    ((0.0, 0.0, 0.0), 2 * math.pi, 0.1),  # body level in the middle of the car
    ((0.4, -0.1, -0.3), math.pi, 0.0),  # on the front edge, no housing
    ((0.1, 0.3, 1.0), 2 * math.pi, 0.02),  # outside the outline (left of it)
])
def test_self_occluded_ranges_agree_with_pymunk_on_the_world_and_the_car_box(mount, fov, housing):
    world = make_world("hallway")
    space = world.build_space()
    lidar = LidarConfig(mount, n_beams=181, fov=fov, max_range=8.0, self_occlusion=True,
                        housing_radius=housing)
    layout = LidarLayout.exact([lidar], CAR)
    for car_pose in ([2.0, 0.0, 0.3], [6.0, 0.4, -2.5], [10.0, -0.3, 1.6]):
        sensor = se2.compose(np.array(car_pose), np.array(mount))
        exact = exact_scan(layout, world, sensor[None, :], car_pose)
        oracle = body_oracle(car_pose, sensor, lidar.beam_angles, 8.0, housing, space)
        assert np.any(exact < 1.0)  # the car is seen
        np.testing.assert_allclose(exact, oracle, atol=1e-9)
        (reading,) = layout.scan(world, sensor[None, :], np.random.default_rng(0),
                                 car_pose=car_pose)
        np.testing.assert_allclose(reading, oracle, atol=1e-5)  # float32


def car_frame_angles(lidar: LidarConfig) -> np.ndarray:
    return np.degrees(lidar.mount[2] + lidar.beam_angles)


def scans(lidar: LidarConfig, car_pose, world):
    plain = LidarLayout.exact([LidarConfig(lidar.mount, lidar.n_beams, lidar.fov)])
    occluded = LidarLayout.exact([lidar], CAR)
    sensor = se2.compose(np.array(car_pose), np.array(lidar.mount))[None, :]
    rng = np.random.default_rng(0)
    return (plain.scan(world, sensor, rng)[0],
            occluded.scan(world, sensor, rng, car_pose=car_pose)[0])


def test_a_270_degree_lidar_on_the_outline_corner_keeps_its_whole_view():
    world = make_world("open_cylinders")
    lidar = LidarConfig((0.4, 0.25, math.pi / 4), 271, 1.5 * math.pi, self_occlusion=True)
    plain, occluded = scans(lidar, [3.0, 3.0, 0.4], world)
    # the first and last beams graze along the car's sides; every other one looks away
    np.testing.assert_array_equal(occluded[1:-1], plain[1:-1])


def test_a_corner_lidar_inside_the_outline_loses_the_beams_grazing_along_the_sides():
    world = make_world("open_cylinders")
    lidar = LidarConfig((0.35, 0.2, math.pi / 4), 271, 1.5 * math.pi, self_occlusion=True)
    plain, occluded = scans(lidar, [3.0, 3.0, 0.4], world)
    angles = car_frame_angles(lidar)  # -90 .. 180 degrees in the car frame
    # 5 cm inside both sides with a 0.1 m housing: free from -60 to +150 degrees (210 of 270)
    free = (angles > -59.5) & (angles < 149.5)
    blocked = (angles < -60.5) | (angles > 150.5)
    np.testing.assert_array_equal(occluded[free], plain[free])
    assert np.all(occluded[blocked] < 0.9) and np.all(plain[blocked] > 0.9)


def test_a_body_level_lidar_in_the_middle_of_the_car_reads_only_the_car():
    world = make_world("open_cylinders")
    lidar = LidarConfig((0.0, 0.0, 0.0), 360, self_occlusion=True)
    _, occluded = scans(lidar, [3.0, 3.0, 0.4], world)
    hl, hw = 0.5 * CAR[0], 0.5 * CAR[1]
    angles = lidar.beam_angles
    with np.errstate(divide="ignore"):
        expected = np.minimum(hl / np.abs(np.cos(angles)), hw / np.abs(np.sin(angles)))
    np.testing.assert_allclose(occluded, expected, atol=1e-6)


def test_the_env_casts_the_outline_in_both_scan_frames():
    corner = {"mount": (0.35, 0.2, math.pi / 4), "fov": 1.5 * math.pi, "n_beams": 271,
              "self_occlusion": True, "range_noise_std": 0.0}
    for frame in ("sensor", "world"):
        env = gym.make("DualLidar-v0", world="hallway",
                       config={"lidars": [corner], "scan_frame": frame})
        env.reset(seed=3)
        observation, *_ = env.step(np.array([0.5, 0.2], dtype=np.float32))
        pose = env.unwrapped.car.pose
        lidar = env.unwrapped.config.lidars[0]
        sensor = se2.compose(pose, np.array(lidar.mount))
        # a world-frame scan casts beam i along world angle beam_angles[i]
        cast_from = sensor if frame == "sensor" else np.array([*sensor[:2], 0.0])
        oracle = body_oracle(pose, cast_from, lidar.beam_angles, lidar.max_range,
                             lidar.housing_radius,
                             env.unwrapped.world.build_space())
        np.testing.assert_allclose(observation["lidar_1"], oracle, atol=1e-5)
        assert np.sum(observation["lidar_1"] < 0.9) >= 40  # about 60 of 271 beams see the car


def test_bad_self_occlusion_settings_are_named():
    with pytest.raises(ConfigError, match=r"lidars\[0\].self_occlusion: expected True or False"):
        gym.make("DualLidar-v0", config={"lidars": [{"mount": (0, 0, 0),
                                                     "self_occlusion": "yes"}]})
    with pytest.raises(ConfigError, match=r"lidars\[0\].housing_radius: expected a finite"):
        gym.make("DualLidar-v0", config={"lidars": [{"mount": (0, 0, 0),
                                                     "housing_radius": -0.1}]})
    lidar = LidarConfig((0.35, 0.2, 0.0), self_occlusion=True)
    with pytest.raises(ConfigError, match="car_size"):
        LidarLayout.exact([lidar])
    layout = LidarLayout.exact([lidar], CAR)
    world = make_world("hallway")
    with pytest.raises(ConfigError, match="car_pose: expected the car's finite world pose"):
        layout.scan(world, [[2.0, 0.0, 0.0]], np.random.default_rng(0))
    beams, params = layout._packed  # the kernel without the car refuses, not ignores, it
    with pytest.raises(ConfigError, match="car: a self-occluded Lidar needs the car's pose"):
        scan_layout_kernel(world.circles, world.segments, len(world.walls), world.grid,
                           np.array([[2.0, 0.0, 0.0]]), beams, params, np.empty(0), np.empty(0))


def test_the_outline_is_the_car_rectangle_counter_clockwise():
    edges = car_outline(np.array([1.0, 2.0, math.pi / 2, 0.4, 0.25]))
    np.testing.assert_allclose(edges[0], [0.75, 2.4, 0.75, 1.6], atol=1e-12)
    np.testing.assert_allclose(edges[:, 2:], np.roll(edges[:, :2], -1, axis=0))
