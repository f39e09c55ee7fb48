"""The paper's Table I beside ours from stored traces (:func:`table_one`): the paper's accuracy
per case next to the mean ± std over seeds of ours, world-aligned and sensor-frame, and, in the
closed areas, world-aligned at the feature density where the paper's method reaches the paper's
closed-area figure (:data:`~estimators.leaderboard.matrix.MATCHED_DENSITY`); and its Markdown
(:func:`table_one_markdown`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from estimators.leaderboard.matrix import MATCHED_DENSITY, TABLE_I, TABLE_I_FRAMES
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.tables import finite_mean, format_number, markdown_table


def _seed_metrics(runs: Sequence[Scenario], estimator: str,
                  records: dict[tuple[Scenario, str], TraceRecord]) -> list[dict[str, float]]:
    return [records[(s, estimator)].metrics for s in runs if (s, estimator) in records]


def table_one(by_frame: Mapping[str, Mapping[tuple[str, str], Sequence[Scenario]]],
              records: dict[tuple[Scenario, str], TraceRecord]) -> list[dict[str, Any]]:
    """Table I: the paper's accuracy per case beside ours, for each scan frame of ``by_frame``
    (``"world"``/``"sensor"`` -> (world, trace) -> the scenarios, one per seed): the mean and
    std over seeds, the mean ATE, and, for the cases without pose-graph correlation, the
    main-Lidar-only ``pc`` as well (NaN where nothing ran); ``by_frame["matched"]`` (optional)
    gives the world-aligned runs at :data:`MATCHED_DENSITY` (``ours_matched_*``)."""
    rows = []
    for case in TABLE_I:
        row: dict[str, Any] = {
            "case": case.case, "area": case.area, "feature": case.feature,
            "pose_graph": "yes" if case.pose_graph else "no",
            "scenario": f"{case.world}+{case.trace}", "estimator": case.estimator,
            "paper_accuracy_percent": case.paper_accuracy,
        }
        for frame in TABLE_I_FRAMES:
            runs = by_frame.get(frame, {}).get((case.world, case.trace), [])
            ours = _seed_metrics(runs, case.estimator, records)
            accuracy = [m["accuracy_percent"] for m in ours]
            main_only = [] if case.pose_graph else _seed_metrics(runs, "pc", records)
            row.update({
                f"ours_{frame}_accuracy_percent": finite_mean(accuracy),
                f"ours_{frame}_std_percent": float(np.std(accuracy)) if ours else math.nan,
                f"ours_{frame}_seeds": len(ours),
                f"ours_{frame}_ate_m": finite_mean([m.get("ate_rmse_m", math.nan) for m in ours]),
                f"pc_main_only_{frame}_accuracy_percent": finite_mean(
                    [m["accuracy_percent"] for m in main_only]),
            })
        matched = [m["accuracy_percent"] for m in _seed_metrics(
            by_frame.get("matched", {}).get((case.world, case.trace), []), case.estimator,
            records)]
        row.update({
            "matched_density": MATCHED_DENSITY,
            "ours_matched_accuracy_percent": finite_mean(matched),
            "ours_matched_std_percent": float(np.std(matched)) if matched else math.nan,
            "ours_matched_seeds": len(matched),
        })
        rows.append(row)
    return rows


def table_one_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """Table I as markdown, with a legend of the two scan frames."""
    titles = list(TABLE_I_FRAMES.values())
    header = ["case", "area", "feature", "pose-graph", "scenario", "estimator", "paper [%]",
              *(f"ours, {title} [%] (mean ± std, seeds)" for title in titles),
              f"ATE {' / '.join(titles)} [m]", f"pc main only, {' / '.join(titles)} [%]",
              f"ours at the density where the paper's closed-area figure is matched "
              f"({MATCHED_DENSITY:g} features / 10 m, world-aligned) [%]"]
    body = []
    for r in rows:
        ours = [f"{format_number(r[f'ours_{frame}_accuracy_percent'])} ± "
                f"{format_number(r[f'ours_{frame}_std_percent'])} ({r[f'ours_{frame}_seeds']})"
                if r[f"ours_{frame}_seeds"] else "not run" for frame in TABLE_I_FRAMES]
        ate = " / ".join(format_number(r[f"ours_{frame}_ate_m"], 3) for frame in TABLE_I_FRAMES)
        main_only = "" if r["pose_graph"] == "yes" else " / ".join(
            format_number(r[f"pc_main_only_{frame}_accuracy_percent"]) for frame in TABLE_I_FRAMES)
        matched = (f"{format_number(r['ours_matched_accuracy_percent'])} ± "
                   f"{format_number(r['ours_matched_std_percent'])} ({r['ours_matched_seeds']})"
                   if r.get("ours_matched_seeds") else "")
        body.append([str(r["case"]), r["area"], r["feature"], r["pose_graph"], r["scenario"],
                     r["estimator"], f"{r['paper_accuracy_percent']:.2f}", *ours, ate,
                     main_only, matched])
    legend = (
        "\nworld-aligned: the paper's setting, scans rotated into world axes (env "
        "`scan_frame=\"world\"`): the translation-only phase correlation never sees a rotation. "
        "sensor-frame: the scans as mounted Lidars give them (the leaderboard's scenarios), "
        "where the paper's method cannot see the car turn. Accuracy = 100% - eq. 11, floored "
        "at 0; ATE for context (eq. 11 ignores direction). The last column: the closed areas "
        f"with door recesses, pillars, corners and clutter at {MATCHED_DENSITY:g} features per "
        "10 m of wall (`python -m benchmarks.table1_sweep`), the density at which the paper's "
        "method reaches the paper's closed-area figure; the columns before are the bare walls."
        "\n"
    )
    return markdown_table(header, body) + legend
