"""Loop edges against the front end over the same span: does each loop edge ``slam`` keeps
know the relation between its two keyframes better than the front end already does?

On sparse-hall drives (``bench_sparse_halls``' layouts, any seed), ``slam`` runs once; for
every loop edge of its final graph the true pose of the newer keyframe in the older one's frame
(from the simulator) gives the edge's error, and the front end's own poses of the two keyframes
give the front end's error over the same span. A loop edge whose error is larger than the front
end's over its span can only pull the map away from a better estimate: ``slam`` beats its front
end only where the loops it keeps beat it. Edges are split into overlap edges (fewer than
``min_loop_separation`` of path apart: the same stretch seen again a few metres on) and revisits,
and by how many of the newer keyframe's points lie within ``inlier_distance`` of the older
place's at the edge's pose (a scan that sees two or three posts has ~10-20).

Per drive kind: edges, the rms heading [deg] and position [m] error of the loop edges and of
the front end over the same spans, the share of edges better than the front end in heading, and
the heading sigma the edges claim (their information), median.

    python benchmarks/bench_loop_edges.py [--drives hall_30x20_waffle ...] [--seeds 10 11 ...]
        [--set min_overlap_separation=10.0 ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
from bench_layouts import parameter
from bench_sparse_halls import DRIVES, Recording, record
from numpy.typing import NDArray
from scipy.spatial import cKDTree

import estimators
from lidar_env.core.se2 import relative, transform_points

#: Pair-count bins [points of the newer keyframe on the older place] the table splits edges by.
PAIR_BINS = (0, 15, 30, 60, 10**9)


def keyframe_observations(slam: Any, observations: int) -> NDArray[np.int64]:
    """Index (K,) of the observation each of ``slam``'s keyframes was made from, out of
    ``observations`` fed to it (``keyframe_scans`` counts the scans it used)."""
    used = np.delete(np.arange(observations), np.asarray(slam.health.skipped, dtype=np.int64))
    return used[slam.keyframe_scans]


def place_points(slam: Any, index: int) -> NDArray[np.float64]:
    """Points (M, 2) of keyframe ``index`` and its ``submap_neighbours`` on each side in its
    frame, placed by the final graph: the old place a loop match is made against."""
    poses = slam.graph.poses
    lo = max(0, index - slam.submap_neighbours)
    hi = min(len(slam.keyframes), index + slam.submap_neighbours + 1)
    return np.concatenate([transform_points(relative(poses[index], poses[k]),
                                            slam.keyframes[k].points) for k in range(lo, hi)])


def loop_edges(recording: Recording, settings: dict[str, Any]) -> NDArray[np.float64]:
    """One row per loop edge of ``slam``'s final graph on ``recording``: path apart [m], pairs,
    edge error (position [m], heading [deg]), front-end error over the span (the same), the
    edge's claimed heading sigma [deg]."""
    slam = estimators.make("slam", **settings)
    slam.reset(recording.setup, recording.poses[0])
    for observation, t in zip(recording.observations, recording.times, strict=True):
        slam.update(observation, t)
    slam.trajectory  # noqa: B018  (the final optimisation drops the irreconcilable loops)
    truth = recording.poses[keyframe_observations(slam, len(recording.poses))]
    graph, keyframes = slam.graph, slam.keyframes
    rows = []
    for k in np.flatnonzero(graph.is_loop):
        old, new = graph.edges[k]
        true = relative(truth[old], truth[new])
        edge = relative(true, graph.measurements[k])
        front = relative(true, relative(keyframes[old].odometry, keyframes[new].odometry))
        distances, _ = cKDTree(place_points(slam, int(old))).query(
            transform_points(graph.measurements[k], keyframes[new].points),
            distance_upper_bound=slam.loop_params.inlier_distance)
        sigma = np.degrees(np.sqrt(np.linalg.inv(graph.information[k])[2, 2]))
        rows.append([keyframes[new].path_length - keyframes[old].path_length,
                     np.isfinite(distances).sum(),
                     np.hypot(*edge[:2]), np.degrees(edge[2]),
                     np.hypot(*front[:2]), np.degrees(front[2]), sigma])
    return np.array(rows, dtype=np.float64).reshape(-1, 7)


def summary(edges: NDArray[np.float64]) -> str:
    """One line: count, rms heading and position errors of edges vs the front end, the share
    of edges better in heading, the median claimed heading sigma."""
    if len(edges) == 0:
        return "  0 edges"
    rms = np.sqrt(np.mean(edges[:, 2:6]**2, axis=0))
    better = np.mean(np.abs(edges[:, 3]) < np.abs(edges[:, 5]))
    return (f"{len(edges):5d} edges: heading {rms[1]:5.2f} vs front end {rms[3]:5.2f} deg, "
            f"position {rms[0]:.3f} vs {rms[2]:.3f} m, {100 * better:3.0f} % better in heading, "
            f"claimed sigma {np.median(edges[:, 6]):4.2f} deg")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", nargs="+", default=["hall_30x20_waffle",
                                                        "hall_30x20_burger_turns",
                                                        "hall_20x15_burger"],
                        choices=list(DRIVES))
    parser.add_argument("--seeds", nargs="+", type=int, default=list(range(10, 20)))
    parser.add_argument("--set", type=parameter, nargs="+", default=[], metavar="NAME=VALUE",
                        help="slam settings")
    parser.add_argument("--json", type=Path, default=None, help="write the edges here")
    args = parser.parse_args(argv)
    settings = dict(args.set)
    separation = estimators.make("slam", **settings).min_loop_separation
    results: dict[str, Any] = {}
    for label in args.drives:
        runs = []
        for seed in args.seeds:
            try:
                runs.append(loop_edges(record(dataclasses.replace(DRIVES[label], seed=seed)),
                                       settings))
            except RuntimeError:  # the drive did not reach its route's end
                continue
        edges = np.concatenate(runs) if runs else np.zeros((0, 7))
        results[label] = edges.tolist()
        overlap = edges[:, 0] < separation
        print(f"{label} ({len(runs)} seeds)")
        print(f"  overlap  {summary(edges[overlap])}")
        print(f"  revisits {summary(edges[~overlap])}")
        for lo, hi in zip(PAIR_BINS[:-1], PAIR_BINS[1:], strict=True):
            chosen = overlap & (edges[:, 1] >= lo) & (edges[:, 1] < hi)
            print(f"  overlap, {lo}-{hi if hi < 10**9 else ''} pairs {summary(edges[chosen])}",
                  flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results))
    return results


if __name__ == "__main__":
    main()
