"""What an estimator reports about its input: scans it could not use, frozen sensors, clock
jumps and blind stretches (:class:`Health`), and the screen that finds them before a scan
reaches the estimator's matching (:class:`ScanScreen`).

A scan is usable when the sensors the estimator reads hold at least :data:`MIN_RETURNS` returns
between them (an estimator's ``min_returns``: scan-to-map odometry, whose map and prior hold a
pose that one pillar's few returns pin down, asks fewer): below that a fit of a handful of
points can land metres away, so the scan is skipped and the constant-velocity prediction
carries the pose (:meth:`estimators.base.Estimator.update`). A sensor whose scan repeats its
previous one exactly while another sensor's scan changed, or while the estimate was moving,
is frozen (a real Lidar's range noise never repeats a scan bit for bit): its scan reads 0 m for
that observation (below every estimator's ``min_range``: no return, and unlike ``max_range`` it
clears no space the sensor did not see). Where every sensor is frozen, the observation is
skipped like a blind one: the match onto the scans that change again finds where the car
went meanwhile (matching the repeats would hold the car still while it drives on), and the
frozen observations lie on the way there; until then they hold the last pose (a car that
stopped dead in a noise-free simulation repeats its scans too). Every sensor repeating while
the estimate stands is a car standing still (a noise-free simulation), and its scans are used.
A time step over :data:`CLOCK_JUMP_FACTOR` times the median of the recent ones is a clock jump
(or scans lost); it is counted, and estimators that scale their prediction by time guard it.
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from lidar_env.core.se2 import compose, relative

#: Returns (readings in (0, max_range)) a usable observation holds over the sensors read.
MIN_RETURNS: int = 10
#: Skipped observations in a row that make a blind stretch (flagged in ``Health``).
BLIND_STRETCH: int = 10
#: A time step this many times the median of the recent ones is a clock jump.
CLOCK_JUMP_FACTOR: float = 5.0
#: Recent time steps the median period is taken over.
CLOCK_HISTORY: int = 50


def sorted_median(ordered: Sequence[float]) -> float:
    """``np.median`` of values already sorted (not empty, no NaN): the middle one, or the mean
    of the middle two, bit for bit."""
    half = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[half])
    return (float(ordered[half - 1]) + float(ordered[half])) / 2


class SortedWindow:
    """The last ``size`` values pushed (no NaN), in arrival order and kept sorted
    (``ordered``), so that their median and extremes are read off rather than computed: a
    median of a few dozen values by numpy costs several microseconds, and estimators consult
    their windows every scan. Iterates in arrival order."""

    def __init__(self, size: int) -> None:
        self._values: deque[float] = deque(maxlen=size)
        self.ordered: list[float] = []

    def __len__(self) -> int:
        return len(self._values)

    def __iter__(self) -> Iterator[float]:
        return iter(self._values)

    def push(self, value: float) -> None:
        """Append ``value``; the oldest value falls out of a full window."""
        if len(self._values) == self._values.maxlen:
            del self.ordered[bisect.bisect_left(self.ordered, self._values[0])]
        self._values.append(value)
        bisect.insort(self.ordered, value)

    @property
    def median(self) -> float:
        """:func:`sorted_median` of the window (needs one value)."""
        return sorted_median(self.ordered)


@dataclass
class Health:
    """Counts of input faults an estimator met since ``reset`` (observations are counted
    from 0, the first one).

    Attributes:
        skipped_scans: observations it could not use (too few returns, or every sensor it
            reads frozen); the constant-velocity prediction carried the pose.
        frozen_scans: sensor scans that repeated that sensor's previous scan exactly while
            another sensor's changed (read as no return) or the estimate moved.
        clock_jumps: time steps over ``CLOCK_JUMP_FACTOR`` x the median period (a clock jump,
            or scans lost).
        blind_stretches: runs of at least ``BLIND_STRETCH`` skipped observations in a row.
        lost_scans: observations after which the estimator lost its place: no placement on
            its map explained enough of the scan (after a long blind stretch, the car facing
            what the map never saw), so the motion model's pose was kept.
        skipped: the indices of the skipped observations.
        stretches: ``(first, last)`` observation indices of each blind stretch.
        jumps: the observation indices at which the clock jumped.
        lost: the indices of the observations counted in ``lost_scans``.
    """

    skipped_scans: int = 0
    frozen_scans: int = 0
    clock_jumps: int = 0
    blind_stretches: int = 0
    skipped: list[int] = field(default_factory=list)
    stretches: list[tuple[int, int]] = field(default_factory=list)
    jumps: list[int] = field(default_factory=list)
    lost_scans: int = 0
    lost: list[int] = field(default_factory=list)

    def note_lost(self, index: int) -> None:
        """Count observation ``index`` as one where the estimator lost its place (it kept
        the motion model's pose)."""
        self.lost_scans += 1
        self.lost.append(index)

    def note_unusable(self, index: int) -> None:
        """Count observation ``index`` as skipped where the estimator found it unusable
        itself (a match no point backs); the prediction carried the pose."""
        self.skipped_scans += 1
        self.skipped.append(index)

    @property
    def ok(self) -> bool:
        """No fault met."""
        return not (self.skipped_scans or self.frozen_scans or self.clock_jumps)

    def counts(self) -> dict[str, int]:
        """The four counts by name (for tables and JSON)."""
        return {"skipped_scans": self.skipped_scans, "frozen_scans": self.frozen_scans,
                "clock_jumps": self.clock_jumps, "blind_stretches": self.blind_stretches}


class ScanScreen:
    """Checks each observation before an estimator takes it and keeps its :class:`Health`.

    Args:
        max_ranges: each sensor's max range [m], in setup order.
        used: the indices of the sensors the estimator reads.
        min_returns: returns a usable observation holds over them (:data:`MIN_RETURNS`).
    """

    def __init__(self, max_ranges: Sequence[float], used: Sequence[int],
                 min_returns: int = MIN_RETURNS) -> None:
        self.max_ranges = list(max_ranges)
        self.used = list(used)
        self.min_returns = min_returns
        self.health = Health()
        self._previous: list[NDArray[np.float64] | None] = [None] * len(self.max_ranges)
        self._steps = SortedWindow(CLOCK_HISTORY)
        self._run = 0  # skipped observations in a row
        #: whether the last observation screened had every sensor frozen
        self.all_frozen = False

    def watch_clock(self, index: int, dt: float) -> bool:
        """Take the (finite) time step ``dt`` [s] before observation ``index``; whether it is a
        jump."""
        jump = (len(self._steps) >= 3 and dt > CLOCK_JUMP_FACTOR * self._steps.ordered[0]
                and dt > CLOCK_JUMP_FACTOR * self._steps.median)
        if jump:
            self.health.clock_jumps += 1
            self.health.jumps.append(index)
        else:
            self._steps.push(dt)
        return jump

    def screen(self, scans: list[NDArray[np.float64]],
               moving: bool) -> tuple[list[NDArray[np.float64]], bool]:
        """The scans (in setup order) with frozen ones read as "no return", and whether the
        observation is usable; ``moving``: the estimate's last step moved."""
        # a scan with no return repeating is blank, not frozen
        repeated = [previous is not None and np.array_equal(previous, scan)
                    and bool(np.any((scan > 0) & (scan < limit)))
                    for previous, scan, limit in zip(self._previous, scans, self.max_ranges,
                                                     strict=True)]
        self._previous = list(scans)
        others_changed = not all(repeated)
        self.all_frozen = not others_changed and moving
        screened = []
        for k, scan in enumerate(scans):
            if repeated[k] and (others_changed or moving):
                self.health.frozen_scans += 1
                scan = np.zeros_like(scan)  # below any min_range: says nothing, clears nothing
            screened.append(scan)
        returns = sum(int(np.count_nonzero((screened[k] > 0) & (screened[k] < self.max_ranges[k])))
                      for k in self.used)
        return screened, returns >= self.min_returns

    def skip(self, index: int) -> None:
        """Record observation ``index`` as skipped."""
        self.health.skipped_scans += 1
        self.health.skipped.append(index)
        self._run += 1
        if self._run == BLIND_STRETCH:
            self.health.blind_stretches += 1
            self.health.stretches.append((index - BLIND_STRETCH + 1, index))
        elif self._run > BLIND_STRETCH:
            first, _ = self.health.stretches[-1]
            self.health.stretches[-1] = (first, index)

    def used_one(self) -> int:
        """Record an observation as used; the number skipped just before it."""
        run, self._run = self._run, 0
        return run


def evident_time_step(distance: float, speed: float, dt: float, typical: float) -> float:
    """The time step [s] the scans bear out, for a velocity model to divide by: ``dt``
    unless it is a clock jump (over ``CLOCK_JUMP_FACTOR`` x the ``typical`` step); then the
    time the car needed for the ``distance`` [m] the scans show at the ``speed`` [m/s] it
    held, within [``typical``, ``dt``] (``typical`` when it stood still). A clock that jumps
    3 s while the scans run on otherwise turns one scan's motion into a velocity 30x too
    slow, and the next guesses lag by metres."""
    if not (typical > 0 and dt > CLOCK_JUMP_FACTOR * typical):
        return dt
    if not speed > 1e-3:
        return typical
    return float(np.clip(distance / speed, typical, dt))


def evident_turn_time(turn: float, rate: float, elapsed: float, least: float) -> float:
    """The time (in [s] or scan intervals, as ``elapsed``) a ``turn`` [rad] over a clock jump
    took at the turn ``rate`` held before it [rad per unit], within [``least``, ``elapsed``]:
    all of ``elapsed`` where that rate turns less in it. A gap's translation says nothing of
    its turn (a robot turning on the spot creeps a few centimetres), and a turn rate
    overestimated by the time its translation bears out starts the next matches turned out
    of their basin; one underestimated only starts them unturned."""
    held = abs(rate)
    if held * elapsed <= abs(turn):
        return elapsed
    return min(max(abs(turn) / held, least), elapsed)


def intervals_since_used(skipped_before: int, clock_jumped: bool, interval: float,
                         typical: float) -> float:
    """How many scan intervals the car may have moved since the last scan an estimator used:
    one plus the scans skipped since (each one interval), or, on a clock jump (scans lost on
    the way, or only the stamp jumped), the ``interval`` [s] over the ``typical`` one (0 when
    none is known yet)."""
    intervals = 1.0 + skipped_before
    if clock_jumped and typical > 0:
        intervals = max(intervals, interval / typical)
    return intervals


def moved(poses: Sequence[NDArray[np.float64]]) -> bool:
    """Whether the last of ``poses`` moved from the one before (over 1 mm or 1 mrad)."""
    if len(poses) < 2:
        return False
    step = relative(poses[-2], poses[-1])
    return bool(np.hypot(step[0], step[1]) > 1e-3 or abs(step[2]) > 1e-3)


class Observations:
    """Where each observation's pose comes from: a used one is a row of the estimator's own
    poses, a skipped one a predicted offset from the used pose before it (so a revised used
    pose carries its skipped ones along)."""

    def __init__(self) -> None:
        self.rows: list[tuple[int, NDArray[np.float64] | None, float]] = []
        self._used: deque[int] = deque(maxlen=2)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def last_time(self) -> float | None:
        return self.rows[-1][2] if self.rows else None

    @property
    def times(self) -> NDArray[np.float64]:
        return np.array([time for _, _, time in self.rows], dtype=np.float64)

    def use(self, pose_index: int, t: float) -> None:
        """Record an observation at ``t`` [s] as used, its pose row ``pose_index``."""
        self._used.append(len(self.rows))
        self.rows.append((pose_index, None, float(t)))

    def skip(self, poses: Sequence[NDArray[np.float64]], t: float,
             hold: bool = False) -> NDArray[np.float64]:
        """Record an observation at ``t`` [s] as skipped; its predicted pose. The prediction:
        the last used increment per observation, once for each observation since, scaled by
        its time step over the median of the last :data:`CLOCK_HISTORY` (at most 2: a clock
        jump is not extrapolated; near 0: a scan republished at once); with ``hold``, the
        last pose (a frozen sensor cannot tell a car driving on from one that stopped dead:
        the scans that change again say which)."""
        index, before, last = self.rows[-1]
        offset = np.zeros(3)
        if hold:
            offset = offset if before is None else before
        elif len(self._used) == 2:
            step = relative(poses[-2], poses[-1]) / (self._used[1] - self._used[0])
            times = [time for _, _, time in self.rows[-CLOCK_HISTORY:]]
            median = float(np.median(np.diff(times))) if len(times) > 1 else t - last
            offset = step * float(np.clip((t - last) / median, 0.0, 2.0))
            offset = offset if before is None else compose(before, offset)
        self.rows.append((len(poses) - 1, offset, float(t)))
        return compose(poses[-1], offset)

    def latest(self, poses: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
        """The latest observation's pose (3,)."""
        index, offset, _ = self.rows[-1]
        return poses[index].copy() if offset is None else compose(poses[index], offset)

    def all_poses(self, used: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 3)`` poses of every observation from ``used`` (one per used observation).
        A skipped observation between two used ones lies on the way between them, by its
        share of the observations between (the motion the scans showed once they came back,
        spread over the stretch rather than one step); after the last used one, at its
        prediction."""
        if len(used) == len(self.rows) or not self.rows:  # none skipped, or fed otherwise
            return used
        poses = np.empty((len(self.rows), 3))
        after: list[int | None] = [None] * len(self.rows)  # the next used observation
        for n in range(len(self.rows) - 2, -1, -1):
            after[n] = n + 1 if self.rows[n + 1][1] is None else after[n + 1]
        before = 0  # the used observation before
        for n, (k, offset, _) in enumerate(self.rows):
            if offset is None:
                poses[n], before = used[k], n
            elif after[n] is None:
                poses[n] = compose(used[k], offset)
            else:
                share = (n - before) / (after[n] - before)
                poses[n] = compose(used[k], share * relative(used[k], used[k + 1]))
        return poses
