"""One estimator over one recording, timed and scored: the core of ``duallidar run``.

:func:`run_estimator` feeds every scan of a :class:`~estimators.leaderboard.run_sources.RunInput`
to a registered estimator (:func:`estimators.datasets.real_log.run_on_log`) and times it in CPU
seconds (``time.process_time``, so a busy machine does not slow the figure down); the
real-time factor is the recording's median scan period over that time per scan. It returns the
estimator's :class:`~estimators.health.Health` beside the trajectory: the scans it skipped,
the frozen scans and clock jumps it met and its blind stretches, so a faulty sensor is
reported rather than absorbed.

:func:`score_run` scores the trajectory on the truth:

* **ATE** (absolute trajectory error): the RMSE [m] of the position error over the scans with a
  truth pose, after the least-squares rigid SE(2) alignment of the estimate onto the truth
  (rotation and translation, no scale; Umeyama 1991), as ``evo_ape tum truth.tum estimate.tum
  -a`` computes it; the heading RMSE [deg] and the end-point drift [% of the distance] after
  the same alignment beside it. The ATE shows drift over the whole run;
* **relation errors** (Kümmerle et al. 2009, :mod:`estimators.evaluation.relations`): the
  error of the estimated motion between two truth poses, ``local`` for consecutive truth poses
  and one set per window (each truth pose to the first one at least that many seconds later);
  with a relations file, its relations split into ``local`` (under 2 s) and ``all``. Local
  errors show the scan matching; a small local error beside a large ATE is drift.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.datasets.real_log import LogRun, run_on_log
from estimators.evaluation.metrics import evaluate
from estimators.evaluation.relations import (
    LOCAL_RELATION_MAX_DT,
    RelationErrors,
    Relations,
    RelationSummary,
    relation_errors,
    relations_from_trajectory,
)
from estimators.health import Health
from estimators.leaderboard.alignment import Alignment, align_to_reference
from estimators.leaderboard.run_sources import RunInput
from estimators.registry import make

#: Windows [s] of the longer relations between truth poses, by default.
DEFAULT_WINDOWS: tuple[float, ...] = (1.0, 5.0)
#: Largest gap [s] between a relation's time and a scan time: relations built from the truth
#: sit on scan times exactly; a relations file is matched on the logged stamps.
EXACT = 1e-6
RELATIONS_FILE_TOLERANCE = 1e-3


@dataclass(frozen=True)
class RelationSet:
    """The relations of one kind (``local``, ``5 s``, ``all``) and the estimate's errors on
    them."""

    label: str
    relations: Relations
    errors: RelationErrors

    def summary(self) -> RelationSummary:
        return self.errors.summary()


@dataclass(frozen=True)
class RunScores:
    """What :func:`score_run` measured (``None``/empty where the truth does not allow it).

    Attributes:
        ate_rmse_m: SE(2)-aligned position RMSE [m] over the scans with a truth pose.
        heading_rmse_deg: heading RMSE after the same alignment [deg].
        drift_percent: aligned end-point error over the truth's distance travelled [%].
        distance_m: distance along the truth poses [m].
        alignment: the motion that puts the estimate in the truth's frame.
        relations: the relation sets, ``local`` first.
    """

    ate_rmse_m: float | None = None
    heading_rmse_deg: float | None = None
    drift_percent: float | None = None
    distance_m: float | None = None
    alignment: Alignment | None = None
    relations: tuple[RelationSet, ...] = field(default_factory=tuple)


def run_estimator(name: str, run_input: RunInput, params: dict[str, Any] | None = None
                  ) -> tuple[LogRun, Health]:
    """``name`` over every scan of ``run_input``: its run (``seconds_per_scan`` in CPU time)
    and the :class:`~estimators.health.Health` of its input (observation indices count the
    recording's scans from 0)."""
    estimator = make(name, **(params or {}))
    start = time.process_time()
    run = run_on_log(estimator, run_input.recording)
    cpu = (time.process_time() - start) / max(len(run.times), 1)
    return dataclasses.replace(run, seconds_per_scan=cpu), estimator.health


def not_applicable(name: str, run_input: RunInput) -> str | None:
    """Why ``name`` cannot run on ``run_input`` (too few Lidars), or ``None``."""
    needed = getattr(make(name), "min_lidars", 1)
    have = run_input.recording.setup.n_lidars
    return f"needs {needed} Lidars, the recording has {have}" if have < needed else None


def _relation_set(label: str, run: LogRun, times: NDArray[np.float64], relations: Relations,
                  tolerance: float) -> RelationSet | None:
    if len(relations) == 0:
        return None
    return RelationSet(label, relations, relation_errors(times, run.poses, relations, tolerance))


def score_run(run_input: RunInput, run: LogRun,
              windows: Sequence[float] = DEFAULT_WINDOWS) -> RunScores:
    """Score ``run`` (over all scans of ``run_input``) on its truth (module docstring)."""
    truth = run_input.truth
    if truth is not None:
        times = run.times[truth.rows]
        metrics = evaluate(run.poses[truth.rows], truth.poses, align="se2")
        alignment = align_to_reference(run.times, run.poses, times, truth.poses, EXACT)
        sets = [_relation_set("local", run, run.times,
                              relations_from_trajectory(times, truth.poses), EXACT)]
        sets += [_relation_set(f"{window:g} s", run, run.times,
                               relations_from_trajectory(times, truth.poses, window), EXACT)
                 for window in windows]
        return RunScores(metrics.ate_rmse_m, metrics.heading_rmse_deg, metrics.drift_percent,
                         metrics.distance_m, alignment, tuple(s for s in sets if s))
    if run_input.relations is not None:
        logged = run_input.logged_times
        tolerance = RELATIONS_FILE_TOLERANCE
        ends = np.stack([run_input.relations.t1, run_input.relations.t2])
        inside = run_input.relations.select(np.all(
            (ends >= logged.min() - tolerance) & (ends <= logged.max() + tolerance), axis=0))
        local = np.abs(inside.t2 - inside.t1) < LOCAL_RELATION_MAX_DT
        sets = [_relation_set("local", run, logged, inside.select(local), tolerance),
                _relation_set("all", run, logged, inside, tolerance)]
        return RunScores(relations=tuple(s for s in sets if s))
    return RunScores()
