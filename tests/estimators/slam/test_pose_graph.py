"""Pose-graph optimisation: exact recovery, analytic Jacobian, robust kernels, public optima."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.paths import SHARED_DATA
from estimators.slam.g2o import read_g2o
from estimators.slam.pose_graph import DisconnectedGraphError, PoseGraph
from estimators.slam.solver import _WhitenedProblem, optimize
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import compose, relative, wrap_angle

DATA = SHARED_DATA / "g2o"
INFO = np.diag([100.0, 100.0, 400.0])


def circle_graph(rng: np.random.Generator, n: int = 40, noise: float = 0.0) -> tuple[PoseGraph,
                                                                                    np.ndarray]:
    """Poses around a 5 m circle, odometry i->i+1 and loop edges back to the first poses;
    the nodes start at the dead-reckoned poses of noisy odometry."""
    angles = 2 * np.pi * np.arange(n) / n
    truth = np.stack([5 * np.cos(angles), 5 * np.sin(angles), wrap_angle(angles + np.pi / 2)], 1)
    graph = PoseGraph()
    odometry = relative(truth[:-1], truth[1:]) + noise * rng.normal(size=(n - 1, 3))
    pose = truth[0]
    graph.add_node(pose)
    for k in range(n - 1):
        pose = compose(pose, odometry[k])
        graph.add_node(pose)
        graph.add_edge(k, k + 1, odometry[k], INFO)
    for k in range(3):
        graph.add_edge(n - 1 - k, k, relative(truth[n - 1 - k], truth[k]), INFO, is_loop=True)
    return graph, truth


def test_single_edge_residual_and_cost_by_hand() -> None:
    graph = PoseGraph()
    graph.add_node([0.0, 0.0, np.pi / 2])
    graph.add_node([0.0, 2.0, np.pi / 2])
    # node 1 is 2 m ahead of node 0; the edge claims 1.5 m ahead and 0.1 rad turned
    graph.add_edge(0, 1, [1.5, 0.0, 0.1], np.diag([1.0, 2.0, 3.0]))
    # e = z^-1 ⊕ (2, 0, 0): rotate (0.5, 0) by -0.1 rad, heading -0.1
    e = np.array([0.5 * np.cos(0.1), -0.5 * np.sin(0.1), -0.1])
    assert graph.cost() == pytest.approx(0.5 * (e[0] ** 2 + 2 * e[1] ** 2 + 3 * e[2] ** 2))
    np.testing.assert_allclose(graph.chi2(), [e[0] ** 2 + 2 * e[1] ** 2 + 3 * e[2] ** 2])


def test_analytic_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(1)
    graph, _ = circle_graph(rng, n=12, noise=0.05)
    graph.add_edge(2, 9, [1.0, -2.0, 0.4], np.array([[5.0, 1.0, 0.2], [1.0, 4.0, 0.3],
                                                     [0.2, 0.3, 9.0]]))
    problem = _WhitenedProblem(graph, fixed=3)
    x = graph.poses[problem.free].ravel() + rng.normal(scale=0.1, size=3 * (graph.n_nodes - 1))
    analytic = problem.jacobian(x).toarray()
    numeric = np.empty_like(analytic)
    for k in range(len(x)):
        step = np.zeros_like(x)
        step[k] = 1e-6
        numeric[:, k] = (problem.residuals(x + step) - problem.residuals(x - step)) / 2e-6
    np.testing.assert_allclose(analytic, numeric, atol=1e-6)


@pytest.mark.parametrize("solver", ["lm", "scipy"])
def test_consistent_measurements_recover_the_truth(solver: str) -> None:
    graph, truth = circle_graph(np.random.default_rng(2), noise=0.0)
    # corrupt the initial guess: dead reckoning was exact, so bend it
    start = truth.copy()
    start[1:] += np.random.default_rng(3).normal(scale=[0.3, 0.3, 0.05], size=(len(truth) - 1, 3))
    graph.poses = start
    result = optimize(graph, solver=solver, max_iterations=200)
    assert result.final_cost < 1e-8 < result.initial_cost
    np.testing.assert_allclose(result.poses[:, :2], truth[:, :2], atol=1e-5)
    np.testing.assert_allclose(wrap_angle(result.poses[:, 2] - truth[:, 2]), 0, atol=1e-6)
    np.testing.assert_array_equal(result.poses[0], truth[0])  # the first pose stays fixed
    np.testing.assert_array_equal(graph.poses, start)  # the graph itself is not changed


def test_loop_edges_reduce_the_drift_of_noisy_odometry() -> None:
    graph, truth = circle_graph(np.random.default_rng(4), noise=0.02)
    drift = np.linalg.norm(graph.poses[-1, :2] - truth[-1, :2])
    result = optimize(graph)
    assert result.converged
    assert np.linalg.norm(result.poses[-1, :2] - truth[-1, :2]) < 0.2 * drift


@pytest.mark.parametrize(("loss", "bound"), [("huber", 0.5), ("cauchy", 0.05)])
def test_robust_loss_limits_the_damage_of_a_false_loop(loss: str, bound: float) -> None:
    """Huber's bounded pull still bends the loop; Cauchy's vanishing pull all but ignores it."""
    graph, truth = circle_graph(np.random.default_rng(5), noise=0.005)
    graph.add_edge(10, 30, [0.5, 0.0, 0.0], INFO, is_loop=True)  # the places are 10 m apart
    plain = optimize(graph)
    robust = optimize(graph, loss=loss, loss_scale=3.0)
    plain_error = np.abs(plain.poses[:, :2] - truth[:, :2]).max()
    robust_error = np.abs(robust.poses[:, :2] - truth[:, :2]).max()
    assert plain_error > 1.0
    assert robust_error < bound * plain_error
    assert robust.chi2[-1] > 1e3 * np.median(robust.chi2)  # the false edge stands out


def test_disconnected_graph_is_a_clear_error() -> None:
    graph = PoseGraph()
    for k in range(4):
        graph.add_node([k, 0.0, 0.0], node_id=10 + k)
    graph.add_edge(0, 1, [1.0, 0.0, 0.0], INFO)
    graph.add_edge(2, 3, [1.0, 0.0, 0.0], INFO)
    with pytest.raises(DisconnectedGraphError, match=r"2 disconnected parts.*node id 10: 12, 13"):
        optimize(graph)


def test_bad_arguments_are_named() -> None:
    graph, _ = circle_graph(np.random.default_rng(6), n=8)
    with pytest.raises(ValueError, match=r"unknown loss 'l1': expected one of linear, huber"):
        optimize(graph, loss="l1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"unknown solver 'gn': expected one of lm, scipy"):
        optimize(graph, solver="gn")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="positive-definite"):
        graph.add_edge(0, 2, [0, 0, 0], np.diag([1.0, -1.0, 1.0]))
    with pytest.raises(EstimatorInputError, match=r"expected a node index in \[0, 8\)"):
        graph.add_edge(0, 8, [0, 0, 0], INFO)
    with pytest.raises(ValueError, match="two different nodes"):
        graph.add_edge(1, 1, [0, 0, 0], INFO)
    with pytest.raises(ValueError, match="empty"):
        optimize(PoseGraph())


@pytest.mark.realdata
@pytest.mark.skipif(not DATA.is_dir(), reason=f"g2o benchmark graphs absent: expected {DATA}")
@pytest.mark.parametrize(("name", "gtsam_optimum"), [("intel", 22.5021), ("MIT", 385.119)])
def test_public_graphs_reach_gtsam_optimum_within_0_1_percent(name: str,
                                                              gtsam_optimum: float) -> None:
    result = optimize(read_g2o(DATA / f"{name}.g2o"))
    assert result.converged
    assert abs(result.final_cost - gtsam_optimum) <= 1e-3 * gtsam_optimum
