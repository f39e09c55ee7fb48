"""The leaderboard's answer in one paragraph (:func:`lead_paragraph`), generated from the ranked
rows of :func:`estimators.leaderboard.headline.annotate_rows`: what ran (estimators, scenario
groups, seeds, the real log), who ranks first and by how much, which neighbours the paired
Wilcoxon test cannot tell apart and why, the best estimator per group, and the real log's best.
It opens ``leaderboard.md``, ``report.html`` and the terminal summary.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from estimators.leaderboard.matrix import Group
from estimators.leaderboard.ranking import ALPHA
from estimators.leaderboard.tables import METRIC_COLUMNS, REAL_METRIC

#: The ranking metrics in words: metric -> (name, unit, decimals).
METRIC_WORDS: dict[str, tuple[str, str, int]] = {
    "ate_rmse_m": ("ATE", "m", 3),
    "accuracy_percent": ("eq.-11 accuracy", "%", 1),
    "heading_rmse_deg": ("heading RMSE", "deg", 2),
    "drift_percent": ("drift", "%", 1),
    "map_iou": ("map IoU", "", 3),
}
#: Fewest paired runs with which the two-sided Wilcoxon signed-rank test can reach p < 0.05
#: (with 5 runs its smallest p-value is 2 / 2**5 = 0.0625).
MIN_SEPARABLE_RUNS = 6


def lower_is_better(metric: str) -> bool:
    """Whether a smaller ``metric`` ranks higher (as ``tables.METRIC_COLUMNS`` says)."""
    return next(lower for key, _, lower in METRIC_COLUMNS if key == metric)


def _value(row: Mapping[str, Any], key: str) -> float:
    value = row.get(key, math.nan)
    return math.nan if value is None else float(value)


def _amount(value: float, metric: str) -> str:
    _, unit, digits = METRIC_WORDS[metric]
    return f"{value:.{digits}f}{' ' + unit if unit and unit != '%' else unit}"


def _names(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def _gap(leader: float, other: float, metric: str) -> str:
    """How far ``other`` is behind ``leader``: a ratio for errors, a difference otherwise."""
    if lower_is_better(metric) and leader > 0:
        ratio = other / leader
        return f"{ratio:.2f}× the leader's" if ratio < 10 else f"{ratio:.0f}× the leader's"
    return f"{abs(other - leader):.{METRIC_WORDS[metric][2]}f} behind"


def _what_ran(rows: Sequence[Mapping[str, Any]], groups: Sequence[Group],
              real_name: str | None) -> str:
    runs = max((int(row["scenarios_run"]) for row in rows), default=0)
    seeds = max((int(row.get("seeds", 0)) for row in rows), default=0)
    names = [str(row["estimator"]) for row in rows]
    text = (f"{len(names)} estimator{'s' * (len(names) != 1)} ({', '.join(names)}) ran on "
            f"{runs} simulated run{'s' * (runs != 1)}: {len(groups)} scenario "
            f"group{'s' * (len(groups) != 1)} ({', '.join(g.name for g in groups)}) × "
            f"{seeds} seed{'s' * (seeds != 1)}")
    return text + (f", and on the {real_name} log." if real_name else "; no real log.")


def _who_wins(rows: Sequence[Mapping[str, Any]], metric: str) -> str:
    name = METRIC_WORDS[metric][0]
    finite = [row for row in rows if math.isfinite(_value(row, metric))]
    if not finite:
        return f"No estimator has a finite {name}."
    leader, best = finite[0], _value(finite[0], metric)
    text = f"By mean {name}, {leader['estimator']} ranks first at {_amount(best, metric)}"
    if len(finite) > 1:
        second = _value(finite[1], metric)
        text += (f"; {finite[1]['estimator']} follows at {_amount(second, metric)} "
                 f"({_gap(best, second, metric)})")
    separated = next((row for row in finite[1:] if not str(row["rank"]).startswith("=")), None)
    if separated is not None and separated is not finite[1]:
        value = _value(separated, metric)
        text += (f"; the first the test separates from the leader is {separated['estimator']} "
                 f"(rank {separated['rank']}) at {_amount(value, metric)} "
                 f"({_gap(best, value, metric)})")
    return text + "."


def _ties(rows: Sequence[Mapping[str, Any]], metric: str) -> str:
    runs = max((int(row["scenarios_run"]) for row in rows), default=0)
    tied: list[list[Mapping[str, Any]]] = []
    for row in rows:
        if str(row["rank"]).startswith("=") and tied:
            tied[-1].append(row)
        else:
            tied.append([row])
    tied = [run for run in tied if len(run) > 1]
    if len(rows) < 2:
        return ""
    if not tied:
        return (f"Every neighbour in the ranking differs: a paired Wilcoxon signed-rank test "
                f"over the {runs} runs gives p < {ALPHA} for each pair.")
    shares = "; ".join(f"{_names([str(r['estimator']) for r in run])} share rank {run[0]['rank']}"
                       for run in tied)
    p_values = [_value(r, "tie_p") for run in tied for r in run[1:]]
    shown = ", ".join(f"{p:.2f}" for p in p_values if math.isfinite(p))
    why = (f"a paired Wilcoxon signed-rank test over their {runs} per-run "
           f"{METRIC_WORDS[metric][0]} values cannot tell neighbours apart"
           + (f" (p = {shown} between consecutive neighbours, none below {ALPHA})"
              if shown else ""))
    if runs < MIN_SEPARABLE_RUNS:
        why += (f"; with fewer than {MIN_SEPARABLE_RUNS} paired runs no difference can reach "
                f"p < {ALPHA}, so more seeds or groups are needed to separate them")
    return f"Ties: {shares}, because {why}."


def _group_winners(rows: Sequence[Mapping[str, Any]], groups: Sequence[Group],
                   metric: str) -> str:
    if len(groups) < 2:
        return ""
    sign = 1.0 if lower_is_better(metric) else -1.0
    wins: dict[str, list[str]] = {}
    for group in groups:
        values = [(sign * _value(row, f"{group.name} {metric}"), str(row["estimator"]))
                  for row in rows]
        finite = [pair for pair in values if math.isfinite(pair[0])]
        if finite:
            wins.setdefault(min(finite)[1], []).append(group.name)
    if not wins:
        return ""
    parts = [f"{name} in {len(won)} of {len(groups)} ({', '.join(won)})"
             for name, won in sorted(wins.items(), key=lambda item: -len(item[1]))]
    return f"Best {METRIC_WORDS[metric][0]} per group: {'; '.join(parts)}."


def _real_best(rows: Sequence[Mapping[str, Any]], real_name: str | None) -> str:
    if not real_name:
        return ""
    scored = sorted((_value(row, REAL_METRIC), str(row["estimator"])) for row in rows
                    if math.isfinite(_value(row, REAL_METRIC)))
    if not scored:
        return f"No estimator has a relation error on {real_name}."
    text = (f"On {real_name}, {scored[0][1]} has the smallest mean relation translation error, "
            f"{scored[0][0]:.3f} m")
    if len(scored) > 1:
        text += f" (next: {scored[1][1]}, {scored[1][0]:.3f} m)"
    return text + "."


def lead_paragraph(rows: Sequence[Mapping[str, Any]], groups: Sequence[Group],
                   real_name: str | None, rank_key: str) -> str:
    """One paragraph (a single line of text) saying what ran, who wins by how much, which
    estimators tie and why, the best per group and on the real log; ``rows`` best first as
    :func:`estimators.leaderboard.headline.annotate_rows` returns them, ``rank_key`` the
    metric they are ranked by (a key of :data:`METRIC_WORDS`)."""
    if not rows:
        return "No estimator ran."
    parts = [_what_ran(rows, groups, real_name), _who_wins(rows, rank_key)]
    if any(math.isfinite(_value(row, rank_key)) for row in rows):
        parts += [_ties(rows, rank_key), _group_winners(rows, groups, rank_key)]
    parts.append(_real_best(rows, real_name))
    return " ".join(part for part in parts if part)
