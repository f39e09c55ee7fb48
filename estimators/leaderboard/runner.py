"""The scenario runner: record missing sensor datasets, replay them through every estimator.

Work is split by scenario: one task records the scenario's sensor dataset if the database lacks
it (or receives the stored one) and replays it through every estimator that has no trace there
yet. Tasks go to any *executor*: an object with ``submit(fn, *args) -> future`` whose futures
have ``done()`` and ``result()``. That covers

* ``None``: run in this process, one task after another;
* ``concurrent.futures.ProcessPoolExecutor(n)``: a local process pool;
* ``dask.distributed.Client(...)`` (or ``client.get_executor()``): a Dask cluster;
* Ray, through a two-line adapter over ``ray.util`` / object refs::

      class RayExecutor:
          def submit(self, fn, *args):
              return ray.remote(fn).remote(*args).future()  # a concurrent.futures.Future

Design choice: **workers return results and only this (parent) process writes the database.**
SQLite allows one writer at a time, cluster workers often share no filesystem with the
database, and a stateless worker can be killed or retried freely. Each finished scenario is
committed as it arrives, one transaction per dataset and per trace, so killing the run (or a
worker) loses only the scenarios still in flight; a re-run skips everything already stored.
At most ``max_in_flight`` tasks are submitted at once, which bounds the memory held by
datasets travelling to and from workers.

A :class:`SideRun` replays extra scenarios through a subset of the estimators in the same
queue (Table I's world-aligned recordings). An estimator that needs more Lidars than a real
log has (:attr:`estimators.base.Estimator.min_lidars`) is decided against before any work: it
is listed in :attr:`RunSummary.not_applicable`, never run, never a failure, never retried.
What a worker runs is :mod:`estimators.leaderboard.tasks`.
"""

from __future__ import annotations

import concurrent.futures as cf
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.records import Scenario, package_version
from estimators.leaderboard.tasks import (
    EstimatorSpec,
    RealLogTask,
    ScenarioOutcome,
    ScenarioTask,
    run_task,
)
from estimators.leaderboard.workers import stop_workers
from lidar_env.core import ConfigError


class FutureLike(Protocol):
    def done(self) -> bool: ...

    def result(self, timeout: float | None = None) -> Any: ...


class ExecutorLike(Protocol):
    def submit(self, fn: Callable[..., Any], /, *args: Any) -> FutureLike: ...


class RunInterrupted(RuntimeError):
    """The executor failed (e.g. a worker process died); committed scenarios are kept."""


class RunCancelled(KeyboardInterrupt):
    """Ctrl-C during a run: the scenarios finished so far are committed, those in flight are
    not. The message is the one line the command line prints (then it exits 130)."""

    def __init__(self, stored: int) -> None:
        super().__init__(f"interrupted; {stored} scenarios stored; re-run to resume")
        self.stored = stored


@dataclass(frozen=True)
class SideRun:
    """Scenarios replayed through some estimators only, their maps not scored: e.g. Table I's
    world-aligned recordings, which only the paper's translation-only estimators need."""

    scenarios: tuple[Scenario, ...]
    estimators: tuple[EstimatorSpec, ...]


@dataclass
class RunSummary:
    """Counts of one :func:`run_scenarios` call."""

    scenarios: int = 0
    skipped: int = 0
    recorded: int = 0
    traces: int = 0
    failures: dict[str, str] = field(default_factory=dict)
    #: "<scenario>: <estimator>" -> why it was not run (e.g. "needs 2 Lidars"); not failures
    not_applicable: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0  # wall time of the call
    stage_seconds: dict[str, float] = field(default_factory=dict)  # worker time per stage
    cpu_seconds: float = 0.0  # workers' CPU time over all tasks: the run's work, whatever load
    committed: int = 0  # scenario outcomes committed by this run


def _pending_task(db: ExperimentDatabase, scenario: Scenario,
                  estimators: Sequence[EstimatorSpec],
                  score_maps: bool = True) -> ScenarioTask | None:
    """The task still to do for ``scenario``, or ``None`` when everything is stored."""
    version = package_version()
    missing = tuple(spec for spec in estimators
                    if not db.has_trace(scenario, spec.name, spec.resolved_params, version))
    has_dataset = db.has_sensor_dataset(scenario)
    if has_dataset and not missing:
        return None
    dataset = db.load_sensor_dataset(scenario) if has_dataset and missing else None
    return ScenarioTask(scenario, missing, dataset, score_maps)


