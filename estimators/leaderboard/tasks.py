"""What a worker runs: one task per scenario (:func:`run_scenario_task`: record its sensor dataset
if the database lacks it, replay it through the estimators that have no trace yet, score each)
or per real log (:func:`run_real_log_task`, a
:class:`~estimators.leaderboard.real_logs.RealLog`), and the outcome it sends back. Tasks are plain,
picklable dataclasses and touch no database: the parent commits every outcome
(:mod:`estimators.leaderboard.runner`). Worker time is reported per stage (:data:`STAGES`).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.recording import (
    OBSTACLE_STRIDE,
    map_reference,
    mover_truth,
    record_with_movers,
    replay,
    score,
    score_map,
    score_movers,
)
from estimators.leaderboard.records import Scenario, SensorDataset, TraceDataset
from estimators.mapping.run_maps import car_frame_obstacles
from estimators.registry import defaults, make, names
from lidar_env.core import ConfigError


@dataclass(frozen=True)
class EstimatorSpec:
    """A registered estimator and the parameters it runs with (over the registry defaults)."""

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in names():
            raise ConfigError(
                f"unknown estimator {self.name!r}: expected one of {', '.join(names())}"
            )

    @property
    def resolved_params(self) -> dict[str, Any]:
        """Every parameter: registry defaults overridden by ``params`` (what gets recorded)."""
        return {**defaults(self.name), **dict(self.params)}

    @property
    def min_lidars(self) -> int:
        """Lidars the estimator needs (:attr:`estimators.base.Estimator.min_lidars`)."""
        return make(self.name, **dict(self.params)).min_lidars

    def not_applicable(self, n_lidars: int) -> str | None:
        """Why the estimator cannot run on data from ``n_lidars`` Lidars, or ``None`` if it can:
        decided before any work, so such a pair is neither run nor a failure."""
        needed = self.min_lidars
        return f"needs {needed} Lidars" if needed > n_lidars else None


@dataclass(frozen=True)
class ScenarioTask:
    """What a worker gets: the scenario, its stored dataset (``None``: record it), the
    estimators still to run on it and whether their maps are scored."""

    scenario: Scenario
    estimators: tuple[EstimatorSpec, ...]
    dataset: SensorDataset | None = None
    score_maps: bool = True


@dataclass
class ScenarioOutcome:
    """What a worker returns; ``failures`` maps a stage (``record``, ``map reference`` or an
    estimator name) to the error it raised, so one broken estimator does not stop the run;
    ``seconds`` is the worker's wall time [s] per kind of work (:data:`STAGES`)."""

    scenario: Scenario
    dataset: SensorDataset | None
    recorded: bool
    traces: list[tuple[TraceDataset, dict[str, float]]] = field(default_factory=list)
    failures: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    cpu_seconds: float = 0.0  # CPU time of the worker process on the whole task [s]

    def timed(self, stage: str, started: float) -> None:
        """Add the time since ``started`` (``time.perf_counter()``) to ``stage``."""
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - started


#: Kinds of worker time reported in :attr:`RunSummary.seconds`: simulating scenarios, running
#: the estimators (their ``update`` calls and setup), the per-scenario map reference and the
#: per-trace map scores.
STAGES = ("record", "estimators", "map reference", "map scores")


