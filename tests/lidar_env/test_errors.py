"""The project's exception types: each is a DualLidarError (a ValueError) and the three with a
built-in kind keep it, so ``except TypeError`` / ``KeyError`` / ``RuntimeError`` code works."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from lidar_env.errors import (
    ArgumentTypeError,
    DualLidarError,
    ResetNeededError,
    UnknownNameError,
)


@pytest.mark.parametrize(("kind", "builtin"), [(ArgumentTypeError, TypeError),
                                               (UnknownNameError, KeyError),
                                               (ResetNeededError, RuntimeError)])
def test_each_kind_is_ours_and_the_builtin(kind: type[Exception], builtin: type) -> None:
    assert issubclass(kind, DualLidarError) and issubclass(kind, ValueError)
    assert issubclass(kind, builtin)


def test_an_unknown_name_reads_unquoted() -> None:
    with pytest.raises(UnknownNameError) as caught:
        estimators.make("nope")
    assert str(caught.value).startswith("unknown estimator 'nope': expected one of ")


def test_step_before_reset_and_a_wrong_config_type_are_named() -> None:
    env = gym.make("DualLidar-v0")
    with pytest.raises(ResetNeededError, match=r"call reset\(\) before step\(\)"):
        env.unwrapped.step(np.zeros(2, np.float32))
    with pytest.raises(ArgumentTypeError, match="config: expected an EnvConfig or a dict"):
        gym.make("DualLidar-v0", config=[1, 2])
