"""The spread of near-best loop poses: wide along what only a post fixes, narrow where walls
cross; it weakens a loop edge only along that direction."""

from __future__ import annotations

import numpy as np

from estimators.matching.scan_matching import LikelihoodField
from estimators.slam.loop_closure import LoopClosureParams, PlaceMap, verify_loop
from estimators.slam.match_uncertainty import score_spread


def wall_and_post(rng: np.random.Generator) -> np.ndarray:
    """A 10 m wall along x at y = 2 m and the near side of a 0.15 m post at (1, -1), with
    1 cm range noise."""
    wall = np.column_stack([np.arange(-5.0, 5.0, 0.05), np.full(200, 2.0)])
    angles = np.linspace(np.pi / 6, 5 * np.pi / 6, 16)
    post = np.array([1.0, -1.0]) - 0.15 * np.column_stack([np.cos(angles), np.sin(angles)])
    return np.concatenate([wall, post]) + rng.normal(0.0, 0.01, (216, 2))


def corner(rng: np.random.Generator) -> np.ndarray:
    """Two 5 m walls meeting at (3, 2), 1 cm range noise."""
    along = np.arange(-2.0, 3.0, 0.05)
    walls = [
        np.column_stack([along, np.full(len(along), 2.0)]),
        np.column_stack([np.full(len(along), 3.0), along]),
    ]
    return np.concatenate(walls) + rng.normal(0.0, 0.01, (2 * len(along), 2))


def test_spread_is_wide_along_what_only_a_post_fixes() -> None:
    rng = np.random.default_rng(0)
    params = LoopClosureParams()
    spread = {}
    for name, scene in (("post", wall_and_post), ("corner", corner)):
        field = LikelihoodField(scene(rng), params.resolution, params.sigma)
        spread[name] = score_spread(
            field,
            scene(rng),
            np.zeros(3),
            params.ambiguity_distance,
            params.spread_turn,
            params.angular_step,
            params.ambiguity_ratio,
            params.spread_sigmas,
        )
    assert np.sqrt(spread["post"][0, 0]) > 0.1  # along the wall: the post's few points
    assert np.sqrt(spread["post"][1, 1]) < 0.05  # across it: the whole wall
    assert np.sqrt(np.diag(spread["corner"])[:2]).max() < 0.05


def test_spread_turns_into_the_match_frame() -> None:
    rng = np.random.default_rng(1)
    params = LoopClosureParams()
    points = wall_and_post(rng)
    field = LikelihoodField(points, params.resolution, params.sigma)
    turned = np.array([0.0, 0.0, np.pi / 2])  # the query's x axis along the place's y
    query = points @ np.array([[0.0, 1.0], [-1.0, 0.0]]).T  # R(-90 deg): placed back by turned
    spread = score_spread(
        field,
        query,
        turned,
        params.ambiguity_distance,
        params.spread_turn,
        params.angular_step,
        params.ambiguity_ratio,
        params.spread_sigmas,
    )
    assert np.sqrt(spread[1, 1]) > 0.1 > 0.05 > np.sqrt(spread[0, 0])


def test_loop_edge_is_weak_only_along_what_the_post_fixes() -> None:
    rng = np.random.default_rng(2)
    place = PlaceMap(wall_and_post(rng), LoopClosureParams())
    result = verify_loop(place, wall_and_post(rng), np.zeros(3), 0.3)
    assert result.accepted, result.reason
    hessian_sd = np.sqrt(np.diag(np.linalg.inv(result.information)))
    edge_sd = np.sqrt(np.diag(np.linalg.inv(result.edge_information)))
    assert hessian_sd[0] < 0.1 < 1.0 < edge_sd[0]  # the Hessian trusts the post
    assert edge_sd[1] < 0.1  # the wall holds across