def _still_pending(db: ExperimentDatabase,
                   task: ScenarioTask | RealLogTask) -> ScenarioTask | RealLogTask | None:
    """``task`` as it stands now: another process on the same database may have stored part
    or all of it since the run was planned (``None``: all of it)."""
    if isinstance(task, RealLogTask):
        spec, scenario = task.estimator, task.log.scenario
        stored = db.has_trace(scenario, spec.name, spec.resolved_params, package_version())
        return None if stored else task
    version = package_version()
    missing = tuple(spec for spec in task.estimators
                    if not db.has_trace(task.scenario, spec.name, spec.resolved_params, version))
    if task.dataset is None and db.has_sensor_dataset(task.scenario):
        return _pending_task(db, task.scenario, missing, task.score_maps)  # gets the stored one
    if task.dataset is not None and not missing:
        return None
    return replace(task, estimators=missing)


def _commit(db: ExperimentDatabase, outcome: ScenarioOutcome, summary: RunSummary) -> None:
    recorded = outcome.dataset is not None and db.save_sensor_dataset(outcome.scenario,
                                                                        outcome.dataset)
    new = db.save_traces(outcome.scenario, outcome.traces) if outcome.traces else []
    summary.recorded += int(recorded)
    summary.traces += sum(trace_id is not None for trace_id in new)
    if (outcome.dataset is not None or new) and not recorded and not any(
            trace_id is not None for trace_id in new):
        summary.skipped += 1  # another process stored all of it while this one worked
    for stage, error in outcome.failures.items():
        summary.failures[f"{outcome.scenario.label}: {stage}"] = error
    for stage, seconds in outcome.seconds.items():
        summary.stage_seconds[stage] = summary.stage_seconds.get(stage, 0.0) + seconds
    summary.cpu_seconds += outcome.cpu_seconds
    summary.committed += 1


def _first_done(pending: set[Any]) -> set[Any]:
    """Block until at least one future is done; return the done ones."""
    if all(isinstance(future, cf.Future) for future in pending):
        done, _ = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
        return set(done)
    while True:  # Dask / Ray futures: poll, they all have done()
        done = {future for future in pending if future.done()}
        if done:
            return done
        time.sleep(0.01)


def _scenario_tasks(db: ExperimentDatabase, scenarios: Iterable[Scenario],
                    estimators: Sequence[EstimatorSpec], summary: RunSummary,
                    on_done: Callable[[Scenario], None] | None,
                    score_maps: bool = True) -> list[ScenarioTask]:
    """The pending scenario tasks; complete scenarios are counted as skipped."""
    todo = []
    for scenario in scenarios:
        summary.scenarios += 1
        task = _pending_task(db, scenario, estimators, score_maps)
        if task is None:
            summary.skipped += 1
            if on_done is not None:
                on_done(scenario)
        else:
            todo.append(task)
    return todo


def _real_log_tasks(db: ExperimentDatabase, logs: Iterable[RealLog],
                    estimators: Sequence[EstimatorSpec], summary: RunSummary,
                    on_done: Callable[[Scenario], None] | None) -> list[RealLogTask]:
    """The pending (log, estimator) tasks; stored traces are counted as skipped, estimators
    that need more Lidars than the log has as not applicable (never run, never failed)."""
    version = package_version()
    todo = []
    for log in logs:
        for spec in estimators:
            summary.scenarios += 1
            reason = spec.not_applicable(log.n_lidars)
            if reason is not None:
                summary.not_applicable[f"{log.scenario.label}: {spec.name}"] = reason
            elif db.has_trace(log.scenario, spec.name, spec.resolved_params, version):
                summary.skipped += 1
            else:
                todo.append(RealLogTask(log, spec))
                continue
            if on_done is not None:
                on_done(log.scenario)
    return todo


def run_scenarios(
    db: ExperimentDatabase,
    scenarios: Iterable[Scenario],
    estimators: Sequence[EstimatorSpec],
    executor: ExecutorLike | None = None,
    *,
    max_in_flight: int = 8,
    on_done: Callable[[Scenario], None] | None = None,
) -> RunSummary:
    """Make sure every scenario has a sensor dataset and a scored trace per estimator.

    Scenarios already complete in ``db`` are skipped; the rest go to ``executor`` (``None``:
    this process) and are committed one by one as they finish. ``on_done`` is called after
    each scenario is settled (e.g. to advance a progress bar). Raises :class:`RunInterrupted`
    when the executor breaks (a killed worker); everything committed before stays.
    """
    return run_matrix(db, scenarios, (), estimators, executor, max_in_flight=max_in_flight,
                      on_done=on_done)


