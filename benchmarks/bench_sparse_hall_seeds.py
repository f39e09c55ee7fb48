"""Sparse halls on layouts the repository does not hold: every drive kind of
``bench_sparse_halls`` (hall of pillars, depot of shelf aisles; TurtleBot3 burger or waffle;
pure pursuit or turn-in-place) rebuilt from other seeds, so a change is judged on many halls
rather than on the six that tests and docs quote.

Per drive kind and estimator: the drift [% of the path] on each seed, their median, the share
of seeds at or under the 1 % target (issue 40) and the worst; the ATE [m] on each seed; and
for each estimator after the first, on how many seeds it ends worse than the first. The
layouts, routes and drives are ``bench_sparse_halls``'s own (``layout``, ``record``,
``replay``, ``score``) with only the seed replaced; a seed whose drive does not reach its
route's end is left out and counted.

    python benchmarks/bench_sparse_hall_seeds.py [--seeds 10 11 ...] [--estimators lidar_odometry]
        [--drives depot_30x15_waffle ...] [--json out.json]
    python benchmarks/bench_sparse_hall_seeds.py --estimators lidar_odometry slam  # vs front end
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
from bench_sparse_halls import DRIVES, record, replay, score

import estimators

#: The drift target [% of the path] (issue 40: a 3.5 m Lidar in sparse halls).
TARGET_DRIFT = 1.0


def sweep(drives: list[str], names: list[str], seeds: list[int]) -> dict[str, Any]:
    """``{drive: {"failed_seeds": [...], estimator: {"drift_percent": [...], "ate_m": [...]},
    "worse_than_first": {estimator: {"drift_percent": k, "ate_m": k}}}}`` per seed, printing
    rows per drive kind and estimator as it goes; each estimator after the first is counted
    on the seeds where it ends worse than the first (``slam`` against its front end: the
    drift is the end point's luck as much as the path's, so the ATE is counted too)."""
    results: dict[str, Any] = {}
    for label in drives:
        row: dict[str, Any] = {"failed_seeds": [],
                               **{name: {"drift_percent": [], "ate_m": []} for name in names}}
        for seed in seeds:
            try:
                recording = record(dataclasses.replace(DRIVES[label], seed=seed))
            except RuntimeError:  # the drive did not reach its route's end
                row["failed_seeds"].append(seed)
                continue
            for name in names:
                scores = score(recording, replay(recording, name)[0])
                for metric in ("drift_percent", "ate_m"):
                    row[name][metric].append(scores[metric])
        for name in names:
            drifts, ates = (np.array(row[name][m]) for m in ("drift_percent", "ate_m"))
            if len(drifts):
                print(f"{label:26s} {name:15s} drift " + " ".join(f"{d:6.2f}" for d in drifts)
                      + f" | median {np.median(drifts):5.2f} %, "
                      f"{100 * np.mean(drifts <= TARGET_DRIFT):3.0f} % of seeds <= "
                      f"{TARGET_DRIFT:g} %, worst {drifts.max():6.2f} %", flush=True)
                print(f"{'':26s} {'':15s} ATE   " + " ".join(f"{a:6.3f}" for a in ates)
                      + f" | median {np.median(ates):5.3f} m", flush=True)
        row["worse_than_first"] = {
            name: {metric: int(np.sum(np.array(row[name][metric])
                                      > np.array(row[names[0]][metric])))
                   for metric in ("drift_percent", "ate_m")} for name in names[1:]}
        for name, worse in row["worse_than_first"].items():
            print(f"{label:26s} {name:15s} worse than {names[0]} on "
                  f"{worse['drift_percent']} (drift) / {worse['ate_m']} (ATE) of "
                  f"{len(row[name]['ate_m'])} seeds", flush=True)
        results[label] = row
    return results


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", type=int, default=list(range(10, 20)))
    parser.add_argument("--drives", nargs="+", default=list(DRIVES), choices=list(DRIVES))
    parser.add_argument("--estimators", nargs="+", default=["lidar_odometry"],
                        choices=estimators.names())
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    print(f"seeds {args.seeds}; drift = final position error over the distance driven")
    results = sweep(args.drives, args.estimators, args.seeds)
    if args.json is not None:
        args.json.write_text(json.dumps({"seeds": args.seeds, "drives": results}, indent=1))
    return results


if __name__ == "__main__":
    main()
