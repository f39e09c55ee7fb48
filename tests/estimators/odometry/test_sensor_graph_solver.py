"""The sensor graph's solver: the compiled iterations against the array form, and both at
``scipy.optimize.least_squares``'s optimum (the solver they replace), on random graphs with
wrong matches among the edges."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from estimators.odometry.sensor_graph import (
    SensorEdge,
    optimize_poses,
    predict_edges,
    robust_gauss_newton,
)
from lidar_env.core.se2 import compose, relative, wrap_angle


def random_graph(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, list[SensorEdge]]:
    """Start poses (N, 3), mounts (S, 3) and edges of a connected graph, 10 % of them wrong."""
    n_sensors, n_nodes = int(rng.integers(1, 4)), int(rng.integers(2, 5))
    mounts = np.column_stack([rng.normal(scale=0.3, size=(n_sensors, 2)),
                              rng.uniform(-3.0, 3.0, n_sensors)])
    truth = np.cumsum(rng.normal(scale=0.1, size=(n_nodes, 3)), axis=0)
    pairs = [(k, k + 1) for k in range(n_nodes - 1)]  # a chain keeps the graph connected
    pairs += [tuple(sorted(rng.choice(n_nodes, 2, replace=False))) for _ in range(5)]
    edges = []
    for a, b in pairs:
        i, j = (int(k) for k in rng.integers(n_sensors, size=2))
        z = relative(compose(truth[a], mounts[i]), compose(truth[b], mounts[j]))
        z = z + rng.normal(scale=[0.01, 0.01, 0.005]) + (rng.random() < 0.1) * rng.normal(0, 0.3, 3)
        edges.append(SensorEdge(int(a), i, int(b), j, z, float(rng.uniform(0.1, 1.0))))
    return truth + rng.normal(scale=0.02, size=truth.shape), mounts, edges


@pytest.mark.parametrize("seed", range(5))
def test_compiled_solver_matches_the_array_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(40):
        start, mounts, edges = random_graph(rng)
        n_fixed = int(rng.integers(1, len(start)))
        compiled = optimize_poses(start, mounts, edges, n_fixed=n_fixed)
        pure = optimize_poses(start, mounts, edges, n_fixed=n_fixed, compiled=False)
        np.testing.assert_allclose(compiled, pure, rtol=0, atol=1e-9)


def scipy_optimum(start: np.ndarray, mounts: np.ndarray, edges: list[SensorEdge]) -> np.ndarray:
    """The poses ``least_squares`` finds for the same cost, converged as far as it goes."""
    weights = np.array([[1 / 0.01, 1 / 0.01, 1 / 0.005]]) * np.sqrt([[e.confidence]
                                                                     for e in edges])
    measured = np.array([e.pose for e in edges])

    def residuals(x: np.ndarray) -> np.ndarray:
        poses = np.vstack([start[:1], start[1:] + x.reshape(-1, 3)])
        error = relative(measured, predict_edges(poses, mounts, edges))  # z⁻¹ ⊕ h
        error[:, 2] = wrap_angle(error[:, 2])
        return (error * weights).ravel()

    found = least_squares(residuals, np.zeros(3 * (len(start) - 1)), loss="cauchy",
                          f_scale=3.0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    solved = np.vstack([start[:1], start[1:] + found.x.reshape(-1, 3)])
    solved[:, 2] = wrap_angle(solved[:, 2])
    return solved


@pytest.mark.parametrize("seed", range(3))
def test_solver_reaches_the_optimum_of_scipys_least_squares(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    for _ in range(20):
        start, mounts, edges = random_graph(rng)
        np.testing.assert_allclose(optimize_poses(start, mounts, edges),
                                   scipy_optimum(start, mounts, edges), rtol=0, atol=1e-7)


def test_gauss_newton_fits_a_line_through_an_outlier() -> None:
    x = np.linspace(0.0, 1.0, 11)
    y = 2.0 * x + 1.0
    y[5] += 10.0

    def residuals(p: np.ndarray) -> np.ndarray:
        return p[0] * x + p[1] - y

    def jacobian(p: np.ndarray) -> np.ndarray:
        return np.column_stack([x, np.ones_like(x)])

    fitted = robust_gauss_newton(residuals, jacobian, np.zeros(2), 0.1)
    np.testing.assert_allclose(fitted, [2.0, 1.0], atol=1e-3)