def run_scenario_task(task: ScenarioTask) -> ScenarioOutcome:
    """Record (if needed) and replay one scenario, scoring each trace and the map its poses
    yield (the map reference, and the scores of the map at the true poses, stored with every
    trace as ``<metric>_true_poses``, are computed once here for all estimators); runs in a
    worker, touches no database."""
    dataset, recorded, recorded_movers = task.dataset, False, None
    outcome = ScenarioOutcome(task.scenario, None, False)
    if dataset is None:
        started = time.perf_counter()
        try:
            (dataset, recorded_movers), recorded = record_with_movers(task.scenario), True
        except Exception:  # reported per stage; the rest of the run goes on
            outcome.failures["record"] = traceback.format_exc(limit=-6)
            return outcome
        finally:
            outcome.timed("record", started)
    outcome.dataset, outcome.recorded = (dataset if recorded else None), recorded
    reference, ceiling, car_frame = None, {}, None
    with_movers = bool(task.scenario.config.get("moving_obstacles"))
    if task.estimators and task.score_maps:
        started = time.perf_counter()
        try:
            reference = map_reference(dataset)
            if reference is not None and len(reference.circles) and not with_movers:
                # the scans' obstacles, detected once and placed at each estimate of the poses
                car_frame = car_frame_obstacles(
                    list(dataset.observations())[::OBSTACLE_STRIDE], dataset.setup)
            if reference is not None:  # the mapper's own score, at the true poses
                ceiling = {f"{name}_true_poses": value for name, value in
                           score_map(reference, dataset.poses, dataset,
                                     label_movers=with_movers, car_frame=car_frame).items()}
        except Exception:  # the trajectories are still scored, without map metrics
            outcome.failures["map reference"] = traceback.format_exc(limit=-6)
        outcome.timed("map reference", started)
    movers = None
    if task.estimators and task.score_maps and with_movers:
        started = time.perf_counter()
        try:  # a stored dataset lacks them: drive it again
            movers = (recorded_movers if recorded_movers is not None
                      else mover_truth(task.scenario, dataset))
        except Exception:  # the trajectories are still scored, without tracker metrics
            outcome.failures["movers"] = traceback.format_exc(limit=-6)
        outcome.timed("map reference", started)
    for spec in task.estimators:
        started = time.perf_counter()
        try:
            trace = replay(dataset, spec.name, spec.params, resolved_params=spec.resolved_params)
            metrics = score(trace, dataset.poses)
        except Exception:  # a broken estimator must not sink the others
            outcome.failures[spec.name] = traceback.format_exc(limit=-6)
            continue
        finally:
            outcome.timed("estimators", started)
        if reference is not None:
            started = time.perf_counter()
            try:
                metrics.update(score_map(reference, trace.poses, dataset,
                                         label_movers=with_movers, car_frame=car_frame),
                               **ceiling)
                if movers is not None:
                    metrics.update(score_movers(dataset, trace.poses, movers))
            except Exception:  # e.g. poses far outside the world: the trace is kept unmapped
                outcome.failures[f"{spec.name} map"] = traceback.format_exc(limit=-6)
            outcome.timed("map scores", started)
        outcome.traces.append((trace, metrics))
    return outcome


@dataclass(frozen=True)
class RealLogTask:
    log: RealLog
    estimator: EstimatorSpec


def run_real_log_task(task: RealLogTask) -> ScenarioOutcome:
    """Run one estimator over a real log and score it with the relations metric
    (Kümmerle et al. 2009): mean translational [m] and rotational [deg] relation errors."""
    from estimators.datasets.real_log import run_on_log, score_relations
    from estimators.registry import make

    log, spec = task.log, task.estimator
    outcome = ScenarioOutcome(log.scenario, None, False)
    started = time.perf_counter()
    try:
        run = run_on_log(make(spec.name, **dict(spec.params)), log.load(), limit=log.scans)
        metrics: dict[str, float] = {"ms_per_step": 1e3 * run.seconds_per_scan}
        for subset, summary in score_relations(run, log.relations()).items():
            metrics.update({
                f"relations_{subset}_translation_m": summary.translation_mean,
                f"relations_{subset}_rotation_deg": summary.rotation_mean,
                f"relations_{subset}_failure_rate": summary.failure_rate,
                f"relations_{subset}_count": float(summary.count),
            })
        step_ms = np.full(len(run.times), 1e3 * run.seconds_per_scan)
        trace = TraceDataset(spec.name, spec.resolved_params, run.times, run.poses, step_ms)
        outcome.traces.append((trace, metrics))
    except Exception:  # a broken estimator: reported, not fatal
        outcome.failures[spec.name] = traceback.format_exc(limit=-6)
    outcome.timed("estimators", started)
    return outcome


def run_task(task: ScenarioTask | RealLogTask) -> ScenarioOutcome:
    """Run one task of either kind (what is sent to the executor), noting its CPU time."""
    started = time.process_time()
    if isinstance(task, RealLogTask):
        outcome = run_real_log_task(task)
    else:
        outcome = run_scenario_task(task)
    outcome.cpu_seconds = time.process_time() - started
    return outcome
