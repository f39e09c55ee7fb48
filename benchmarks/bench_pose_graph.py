"""Pose-graph optimisation on the public 2D benchmark graphs against GTSAM's optima.

For each graph in ``../shared/data/g2o/``: our final cost ``0.5 * sum r^T Omega r`` (GTSAM's
graph error, same residual convention), its relative difference to the optimum GTSAM 4.3
Levenberg–Marquardt reaches (``SOURCE.md`` there), and the wall time. The same run also times
``scipy.optimize.least_squares`` (trust-region reflective + LSMR) with the same analytic sparse
Jacobian and with finite differences over the Jacobian's sparsity pattern, as references.

    python benchmarks/bench_pose_graph.py [--skip-scipy]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from scipy.optimize import least_squares

from estimators.paths import SHARED_DATA
from estimators.slam.g2o import read_g2o
from estimators.slam.pose_graph import PoseGraph
from estimators.slam.solver import _WhitenedProblem, optimize

DATA = SHARED_DATA / "g2o"
#: file -> (GTSAM 4.3 LM optimum, GTSAM time [s] where SOURCE.md / the issue gives one)
GTSAM = {
    "intel": (22.5021, 0.05),
    "CSAIL": (20.2754, None),
    "MIT": (385.119, None),
    "manhattan": (1774.52, 0.19),
}


def finite_difference_scipy(graph: PoseGraph, max_nfev: int) -> tuple[float, float]:
    """least_squares with 2-point finite differences over the known sparsity pattern."""
    problem = _WhitenedProblem(graph, 0)
    x0 = graph.poses[1:].ravel()
    pattern = problem.jacobian(x0) != 0
    start = time.perf_counter()
    result = least_squares(problem.residuals, x0, jac_sparsity=pattern, method="trf",
                           tr_solver="lsmr", max_nfev=max_nfev, ftol=1e-10, xtol=1e-10)
    seconds = time.perf_counter() - start
    return graph.cost(problem.poses_of(result.x)), seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-scipy", action="store_true", help="only time our LM solver")
    parser.add_argument("--scipy-max-nfev", type=int, default=200)
    args = parser.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"benchmark graphs not found: expected {DATA}")
    machine = platform.processor() or platform.machine()
    print(f"machine: {machine}, python {platform.python_version()}")
    header = (f"{'graph':10s} {'nodes':>6s} {'edges':>6s} {'GTSAM opt':>10s} {'ours (lm)':>11s} "
              f"{'rel diff':>9s} {'t lm [s]':>8s} {'t GTSAM':>7s} {'ratio':>6s}")
    if not args.skip_scipy:
        header += f" {'scipy-analytic cost/t':>24s} {'scipy-fd cost/t':>22s}"
    print(header)
    for name, (optimum, gtsam_seconds) in GTSAM.items():
        graph = read_g2o(DATA / f"{name}.g2o")
        optimize(graph, max_iterations=1)  # warm imports and caches outside the timing
        result = optimize(graph)
        rel = (result.final_cost - optimum) / optimum
        ratio = f"{result.seconds / gtsam_seconds:6.2f}" if gtsam_seconds else f"{'-':>6s}"
        gtsam_t = f"{gtsam_seconds:7.2f}" if gtsam_seconds else f"{'-':>7s}"
        line = (f"{name:10s} {graph.n_nodes:6d} {graph.n_edges:6d} {optimum:10.4f} "
                f"{result.final_cost:11.4f} {rel:+9.2e} {result.seconds:8.3f} {gtsam_t} {ratio}")
        if not args.skip_scipy:
            sci = optimize(graph, solver="scipy", max_iterations=args.scipy_max_nfev)
            fd_cost, fd_seconds = finite_difference_scipy(graph, args.scipy_max_nfev)
            line += f" {sci.final_cost:14.4f}/{sci.seconds:6.2f}s"
            line += f" {fd_cost:12.4f}/{fd_seconds:6.2f}s"
        print(line, flush=True)
    print(f"(relative difference = (ours - GTSAM) / GTSAM; target |diff| <= 1e-3; "
          f"numpy {np.__version__})")


if __name__ == "__main__":
    main()
