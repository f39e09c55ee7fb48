"""How sure a rank is: metric means ± standard deviations over seeds with the number of runs
(:func:`seed_spread`), and ties between ranked neighbours that a paired Wilcoxon signed-rank
test over the per-scenario values cannot tell apart (:func:`mark_ties`, :func:`tied_ranks`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from estimators.leaderboard.records import Scenario, TraceRecord

#: Significance level of the neighbour test: a pair with p >= ALPHA is a tie.
ALPHA = 0.05


@dataclass(frozen=True)
class Spread:
    """A metric over seeds: the mean and population std of its per-seed values and the number
    of runs (scenarios) behind them. NaN mean when nothing finite ran."""

    mean: float
    std: float
    seeds: int
    runs: int

    def text(self, digits: int) -> str:
        """``mean ± std`` at ``digits`` decimals (``n/a`` when not finite)."""
        if not math.isfinite(self.mean):
            return "n/a"
        return f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"


def seed_spread(runs: Sequence[Scenario], estimator: str, metric: str,
                records: Mapping[tuple[Scenario, str], TraceRecord]) -> Spread:
    """``metric`` of ``estimator`` over ``runs``: averaged within each seed (over the runs of
    that seed, e.g. one per group), then mean ± std over the seeds."""
    per_seed: dict[int, list[float]] = {}
    count = 0
    for scenario in runs:
        record = records.get((scenario, estimator))
        value = math.nan if record is None else record.metrics.get(metric, math.nan)
        if value is not None and math.isfinite(value):
            per_seed.setdefault(scenario.seed, []).append(float(value))
            count += 1
    means = [float(np.mean(values)) for values in per_seed.values()]
    if not means:
        return Spread(math.nan, math.nan, 0, 0)
    return Spread(float(np.mean(means)), float(np.std(means)), len(means), count)


def paired_p_value(first: Sequence[float], second: Sequence[float]) -> float:
    """Two-sided p-value of the Wilcoxon signed-rank test on paired values (NaN pairs dropped;
    1.0 when no pair differs, so equal estimators always tie)."""
    from scipy.stats import wilcoxon

    a, b = np.asarray(first, dtype=np.float64), np.asarray(second, dtype=np.float64)
    keep = np.isfinite(a) & np.isfinite(b)
    differences = a[keep] - b[keep]
    if not np.any(differences != 0):
        return 1.0
    return float(wilcoxon(differences, zero_method="wilcox").pvalue)


def mark_ties(ranked: Sequence[str], per_scenario: Mapping[str, Sequence[float]],
              alpha: float = ALPHA) -> list[bool]:
    """For each estimator of ``ranked`` (best first): whether it ties with the one above it,
    i.e. the paired test over ``per_scenario`` (name -> values in one scenario order) gives
    p >= ``alpha``. The first is never a tie."""
    ties = [False]
    for above, below in zip(ranked[:-1], ranked[1:], strict=True):
        p = paired_p_value(per_scenario[above], per_scenario[below])
        ties.append(not p < alpha)
    return ties[:len(ranked)]


def tied_ranks(ties: Sequence[bool]) -> list[str]:
    """Rank labels from :func:`mark_ties`: an estimator that ties with the one above shares its
    rank, written ``=k`` (``[False, True, False]`` -> ``["1", "=1", "3"]``)."""
    labels: list[str] = []
    leader = 1
    for index, tie in enumerate(ties):
        if index == 0 or not tie:
            leader = index + 1
            labels.append(str(leader))
        else:
            labels.append(f"={leader}")
    return labels


def per_scenario_values(runs: Sequence[Scenario], names: Sequence[str], metric: str,
                        records: Mapping[tuple[Scenario, str], TraceRecord]
                        ) -> dict[str, list[float]]:
    """``metric`` per estimator over ``runs`` in one order (NaN where it did not run)."""
    values: dict[str, list[float]] = {}
    for name in names:
        row = []
        for scenario in runs:
            record = records.get((scenario, name))
            value = math.nan if record is None else record.metrics.get(metric, math.nan)
            row.append(math.nan if value is None else float(value))
        values[name] = row
    return values


#: The line under the headline table that states the test.
TEST_NOTE = ("Ties (`=k`: shares rank k with the row above): neighbours in the ranking whose "
             "per-scenario {metric} a paired two-sided Wilcoxon signed-rank test "
             "(scipy.stats.wilcoxon, zero differences dropped) over the {n} simulated runs "
             "cannot tell apart at p < {alpha}; with fewer than 6 paired runs no difference "
             "can reach that level, so every neighbour ties.")
