"""Where ``pc_fusion`` looks for the car after scans it could not use or never got: blind
scans skipped, or a clock jump (scans lost on the way, or only the stamp jumped). Times [s].

Past the prediction horizon a constant-velocity guess over the whole gap is no better known
than one over a single interval: the car may have kept its speed (scans lost or blind while it
drove on) or the stamp alone may have jumped (scans kept coming). Both are matched and the
one whose matches explain more of the scans is kept (the longer guess turns the car by one
interval's turn only: over seconds the extrapolated turn is the least known part of it, and
the correlation measures the turn); where the scans cannot tell them apart
(a corridor's axis, which the prior decides), the longer guess wins only after skipped scans,
which prove the time passed.
"""

from __future__ import annotations

from collections.abc import Sequence

#: Two candidate motions whose matches explain shares of the scans within this of each other
#: are equally good fits (``rotation_pc.QUALITY_TOLERANCE``'s reading of a share).
SCORE_TOLERANCE = 0.02


def intervals_since_used(skipped_before: int, clock_jumped: bool, interval: float,
                         typical: Sequence[float]) -> float:
    """How many scan intervals the car may have moved since the last scan used: one plus the
    scans skipped since (each one interval), or, on a clock jump, the ``interval`` [s] over
    the ``typical`` one (``typical``: the median step, or empty when none is known)."""
    intervals = 1.0 + skipped_before
    if clock_jumped and typical and typical[0] > 0:
        intervals = max(intervals, interval / typical[0])
    return intervals