def run_real_logs(
    db: ExperimentDatabase,
    logs: Iterable[RealLog],
    estimators: Sequence[EstimatorSpec],
    executor: ExecutorLike | None = None,
    *,
    max_in_flight: int = 8,
    on_done: Callable[[Scenario], None] | None = None,
) -> RunSummary:
    """Score every estimator on recorded logs (relations metric), skipping stored traces.

    One task per (log, estimator), since a log is one long sequence; tasks, commits and
    failures behave as in :func:`run_scenarios`.
    """
    return run_matrix(db, (), logs, estimators, executor, max_in_flight=max_in_flight,
                      on_done=on_done)


def run_matrix(
    db: ExperimentDatabase,
    scenarios: Iterable[Scenario],
    logs: Iterable[RealLog],
    estimators: Sequence[EstimatorSpec],
    executor: ExecutorLike | None = None,
    *,
    side_runs: Iterable[SideRun] = (),
    max_in_flight: int = 8,
    on_done: Callable[[Scenario], None] | None = None,
) -> RunSummary:
    """:func:`run_scenarios`, then each of ``side_runs`` (its scenarios through its own
    estimators, no map scores), then :func:`run_real_logs`, through one queue: the short
    tasks go last, so they fill the workers that finish their scenarios first instead of
    waiting for the slowest scenario."""
    summary = RunSummary()
    todo: list[ScenarioTask | RealLogTask] = []
    todo += _scenario_tasks(db, scenarios, estimators, summary, on_done)
    for side in side_runs:
        todo += _scenario_tasks(db, side.scenarios, side.estimators, summary, on_done,
                                score_maps=False)
    todo += _real_log_tasks(db, logs, estimators, summary, on_done)
    return _execute(db, todo, executor, summary, max_in_flight, on_done)


def _refresh(db: ExperimentDatabase, task: ScenarioTask | RealLogTask, summary: RunSummary,
             on_done: Callable[[Scenario], None] | None) -> ScenarioTask | RealLogTask | None:
    """:func:`_still_pending`, counting a task another process finished as already stored."""
    current = _still_pending(db, task)
    if current is None:
        summary.skipped += 1
        if on_done is not None:
            on_done(task.log.scenario if isinstance(task, RealLogTask) else task.scenario)
    return current


def _execute(db: ExperimentDatabase, todo: Sequence[ScenarioTask | RealLogTask],
             executor: ExecutorLike | None, summary: RunSummary, max_in_flight: int,
             on_done: Callable[[Scenario], None] | None) -> RunSummary:
    """Run ``todo`` (here or on ``executor``), committing each outcome."""
    if max_in_flight < 1:
        raise ConfigError(f"max_in_flight: expected an integer >= 1, got {max_in_flight}")
    start = time.perf_counter()
    try:
        if executor is None:
            for planned in todo:
                task = _refresh(db, planned, summary, on_done)
                if task is None:
                    continue
                outcome = run_task(task)
                _commit(db, outcome, summary)
                if on_done is not None:
                    on_done(outcome.scenario)
        else:
            _run_on(executor, todo, db, summary, max_in_flight, on_done)
    except KeyboardInterrupt:
        # each commit is one transaction, so what is stored is whole; stop the workers now
        stop_workers(executor)
        raise RunCancelled(summary.committed) from None
    summary.seconds = time.perf_counter() - start
    return summary


def _run_on(executor: ExecutorLike, todo: Sequence[ScenarioTask | RealLogTask],
            db: ExperimentDatabase, summary: RunSummary,
            max_in_flight: int, on_done: Callable[[Scenario], None] | None) -> None:
    queue = list(reversed(todo))
    pending: set[Any] = set()
    failure: Exception | None = None
    lost = 0
    while (queue or pending) and failure is None:
        # the tasks catch their own errors: whatever is raised here is the executor's
        try:
            while queue and len(pending) < max_in_flight:
                task = _refresh(db, queue.pop(), summary, on_done)
                if task is not None:
                    pending.add(executor.submit(run_task, task))
            done = _first_done(pending)
        except Exception as error:
            failure, done = error, set()
        for future in done:
            pending.discard(future)
            try:
                outcome = future.result()
            except Exception as error:
                failure, lost = failure or error, lost + 1
                continue
            _commit(db, outcome, summary)  # finished work is kept even when others failed
            if on_done is not None:
                on_done(outcome.scenario)
    if failure is not None:
        for future in pending:
            future.cancel()
        raise RunInterrupted(
            f"the executor failed ({type(failure).__name__}: {failure}); {summary.recorded} "
            f"sensor datasets and {summary.traces} traces of this run are committed, "
            f"{len(pending) + len(queue) + lost} tasks are not: re-run to resume"
        ) from failure
