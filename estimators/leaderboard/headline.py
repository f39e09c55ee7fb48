"""The leaderboard as a reader sees it: the ranked rows of
:func:`estimators.leaderboard.tables.rank_table` with their spread over seeds and tie marks
(:func:`annotate_rows`), and the Markdown of the board (:func:`board_markdown`): the answer in
one paragraph (:func:`estimators.leaderboard.summary.lead_paragraph`), the headline table
(rank, estimator, accuracy, ATE, heading error, drift, ms/step, real-log error) with its notes,
then the per-group tables, each ranked by the group's own result, and the map-score table.
Every simulated figure is mean ± std over seeds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from estimators.leaderboard.matrix import Group
from estimators.leaderboard.ranking import (
    ALPHA,
    TEST_NOTE,
    mark_ties,
    paired_p_value,
    per_scenario_values,
    seed_spread,
    tied_ranks,
)
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.summary import lead_paragraph, lower_is_better
from estimators.leaderboard.tables import (
    METRIC_COLUMNS,
    RANK_KEYS,
    REAL_METRIC,
    format_number,
    markdown_table,
)

#: The headline's simulated metrics: (metric, column title, decimals).
HEADLINE_METRICS: tuple[tuple[str, str, int], ...] = (
    ("accuracy_percent", "eq.-11 accuracy [%]", 1),
    ("ate_rmse_m", "ATE [m]", 3),
    ("heading_rmse_deg", "heading RMSE [deg]", 2),
    ("drift_percent", "drift [%]", 1),
    ("ms_per_step", "ms/step", 2),
)
#: The per-group tables' metrics (ms/step is a property of the estimator, not of the group).
GROUP_METRICS = HEADLINE_METRICS[:4]
MAP_METRICS: tuple[tuple[str, str, int], ...] = tuple(
    (key, title, 3) for key, title, _ in METRIC_COLUMNS
    if key.startswith(("map_", "cylinder_", "mover_", "moving_")))


def annotate_rows(rows: Sequence[dict[str, Any]], groups: Sequence[Group],
                  scenarios: Mapping[str, Sequence[Scenario]],
                  records: Mapping[tuple[Scenario, str], TraceRecord],
                  rank_key: str) -> list[dict[str, Any]]:
    """Copies of ``rows`` (best first) with, per metric, ``<metric>_std`` over seeds (and per
    group ``<group> <metric>`` and ``_std`` for :data:`GROUP_METRICS` and ``rank_key``),
    ``seeds``, ``rank`` (``"=k"`` for a tie with the row above) and ``tie_p`` (the neighbour
    test's p-value, NaN for the first row)."""
    every = [s for group in groups for s in scenarios[group.name]]
    names = [row["estimator"] for row in rows]
    values = per_scenario_values(every, names, rank_key, records)
    ties = mark_ties(names, values)
    annotated = []
    for index, (row, label) in enumerate(zip(rows, tied_ranks(ties), strict=True)):
        new = dict(row)
        for key, _, _ in METRIC_COLUMNS:
            spread = seed_spread(every, row["estimator"], key, records)
            new[f"{key}_std"] = spread.std
            new["seeds"] = max(new.get("seeds", 0), spread.seeds)
        for group in groups:
            for key in dict.fromkeys([*(k for k, _, _ in GROUP_METRICS), rank_key]):
                spread = seed_spread(scenarios[group.name], row["estimator"], key, records)
                new[f"{group.name} {key}"] = spread.mean
                new[f"{group.name} {key}_std"] = spread.std
                new[f"{group.name} runs"] = spread.runs
        new["rank"] = label
        new["tie_p"] = math.nan if index == 0 else paired_p_value(values[names[index - 1]],
                                                                  values[row["estimator"]])
        annotated.append(new)
    return annotated


def _cell(row: Mapping[str, Any], key: str, digits: int, prefix: str = "") -> str:
    mean = row.get(f"{prefix}{key}", math.nan)
    if mean is None or not math.isfinite(mean):
        return "n/a"
    std = row.get(f"{prefix}{key}_std", math.nan)
    return f"{mean:.{digits}f} ± {std:.{digits}f}" if math.isfinite(std) else f"{mean:.{digits}f}"


def _name(row: Mapping[str, Any]) -> str:
    if row["scenarios"] < row["scenarios_run"]:  # means over fewer scenarios: say so
        return f"{row['estimator']} (scored on {row['scenarios']} of {row['scenarios_run']})"
    return str(row["estimator"])


def headline_markdown(rows: Sequence[Mapping[str, Any]], real_name: str | None) -> str:
    """The headline table (≤ 8 columns) of :func:`annotate_rows`' rows."""
    header = ["#", "estimator", *(title for _, title, _ in HEADLINE_METRICS)]
    if real_name:
        header.append(f"{real_name} rel. error [m]")
    body = []
    for row in rows:
        cells = [row["rank"], _name(row)]
        cells += [_cell(row, key, digits) for key, _, digits in HEADLINE_METRICS]
        if real_name:
            note = row.get("real_note")
            cells.append(f"n/a ({note})" if note
                         else format_number(row.get(REAL_METRIC, math.nan), 3))
        body.append(cells)
    return markdown_table(header, body)


def group_order(rows: Sequence[Mapping[str, Any]], group: Group,
                rank_key: str) -> list[Mapping[str, Any]]:
    """``rows`` ordered by the group's own ``rank_key`` mean, best first (NaN last; equal
    values keep the overall order)."""
    sign = 1.0 if lower_is_better(rank_key) else -1.0

    def key(row: Mapping[str, Any]) -> tuple[bool, float]:
        value = row.get(f"{group.name} {rank_key}", math.nan)
        finite = value is not None and math.isfinite(value)
        return (not finite, sign * value if finite else 0.0)

    return sorted(rows, key=key)


def group_markdown(rows: Sequence[Mapping[str, Any]], group: Group,
                   rank_key: str = "ate_rmse_m") -> str:
    """One group's table, ranked by the group's own ``rank_key`` (``#``; the headline's rank
    in ``overall #``): the group's accuracy, ATE, heading and drift, and the runs behind them."""
    header = ["#", "estimator", *(title for _, title, _ in GROUP_METRICS), "runs", "overall #"]
    body = [[str(place), str(row["estimator"]),
             *(_cell(row, key, digits, f"{group.name} ") for key, _, digits in GROUP_METRICS),
             str(row.get(f"{group.name} runs", 0)), str(row["rank"])]
            for place, row in enumerate(group_order(rows, group, rank_key), start=1)]
    return markdown_table(header, body)


def map_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """The map (and, where movers walked, tracker) scores of the estimators' poses, mean ± std
    over seeds; a column no run has (the tracker's without movers) is left out."""
    shown = [(key, title, digits) for key, title, digits in MAP_METRICS
             if not key.startswith(("mover_", "moving_"))
             or any(math.isfinite(row.get(key, math.nan)) for row in rows)]
    header = ["overall #", "estimator", *(title for _, title, _ in shown)]
    body = [[row["rank"], str(row["estimator"]),
             *(_cell(row, key, digits) for key, _, digits in shown)] for row in rows]
    return markdown_table(header, body)


def board_markdown(rows: Sequence[Mapping[str, Any]], groups: Sequence[Group],
                   real_name: str | None, rank_by: str) -> str:
    """The board: the lead paragraph, the headline table and its notes, then (after the first
    ``##`` heading) one table per group, ranked by the group's own ``rank_by`` (a key of
    :data:`~estimators.leaderboard.tables.RANK_KEYS`), and the map table."""
    rank_key = RANK_KEYS[rank_by]
    runs = max((row["scenarios_run"] for row in rows), default=0)
    seeds = max((row.get("seeds", 0) for row in rows), default=0)
    metric = next(title for key, title, _ in METRIC_COLUMNS if key == rank_key)
    lines = [lead_paragraph(rows, groups, real_name, rank_key), "",
             headline_markdown(rows, real_name),
             f"Simulated figures: mean ± std over {seeds} seed(s) of each seed's mean over "
             f"{len(groups)} group(s) ({runs} simulated runs per estimator); ranked by "
             f"{rank_by}." + (f" {real_name}: one run of the real log, mean relation "
                              "translation error." if real_name else ""), "",
             TEST_NOTE.format(metric=rank_by, n=runs, alpha=ALPHA), ""]
    lines += [f"## Per group: each table ranked by the group's own {metric}", "",
              "`#` is the place in the group, `overall #` the headline's rank.", ""]
    for group in groups:
        lines += [f"### {group.name} (mean ± std over seeds)", "",
                  group_markdown(rows, group, rank_key)]
    lines += ["## Maps at the estimated poses (mean ± std over seeds)", "", map_markdown(rows)]
    return "\n".join(lines)
