"""Faults of the ranges: blinded sectors or whole scans, beams dropped in bursts, a frozen
Lidar that republishes one scan, and range outliers. Ranges [m], angles [rad] in the sensor
frame, counted by beam index (beam ``i`` of ``n`` looks at ``2 pi i / n``, as on the env's
Lidars).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError
from lidar_env.faults.frames import Fault, Frame

FILLS = ("max_range", "zero")


def check_share(name: str, value: float) -> None:
    """Raise a ConfigError naming ``name`` unless ``value`` lies in [0, 1]."""
    if not 0.0 <= value <= 1.0:
        raise ConfigError(f"{name}: expected a share in [0, 1], got {value!r}")


def check_count(name: str, value: int | None, least: int) -> None:
    """Raise a ConfigError naming ``name`` unless ``value`` is an integer >= ``least``."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise ConfigError(f"{name}: expected an integer >= {least}, got {value!r}")


def in_stretch(step: int, every: int | None, stretch: int, offset: int) -> bool:
    """Whether clean scan ``step`` lies in one of the stretches of ``stretch`` scans that
    start every ``every`` scans from ``offset`` (never when ``every`` is None)."""
    return every is not None and step >= offset and (step - offset) % every < stretch


def check_schedule(every: int | None, stretch: int, offset: int, probability: float) -> None:
    """Raise a ConfigError naming the first bad setting of a fault's schedule (as read by
    :func:`in_stretch`): ``every`` an integer >= 1 or None, ``stretch`` >= 1, ``offset`` >= 0
    and ``probability`` (of a random start per scan) in [0, 1]."""
    if every is not None:
        check_count("every", every, 1)
    check_count("stretch", stretch, 1)
    check_count("offset", offset, 0)
    check_share("probability", probability)


def sector_mask(n_beams: int, centre: float, width: float) -> NDArray[np.bool_]:
    """``(n_beams,)`` the beams (beam ``i`` at ``2 pi i / n``) within ``width / 2`` [rad] of
    ``centre`` [rad]; all of them for a width of 2 pi or more."""
    angles = 2.0 * np.pi * np.arange(n_beams) / n_beams
    off = np.abs((angles - centre + np.pi) % (2.0 * np.pi) - np.pi)
    return off <= 0.5 * width


def burst_mask(n_beams: int, fraction: float, burst: int,
               rng: np.random.Generator) -> NDArray[np.bool_]:
    """``(n_beams,)`` beams dropped in runs of ``burst`` neighbours: the scan is cut into
    runs from a random beam on, each dropped with probability ``fraction`` (so ``fraction``
    of the beams on average)."""
    start = int(rng.integers(burst))
    runs = (np.arange(n_beams) + start) // burst
    dropped = rng.random(int(runs[-1]) + 1) < fraction
    return dropped[runs]


@dataclass
class Blind(Fault):
    """A blinded Lidar: the beams of a sector (or of the whole scan) read ``max_range`` (no
    return: a covered or dazzled window) or 0 m (``fill="zero"``: a sensor reporting zeros).

    Attributes:
        every, stretch, offset: stretches of ``stretch`` consecutive scans are blind, one
            starting every ``every`` scans from scan ``offset`` (2, 1, 1: every other scan;
            ``every=None``: none on a schedule).
        probability: chance that a stretch starts at a scan otherwise clear (random blinding).
        width: [rad] the blind sector, centred at an angle drawn per stretch (2 pi or more,
            the default: the whole scan).
        fill: "max_range" or "zero".
        keys: the Lidars blinded (None: all).
    """

    every: int | None = 2
    stretch: int = 1
    offset: int = 1
    probability: float = 0.0
    width: float = 2.0 * np.pi
    fill: str = "max_range"
    keys: Sequence[str] | None = None
    _left: int = field(default=0, init=False, repr=False)
    _centre: float = field(default=0.0, init=False, repr=False)

    def __post_init__(self) -> None:
        check_schedule(self.every, self.stretch, self.offset, self.probability)
        if not self.width > 0:
            raise ConfigError(f"width: expected a positive angle [rad], got {self.width!r}")
        if self.fill not in FILLS:
            raise ConfigError(f"fill: expected one of {', '.join(FILLS)}, got {self.fill!r}")

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._left = 0

    def apply(self, frame: Frame) -> Frame | None:
        scheduled = in_stretch(frame.step, self.every, self.stretch, self.offset)
        drawn = self.probability > 0 and self.rng.random() < self.probability
        if scheduled and self._left == 0:
            self._left = self.stretch - (frame.step - self.offset) % self.every
            self._centre = float(self.rng.uniform(0.0, 2.0 * np.pi))
        elif drawn and self._left == 0:
            self._left = self.stretch
            self._centre = float(self.rng.uniform(0.0, 2.0 * np.pi))
        if self._left == 0:
            return frame
        self._left -= 1
        scans = dict(frame.scans)
        for key in self._keys(frame, self.keys):
            scan = np.array(scans[key], copy=True)
            scan[sector_mask(len(scan), self._centre, self.width)] = (
                self.max_ranges[key] if self.fill == "max_range" else 0.0)
            scans[key] = scan
        return frame.with_scans(scans)


