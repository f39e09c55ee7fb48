"""A picture of a :class:`~estimators.slam.graph_slam.GraphSlam` run: the corrected map, the
front end's path, the smoothed path, loop edges and the truth (matplotlib,
``pip install duallidar[plots]``).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from numpy.typing import NDArray


def save_slam_figure(slam: Any, path: str | os.PathLike[str],
                     truth: NDArray[np.float64] | None = None) -> None:
    """Save a picture of ``slam``'s (a :class:`~estimators.slam.graph_slam.GraphSlam`)
    corrected map (grey points), the front end's path (dotted), the smoothed path, odometry
    edges and loop edges (red), and ``truth`` (N, 3) poses if given."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:
        raise ImportError("render needs matplotlib: pip install duallidar[plots]") from err
    points, poses, edges = slam.corrected_map(), slam.graph.poses, slam.graph.edges
    fig, ax = plt.subplots(figsize=(8, 8))
    ax.scatter(points[:, 0], points[:, 1], s=0.2, c="0.6", linewidths=0)
    odometry, smoothed = slam.odometry_trajectory, slam.trajectory
    ax.plot(odometry[:, 0], odometry[:, 1], ":", lw=0.8, c="tab:orange", label="front end")
    ax.plot(smoothed[:, 0], smoothed[:, 1], lw=0.8, c="tab:blue", label="slam")
    if truth is not None:
        ax.plot(truth[:, 0], truth[:, 1], lw=0.8, c="k", label="truth")
    for (i, j), loop in zip(edges, slam.graph.is_loop, strict=True):
        if loop:
            ax.plot(poses[[i, j], 0], poses[[i, j], 1], c="tab:red", lw=0.6)
    ax.plot([], [], c="tab:red", label=f"loop edges ({slam.n_loops})")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize=8)
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)
