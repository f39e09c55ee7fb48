"""The scan clock an estimator is fed: ``update(observation, t)`` checks ``t`` here.

A time must be a real number (not a bool, a string or None), finite, within
:data:`MAX_TIME` [s] of zero (so differences and products of times stay finite), and strictly
later than the previous observation's: a repeated or backward stamp is a fault of the
recording, and an estimator that took it would divide by a zero or negative interval.
"""

from __future__ import annotations

import math
import numbers

from lidar_env.core.errors import EstimatorInputError

#: [s] largest accepted magnitude of a time stamp: about 3 x 10^10 years, far past any
#: clock (Unix or robot), yet small enough that any product with a speed stays finite.
MAX_TIME: float = 1e18


def check_time(t: object, previous: float | None) -> float:
    """``t`` [s] as a float, after checking it is a finite real number later than ``previous``
    (the last observation's time, None for the first).

    Raises:
        EstimatorInputError: naming ``t`` and, for a clock that does not run forward, the
            previous time.
    """
    if isinstance(t, bool) or not isinstance(t, numbers.Real):
        raise EstimatorInputError(
            f"t: expected a real number of seconds, got {type(t).__name__} {t!r}"
        )
    value = float(t)
    if not math.isfinite(value) or abs(value) > MAX_TIME:
        raise EstimatorInputError(
            f"t: expected a finite time within +-{MAX_TIME:g} s, got {value!r}"
        )
    if previous is not None and not value > previous:
        raise EstimatorInputError(
            f"t: expected a time later than the previous observation's {previous!r} s, "
            f"got {value!r} (the clock must run strictly forward)"
        )
    return value
