"""``pc_fusion``'s recovery after scans lost or skipped: which guess's match is kept, and when
the search on the keyframe runs."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from estimators.health import BLIND_STRETCH
from estimators.matching.scan_recovery import UNPLACED_BELOW
from estimators.odometry.fusion_recovery import POOR_SCORE, BlindScans, recovered
from lidar_env.core.se2 import compose
from tests.estimators.room_scans import scan_points


def solver(scores: dict[float, float]):
    """A stand-in for the matches from a guess: the motion is the guess, its score looked up
    by the guess's x [m] (0 for any other)."""
    def solve(guess: list[float]):
        return np.array(guess, dtype=np.float64), None, scores.get(round(guess[0], 6), 0.0)
    return solve


#: The one-interval guess and the longer one of the stand-in solvers (the motion is the guess).
ONE, LONGER = [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]


def same(motion: np.ndarray) -> list[float]:
    return motion.tolist()


def blind(search, within=lambda found: True) -> SimpleNamespace:
    """Blind scans whose search finds what ``search`` returns (None: nothing), that see
    through nothing anywhere and whose guess reaches the motions ``within`` says."""
    namespace = SimpleNamespace(
        searched=lambda: [] if (found := search()) is None else [found],
        seen_through=lambda motion: 0, intervals=2.0, share_error=lambda share: 0.02,
        within_reach=within)
    namespace.likelier = lambda other, found: BlindScans.likelier(namespace, other, found)
    return namespace


def test_the_search_runs_only_where_neither_guess_fits() -> None:
    searched = []

    def search() -> np.ndarray:
        searched.append(True)
        return np.array([3.0, 0.0, 0.0])

    fitting = solver({1.0: 0.9, 2.0: 0.8, 3.0: 0.95})
    found = recovered(fitting, fitting(ONE), ONE, LONGER, 2.0, True, same, blind(search))[0]
    assert not searched and found[0][0] == 1.0
    poor = solver({1.0: POOR_SCORE - 0.1, 2.0: 0.2, 3.0: 0.9})
    found = recovered(poor, poor(ONE), ONE, LONGER, 2.0, True, same, blind(search))[0]
    assert searched and found[0][0] == 3.0


def test_a_match_out_of_the_guess_reach_gives_way_to_one_within_it() -> None:
    """ACES after a turn on the spot while blind: a corridor seen turned round fits the new
    scans as well 2 m down it, farther than the stopped robot can have driven; the search's
    match within reach is kept, and searched for although the far one explains enough."""
    scores = solver({1.0: 0.6, 2.0: 0.2, 3.0: 0.55})
    within = blind(lambda: np.array([3.0, 0.0, 0.0]), lambda found: found[0][0] != 1.0)
    found, _ = recovered(scores, scores(ONE), ONE, LONGER, 2.0, False, same, within)
    assert found[0][0] == 3.0
    found, _ = recovered(scores, scores(ONE), ONE, LONGER, 2.0, False, same,
                         blind(lambda: np.array([3.0, 0.0, 0.0])))
    assert found[0][0] == 1.0


def test_a_search_that_explains_no_more_is_not_taken() -> None:
    poor = solver({1.0: 0.3, 2.0: 0.2, 3.0: 0.31})
    found, _ = recovered(poor, poor(ONE), ONE, LONGER, 2.0, False, same,
                         blind(lambda: np.array([3.0, 0.0, 0.0])))
    assert found[0][0] == 1.0
    nothing, _ = recovered(poor, poor(ONE), ONE, LONGER, 2.0, False, same, blind(lambda: None))
    assert nothing[0][0] == 1.0


