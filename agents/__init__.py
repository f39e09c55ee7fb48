"""Drivers for ``DualLidar-v0``: a shared :class:`Driver` protocol and a scripted driver."""

from agents.driver import Driver
from agents.scripted import PurePursuitDriver

__all__ = ["Driver", "PurePursuitDriver"]
