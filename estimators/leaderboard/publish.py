"""What the leaderboard command draws and publishes after the tables: every figure
(:func:`draw_all`: Fig. 8, the maps, error over distance, the real-log relation errors, cost
against accuracy) and the self-contained ``report.html`` of the run (:func:`publish_report`).
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
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
             rows: Sequence[Mapping[str, Any]], logs: Sequence[RealLog], out: Path) -> list[Path]:
    """Every figure of the run into ``out`` (PNG + SVG each); returns the files written.
    Raises ImportError without matplotlib."""
    import matplotlib  # noqa: F401  (fail early, with the caller's hint, when it is missing)

    names = [spec.name for spec in specs]
    written = draw_figure_8(db, groups, scenarios, records, specs, out)
    written += draw_map_figure(db, groups, scenarios, records,
                               [row["estimator"] for row in rows], out)
    every = [s for group in groups for s in scenarios[group.name]]
    written += draw_segment_errors(db, every, names, records, out)
    written += draw_speed_accuracy(rows, out)
    for log in logs[:1]:
        samples = relation_error_samples(db, log.scenario, log.relations(), names, records)
        written += draw_relation_histograms(samples, log.name.upper(), out)
    return written


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
