"""Drivers for ``DualLidar-v0``: a shared :class:`Driver` protocol and a scripted driver."""

from agents.driver import DRIVERS, Driver, make_driver
from agents.scripted import PurePursuitDriver

__all__ = ["DRIVERS", "Driver", "PurePursuitDriver", "make_driver"]
