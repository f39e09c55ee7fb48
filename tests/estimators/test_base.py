"""The Estimator interface and SensorSetup (``estimators.base``), and the registry
(``estimators.make``, ``estimators.names``)."""

import numpy as np
import pytest

import estimators
from estimators.base import Estimator, SensorSetup, default_beam_angles


class ConstantStep(Estimator):
    """Moves 1 m forward per update: exercises the base class bookkeeping only."""

    def _start(self, scans, t):
        self.starts = getattr(self, "starts", 0) + 1

    def _step(self, scans, t):
        return self.pose + np.array([1.0, 0.0, 0.0])


def setup() -> SensorSetup:
    return SensorSetup(np.array([[0.25, 0, 0], [-0.25, 0, 0]]), default_beam_angles(8), 10.0)


def observation(value: float = 1.0) -> dict[str, np.ndarray]:
    return {"lidar_1": np.full(8, value, np.float32), "lidar_2": np.full(8, value, np.float32)}


def test_trajectory_has_one_row_per_observation_starting_at_initial_pose() -> None:
    est = ConstantStep()
    est.reset(setup(), initial_pose=(1.0, 2.0, 0.5))
    for k in range(4):
        est.update(observation(1.0 + k), t=0.1 * k)
    np.testing.assert_allclose(est.trajectory[:, 0], [1, 2, 3, 4])
    np.testing.assert_allclose(est.times, [0.0, 0.1, 0.2, 0.3])
    est.reset(setup())
    assert est.trajectory.shape == (0, 3)


@pytest.mark.parametrize(
    ("obs", "message"),
    [
        ({"lidar_1": np.ones(8)}, "lidar_2"),
        ({"lidar_1": np.ones(7), "lidar_2": np.ones(8)}, "shape"),
        ({"lidar_1": np.full(8, np.nan), "lidar_2": np.ones(8)}, "NaN"),
        ({"lidar_1": -np.ones(8), "lidar_2": np.ones(8)}, "negative"),
    ],
)
def test_bad_scans_raise_readable_errors(obs, message) -> None:
    est = ConstantStep()
    est.reset(setup())
    with pytest.raises((KeyError, ValueError), match=message):
        est.update(obs, 0.0)


def test_update_before_reset_and_bad_setup() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        ConstantStep().update(observation(), 0.0)
    with pytest.raises(ValueError, match="mounts"):
        SensorSetup(np.zeros((3, 2)), default_beam_angles(8), 10.0)
    with pytest.raises(ValueError, match="max_range"):
        SensorSetup(np.zeros((1, 3)), default_beam_angles(8), -1.0)


def test_unknown_estimator_lists_valid_names() -> None:
    with pytest.raises(KeyError, match="expected one of"):
        estimators.make("no_such_estimator")


def test_an_unknown_parameter_is_named_with_the_valid_ones() -> None:
    from lidar_env.core.errors import ConfigError

    for name in estimators.names():
        with pytest.raises(ConfigError, match=f"{name}: unknown parameter.*no_such"):
            estimators.make(name, no_such=1)
    with pytest.raises(ConfigError, match="expected some of .*sideslip_sigma"):
        estimators.make("lidar_odometry", sideslip=1e-3)


def test_registry_defaults_are_what_make_uses() -> None:
    for name in estimators.names():
        params = estimators.registry.defaults(name)
        assert isinstance(params, dict)
    params = estimators.registry.defaults("pc")
    params["lidar"] = 99  # a copy: the registry is not changed through it
    assert estimators.registry.defaults("pc") != params
    with pytest.raises(KeyError, match="expected one of"):
        estimators.registry.defaults("nope")
