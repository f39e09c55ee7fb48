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

Messages quote a value the user gave through :func:`quoted`, which bounds the quote (and
the work of making it) whatever the value holds: a nested YAML alias or a huge array never
turns an error message into gigabytes.

This module imports only the standard library, so every package (``lidar_env``,
``estimators``, ``agents``) can use it.
"""

from __future__ import annotations

import reprlib

#: [characters] longest quote of a user's value in an error message (see :func:`quoted`).
QUOTE_LIMIT = 80


def _quoter() -> reprlib.Repr:
    quoter = reprlib.Repr()
    quoter.maxlevel, quoter.maxlist, quoter.maxtuple, quoter.maxdict = 3, 6, 6, 4
    quoter.maxset = quoter.maxfrozenset = quoter.maxdeque = quoter.maxarray = 6
    quoter.maxstring = quoter.maxlong = quoter.maxother = QUOTE_LIMIT
    return quoter


_QUOTER = _quoter()


def quoted(value: object, limit: int = QUOTE_LIMIT) -> str:
    """``repr(value)`` for an error message, at most ``limit`` characters (cut with ``...``).

    Nested containers are shown to a bounded depth and width (``reprlib``), so quoting costs
    little whatever ``value`` holds; an object whose ``repr`` fails (an int too long to print)
    is named by its type.
    """
    try:
        text = " ".join(_QUOTER.repr(value).split())
    except Exception:  # noqa: BLE001 - any repr may fail; the message must not
        text = f"<{type(value).__name__}>"
        if isinstance(value, int):
            text = f"<int of {int(value.bit_length() * 0.30103) + 1} digits>"
    return text if len(text) <= limit else text[: max(limit - 3, 0)] + "..."


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
