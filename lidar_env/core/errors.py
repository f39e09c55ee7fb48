"""The project's exception hierarchy: every error duallidar raises for bad input derives from
:class:`DualLidarError`, so a user can catch ours and tell them apart from bugs.

``DualLidarError`` subclasses ``ValueError`` (bad input is a bad value), and each area has its
own subclass. Three also keep the built-in kind Python code expects of them:
:class:`ArgumentTypeError` is a ``TypeError``, :class:`UnknownNameError` a ``KeyError`` and
:class:`ResetNeededError` a ``RuntimeError``. Messages name the argument, or the file and
line, and say what was expected::

    try:
        env = gym.make("DualLidar-v0", config={"max_speed": -1})
    except ConfigError as error:
        print(error)  # max_speed: expected a finite value > 0 [m/s], got -1

This module imports nothing, so every package (``lidar_env``, ``estimators``, ``agents``) can
use it.
"""

from __future__ import annotations


class DualLidarError(ValueError):
    """Base of every error duallidar raises for bad input."""


class ConfigError(DualLidarError):
    """An env config, reset option, action, or an estimator's or tool's parameter is invalid."""


class ResetNeededError(DualLidarError, RuntimeError):
    """A call out of order: ``step()`` (or ``act()``, ``update()``, ``render()``) before the
    first ``reset()``, or ``step()`` after the episode ended (Gymnasium leaves that undefined;
    we refuse it so that a car never drives on past a wall or the goal unnoticed)."""


class ArgumentTypeError(DualLidarError, TypeError):
    """An argument of the wrong type (a list where a config dict or a Generator belongs)."""


class UnknownNameError(DualLidarError, KeyError):
    """A name that is not registered (an estimator, a stored scenario or trace); the message
    lists what is."""

    def __str__(self) -> str:  # KeyError's own would quote the message
        return str(self.args[0]) if self.args else ""


class MapError(DualLidarError):
    """A world, map image, ROS map, obstacle geometry or trace cannot be built as asked."""


class EstimatorInputError(DualLidarError):
    """Scans, clock times or a sensor setup handed to an estimator are invalid."""


class LogFormatError(DualLidarError):
    """A recording or graph file (CARMEN, ROS bag, g2o, TUM, relations) is malformed."""


class DatabaseError(DualLidarError):
    """The experiment database is missing, foreign, corrupt or of another schema."""
