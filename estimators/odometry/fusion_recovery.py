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

Either guess may be a metre or more from the car after a turn, and the correlation that seeds
the matches is ambiguous across such a gap (it may land a metre off too); a few ICP
iterations from there stop short of the fit. So the kept motion is matched again from itself
(:func:`recovered`) while that explains more of the scans: each round starts closer.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: A car motion (3,) from the latest keyframe, its edges and their mean share explained.
Solution = tuple[NDArray[np.float64], Any, float]

#: Two candidate motions whose matches explain shares of the scans within this of each other
#: are equally good fits (``rotation_pc.QUALITY_TOLERANCE``'s reading of a share).
SCORE_TOLERANCE = 0.02


#: Most rounds of matching a recovered motion again from itself (each converges further;
#: two or three reach the fit).
POLISH_ROUNDS = 5


def recovered(solve: Callable[[list[float]], Solution], found: Solution, longer: list[float],
              skipped: bool, step_to: Callable[[NDArray[np.float64]], list[float]]) -> Solution:
    """The motion found after scans lost or skipped: ``found`` (matched from the one-interval
    guess) or the match from the ``longer`` guess (car frame, from the last pose used) where
    it explains more of the scans, or as much after ``skipped`` scans; then matched again
    from itself (``step_to``: a motion from the keyframe as a guess from the last pose used)
    while that explains more. ``solve``: the matches from a guess."""
    other = solve(longer)
    if other[2] > found[2] + SCORE_TOLERANCE or (
            skipped and other[2] >= found[2] - SCORE_TOLERANCE):
        found = other
    for _ in range(POLISH_ROUNDS):
        again = solve(step_to(found[0]))
        if not again[2] > found[2]:
            break
        found = again
    return found
