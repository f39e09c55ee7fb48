"""Drivers for ``DualLidar-v0``: a shared :class:`Driver` protocol and a scripted driver."""

from agents.driver import DRIVERS, Driver, make_driver
from agents.scripted import PurePursuitDriver
from lidar_env import __version__

__all__ = ["DRIVERS", "__version__", "Driver", "PurePursuitDriver", "make_driver"]
