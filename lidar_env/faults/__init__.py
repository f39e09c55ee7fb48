"""Sensor faults on purpose: blinded, dropped, frozen, noisy or lost scans and a faulty clock,
injected into the env by a Gymnasium wrapper or into a recorded log by the same code.

Faults are wrappers (:class:`FaultInjection`) rather than keys of :class:`~lidar_env.EnvConfig`:
they compose (nest several, in the order the sensor chain applies them), they wrap any env
with Lidar observations, and the config stays about the world and the car. Each fault is a
small object (:mod:`.scan_faults`, :mod:`.clock_faults`) with ``reset(rng, max_ranges)`` and
``apply(frame) -> frame or None`` (None: the scan is lost); the wrapper feeds it the env's
frames, :func:`apply_faults` a sequence of recorded ones (``estimators.datasets.faults``
does so for a :class:`~estimators.datasets.recording.Recording`). Every fault draws from its
own generator spawned from the env's ``np_random`` (or from the seed given for a log): same
seed, same faults, and the env's own draws (noise, dropouts, movers) stay those of a clean
run. This subpackage sits above the env's top modules; nothing in ``lidar_env`` imports it.
"""

from lidar_env.faults.clock_faults import ClockJitter, ClockJump, ClockStall, ScanLoss
from lidar_env.faults.frames import Fault, Frame, apply_faults, spawn_generators
from lidar_env.faults.scan_faults import BeamDropout, Blind, FrozenLidar, RangeOutliers
from lidar_env.faults.wrappers import FaultInjection

__all__ = [
    "BeamDropout",
    "Blind",
    "ClockJitter",
    "ClockJump",
    "ClockStall",
    "Fault",
    "FaultInjection",
    "Frame",
    "FrozenLidar",
    "RangeOutliers",
    "ScanLoss",
    "apply_faults",
    "spawn_generators",
]
