"""What the leaderboard command draws and publishes after the tables: every figure
(:func:`draw_all`: Fig. 8, the maps, error over distance, the real-log relation errors, cost
against accuracy) and the self-contained ``report.html`` of the run (:func:`publish_report`).
"""

from __future__ import annotations

import shlex
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.figures import draw_figure_8, draw_map_figure
from estimators.leaderboard.matrix import Group
from estimators.leaderboard.plots import (
    draw_relation_histograms,
    draw_segment_errors,
    draw_speed_accuracy,
    relation_error_samples,
)
from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.records import Scenario, TraceRecord
from estimators.leaderboard.report import write_report
from estimators.leaderboard.tasks import EstimatorSpec
from estimators.leaderboard.workers import process_pool

#: Each figure's caption in the report, by file name.
CAPTIONS: dict[str, str] = {
    "fig8_traces.png": "Fig. 8: every estimator's trace over the map (truth black) and its "
                       "position error over the distance travelled, one run per group.",
    "fig8_lidar_image.png": "Fig. 8: the eq.-5 image of one scan, sensor frame.",
    "maps.png": "Occupancy maps: the true map and the maps built at the best estimator's and "
                "the paper estimator's poses.",
    "segment_errors.png": "Relative error over segments of growing length (KITTI-style).",
    "speed_accuracy.png": "Cost against accuracy, one point per estimator.",
    "relation_errors.png": "Real log: the distribution of each estimator's relation errors.",
}


def draw_all(db: ExperimentDatabase, groups: Sequence[Group],
             scenarios: dict[str, list[Scenario]],
             records: dict[tuple[Scenario, str], TraceRecord], specs: Sequence[EstimatorSpec],
             rows: Sequence[Mapping[str, Any]], logs: Sequence[RealLog], out: Path,
             workers: int = 1) -> list[Path]:
    """Every figure of the run into ``out`` (PNG + SVG each); returns the files written, in
    the same order whatever ``workers``: with more than one, the figures are drawn by that many
    processes at once (each opens the database again, read only; a figure takes 1-4 s, most of
    it matplotlib's PNG and SVG rendering). Raises ImportError without matplotlib."""
    import matplotlib  # noqa: F401  (fail early, with the caller's hint, when it is missing)

    names = [spec.name for spec in specs]
    every = [s for group in groups for s in scenarios[group.name]]
    jobs: list[tuple[Callable[..., list[Path]], bool, tuple[Any, ...]]] = [  # (draw, db?, args)
        (draw_figure_8, True, (groups, scenarios, records, specs, out)),
        (draw_map_figure, True, (groups, scenarios, records,
                                 [row["estimator"] for row in rows], out)),
        (draw_segment_errors, True, (every, names, records, out)),
        (draw_speed_accuracy, False, (list(rows), out)),
    ]
    for log in logs[:1]:
        samples = relation_error_samples(db, log.scenario, log.relations(), names, records)
        jobs.append((draw_relation_histograms, False, (samples, log.name.upper(), out)))
    if workers <= 1:
        return [path for draw, with_db, args in jobs
                for path in (draw(db, *args) if with_db else draw(*args))]
    with process_pool(min(workers, len(jobs))) as pool:
        futures = [pool.submit(_draw, draw, db.path if with_db else None, args)
                   for draw, with_db, args in jobs]
        return [path for future in futures for path in future.result()]


def _draw(draw: Callable[..., list[Path]], db_path: Path | None,
          args: tuple[Any, ...]) -> list[Path]:
    """One figure job in a worker process: ``draw(db, *args)`` on the database at ``db_path``
    opened again (``draw(*args)`` without one)."""
    if db_path is None:
        return draw(*args)
    with ExperimentDatabase(db_path, verify=False) as db:
        return draw(db, *args)


def publish_report(out: Path, written: Sequence[Path], config: Mapping[str, object],
                   argv: Sequence[str]) -> Path:
    """``out/report.html`` from the tables and PNG figures this run wrote (``written``):
    ``leaderboard.md``, ``table1.md`` when written, the figures in :data:`CAPTIONS` order."""
    names = {path.name for path in written}
    board = (out / "leaderboard.md").read_text(encoding="utf-8")
    title, _, board = board.partition("\n")
    table_one = None
    if "table1.md" in names:
        table_one = (out / "table1.md").read_text(encoding="utf-8").partition("\n")[2]
    figures = {out / name: caption for name, caption in CAPTIONS.items() if name in names}
    command = shlex.join(["python", "-m", "estimators.leaderboard", *argv])
    settings = {key: value for key, value in config.items() if key != "argv"}
    return write_report(out / "report.html", title=title.lstrip("# "), board=board,
                        table_one=table_one, figures=figures, config=settings, command=command)
