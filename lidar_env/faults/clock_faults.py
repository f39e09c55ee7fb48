"""Faults of the clock and of delivery: stamps that jitter, stall or jump while the scans run
on, and scans that never arrive. Times [s].

Every stamp a fault hands on is later than the one before (by at least :data:`MIN_STEP`):
a stamp that does not advance is refused by every estimator as a fault of the recording
(``lidar_env.core.clock``), so a stalled clock here creeps rather than stands.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from lidar_env.core import ConfigError
from lidar_env.faults.frames import Fault, Frame
from lidar_env.faults.scan_faults import check_schedule, in_stretch

#: [s] the least step between two faulted stamps (1 us).
MIN_STEP: float = 1e-6


class ClockFault(Fault):
    """A fault of the stamps: it maps each clean stamp to a faulty one, kept strictly
    increasing."""

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._previous = -np.inf

    def stamp(self, frame: Frame) -> float:
        """The faulty stamp of ``frame`` before it is kept increasing."""
        raise NotImplementedError

    def apply(self, frame: Frame) -> Frame | None:
        time = max(self.stamp(frame), self._previous + MIN_STEP)
        self._previous = time
        return frame.with_time(time)


@dataclass
class ClockJitter(ClockFault):
    """Stamps off by a normal error of ``sigma`` [s] (0.01: a busy driver thread)."""

    sigma: float = 0.01

    def __post_init__(self) -> None:
        if not self.sigma >= 0:
            raise ConfigError(f"sigma: expected a non-negative time [s], got {self.sigma!r}")

    def stamp(self, frame: Frame) -> float:
        return frame.time + float(self.rng.normal(0.0, self.sigma))


@dataclass
class ClockStall(ClockFault):
    """A clock that stops for ``stretch`` scans (each stamped 1 us after the last) and then
    catches up with the true time, at scheduled or random scans.

    Attributes:
        every, stretch, offset: stalls of ``stretch`` scans start every ``every`` scans from
            scan ``offset`` (None: none on a schedule).
        probability: chance that a stall starts at a scan otherwise running.
    """

    every: int | None = 50
    stretch: int = 5
    offset: int = 10
    probability: float = 0.0
    _left: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        check_schedule(self.every, self.stretch, self.offset, self.probability)

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._left = 0

    def stamp(self, frame: Frame) -> float:
        drawn = self.probability > 0 and self.rng.random() < self.probability
        if self._left == 0 and (in_stretch(frame.step, self.every, self.stretch, self.offset)
                                or drawn):
            self._left = self.stretch
        if self._left == 0 or not np.isfinite(self._previous):
            return frame.time
        self._left -= 1
        return self._previous  # then MIN_STEP later


@dataclass
class ClockJump(ClockFault):
    """A clock that jumps ``jump`` [s] forward (and stays ahead) while the scans run on: at
    scheduled scans or at random.

    Attributes:
        jump: [s] each jump (3.0).
        every, offset: a jump every ``every`` scans from scan ``offset`` (None: never on a
            schedule).
        probability: chance of a jump at any scan.
    """

    jump: float = 3.0
    every: int | None = 50
    offset: int = 10
    probability: float = 0.0
    _ahead: float = field(default=0.0, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.jump) and self.jump > 0):
            raise ConfigError(f"jump: expected a positive time [s], got {self.jump!r}")
        check_schedule(self.every, 1, self.offset, self.probability)

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._ahead = 0.0

    def stamp(self, frame: Frame) -> float:
        drawn = self.probability > 0 and self.rng.random() < self.probability
        if in_stretch(frame.step, self.every, 1, self.offset) or drawn:
            self._ahead += self.jump
        return frame.time + self._ahead


@dataclass
class ScanLoss(Fault):
    """Scans that never arrive: stretches of ``stretch`` consecutive scans lost, at scheduled
    or random scans (the stamps of those that arrive are true, so a gap shows in the clock).

    Attributes:
        probability: chance that a loss starts at any scan (0.05).
        stretch: scans lost in a row (1).
        every, offset: also a loss every ``every`` scans from scan ``offset`` (None: none).

    The first scan always arrives (an estimator starts from it).
    """

    probability: float = 0.05
    stretch: int = 1
    every: int | None = None
    offset: int = 1
    _left: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        check_schedule(self.every, self.stretch, self.offset, self.probability)

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._left = 0

    def apply(self, frame: Frame) -> Frame | None:
        drawn = self.probability > 0 and self.rng.random() < self.probability
        if self._left == 0 and (in_stretch(frame.step, self.every, 1, self.offset) or drawn):
            self._left = self.stretch
        if frame.step == 0 or self._left == 0:
            return frame
        self._left -= 1
        return None