def test_the_search_finds_the_car_on_the_keyframe_and_needs_enough_points() -> None:
    rng = np.random.default_rng(0)
    start, motion = np.array([4.0, 5.0, 0.3]), np.array([0.8, -0.3, np.radians(50.0)])
    keyframe = [SimpleNamespace(points=scan_points(start, rng))]
    scan = [SimpleNamespace(points=scan_points(compose(start, motion), rng))]
    mounts = [np.zeros(3)]
    # guessed as no motion at all: 0.85 m and 50 degrees off, past any ICP basin
    found = BlindScans.of(mounts, keyframe, scan, np.zeros(3), 10.0, 1.0).searched()[0]
    assert np.hypot(*(found[:2] - motion[:2])) < 0.1 and abs(found[2] - motion[2]) < 0.05
    few = [SimpleNamespace(points=scan[0].points[:20])]  # under MIN_SEARCH_POINTS
    assert BlindScans.of(mounts, keyframe, few, np.zeros(3), 10.0, 1.0).searched() == []


def test_after_blind_scans_the_longer_guess_wins_within_the_shares_standard_error() -> None:
    """ACES down a corridor after 3 s blind: the match where the car stopped explains 82 % of
    its 180 returns, the one where it drove on 80 % (the keyframe saw more of the corridor
    near itself); within the share's standard error (3 %) the scans cannot tell, and the
    skipped scans prove the time passed."""
    scores = solver({1.0: 0.822, 2.0: 0.800})
    for points, kept in [(180, 2.0), (20_000, 1.0)]:
        scans = BlindScans(np.zeros((180, 2)), np.zeros((points, 2)), np.array(LONGER), 20.0,
                           3.0)
        found, _ = recovered(scores, scores(ONE), ONE, LONGER, 2.0, True, same, scans)
        assert found[0][0] == kept


def corridor_solver(crossed: float):
    """A stand-in for the matches down a corridor along x: the scans pin y at ``crossed``
    [m] and leave x where the guess put it; every match explains 80 % of the scans."""
    def solve(guess: list[float]):
        return np.array([guess[0], crossed, 0.0]), None, 0.8
    return solve


def test_after_lost_scans_the_guess_the_pinned_directions_bear_out_is_kept() -> None:
    """A car weaving down a corridor, 0.1 m along and 0.065 m across it per interval, then
    11 intervals between two scans: lost scans (it crossed 0.72 m) or a stamp that jumped
    alone (it crossed 0.065 m). Both guesses' matches explain the scans alike; the one whose
    guess predicted the crossing keeps its place along the axis."""
    one, longer = [0.1, 0.065, 0.0], [1.1, 0.715, 0.0]
    for crossed, kept in [(0.72, 1.1), (0.065, 0.1)]:
        solve = corridor_solver(crossed)
        found, lost = recovered(solve, solve(one), one, longer, 11.0, False, same)
        assert found[0][0] == kept and not lost


def test_a_blind_stretch_that_leaves_the_car_facing_the_unseen_is_flagged() -> None:
    """After a blind stretch, the best match explains under POOR_SCORE of the scans and they
    see through keyframe points there: the car is lost (the match is kept, flagged)."""
    def scans(seen: int) -> SimpleNamespace:
        namespace = SimpleNamespace(
            searched=lambda: [], within_reach=lambda found: True,
            seen_through=lambda motion: seen, intervals=101.0, share_error=lambda share: 0.02,
            off_seen_through=lambda match_from, found: (found, seen))
        namespace.lost = lambda found: BlindScans.lost(namespace, found)
        return namespace

    poor = solver({1.0: 0.43, 2.0: 0.1})
    for seen, flagged in [(40, True), (0, False)]:
        found, lost = recovered(poor, poor(ONE), ONE, LONGER, 101.0, True, same, scans(seen))
        assert found[0][0] == 1.0 and lost == flagged


def test_after_a_blind_stretch_a_match_explaining_under_a_quarter_leaves_the_car_unplaced(
) -> None:
    # Intel from scan 3000 after 100 blind scans: the kept match explained 15.6 % 5.5 m off
    stretch = SimpleNamespace(intervals=BLIND_STRETCH + 1.0)
    assert BlindScans.unplaced(stretch, UNPLACED_BELOW - 0.01)
    assert not BlindScans.unplaced(stretch, UNPLACED_BELOW)
    assert not BlindScans.unplaced(SimpleNamespace(intervals=2.0), 0.1)  # a short gap
