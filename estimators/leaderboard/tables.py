"""The leaderboard's tables from stored traces: the ranking (:func:`rank_table`, mean ATE over the
simulated scenarios, one column per group and the real-log relation error); its Markdown, with
the spread over seeds and the tie marks, is :mod:`estimators.leaderboard.headline`.
The paper's Table I beside ours lives in :mod:`estimators.leaderboard.table_one`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimators.leaderboard.matrix import Group
from estimators.leaderboard.records import Scenario, TraceRecord, canonical_json
from estimators.leaderboard.tasks import EstimatorSpec

#: (metric stored in the database, column title, lower is better)
METRIC_COLUMNS: tuple[tuple[str, str, bool], ...] = (
    ("accuracy_percent", "eq.-11 accuracy [%]", False),
    ("ate_rmse_m", "ATE [m]", True),
    ("heading_rmse_deg", "heading RMSE [deg]", True),
    ("drift_percent", "drift [%]", True),
    ("ms_per_step", "ms/step", True),
    ("map_iou", "map IoU", False),
    ("map_precision", "map precision", False),
    ("map_recall", "map recall", False),
    ("cylinder_recall", "cylinder recall", False),
    ("cylinder_error_m", "cylinder error [m]", True),
    ("mover_recall", "mover recall", False),
    ("mover_position_error_m", "mover error [m]", True),
    ("mover_velocity_error_mps", "mover velocity error [m/s]", True),
    ("moving_label_precision", "moving-label precision", False),
)


RANK_KEYS: dict[str, str] = {"ate": "ate_rmse_m", "accuracy": "accuracy_percent",
                             "heading": "heading_rmse_deg", "drift": "drift_percent",
                             "map": "map_iou"}


#: The paper's estimator, whose map ``maps.png`` shows next to the best one's.
PAPER_ESTIMATOR = "pc_pg"


REAL_METRIC = "relations_all_translation_m"


def finite_mean(values: list[float]) -> float:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def format_number(value: float, digits: int = 2) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def current_records(records: list[TraceRecord], specs: Sequence[EstimatorSpec],
             version: str) -> dict[tuple[Scenario, str], TraceRecord]:
    """The records made by exactly the requested estimators, params and package version."""
    wanted = {spec.name: spec.resolved_params for spec in specs}
    return {
        (record.scenario, record.trace.estimator): record
        for record in records
        if record.trace.estimator in wanted
        and canonical_json(record.trace.params) == canonical_json(wanted[record.trace.estimator])
        and record.trace.package_version == version
    }


def rank_table(groups: Sequence[Group], scenarios: dict[str, list[Scenario]],
               specs: Sequence[EstimatorSpec], records: dict[tuple[Scenario, str], TraceRecord],
               real: Scenario | None, rank_key: str,
               real_not_applicable: Mapping[str, str] | None = None) -> list[dict[str, Any]]:
    """One row per estimator: metric means over every simulated scenario, per-group accuracy
    and ATE, the real-log relation error (or, in ``real_note``, why the estimator does not
    apply to the log: ``real_not_applicable`` maps its name to the reason); sorted best first
    (NaN last)."""
    rows = []
    for spec in specs:
        mine = [records[(s, spec.name)] for group in groups for s in scenarios[group.name]
                if (s, spec.name) in records]
        total = sum(len(scenarios[group.name]) for group in groups)
        row: dict[str, Any] = {"estimator": spec.name, "scenarios": len(mine),
                               "scenarios_run": total}
        for key, _, _ in METRIC_COLUMNS:
            row[key] = finite_mean([r.metrics.get(key, math.nan) for r in mine])
        for group in groups:
            in_group = [records[(s, spec.name)] for s in scenarios[group.name]
                        if (s, spec.name) in records]
            row[f"{group.name} accuracy_percent"] = finite_mean(
                [r.metrics.get("accuracy_percent", math.nan) for r in in_group])
            row[f"{group.name} ate_rmse_m"] = finite_mean(
                [r.metrics.get("ate_rmse_m", math.nan) for r in in_group])
        if real is not None:
            record = records.get((real, spec.name))
            row[REAL_METRIC] = math.nan if record is None else record.metrics.get(REAL_METRIC)
            row["real_note"] = (real_not_applicable or {}).get(spec.name, "")
        rows.append(row)
    lower_better = next(lower for key, _, lower in METRIC_COLUMNS if key == rank_key)

    def order(row: dict[str, Any]) -> tuple[bool, float]:
        value = row[rank_key]
        return (not math.isfinite(value), value if lower_better else -value)

    return sorted(rows, key=order)


def markdown_table(header: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines) + "\n"


def map_ceiling_note(records: dict[tuple[Scenario, str], TraceRecord]) -> str:
    """A line under the table: the map scores at the true poses (the mapper's own ceiling for
    the estimators' map columns), averaged over the scenarios like the columns."""
    per_scenario = {scenario: record.metrics for (scenario, _), record in records.items()
                    if "map_iou_true_poses" in record.metrics}
    if not per_scenario:
        return ""
    scores = []
    for key, title, _ in METRIC_COLUMNS:
        if key.startswith(("map_", "cylinder_")):
            mean = finite_mean([m.get(f"{key}_true_poses", math.nan)
                                for m in per_scenario.values()])
            scores.append(f"{title} {format_number(mean, 3)}")
    return f"\nMaps at the true poses (the mapper's ceiling): {', '.join(scores)}.\n"


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
