"""The ray caster indexes a sensor's beams directly when they come in the order of their wrapped
angles (``IN_ORDER`` in the packed params), and through the beams' ``order`` otherwise: both
paths must give the same ranges bit for bit, over circles, walls and polygon edges."""

from __future__ import annotations

import numpy as np
import pytest

from lidar_env.sensors.lidar import cast_rays
from lidar_env.sensors.lidar_config import IN_ORDER, pack_sensors
from tests.lidar_env.sensors.test_lidar import image_world, random_free_poses, random_world

BEAMS = 2.0 * np.pi * np.arange(360) / 360
ROW = (0.0, 10.0, 0.0, 0.0, -1.0, 0.0)  # offset, max range, noise, dropout, housing, min range


def test_in_order_flag_marks_beams_sorted_by_wrapped_angle_only() -> None:
    rng = np.random.default_rng(0)
    sweeps = [BEAMS, BEAMS - np.pi, BEAMS[::-1], rng.permutation(BEAMS), np.array([0.3])]
    _, params = pack_sensors(sweeps, [ROW] * len(sweeps))
    np.testing.assert_array_equal(params[:, IN_ORDER], [1.0, 0.0, 0.0, 0.0, 1.0])


@pytest.mark.parametrize("make_world", [random_world, lambda rng: image_world()],
                         ids=["mixed", "from_image"])
@pytest.mark.parametrize("uniform", [True, False], ids=["uniform", "uneven"])
def test_in_order_and_permuted_beams_read_the_same_bit_for_bit(make_world, uniform: bool) -> None:
    rng = np.random.default_rng(3)
    world = make_world(rng)
    poses = random_free_poses(world, rng, 24)
    beams = BEAMS if uniform else np.sort(rng.uniform(0.0, 2.0 * np.pi, 200))
    permutation = rng.permutation(len(beams))
    direct = cast_rays(world, poses, beams, 10.0)
    through_order = cast_rays(world, poses, beams[permutation], 10.0)
    assert np.mean(direct < 10.0) > 0.2, "the scans should see plenty of obstacles"
    assert direct[:, permutation].tobytes() == through_order.tobytes()
