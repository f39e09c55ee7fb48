"""What a fault acts on (:class:`Frame`: one observation's scans and its time stamp), the
interface every fault implements (:class:`Fault`) and the loop that applies faults to a
sequence of frames (:func:`apply_faults`)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError


@dataclass(frozen=True)
class Frame:
    """One observation as a fault sees it.

    Attributes:
        scans: ``{key: (n,) ranges [m]}`` in each Lidar's frame (``lidar_1`` ..).
        time: the stamp [s] the consumer will read (``info["time"]`` in the env).
        step: index of the observation in the clean stream (0 for the first, lost ones
            counted), so a fault can act on every k-th scan whatever the faults before it did.
    """

    scans: Mapping[str, NDArray]
    time: float
    step: int

    def with_scans(self, scans: Mapping[str, NDArray]) -> Frame:
        return replace(self, scans=dict(scans))

    def with_time(self, time: float) -> Frame:
        return replace(self, time=float(time))


class Fault(ABC):
    """A sensor fault: :meth:`reset` at the start of each episode or log, then :meth:`apply`
    to every frame in order. It keeps what state it needs (a frozen scan, a clock offset)
    between frames; it never changes the arrays it is given (it returns new ones)."""

    def reset(self, rng: np.random.Generator, max_ranges: Mapping[str, float]) -> None:
        """Start over with the generator ``rng`` and each Lidar's max range [m] by key."""
        self.rng = rng
        self.max_ranges = dict(max_ranges)

    @abstractmethod
    def apply(self, frame: Frame) -> Frame | None:
        """The frame as the faulty sensor delivers it, or None when it is lost."""

    def _keys(self, frame: Frame, keys: Sequence[str] | None) -> list[str]:
        """The keys of ``frame`` this fault acts on (all when ``keys`` is None)."""
        if keys is None:
            return list(frame.scans)
        missing = [key for key in keys if key not in frame.scans]
        if missing:
            raise ConfigError(f"{type(self).__name__}: keys {missing} are not among the "
                              f"observation's {sorted(frame.scans)}")
        return list(keys)


def spawn_generators(parent: np.random.Generator, count: int) -> list[np.random.Generator]:
    """``count`` independent generators spawned from ``parent`` without drawing from it (its
    own stream stays that of a run without faults)."""
    try:
        return list(parent.spawn(count))
    except (TypeError, ValueError):  # a generator built without a SeedSequence
        seeds = np.random.SeedSequence(int(parent.bit_generator.random_raw()))
        return [np.random.default_rng(child) for child in seeds.spawn(count)]


def apply_faults(frames: Iterable[Frame], faults: Sequence[Fault], seed: int,
                 max_ranges: Mapping[str, float]) -> Iterator[Frame]:
    """The frames that survive ``faults`` (applied in order to each), faulted.

    Args:
        frames: the clean frames, in time order.
        faults: reset here with generators spawned from ``seed``.
        seed: same seed, same faults.
        max_ranges: each Lidar's max range [m] by key (the value of "no return").
    """
    for fault in faults:
        if not isinstance(fault, Fault):
            raise ConfigError(f"faults: expected Fault objects, got {type(fault).__name__}")
    for fault, rng in zip(faults, spawn_generators(np.random.default_rng(seed), len(faults)),
                          strict=True):
        fault.reset(rng, max_ranges)
    for frame in frames:
        faulted: Frame | None = frame
        for fault in faults:
            faulted = fault.apply(faulted)
            if faulted is None:
                break
        if faulted is not None:
            yield faulted