@dataclass
class BeamDropout(Fault):
    """Beams lost in bursts (a dirty window, a flaky receiver): on every scan, runs of
    ``burst`` neighbouring beams read ``max_range`` (no return), each run with probability
    ``fraction``.

    Attributes:
        fraction: share of the beams dropped on average (0.5).
        burst: beams per run (8).
        keys: the Lidars affected (None: all).
    """

    fraction: float = 0.5
    burst: int = 8
    keys: Sequence[str] | None = None

    def __post_init__(self) -> None:
        check_share("fraction", self.fraction)
        check_count("burst", self.burst, 1)

    def apply(self, frame: Frame) -> Frame | None:
        scans = dict(frame.scans)
        for key in self._keys(frame, self.keys):
            scan = np.array(scans[key], copy=True)
            scan[burst_mask(len(scan), self.fraction, self.burst, self.rng)] = (
                self.max_ranges[key])
            scans[key] = scan
        return frame.with_scans(scans)


@dataclass
class FrozenLidar(Fault):
    """A frozen Lidar: from scan ``after`` on, for ``duration`` scans, its driver republishes
    the scan it took at ``after`` (the stamps keep running).

    Attributes:
        keys: the Lidars frozen (("lidar_2",): the second one).
        after: the clean scan index the freeze starts at (0: the first scan, forever).
        duration: scans it lasts (None: to the end).
    """

    keys: Sequence[str] | None = ("lidar_2",)
    after: int = 0
    duration: int | None = None
    _held: dict[str, NDArray] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        check_count("after", self.after, 0)
        if self.duration is not None:
            check_count("duration", self.duration, 1)

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        super().reset(rng, max_ranges)
        self._held = {}

    def apply(self, frame: Frame) -> Frame | None:
        end = np.inf if self.duration is None else self.after + self.duration
        if not self.after <= frame.step < end:
            self._held = {}
            return frame
        scans = dict(frame.scans)
        for key in self._keys(frame, self.keys):
            held = self._held.setdefault(key, np.array(scans[key], copy=True))
            scans[key] = held.copy()
        return frame.with_scans(scans)


@dataclass
class RangeOutliers(Fault):
    """Spurious returns (multipath, dust, a glass door): each beam reads a range drawn
    uniformly in [0, max_range) with probability ``probability``.

    Attributes:
        probability: per beam (0.02).
        keys: the Lidars affected (None: all).
    """

    probability: float = 0.02
    keys: Sequence[str] | None = None

    def __post_init__(self) -> None:
        check_share("probability", self.probability)

    def apply(self, frame: Frame) -> Frame | None:
        scans = dict(frame.scans)
        for key in self._keys(frame, self.keys):
            scan = np.array(scans[key], copy=True)
            hit = self.rng.random(len(scan)) < self.probability
            scan[hit] = self.rng.uniform(0.0, self.max_ranges[key], int(hit.sum()))
            scans[key] = scan
        return frame.with_scans(scans)
