"""``pc_fusion``'s recovery after scans lost or skipped: which guess's match is kept, and when
the search on the keyframe runs."""

from __future__ import annotations

import numpy as np

from estimators.odometry.fusion_recovery import POOR_SCORE, recovered


def solver(scores: dict[float, float]):
    """A stand-in for the matches from a guess: the motion is the guess, its score looked up
    by the guess's x [m] (0 for any other)."""
    def solve(guess: list[float]):
        return np.array(guess, dtype=np.float64), None, scores.get(round(guess[0], 6), 0.0)
    return solve


def same(motion: np.ndarray) -> list[float]:
    return motion.tolist()


def test_the_search_runs_only_where_neither_guess_fits() -> None:
    searched = []

    def search() -> np.ndarray:
        searched.append(True)
        return np.array([3.0, 0.0, 0.0])

    fitting = solver({1.0: 0.9, 2.0: 0.8, 3.0: 0.95})
    found = recovered(fitting, fitting([1.0, 0.0, 0.0]), [2.0, 0.0, 0.0], True, same, search)
    assert not searched and found[0][0] == 1.0
    poor = solver({1.0: POOR_SCORE - 0.1, 2.0: 0.2, 3.0: 0.9})
    found = recovered(poor, poor([1.0, 0.0, 0.0]), [2.0, 0.0, 0.0], True, same, search)
    assert searched and found[0][0] == 3.0


def test_a_search_that_explains_no_more_is_not_taken() -> None:
    poor = solver({1.0: 0.3, 2.0: 0.2, 3.0: 0.31})
    found = recovered(poor, poor([1.0, 0.0, 0.0]), [2.0, 0.0, 0.0], False, same,
                      lambda: np.array([3.0, 0.0, 0.0]))
    assert found[0][0] == 1.0
    nothing = recovered(poor, poor([1.0, 0.0, 0.0]), [2.0, 0.0, 0.0], False, same,
                        lambda: None)
    assert nothing[0][0] == 1.0
