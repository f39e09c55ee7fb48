"""SensorSetup with K Lidars of their own geometry (``estimators.base.Sensor``): per-sensor
scans are checked against their own beam count, shared-geometry accessors refuse to guess,
and bad mounts, angles and ranges name the field and the sensor."""

import numpy as np
import pytest

from estimators.base import LIDAR_KEYS, Sensor, SensorSetup, default_beam_angles
from lidar_env.core.errors import EstimatorInputError


def corner_setup() -> SensorSetup:
    """Two 270-degree corner Lidars of 270 beams (7 m) and a 180-degree one of 90 beams (20 m)."""
    wide = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 270)
    front = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 90)
    return SensorSetup(sensors=(
        Sensor((0.35, 0.2, np.pi / 4), wide, 7.0),
        Sensor((-0.35, -0.2, -3 * np.pi / 4), wide, 7.0),
        Sensor((0.4, 0.0, 0.0), front, 20.0),
    ))


def test_k_sensors_keep_their_own_geometry() -> None:
    setup = corner_setup()
    assert setup.n_lidars == 3 and setup.keys == ("lidar_1", "lidar_2", "lidar_3")
    assert [s.n_beams for s in setup.sensors] == [270, 270, 90]
    assert [s.index for s in setup.sensors] == [0, 1, 2]
    np.testing.assert_array_equal(setup.mounts[:, 0], [0.35, -0.35, 0.4])
    assert not setup.uniform
    with pytest.raises(EstimatorInputError, match=r"setup.sensors\[k\].beam_angles"):
        _ = setup.beam_angles
    with pytest.raises(EstimatorInputError, match="max_range"):
        _ = setup.max_range
    scans = setup.check_observation({"lidar_1": np.ones(270), "lidar_2": np.ones(270),
                                     "lidar_3": np.ones(90)})
    assert [len(scans[k]) for k in setup.keys] == [270, 270, 90]
    with pytest.raises(ValueError, match=r"lidar_3: expected a scan of shape \(90,\)"):
        setup.check_observation({"lidar_1": np.ones(270), "lidar_2": np.ones(270),
                                 "lidar_3": np.ones(270)})


def test_shared_geometry_constructor_is_the_same_as_sensors() -> None:
    angles = default_beam_angles(360)
    mounts = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])
    simple = SensorSetup(mounts, angles, 10.0)
    explicit = SensorSetup(sensors=[Sensor(m, angles, 10.0) for m in mounts])
    assert simple.uniform and explicit.uniform
    np.testing.assert_array_equal(simple.mounts, explicit.mounts)
    np.testing.assert_array_equal(simple.beam_angles, angles)
    assert simple.max_range == explicit.max_range == 10.0
    one = SensorSetup(np.zeros(3), angles[:180], 30.0)  # the CARMEN case: one row
    assert one.n_lidars == 1 and one.keys == ("lidar_1",)


def test_up_to_eight_lidars() -> None:
    angles = default_beam_angles(8)
    assert SensorSetup(np.zeros((8, 3)), angles, 5.0).keys == LIDAR_KEYS
    with pytest.raises(EstimatorInputError, match="K in 1..8"):
        SensorSetup(np.zeros((9, 3)), angles, 5.0)
    with pytest.raises(EstimatorInputError, match="1 to 8 Lidars, got 0"):
        SensorSetup(sensors=())


@pytest.mark.parametrize(
    ("sensor", "message"),
    [
        (dict(mount=(0.0, np.nan, 0.0)), r"mount of sensor 1 \(lidar_2\)"),
        (dict(mount=(0.0, 0.0, np.inf)), r"mount of sensor 1 \(lidar_2\)"),
        (dict(beam_angles=np.r_[0.0, np.nan, 1.0]), r"beam_angles of sensor 1 .*beam 1"),
        (dict(max_range=np.inf), r"max_range of sensor 1"),
        (dict(max_range=np.nan), r"max_range of sensor 1"),
        (dict(max_range=0.0), r"max_range of sensor 1"),
    ],
)
def test_non_finite_geometry_names_field_and_sensor(sensor, message) -> None:
    good = dict(mount=(0.0, 0.0, 0.0), beam_angles=default_beam_angles(8), max_range=5.0)
    bad = {**good, **sensor}
    with pytest.raises(EstimatorInputError, match=message):
        SensorSetup(sensors=(Sensor(**good), Sensor(index=1, **bad)))
    if "mount" in sensor:  # the shared-geometry constructor names the row too
        with pytest.raises(EstimatorInputError, match=message):
            SensorSetup(np.array([good["mount"], bad["mount"]]), good["beam_angles"], 5.0)


def test_every_estimator_runs_on_a_mixed_layout_or_says_why_not() -> None:
    """Two 360-degree Lidars plus a 180-degree one: the single-Lidar estimators read their own
    Lidar's beams; the paper's two-Lidar pose-graph correlation refuses by name."""
    import gymnasium as gym

    import lidar_env  # noqa: F401  (registers DualLidar-v0)
    from estimators import registry
    from lidar_env.core.errors import EstimatorInputError

    config = {"lidars": [{"mount": (0.3, 0.0, 0.0)}, {"mount": (-0.3, 0.0, 0.0)},
                         {"mount": (0.0, 0.2, 1.57), "n_beams": 181, "fov": 3.14}]}
    env = gym.make("DualLidar-v0", world="hallway", trace="straight", config=config)
    for name in registry.names():
        observation, info = env.reset(seed=0)
        estimator = registry.make(name)
        if name == "pc_pg":
            with pytest.raises(EstimatorInputError, match="pc_pg needs 2 Lidars, the setup has 3"):
                estimator.reset(SensorSetup.from_env(env), info["pose"])
            continue
        estimator.reset(SensorSetup.from_env(env), info["pose"])
        for _ in range(5):
            estimator.update(observation, info["time"])
            truth = info["pose"]
            observation, _, _, _, info = env.step(np.array([0.6, 0.0], np.float32))
        assert np.all(np.isfinite(estimator.trajectory)), name
        if name in ("icp", "lidar_odometry", "slam", "pc_fusion", "pc_rot_icp"):
            assert abs(estimator.trajectory[-1][0] - truth[0]) < 0.05, name
